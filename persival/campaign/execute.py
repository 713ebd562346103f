"""Solving one design point where it runs (a dask worker or the driver): attempts, retries,
time limit, warm starts. Never raises for a failure of the simulator: the outcome says what
happened, so a chain of states and the campaign go on.
"""

from __future__ import annotations

import threading
import time
import traceback
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from persival.campaign.simulator import (
    SimulationTimeout,
    SimulatorSpec,
    cached_simulator,
    forget_cached_simulator,
)

__all__ = ["StateTask", "StateOutcome", "solve_state"]

# After cancel() a timed-out attempt gets this long to wind down before it counts as hung.
_CANCEL_GRACE_S = 10.0
_REASON_MAX_CHARS = 2000
# Warm-start tokens kept per process, most recent chains first (an FE token is a full state).
_MAX_TOKENS = 8
_TOKENS: OrderedDict[tuple[int, str], object] = OrderedDict()
_SHAPES: dict[int, dict[str, tuple[int, int]]] = {}
_LOCK = threading.Lock()


@dataclass
class StateTask:
    index: int  # row of the state in the design (and the store)
    state_id: int
    activations: np.ndarray  # (5,)
    chain: str  # states of one chain run in path order and may warm-start from each other
    timeout_s: float | None
    max_attempts: int


@dataclass
class StateOutcome:
    index: int
    ok: bool
    elbow_angle_deg: float = float("nan")
    positions: dict[str, np.ndarray] | None = None
    statistics: dict = field(default_factory=dict)
    reason: str = ""
    wall_time_s: float = 0.0
    attempts: int = 0
    # An attempt is still running in an abandoned thread of this process (a simulator that
    # ignored or has no cancel()); only a restart of the process stops it.
    hung: bool = False
    worker: str | None = None


def _worker_address() -> str | None:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return None


def _reason(exc: BaseException) -> str:
    msg = f"{type(exc).__name__}: {exc}".strip()
    return msg[:_REASON_MAX_CHARS]


class _Hung(Exception):
    pass


def _call_with_timeout(sim, alpha, token, attempt, timeout_s):
    if timeout_s is None:
        return sim.simulate(alpha, token, attempt)
    box: dict = {}

    def target():
        try:
            box["value"] = sim.simulate(alpha, token, attempt)
        except BaseException as exc:  # handed to the caller below
            box["error"] = exc

    # Daemon: a simulator that never returns must not keep the process alive at exit.
    thread = threading.Thread(target=target, name="persival-simulate", daemon=True)
    thread.start()
    thread.join(timeout_s)
    if thread.is_alive():
        cancel = getattr(sim, "cancel", None)
        if callable(cancel):
            try:
                cancel()
            except Exception:
                pass
            thread.join(_CANCEL_GRACE_S)
        exc = SimulationTimeout(f"timeout: attempt {attempt} ran longer than {timeout_s:g} s")
        if thread.is_alive():
            raise _Hung() from exc
        raise exc
    if "error" in box:
        raise box["error"]
    return box["value"]


def _expected_shapes(sim) -> dict[str, tuple[int, int]]:
    key = id(sim)
    if key not in _SHAPES:
        ref = sim.reference()
        _SHAPES[key] = {name: (s.n_nodes, 3) for name, s in ref.surfaces.items()}
    return _SHAPES[key]


def _check_result(result, shapes) -> dict[str, np.ndarray]:
    angle = float(result.elbow_angle_deg)
    if not np.isfinite(angle):
        raise ValueError(f"the simulator returned a non-finite elbow angle ({angle})")
    if set(result.surfaces) != set(shapes):
        raise ValueError(f"the simulator returned surfaces {sorted(result.surfaces)}, its "
                         f"reference has {sorted(shapes)}")
    positions = {}
    for name, shape in shapes.items():
        p = np.asarray(result.surfaces[name], dtype=np.float64)
        if p.shape != shape:
            raise ValueError(f"surface {name}: {p.shape} positions, reference has {shape}")
        if not np.isfinite(p).all():
            raise ValueError(f"surface {name}: non-finite positions")
        positions[name] = p
    return positions


def solve_state(spec: SimulatorSpec, factory, task: StateTask) -> StateOutcome:
    """Solve one state: up to ``max_attempts`` attempts (attempt = 0, 1, ...; the simulator takes
    smaller load steps on retries); a timeout ends the state at once (a hung solve would only hang
    again). Warm-starts from the previous state of the same chain solved in this process."""
    t0 = time.perf_counter()
    out = StateOutcome(index=task.index, ok=False, worker=_worker_address())
    try:
        sim = cached_simulator(spec, factory)
        shapes = _expected_shapes(sim)
    except Exception as exc:
        out.reason = "could not build the simulator: " + _reason(exc)
        out.statistics = {"traceback": traceback.format_exc(limit=5)}
        out.wall_time_s = time.perf_counter() - t0
        return out
    key = (id(sim), task.chain)
    with _LOCK:
        token = _TOKENS.get(key)
    errors = []
    alpha = np.array(task.activations, dtype=np.float64)
    for attempt in range(task.max_attempts):
        out.attempts = attempt + 1
        try:
            result, new_token = _call_with_timeout(sim, alpha.copy(), token, attempt, task.timeout_s)
            positions = _check_result(result, shapes)
        except _Hung as hung:
            _forget(spec, sim)
            out.hung = True
            out.reason = str(hung.__cause__)
            break
        except SimulationTimeout as exc:
            out.reason = str(exc) if str(exc).startswith("timeout") else "timeout: " + str(exc)
            break
        except Exception as exc:
            errors.append(_reason(exc))
            out.reason = errors[-1]
            token = None  # a failed solve may leave a token that is no good start
            continue
        stats = dict(result.statistics or {})
        if errors:
            stats["failed_attempts"] = errors
        stats["simulator_wall_time_s"] = float(result.wall_time_s)
        out.ok, out.reason = True, ""
        out.elbow_angle_deg = float(result.elbow_angle_deg)
        out.positions = positions
        out.statistics = stats
        if new_token is not None:
            _remember(key, new_token)
        break
    if not out.ok:
        out.statistics = {"attempt_errors": errors} if errors else {}
        if len(errors) > 1 and not out.reason.startswith("timeout"):
            out.reason = f"{errors[-1]} (after {len(errors)} attempts)"
    out.wall_time_s = time.perf_counter() - t0
    return out


def _forget(spec: SimulatorSpec, sim) -> None:
    """After a hung attempt: the abandoned attempt may still use ``sim``, so later states get a
    fresh instance, and nothing of this one (tokens, shapes keyed by its id) may leak to it."""
    forget_cached_simulator(spec)
    with _LOCK:
        for k in [k for k in _TOKENS if k[0] == id(sim)]:
            del _TOKENS[k]
        _SHAPES.pop(id(sim), None)


def _remember(key: tuple, token) -> None:
    """A solved state's warm-start token for the next state of its chain (the newest kept)."""
    with _LOCK:
        _TOKENS[key] = token
        _TOKENS.move_to_end(key)
        while len(_TOKENS) > _MAX_TOKENS:
            _TOKENS.popitem(last=False)
