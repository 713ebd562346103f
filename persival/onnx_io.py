"""Writing a PyTorch graph to ONNX and opening it with onnxruntime: one place for the exporter's
settings, used by every model the project ships (deformation, activation models).

The TorchScript exporter (``dynamo=False``): these graphs are dense products, gathers and
comparisons traced at one example, and every file is checked against its PyTorch graph right
after it is written (docs/deployment.md says why not the dynamo exporter yet). Its deprecation
warning is shown once per process, not muted: it says which exporter wrote the files.
"""

from __future__ import annotations

import warnings
from pathlib import Path

__all__ = ["OPSET", "export_graph", "onnx_session"]

OPSET = 17
_warned = False


def export_graph(module, example, path: str | Path, input_name, output_names: list[str], fold: bool = True,
                 dynamic_axes: dict | None = None) -> Path:
    """Trace ``module`` to ONNX at ``path``; ``example`` and ``input_name``: one tensor and name, or
    tuples of them. Every input and output has a dynamic batch axis 0 unless ``dynamic_axes`` says
    otherwise; ``fold``: constant folding at export (off keeps float16 weights and their casts,
    which the runtime folds when it loads the file)."""
    import torch

    global _warned
    examples = example if isinstance(example, tuple) else (example,)
    input_names = list(input_name) if isinstance(input_name, tuple) else [input_name]
    axes = {name: {0: "batch"} for name in input_names + list(output_names)}
    axes.update({name: axis for name, axis in (dynamic_axes or {}).items() if name in axes})
    with warnings.catch_warnings():
        if _warned:  # shown once per process: a pipeline writes a dozen files with the same exporter
            warnings.simplefilter("ignore", DeprecationWarning)
        # the tracer notes every strided Slice it cannot fold; each file is checked after export instead
        warnings.filterwarnings("ignore", message="Constant folding", category=UserWarning)
        torch.onnx.export(module.eval(), examples, str(path), input_names=input_names, output_names=list(output_names),
                          dynamic_axes=axes, opset_version=OPSET, dynamo=False, do_constant_folding=fold)
    _warned = True
    return Path(path)


def onnx_session(path: str | Path, threads: int | None = None):
    """An onnxruntime CPU session; ``threads``: intra- and inter-op threads (None: the runtime's default)."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    if threads is not None:
        options.intra_op_num_threads = threads
        options.inter_op_num_threads = threads
    options.log_severity_level = 3  # the optional load input is also an initializer: ORT warns about it at every load
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
