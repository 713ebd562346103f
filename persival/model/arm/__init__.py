"""The assembled arm: the model file and its packaged variants, the meshed body, each muscle as its
own FE problem, the joint's balance, and the caches of solved states (docs/theory.md, section 3)."""
