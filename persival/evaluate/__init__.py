"""PerSival stage: evaluate."""
