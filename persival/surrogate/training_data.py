"""Training data for the networks (docs/theory.md, 7.4): SG evaluations at alpha_opt(Theta) and at random alpha.

The paper trains on SG deformations at the optimal activations of sampled angles; a network
trained on that curve alone has never seen the rest of [0,1]^5, where a viewer's activation
sliders go. So the set mixes both, ``angle_fraction`` of the samples on the curve (Theta
uniform over the activation model's range) and the rest uniform in the cube. Default 0.5: the
curve is one-dimensional, so half the samples cover it densely, and the other half is as many
random states as the SG's own grid has points, several times over.

Written to a zarr folder in chunks of ``chunk`` samples as they are computed (any number of
samples in bounded memory; a killed run resumes at the first unwritten chunk), seeded, so the
same call gives the same bytes. Positions are float32 (the network's precision).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from persival.file_header import check_header
from persival.surrogate.dataset import Dataset, Surfaces

__all__ = ["generate_training_data", "load_training_data", "open_dataset", "sample_inputs"]

_FORMAT = "persival-training-data"
_VERSION = 1  # folders written before the header had a version are version 1


def sample_inputs(activation_model, n_samples: int, angle_fraction: float, seed: int):
    """(activations (n, 5), target angle (n,), NaN for random samples), in a seeded shuffled order."""
    if n_samples < 1:
        raise ValueError(f"n_samples must be >= 1, got {n_samples}")
    if not 0.0 <= angle_fraction <= 1.0:
        raise ValueError(f"angle_fraction must lie in [0, 1], got {angle_fraction}")
    rng = np.random.default_rng(seed)
    n_angle = int(round(angle_fraction * n_samples))
    lo, hi = activation_model.range_deg
    targets = rng.uniform(lo, hi, n_angle)
    alpha = np.vstack([activation_model.predict(targets) if n_angle else np.empty((0, 5)),
                       rng.uniform(0.0, 1.0, (n_samples - n_angle, 5))])
    targets = np.concatenate([targets, np.full(n_samples - n_angle, np.nan)])
    order = rng.permutation(n_samples)
    return np.clip(alpha[order], 0.0, 1.0), targets[order]


def generate_training_data(sg, activation_model, out: str | Path, n_samples: int = 4000,
                           angle_fraction: float = 0.5, seed: int = 0, chunk: int = 256, progress=None) -> Path:
    """Write the training set of ``sg`` (a fitted :class:`SparseGridSurrogate`) to ``out``."""
    out = Path(out)
    alpha, targets = sample_inputs(activation_model, n_samples, angle_fraction, seed)
    config = {"n_samples": n_samples, "angle_fraction": angle_fraction, "seed": seed, "chunk": chunk,
              "angle_range_deg": list(activation_model.range_deg)}
    kept = ("simulator", "profile", "states", "label", "model_hash", "simulator_options")
    source = {**{k: v for k, v in sg.metadata.items() if k in kept},
              "generator": f"level-{sg.metadata.get('level')} sparse grid ({sg.metadata.get('grid_points')} points)"}
    n_nodes = sg.n_nodes
    meta_file = out / "training_data.json"
    group = _open_or_create(out, config, n_samples, n_nodes, chunk)
    if group is None:  # complete already, same config
        return out
    sg.surfaces.save(out / "surfaces.npz")
    done = group["chunk_done"]
    for c in range(int(np.ceil(n_samples / chunk))):
        if done[c]:
            continue
        rows = slice(c * chunk, min(n_samples, (c + 1) * chunk))
        positions, angles = sg.predict_with_angle(alpha[rows])
        group["positions"][rows] = positions.astype(np.float32)
        group["elbow_angles"][rows] = angles
        done[c] = 1  # last: a chunk counts only once its data is on disk
        if progress is not None:
            progress(rows.stop - rows.start, n_samples)
    group["activations"][:] = alpha
    group["target_deg"][:] = targets
    meta_file.write_text(json.dumps({"format": _FORMAT, "version": _VERSION, "config": config, "source": source,
                                       "complete": True}, indent=2))
    return out


def _open_or_create(out: Path, config: dict, n: int, n_nodes: int, chunk: int):
    import zarr

    meta_file = out / "training_data.json"
    if meta_file.exists():
        meta = json.loads(meta_file.read_text())
        if meta.get("config") != config:
            raise ValueError(f"{out} holds training data of another configuration ({meta.get('config')}); "
                             "choose another folder")
        if meta.get("complete"):
            return None
        return zarr.open_group(str(out / "arrays.zarr"), mode="r+")
    if out.exists() and any(out.iterdir()):
        raise ValueError(f"{out} exists and is not a training-data folder")
    out.mkdir(parents=True, exist_ok=True)
    meta_file.write_text(json.dumps({"format": _FORMAT, "version": _VERSION, "config": config, "complete": False}, indent=2))
    group = zarr.open_group(str(out / "arrays.zarr"), mode="w")
    group.create_array("positions", shape=(n, n_nodes, 3), chunks=(chunk, n_nodes, 3), dtype="f4")
    group.create_array("elbow_angles", shape=(n,), chunks=(n,), dtype="f8")
    group.create_array("activations", shape=(n, 5), chunks=(n, 5), dtype="f8")
    group.create_array("target_deg", shape=(n,), chunks=(n,), dtype="f8")
    group.create_array("chunk_done", shape=(int(np.ceil(n / chunk)),), chunks=(1,), dtype="i1", fill_value=0)
    return group


def load_training_data(path: str | Path) -> Dataset:
    """A complete training-data folder as a :class:`Dataset` (``source`` says it is SG data)."""
    import zarr

    path = Path(path)
    meta = check_header({"version": 1, **json.loads((path / "training_data.json").read_text())}, path,
                        "training-data folder", _FORMAT, _VERSION, advice="make it again (`persival data`)")
    if not meta.get("complete"):
        raise ValueError(f"{path} is incomplete: run persival data again with the same options to finish it")
    g = zarr.open_group(str(path / "arrays.zarr"), mode="r")
    source = {**meta["source"], "training_data": meta["config"], "states": meta["config"]["n_samples"],
              "label": f"SG data ({meta['source'].get('generator')}) of {meta['source'].get('label')}"}
    return Dataset(g["activations"][:], g["positions"][:], g["elbow_angles"][:], Surfaces.load(path / "surfaces.npz"),
                   source, np.asarray(g["target_deg"][:]))


def open_dataset(path: str | Path) -> Dataset:
    """A dataset folder: the training-data generator's (training_data.json) or :meth:`Dataset.save`'s."""
    path = Path(path)
    return load_training_data(path) if (path / "training_data.json").exists() else Dataset.load(path)
