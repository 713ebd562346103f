"""Every script in docs/examples runs as a user would run it, and prints the number it promises.

Each script runs in its own process (the repository on PYTHONPATH, a fresh output folder as its
argument, the test run's state cache inherited from tests/conftest.py); the test reads one
labelled number from its output and checks it. The doctest examples of the main public classes
run here too.
"""

from __future__ import annotations

import doctest
import importlib
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "docs" / "examples"


def run_example(name: str, out: Path) -> str:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    result = subprocess.run([sys.executable, "-W", "ignore::DeprecationWarning", str(EXAMPLES / name), str(out)],
                            capture_output=True, text=True, env=env, timeout=900, cwd=out)
    assert result.returncode == 0, f"{name} failed:\n{result.stdout[-2000:]}\n{result.stderr[-4000:]}"
    return result.stdout


def number(stdout: str, label: str) -> float:
    """The number after ``label:`` on a line of the script's output."""
    match = re.search(rf"^{re.escape(label)}: ([-+0-9.eE]+)", stdout, re.MULTILINE)
    assert match, f"no line '{label}: <number>' in:\n{stdout}"
    return float(match.group(1))


# script -> (label of the printed number, the check it must pass, why)
CHECKS = {
    "fit_sparse_grid.py": ("worst MaxAE", lambda x: 1.0 < x < 20.0,
                           "a level-1 grid interpolates random states to millimetres, not exactly"),
    "inverse_problem.py": ("largest angle miss", lambda x: 0.0 <= x < 1e-3,
                           "least effort meets every reachable target exactly"),
    "serve.py": ("server vs Python", lambda x: 0.0 <= x < 1e-3,
                 "the server answers what the exported network computes"),
    "train_export.py": ("ONNX vs PyTorch", lambda x: 0.0 <= x < 1e-3,
                        "the float32 ONNX tier is the trained network"),
    "tracker_client.py": ("largest quaternion angle error", lambda x: 0.0 <= x < 1e-3,
                          "the angle between the segments' axes is the elbow angle sent, whatever the forearm's twist"),
    "simulate_state.py": ("elbow angle", lambda x: 115.0 < x < 132.0,
                          "the biceps at half activation flexes the arm from 32 deg to about 124 deg"),
}
SLOW = {"simulate_state.py", "train_export.py"}  # meshing the coarse arm; torch training and the export


def test_every_example_is_checked():
    assert {p.name for p in EXAMPLES.glob("*.py")} == set(CHECKS)


@pytest.mark.parametrize("script", [pytest.param(s, marks=pytest.mark.slow) if s in SLOW else s for s in CHECKS])
def test_example_runs_and_prints_its_number(script, tmp_path):
    label, check, why = CHECKS[script]
    value = number(run_example(script, tmp_path), label)
    assert check(value), f"{script}: {label} = {value}, expected: {why}"


DOCTEST_MODULES = ["persival.vocabulary", "persival.surrogate.sparse_grid", "persival.surrogate.dataset",
                   "persival.campaign.design", "persival.surrogate.reduction", "persival.file_header"]


@pytest.mark.parametrize("module", DOCTEST_MODULES)
def test_doctest_examples(module):
    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0, f"{module} has no >>> examples"
    assert result.failed == 0
