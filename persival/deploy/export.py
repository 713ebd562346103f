"""The portable export (docs/theory.md, 7.6; layout and contract: docs/deployment.md).

``export_model(surrogate, out, activation_model=...)`` writes the deformation network as ONNX
in three tiers (float32; float16 weights with float32 inputs and outputs; dynamic int8
quantization of the matrix products), the activation models, and ``metadata.json`` with the
surfaces, the skeleton, the reachable range and the provenance. Every tier is run once through
onnxruntime against the PyTorch graph it came from, and the differences go into the metadata:
float32 must agree within 1e-4 mm or the export fails. A graph that takes the load in the hand
(``load_kg``) is written twice: ``deformation.onnx`` with the load optional (0 kg by default, the
deployment contract: activations alone) and ``deformation_load.onnx`` with it a required input,
for runtimes that cannot feed an input backed by an initializer (onnxruntime-web).
"""

from __future__ import annotations

import datetime as _dt
import json
import logging
import shutil
import warnings
from pathlib import Path

import numpy as np
import torch

import persival
from persival.onnx_io import OPSET, export_graph, onnx_session
from persival.vocabulary import MUSCLES, UNITS

__all__ = ["export_model", "FORMAT_NAME", "FORMAT_VERSION", "OPSET", "FLOAT32_TOLERANCE_MM"]

FORMAT_NAME = "persival-export"
FORMAT_VERSION = 1
FLOAT32_TOLERANCE_MM = 1e-4
TIERS = ("float32", "float16", "int8")
LOAD_INPUT = "load_kg"  # optional second input of a graph that solves the joint equilibrium
LOAD_FILE = "deformation_load.onnx"  # the same graph with load_kg a required input
LOAD_PROBE_KG = 2.0  # the load the required-input file is checked at


def _onnx(module: torch.nn.Module, example, path: Path, input_name, output_names: list[str], fold: bool = True) -> None:
    """Trace ``module`` to ONNX (persival.onnx_io); the optional load has its own batch size: its
    default (one row, 0 kg) broadcasts over any batch."""
    export_graph(module, example, path, input_name, output_names, fold=fold, dynamic_axes={LOAD_INPUT: {0: "load_batch"}})


def _optional_load_input(path: Path) -> None:
    """Make the graph's ``load_kg`` input optional: an initializer of the same name (0 kg) is its
    default, so a client that feeds ``activations`` only (the deployment contract) still runs it."""
    import onnx
    from onnx import numpy_helper

    model = onnx.load(str(path))
    model.graph.initializer.append(numpy_helper.from_array(np.zeros((1, 1), dtype=np.float32), name=LOAD_INPUT))
    onnx.save(model, str(path))


def _tiers(float32: Path, tiers=TIERS) -> dict[str, Path]:
    """float16 and int8 variants next to the float32 file (those of ``tiers``)."""
    if tuple(tiers) == ("float32",):
        return {"float32": float32}
    import onnx
    from onnxconverter_common import float16
    from onnxruntime.quantization import QuantType, quantize_dynamic

    half = float32.with_name(float32.stem + ".float16.onnx")
    int8 = float32.with_name(float32.stem + ".int8.onnx")
    quantization_log = logging.getLogger()  # onnxruntime.quantization advises pre-processing on the root logger
    level = quantization_log.level
    with warnings.catch_warnings():
        # weights below float16's range are flushed to +-1e-7 and say so, once per weight
        warnings.filterwarnings("ignore", message="the float32 number", category=UserWarning)
        # Adds stay float32: they carry the reference coordinates (hundreds of mm) of the last bias
        model16 = float16.convert_float_to_float16(onnx.load(str(float32)), keep_io_types=True, op_block_list=["Add"])
        onnx.save(model16, str(half))
        quantization_log.setLevel(logging.ERROR)
        try:
            # per channel: the POD modes differ in scale by orders of magnitude
            quantize_dynamic(str(float32), str(int8), weight_type=QuantType.QInt8, per_channel=True)
        finally:
            quantization_log.setLevel(level)
    return {tier: path for tier, path in {"float32": float32, "float16": half, "int8": int8}.items() if tier in tiers}


