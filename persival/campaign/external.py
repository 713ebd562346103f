"""A simulator that runs an external command per state (kind "external").

The command line is a template; for each state it is filled in and run in a fresh temporary
directory, and must leave there a result mesh (VTU / XDMF / d3plot, see ``importers``) and a
small JSON file with the elbow angle::

    {"elbow_angle_deg": 87.2, "statistics": {"newton_iterations": 14}}   # statistics optional

Template fields: ``{a0}`` ... ``{a4}`` (activations, shortest exact decimal form), ``{alpha}``
(the five joined by commas), ``{out}`` (the temporary directory, also the working directory),
``{attempt}`` (0, then 1, 2, ... on retries: use smaller load steps). Example::

    python my_fe.py --alpha {alpha} --out {out}/result.vtu --substeps-scale {attempt}

The filled-in line is split like a shell would (``shlex``) and run without a shell, unless
``shell=True``. The command runs in its own process group, so a timeout (``cancel()``) kills it
and everything it started.
"""

from __future__ import annotations

import hashlib
import json
import os
import shlex
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from persival.campaign.importers import read_surfaces
from persival.campaign.simulator import (
    ReferenceGeometry,
    SimulationResult,
    SimulationTimeout,
    SurfaceTopology,
)
from persival.vocabulary import MUSCLES, N_ACTIVATIONS, check_activation_vector

__all__ = ["ExternalSimulator", "ExternalCommandError"]

_TAIL_CHARS = 800


class ExternalCommandError(RuntimeError):
    """The command failed or left no usable result."""


def _tail(path: Path) -> str:
    try:
        text = path.read_text(errors="replace").strip()
    except OSError:
        return ""
    return text[-_TAIL_CHARS:]


