"""The continuum core: the constitutive law, tet10 elements, assembly, Newton, linear algebra and
penalty contact against rigid obstacles (docs/theory.md, sections 1-2). Knows nothing of arms."""