def _check_tiers(files: dict[str, Path], graph, probe: np.ndarray, names: list[str],
                 tolerance_mm: float = FLOAT32_TOLERANCE_MM) -> dict:
    """Max |onnxruntime - torch| per tier and output, on the probe activations."""
    with torch.no_grad():
        inputs = (torch.as_tensor(probe, dtype=torch.float32),)
        ref = graph(*inputs, torch.zeros(len(probe), 1)) if _takes_load(graph) else graph(*inputs)
    ref = [r.numpy() for r in (ref if isinstance(ref, tuple) else (ref,))]
    out = {}
    for tier, path in files.items():
        got = onnx_session(path).run(None, {"activations": probe.astype(np.float32)})
        diffs = {name: float(np.abs(g - r).max()) for name, g, r in zip(names, got, ref)}
        out[tier] = {"file": path.name, "bytes": path.stat().st_size,
                     "max_abs_diff_vs_torch": diffs}
    worst = out["float32"]["max_abs_diff_vs_torch"]["positions"]
    if worst > tolerance_mm:
        raise RuntimeError(f"the float32 ONNX model differs from PyTorch by {worst:.2e} mm (tolerance {tolerance_mm:.0e})")
    return out


def _check_load_variant(path: Path, graph, probe: np.ndarray, names: list[str], tolerance_mm: float) -> dict:
    """Max |onnxruntime - torch| per output of the required-load file at LOAD_PROBE_KG in the hand."""
    load = np.full((len(probe), 1), LOAD_PROBE_KG, np.float32)
    with torch.no_grad():
        ref = graph(torch.as_tensor(probe, dtype=torch.float32), torch.as_tensor(load))
    ref = [r.numpy() for r in (ref if isinstance(ref, tuple) else (ref,))]
    got = onnx_session(path).run(None, {"activations": probe.astype(np.float32), LOAD_INPUT: load})
    diffs = {name: float(np.abs(g - r).max()) for name, g, r in zip(names, got, ref)}
    if diffs["positions"] > tolerance_mm:
        raise RuntimeError(f"{path.name} differs from PyTorch at {LOAD_PROBE_KG} kg by {diffs['positions']:.2e} mm "
                           f"(tolerance {tolerance_mm:.0e})")
    return {"file": path.name, "inputs": {"activations": [None, 5], LOAD_INPUT: [None, 1]}, "bytes": path.stat().st_size,
            "checked_at_load_kg": LOAD_PROBE_KG, "max_abs_diff_vs_torch": diffs}


def _export_deformation(surrogate, graph, folder: Path, names: list[str], probe: np.ndarray) -> dict:
    """Write and check the deformation graph's files in ``folder``; returns ``{"variants"}`` and,
    for a graph that takes the load, ``"load_variant"`` (deformation_load.onnx)."""
    path = folder / "deformation.onnx"
    tolerance = getattr(surrogate, "export_tolerance_mm", FLOAT32_TOLERANCE_MM)
    load = {}
    if _takes_load(graph):
        _onnx(graph, (torch.full((2, 5), 0.5), torch.zeros(2, 1)), path, ("activations", LOAD_INPUT), names,
              fold=getattr(surrogate, "export_constant_folding", True))
        shutil.copyfile(path, folder / LOAD_FILE)  # before the load becomes optional: a true input there
        _optional_load_input(path)
        load["load_variant"] = _check_load_variant(folder / LOAD_FILE, graph, probe, names, tolerance)
    else:
        _onnx(graph, torch.full((2, 5), 0.5), path, "activations", names)
    variants = _check_tiers(_tiers(path, getattr(surrogate, "deploy_tiers", TIERS)), graph, probe, names, tolerance)
    return {"variants": variants, **load}


def _takes_load(graph) -> bool:
    import inspect

    return LOAD_INPUT in inspect.signature(graph.forward).parameters