class ExternalSimulator:
    """Runs ``command`` per state and imports its result.

    Options (json-able, they form the campaign's SimulatorSpec):
      command: template (see module doc).
      reference: result file with the undeformed geometry, same format and parts as the
        results (for d3plot any result: its initial coordinates are used).
      surfaces: {muscle name: selector} (see ``importers``), in the order to store them.
      result: file name of the mesh the command writes in {out} (default "result.vtu").
      angle_file: file name of the JSON it writes (default "result.json").
      displacement_field: meshio point-data array holding displacements, when the result
        mesh keeps reference points (default: points are current positions).
      shell: run through /bin/sh (pipes, redirections) instead of a plain argument list.
      workdir: where temporary directories go (default: the system's temp dir).
      keep_failed: keep the temporary directory of a failed run, for debugging.
    """

    name = "external"

    def __init__(self, command: str, reference: str, surfaces: dict[str, dict] | None = None,
                 result: str = "result.vtu", angle_file: str = "result.json",
                 displacement_field: str | None = None, shell: bool = False,
                 workdir: str | None = None, keep_failed: bool = False) -> None:
        if not isinstance(command, str) or not command.strip():
            raise ValueError("external simulator: 'command' must be a non-empty template")
        try:
            self._fill(command, np.zeros(N_ACTIVATIONS), "/tmp/x", 0)
        except (KeyError, IndexError, ValueError) as exc:
            raise ValueError(f"external simulator: bad command template {command!r}: unknown or "
                             f"malformed field {exc}; use {{a0}}..{{a4}}, {{alpha}}, {{out}}, "
                             "{attempt}") from None
        if not surfaces:
            raise ValueError("external simulator: 'surfaces' must map muscle names to part "
                             f"selectors, e.g. {{'{MUSCLES[0]}': {{'part_id': 1}}}}")
        self.command = command
        self.reference_path = Path(reference)
        if not self.reference_path.exists():
            raise ValueError(f"external simulator: reference file {reference} does not exist")
        self.surfaces = dict(surfaces)
        self.result = result
        self.angle_file = angle_file
        self.displacement_field = displacement_field
        self.shell = bool(shell)
        self.workdir = workdir
        self.keep_failed = bool(keep_failed)
        self._proc: subprocess.Popen | None = None
        self._cancelled = False
        self._lock = threading.Lock()
        self._reference: ReferenceGeometry | None = None

    # ---- interface ---------------------------------------------------------------------------
    def reference(self) -> ReferenceGeometry:
        if self._reference is None:
            parts = read_surfaces(self.reference_path, self.surfaces, reference=True)
            h = hashlib.sha256()
            h.update(json.dumps({"command": self.command, "surfaces": self.surfaces},
                                sort_keys=True).encode())
            with open(self.reference_path, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
            self._reference = ReferenceGeometry(
                surfaces={n: SurfaceTopology(n, p.points, p.triangles, p.node_ids)
                          for n, p in parts.items()},
                model_hash=h.hexdigest(),
                description={"model": "external", "command": self.command,
                             "reference_file": str(self.reference_path.resolve()),
                             "units": "as written by the command"},
            )
        return self._reference

    def simulate(self, activations, warm_start=None, attempt: int = 0):
        t0 = time.perf_counter()
        alpha = check_activation_vector(activations)
        ref = self.reference()
        out = Path(tempfile.mkdtemp(prefix="persival-ext-", dir=self.workdir))
        ok = False
        try:
            line = self._fill(self.command, alpha, str(out), attempt)
            rc = self._run(line, out)
            if self._cancelled:
                raise SimulationTimeout("timeout: the external command was killed")
            if rc != 0:
                raise ExternalCommandError(
                    f"command exited with status {rc}; stderr: {_tail(out / 'stderr.txt') or '(empty)'}"
                )
            angle, stats = self._read_angle(out / self.angle_file)
            parts = read_surfaces(out / self.result, self.surfaces,
                                  displacement_field=self.displacement_field)
            positions = {}
            for name, part in parts.items():
                if not np.array_equal(part.triangles, ref.surfaces[name].triangles):
                    raise ExternalCommandError(f"surface {name}: the result's mesh differs from "
                                               "the reference mesh (other topology)")
                positions[name] = part.points
            stats.update({"command_return_code": rc, "attempt": attempt})
            ok = True
            return SimulationResult(angle, positions, stats, time.perf_counter() - t0), None
        finally:
            if ok or not self.keep_failed:
                shutil.rmtree(out, ignore_errors=True)

    def cancel(self) -> None:
        """Kill the running command and its children (called on timeout from another thread)."""
        with self._lock:
            self._cancelled = True
            proc = self._proc
        if proc is not None and proc.poll() is None:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass

    # ---- helpers -----------------------------------------------------------------------------
    @staticmethod
    def _fill(template: str, alpha: np.ndarray, out: str, attempt: int) -> str:
        values = [repr(float(a)) for a in alpha]  # shortest decimal that reads back exactly
        fields = {f"a{i}": v for i, v in enumerate(values)}
        return template.format(alpha=",".join(values), out=shlex.quote(out),
                               attempt=int(attempt), **fields)

    def _run(self, line: str, out: Path) -> int:
        args = line if self.shell else shlex.split(line)
        with open(out / "stdout.txt", "wb") as so, open(out / "stderr.txt", "wb") as se:
            with self._lock:
                self._cancelled = False
                try:
                    self._proc = subprocess.Popen(args, shell=self.shell, cwd=out, stdout=so,
                                                  stderr=se, stdin=subprocess.DEVNULL,
                                                  start_new_session=True)
                except OSError as exc:
                    raise ExternalCommandError(f"could not start {line!r}: {exc}") from None
            try:
                return self._proc.wait()
            finally:
                with self._lock:
                    self._proc = None

    @staticmethod
    def _read_angle(path: Path) -> tuple[float, dict]:
        if not path.is_file():
            raise ExternalCommandError(f"the command wrote no {path.name}")
        try:
            data = json.loads(path.read_text())
            angle = float(data["elbow_angle_deg"])
        except (ValueError, KeyError, TypeError) as exc:
            raise ExternalCommandError(f"{path.name}: expected JSON with a numeric "
                                       f"'elbow_angle_deg' ({type(exc).__name__}: {exc})") from None
        stats = data.get("statistics") or {}
        if not isinstance(stats, dict):
            stats = {"statistics": stats}
        return angle, dict(stats)
