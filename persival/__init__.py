"""PerSival: finite-element upper-limb model, sparse-grid and neural surrogates, deployment."""

__version__ = "0.1.0"
