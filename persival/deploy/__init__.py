"""PerSival stage: deploy."""
