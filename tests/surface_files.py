"""Muscle surfaces the tests write themselves (docs/own_anatomy.md): a triangulated spindle, the
same with a segmentation's defects, bad surfaces, and model files that use them."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from persival.model.arm.defaults import default_model_path

SPINDLE_LENGTH = 330.0  # mm between the two cap centres, along +z from the origin


def spindle(length: float = SPINDLE_LENGTH, belly: float = 20.0, tendon: float = 4.0, ring: int = 16, stations: int = 31):
    """A closed fusiform surface along +z, r = r_t + (r_b - r_t) sin^2(pi s), flat end caps with a
    centre vertex: (vertices, outward triangles). Origin cap centre at 0, insertion at ``length``."""
    s = np.linspace(0.0, 1.0, stations)
    r = tendon + (belly - tendon) * np.sin(np.pi * s) ** 2
    t = np.linspace(0.0, 2.0 * np.pi, ring, endpoint=False)
    rings = [np.column_stack([ri * np.cos(t), ri * np.sin(t), np.full(ring, length * si)]) for si, ri in zip(s, r)]
    vertices = np.vstack(rings + [[[0.0, 0.0, 0.0]], [[0.0, 0.0, length]]])

    def at(i, j):
        return i * ring + j % ring

    faces = []
    for i in range(stations - 1):
        for j in range(ring):
            faces += [[at(i, j), at(i, j + 1), at(i + 1, j + 1)], [at(i, j), at(i + 1, j + 1), at(i + 1, j)]]
    low, high = stations * ring, stations * ring + 1
    for j in range(ring):
        faces += [[low, at(0, j + 1), at(0, j)], [high, at(stations - 1, j), at(stations - 1, j + 1)]]
    return vertices, np.array(faces)


def with_defects(vertices, faces, duplicates: int = 30, flips: int = 40, hole=(100, 101), seed: int = 0):
    """A segmentation's defects: ``duplicates`` vertices copied (one triangle uses the copy), the
    triangles ``hole`` removed (a small hole), ``flips`` triangles turned the wrong way."""
    rng = np.random.default_rng(seed)
    faces = np.delete(np.array(faces), list(hole), axis=0)
    flipped = rng.choice(len(faces), flips, replace=False)
    faces[flipped] = faces[flipped][:, ::-1]
    copies = []
    for k, v in enumerate(rng.choice(len(vertices), duplicates, replace=False)):
        face = np.flatnonzero((faces == v).any(axis=1))[0]
        faces[face] = np.where(faces[face] == v, len(vertices) + k, faces[face])
        copies.append(vertices[v])
    return np.vstack([vertices, *copies]), faces


def write_obj(path: Path, vertices, faces) -> Path:
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(vertices, dtype=float).tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.asarray(faces).tolist()]
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)


def write_stl(path: Path, vertices, faces) -> Path:
    import trimesh

    trimesh.Trimesh(vertices, faces, process=False).export(str(path))
    return Path(path)


def model_with_surface(path: Path, surface: str, origin_point=(0.0, 0.0, 0.0), insertion_point=(0.0, 0.0, SPINDLE_LENGTH),
                       units: str = "mm", scale_to_fit: bool = False, muscle: str = "biceps",
                       replace: dict | None = None) -> Path:
    """The built-in model file with ``muscle`` taken from ``surface`` (relative to the model file);
    ``replace``: other keys of that muscle to change, e.g. {"fibre_prestretch": "1.0"}."""
    text = default_model_path().read_text()
    keys = (f'surface = "{surface}"\nsurface_units = "{units}"\norigin_point = {[float(v) for v in origin_point]}\n'
            f"insertion_point = {[float(v) for v in insertion_point]}\nscale_to_fit = {str(scale_to_fit).lower()}\n")
    block_start = text.index(f'name = "{muscle}"\n')
    block_end = text.find("[[", block_start)
    block = text[block_start:block_end]
    for key, value in (replace or {}).items():
        block = re.sub(rf"^{key} = .*$", f"{key} = {value}", block, flags=re.M)
    text = text[:block_start] + f'name = "{muscle}"\n' + keys + block[len(f'name = "{muscle}"\n'):] + text[block_end:]
    Path(path).write_text(text)
    return Path(path)


def biceps_like(ring: int = 48, stations: int = 320, seed: int = 3):
    """A real-looking biceps surface at about 1 mm triangles: bent (an 18 mm bow, and a 6 mm drift),
    asymmetric (the belly widest at 60 %), elliptical sections of 22 x 15 mm turning 35 deg along
    it, 3.5 and 4.5 mm tendons with rounded ends, 1.5 % noise on the belly, in an MRI-like frame
    (turned 12 deg, shifted). Returns (vertices, outward triangles, origin end, insertion end)."""
    rng = np.random.default_rng(seed)
    length = 345.0
    s = np.linspace(0.0, 1.0, stations)
    centre = np.column_stack([18.0 * np.sin(np.pi * s) ** 1.3, 6.0 * s**2, -length * s])
    x = np.clip((s - 0.12) / 0.8, 0.0, 1.0)
    belly = np.where((s > 0.12) & (s < 0.92), np.sin(np.pi * x ** (np.log(0.5) / np.log(0.6))) ** 0.8, 0.0)
    tendon = 3.5 + s
    rounding = np.sqrt(np.clip(np.minimum(s, 1.0 - s) * length / 3.0, 0.0, 1.0))  # over the last 3 mm
    semi_a = (tendon + (22.0 - tendon) * belly) * rounding
    semi_b = (tendon + (15.0 - tendon) * belly) * rounding
    t = np.linspace(0.0, 2.0 * np.pi, ring, endpoint=False)
    tangent = np.gradient(centre, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1)[:, None]
    rows = []
    for k in range(1, stations - 1):
        e1 = np.cross(tangent[k], [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(tangent[k], e1)
        noise = 1.0 + 0.015 * rng.standard_normal(ring) * belly[k]
        turn = t + np.radians(35.0) * s[k]
        rows.append(centre[k] + (semi_a[k] * np.cos(turn) * noise)[:, None] * e1
                    + (semi_b[k] * np.sin(turn) * noise)[:, None] * e2)
    n = len(rows)
    vertices = np.vstack(rows + [centre[:1], centre[-1:]])

    def at(i, j):
        return i * ring + j % ring

    faces = []
    for i in range(n - 1):
        for j in range(ring):
            faces += [[at(i, j), at(i + 1, j), at(i + 1, j + 1)], [at(i, j), at(i + 1, j + 1), at(i, j + 1)]]
    for j in range(ring):
        faces += [[n * ring, at(0, j), at(0, j + 1)], [n * ring + 1, at(n - 1, j + 1), at(n - 1, j)]]
    faces = np.array(faces)
    tri = vertices[faces]
    if np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() < 0:
        faces = faces[:, ::-1]
    angle = np.radians(12.0)
    turn = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(angle), -np.sin(angle)], [0.0, np.sin(angle), np.cos(angle)]])
    offset = np.array([112.3, -45.1, 812.0])
    return vertices @ turn.T + offset, faces, centre[0] @ turn.T + offset, centre[-1] @ turn.T + offset
