"""The inference requests the server answers (REST and WebSocket alike), and their limits.

One parser for both transports, so a request that is refused over HTTP is refused, with the
same message, over the WebSocket. Every refusal is a `RequestError` carrying the HTTP status
(4xx): over HTTP it becomes the response status, over the WebSocket an error message on the
same connection, which stays open.
"""

from __future__ import annotations

import json
import math
import struct
import time

import numpy as np

from persival.deploy.artifacts import DeployedModel

__all__ = ["RequestError", "TokenBucket", "parse_request", "answer", "encode_binary", "BINARY_HEADER"]

_FIELDS = {"activations", "angle_deg", "load_kg", "tier", "id", "encoding"}
#: Binary reply: uint32 id, float32 elbow angle, float32 x 5 activations, then positions
#: (n_nodes x 3 float32), little-endian; 28 bytes keep the positions 4-byte aligned, so a
#: browser reads them as a Float32Array view without a copy.
BINARY_HEADER = struct.Struct("<If5f")


class RequestError(ValueError):
    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


class TokenBucket:
    """Requests per second with a burst allowance (one bucket per client or connection)."""

    def __init__(self, rate: float, burst: float) -> None:
        self.rate, self.burst = float(rate), float(burst)
        self.tokens, self.stamp = float(burst), time.monotonic()

    def take(self) -> bool:
        now = time.monotonic()
        self.tokens = min(self.burst, self.tokens + (now - self.stamp) * self.rate)
        self.stamp = now
        if self.tokens < 1.0:
            return False
        self.tokens -= 1.0
        return True


def _reject_constants(token: str):
    # json.loads accepts NaN / Infinity by default; the API only speaks standard JSON.
    raise RequestError(400, f"not standard JSON: {token}")


def decode(text: str | bytes, max_bytes: int) -> dict:
    if len(text) > max_bytes:
        raise RequestError(413, f"request larger than {max_bytes} bytes")
    try:
        payload = json.loads(text, parse_constant=_reject_constants)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RequestError(400, f"request is not valid JSON: {exc}") from None
    if not isinstance(payload, dict):
        raise RequestError(422, "request must be a JSON object")
    return payload


def _check_id(value, binary: bool):
    if value is None:
        return None
    if binary and not (isinstance(value, int) and not isinstance(value, bool) and 0 <= value < 2**32):
        raise RequestError(422, "id must be an integer in [0, 2^32) with encoding 'binary'")
    if not (isinstance(value, (int, str)) and not isinstance(value, bool)) or len(str(value)) > 64:
        raise RequestError(422, "id must be an integer or a string of at most 64 characters")
    return value


def parse_request(payload: dict, model: DeployedModel) -> tuple[np.ndarray, float, str, dict]:
    """(activations (5,) float32, load in the hand (kg), tier, echo fields) for a request, or
    RequestError. One contract (SPEC 9): `(activations, load_kg) -> (positions, angle)` and
    `(angle_deg, load_kg) -> activations`, then the positions and angle of those activations
    with the same load."""
    unknown = sorted(set(payload) - _FIELDS)
    if unknown:
        raise RequestError(422, f"unknown field(s) {unknown}; allowed: {sorted(_FIELDS)}")
    encoding = payload.get("encoding", "json")
    if encoding not in ("json", "binary"):
        raise RequestError(422, "encoding must be 'json' or 'binary'")
    echo = {"id": _check_id(payload.get("id"), encoding == "binary"), "encoding": encoding}
    tier = payload.get("tier", "float32")
    if tier not in model.tiers:
        raise RequestError(422, f"tier must be one of {model.tiers}")
    has_a, has_angle = "activations" in payload, "angle_deg" in payload
    if has_a == has_angle:
        raise RequestError(422, "give exactly one of 'activations' or 'angle_deg'")
    try:
        load = model.check_load(payload.get("load_kg", 0.0))
        if load and not model.takes_load:
            raise ValueError("load_kg: this export's deformation model takes no load")
        if has_a:
            return model.check_activations(payload["activations"]), load, tier, echo
        activations = model.activations_for_angle(payload["angle_deg"], load)
    except ValueError as exc:
        raise RequestError(422, str(exc)) from None
    return np.asarray(activations, dtype=np.float32), load, tier, echo


def _rounded(values) -> list:
    # float32 -> shortest decimal that reads back as the same float32 (JSON stays ~2x smaller
    # than float64 repr and loses nothing the model computed).
    return [float(np.format_float_positional(v, unique=True, trim="-")) for v in values]


def answer(activations: np.ndarray, load_kg: float, tier: str, model: DeployedModel) -> tuple[np.ndarray, float]:
    positions, angle = model.predict(activations, tier, load_kg)
    return positions[0], float(angle[0])


def encode_json(activations, positions, angle: float, tier: str, model: DeployedModel, echo) -> dict:
    # null when the export has no angle output (docs/deployment.md makes it optional)
    elbow = float(np.float32(angle)) if math.isfinite(angle) else None
    out = {"activations": _rounded(activations), "elbow_angle_deg": elbow, "tier": tier,
           "muscles": {name: p.tolist() for name, p in model.split(positions).items()}}
    if echo.get("id") is not None:
        out["id"] = echo["id"]
    return out


def encode_binary(activations, positions, angle: float, echo) -> bytes:
    header = BINARY_HEADER.pack(int(echo.get("id") or 0), angle, *(float(a) for a in activations))
    return header + np.ascontiguousarray(positions, dtype="<f4").tobytes()
