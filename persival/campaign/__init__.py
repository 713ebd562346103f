"""PerSival stage: campaign."""