def _export_activation_model(model, out: Path) -> dict:
    path = out / "activation_angle.onnx"
    module = model.torch_module()
    _onnx(module, torch.full((2, 1), 0.5 * sum(model.range_deg)), path, "elbow_angle_deg", ["activations"])
    probe = np.linspace(*model.range_deg, 257)[:, None]
    got = onnx_session(path).run(None, {"elbow_angle_deg": probe.astype(np.float32)})[0]
    diff = float(np.abs(got - model.predict(probe[:, 0])).max())
    if diff > 1e-6:
        raise RuntimeError(f"activation_angle.onnx differs from Python by {diff:.2e} (tolerance 1e-6)")
    return {"file": path.name, "input": "elbow_angle_deg", "output": "activations",
            "range_deg": list(model.range_deg), "knots": len(model.knots), "max_abs_diff_vs_python": diff,
            "source": getattr(model, "source", "least effort on the sparse grid (the paper's inverse problem)"),
            "branch_notes": model.branch_notes}


def export_model(surrogate, out: str | Path, activation_model=None, motion_model=None, accuracy: dict | None = None,
                 n_probe: int = 64, seed: int = 0, held_out=None, name: str | None = None) -> dict:
    """Write the export folder for a fitted surrogate with ``deployable()`` (a network or the
    structured surrogate); returns the metadata. ``held_out``: a Dataset of FE states to measure
    the exported float32 file against (metadata provenance ``deployed``); ``name``: the model's
    name there (default: its architecture)."""
    from persival.campaign.skeleton import skeleton_for

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"{out} exists and is not a folder")
    tmp = out.with_name(f".{out.name}.exporting")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    graph = surrogate.deployable()
    names = ["positions", "elbow_angle_deg"] if surrogate.has_angle else ["positions"]
    takes_load = _takes_load(graph)
    files = _export_deformation(surrogate, graph, tmp, names, np.random.default_rng(seed).uniform(0.0, 1.0, (n_probe, 5)))
    surfaces = surrogate.surfaces
    source = surrogate.metadata.get("source", {})
    n = surfaces.n_nodes
    outputs = {"positions": [None, n, 3], **({"elbow_angle_deg": [None, 1]} if surrogate.has_angle else {})}
    inputs = {"activations": [None, 5], **({LOAD_INPUT: [None, 1]} if takes_load else {})}
    models = {"deformation": {"inputs": inputs, "optional_inputs": {LOAD_INPUT: 0.0} if takes_load else {}, "outputs": outputs,
                              **files, "architecture": surrogate.metadata.get("arch"),
                              "parameters": surrogate.metadata.get("parameters"), "accuracy": accuracy or {}}}
    if activation_model is not None:
        models["activation_angle"] = _export_activation_model(activation_model, tmp)
    if motion_model is not None:
        models["activation_motion"] = motion_model.export_onnx(tmp)
    metadata = {
        "format": FORMAT_NAME, "format_version": FORMAT_VERSION, "units": {**UNITS, "load": "kg"},
        "muscles": list(MUSCLES), "n_nodes": n, "surfaces": surfaces.ranges(),
        "reference_points": np.round(surfaces.reference_points, 4).tolist(),
        "triangles": surfaces.triangles.tolist(),
        "skeleton": skeleton_for(source.get("simulator", ""), source.get("simulator_options")),
        "elbow_angle_range_deg": list(activation_model.range_deg) if activation_model is not None else None,
        "models": models,
        "provenance": {"source": source, "dataset_sha256": surrogate.metadata.get("training", {}).get("dataset_sha256"),
                       "training": {k: v for k, v in surrogate.metadata.get("training", {}).items() if k != "history"},
                       "persival_version": persival.__version__, "torch": torch.__version__, "opset": OPSET,
                       "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")},
    }
    if held_out is not None:
        from persival.deploy.held_out import held_out_accuracy

        metadata["provenance"]["deployed"] = {"model": name or surrogate.metadata.get("arch"),
                                              "held_out_fe": held_out_accuracy(tmp / "deformation.onnx", held_out)}
    (tmp / "metadata.json").write_text(json.dumps(metadata, default=float))
    if out.exists():
        shutil.rmtree(out)
    tmp.rename(out)
    return metadata
