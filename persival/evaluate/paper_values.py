"""The paper's own figures (its FE model of the arm, not ours), as docs/theory.md, 8.2 and 8.4 use them.

Keys follow the evaluation tables' column keys, so a paper row sits under our columns.
"""

from __future__ import annotations

__all__ = ["IN_TRAINING", "RANDOM_ACTIVATIONS", "RANDOM_ANGLES", "ERROR_PROPAGATION", "PROTOTYPES", "SPEED"]

_WHO = {"network": "paper's NN (their arm)", "scope": "biceps"}

# "MaxAE 0.37 mm (0.38 %), mean 0.014 mm ... an average over all evaluated states" (after 2000 epochs)
IN_TRAINING = [{**_WHO, "mean MaxAE_mm": 0.37, "mean MaxRE_pct": 0.38, "mean MAE_mm": 0.014}]
# Table "Out-of-training accuracy"; the 300-draw stopping rule
RANDOM_ACTIVATIONS = [{**_WHO, "max MaxAE_mm": 11.96, "max MaxRE_pct": 13.28, "mean MAE_mm": 2.15, "mean MRE_pct": 1.59}]
RANDOM_ANGLES = [{**_WHO, "max MaxAE_mm": 3.75, "max MaxRE_pct": 5.69, "mean MAE_mm": 0.97, "mean MRE_pct": 0.57}]
# Table "Error propagation test": 25 random activations solved by their FE model
ERROR_PROPAGATION = [
    {"surrogate": "paper's SG (their arm)", "scope": "biceps", "tested_on": "25 FE states", "states": 25,
     "max MaxAE_mm": 17.79, "max MaxRE_pct": 10.14, "mean MAE_mm": 2.86, "mean MRE_pct": 1.52},
    {"surrogate": "paper's NN (their arm)", "scope": "biceps", "tested_on": "25 FE states", "states": 25,
     "max MaxAE_mm": 18.28, "max MaxRE_pct": 9.38, "mean MAE_mm": 2.84, "mean MRE_pct": 1.45},
]
# Table "Prototyping": 10 hidden layers, the x coordinate of the biceps (2809 nodes), in-training MAE after 10 epochs
PROTOTYPES = [
    {"shape": "T-shaped", "hidden_layers": 10, "parameters": 17_154, "mae_mm": 430.0},
    {"shape": "rectangular", "hidden_layers": 10, "parameters": 71_056_494, "mae_mm": 2.4},
    {"shape": "triangular", "hidden_layers": 10, "parameters": 26_103_046, "mae_mm": 2.2},
]
# Table "Average evaluation times" (batch 1, mean of 1000, Intel i5 6 cores 3 GHz / GTX 1650)
SPEED = [
    {"variant": "three separate nets", "runtime": "Keras (paper)", "batch": 1, "ms_per_call": 13.65},
    {"variant": "three separate nets", "runtime": "Keras, GPU (paper)", "batch": 1, "ms_per_call": 4.05},
    {"variant": "combined", "runtime": "Keras (paper)", "batch": 1, "ms_per_call": 13.34},
    {"variant": "combined", "runtime": "Keras, GPU (paper)", "batch": 1, "ms_per_call": 3.48},
    {"variant": "combined", "runtime": "TFLite (paper)", "batch": 1, "ms_per_call": 9.88},
]
