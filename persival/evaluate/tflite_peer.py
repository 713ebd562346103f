"""The paper-architecture peer in Keras / TensorFlow Lite (docs/theory.md, 8.4), timed in a child process.

The paper ran its combined net (common input, three per-coordinate nets, concatenated output)
under Keras and TensorFlow Lite. This module rebuilds that net for 5 -> ``n_nodes`` with the
widths of docs/theory.md, 7.2 in Keras 3, converts it to a float32 TFLite flatbuffer and times batch 1 (and
batch 64) under Keras and under the TFLite interpreter (XNNPACK) with 1 and 2 threads.

TensorFlow is an optional extra (``pip install -e '.[peer]'``) and runs in its own process
(``python -m persival.evaluate.tflite_peer``): it never shares a process with PyTorch, and
the benchmark reads one JSON line from it.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["peer_available", "INSTALL_HINT", "main"]

INSTALL_HINT = "the TFLite peer is not installed: pip install -e '.[peer]' (tensorflow-cpu)"


def peer_available() -> bool:
    return importlib.util.find_spec("tensorflow") is not None


def _keras_paper_net(n_nodes: int, n_mid: int, activation: str):
    import keras

    from persival.surrogate.networks import paper_widths

    widths = paper_widths(5, n_mid, n_nodes, 5)
    alpha = keras.Input((5,), name="activations")
    outputs = []
    for axis in "xyz":
        h = alpha
        for k, w in enumerate(widths):
            h = keras.layers.Dense(w, activation=activation, name=f"{axis}_hidden{k}")(h)
        outputs.append(keras.layers.Dense(n_nodes, name=f"{axis}_out")(h))
    model = keras.Model(alpha, keras.layers.Concatenate(name="positions")(outputs))
    return model, widths


def _interpreter(content: bytes, threads: int):
    try:
        from ai_edge_litert.interpreter import Interpreter
    except ImportError:
        import warnings

        import tensorflow as tf

        warnings.filterwarnings("ignore", message=".*tf.lite.Interpreter is deprecated.*")
        Interpreter = tf.lite.Interpreter  # noqa: N806
    return Interpreter(model_content=content, num_threads=threads)


def _time(fn, reps: int, budget_s: float) -> dict:
    from persival.evaluate.timing import time_calls  # torch-free at import: safe beside TensorFlow

    return time_calls(fn, reps, warmup=5, budget_s=budget_s)


def run_peer(n_nodes: int = 2809, n_mid: int = 700, activation: str = "silu", reps: int = 1000,
             budget_s: float = 8.0, batches=(1, 64), threads=(1, 2)) -> dict:
    import numpy as np
    import tensorflow as tf

    model, widths = _keras_paper_net(n_nodes, n_mid, activation)
    rows = []
    for batch in batches:
        x = tf.constant(np.full((batch, 5), 0.5, np.float32))
        timing = _time(lambda x=x: model(x, training=False), reps, budget_s)
        rows.append({"runtime": f"Keras {tf.keras.__version__ if hasattr(tf.keras, '__version__') else ''}".strip(),
                     "threads": "default", "batch": batch, **timing})
    t0 = time.perf_counter()
    content = tf.lite.TFLiteConverter.from_keras_model(model).convert()
    convert_s = time.perf_counter() - t0
    for n_threads in threads:
        for batch in batches:
            it = _interpreter(content, n_threads)
            inp = it.get_input_details()[0]
            it.resize_tensor_input(inp["index"], [batch, 5])
            it.allocate_tensors()
            x = np.random.default_rng(0).uniform(0, 1, (batch, 5)).astype(np.float32)

            def call(it=it, x=x, index=inp["index"]):
                it.set_tensor(index, x)
                it.invoke()
            rows.append({"runtime": "TFLite (XNNPACK)", "threads": n_threads, "batch": batch,
                         **_time(call, reps, budget_s)})
    params = int(model.count_params())
    return {"tensorflow": tf.__version__, "n_nodes": n_nodes, "widths": widths, "parameters": params,
            "activation": activation, "tflite_bytes": len(content), "convert_s": convert_s, "rows": rows}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, default=2809)
    parser.add_argument("--mid", type=int, default=700)
    parser.add_argument("--activation", default="silu")
    parser.add_argument("--reps", type=int, default=1000)
    parser.add_argument("--budget", type=float, default=8.0, help="seconds per row at most (then fewer calls)")
    parser.add_argument("--batches", default="1,64")
    args = parser.parse_args(argv)
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")
    with tempfile.TemporaryDirectory() as tmp:
        os.environ.setdefault("TMPDIR", tmp)
        result = run_peer(args.nodes, args.mid, args.activation, args.reps, args.budget,
                          tuple(int(b) for b in args.batches.split(",")))
    sys.stdout.write("\n" + json.dumps(result) + "\n")
    return 0


def run_in_subprocess(n_nodes: int = 2809, n_mid: int = 700, activation: str = "silu", reps: int = 1000,
                      budget_s: float = 8.0, timeout_s: float = 900.0, batches=(1, 64)) -> dict:
    """Run the peer in a child process; returns its JSON result or raises RuntimeError with its stderr tail."""
    import subprocess

    env = {**os.environ, "TF_CPP_MIN_LOG_LEVEL": "3", "PYTHONWARNINGS": "ignore"}
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    cmd = [sys.executable, "-m", "persival.evaluate.tflite_peer", "--nodes", str(n_nodes), "--mid", str(n_mid),
           "--activation", activation, "--reps", str(reps), "--budget", str(budget_s),
           "--batches", ",".join(str(int(b)) for b in batches)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, env=env)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("{")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"the TFLite peer failed (exit {proc.returncode}): {proc.stderr.strip()[-400:]}")
    return json.loads(lines[-1])


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
