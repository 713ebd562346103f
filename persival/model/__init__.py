"""PerSival stage: model."""
