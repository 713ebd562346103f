"""PerSival stage: surrogate."""
