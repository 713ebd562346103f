"""The inference server (persival serve) and its artifact loader: API, limits, files, errors, load.

The export folder is the real one of the session's small run (tests/conftest.py: analytic
campaign -> SG -> POD net -> persival.deploy.export). That run has no motion model (the analytic
stand-in has no muscle moments), so the requests with a load go to a second, contract-only
folder (`motion_export_dir`, built below from the analytic simulator's states with a
least-squares deformation model and a motion model as plain ONNX graphs, laid out as
docs/deployment.md says).
"""

from __future__ import annotations

import json
import shutil
import socket
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # a shared fixture of this module takes minutes (make test-fast skips it)

N_STATES = 48


# --- the export folder (the one place that knows how it is made) --------------------------------

def _graph_model(nodes, inputs, outputs, inits):
    import onnx
    from onnx import helper

    for i, node in enumerate(nodes):
        node.name = f"n{i}_{node.op_type}"  # unique names: the float16 converter needs them
    graph = helper.make_graph(nodes, "g", inputs, outputs, inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    return model


def _deformation_model(weights: np.ndarray, bias: np.ndarray, n_nodes: int):
    """activations -> [a, a_i a_j (i <= j)] -> affine map -> positions, elbow angle."""
    from onnx import TensorProto as T
    from onnx import helper as h
    from onnx import numpy_helper as nh

    iu = np.triu_indices(5)
    sel = np.zeros((25, 15), np.float32)
    sel[iu[0] * 5 + iu[1], np.arange(15)] = 1.0
    inits = [nh.from_array(sel, "sel"), nh.from_array(weights[:, :-1], "W"), nh.from_array(bias[:-1], "b"),
             nh.from_array(weights[:, -1:], "Wa"), nh.from_array(bias[-1:], "ba")]
    inits += [nh.from_array(np.array(s, np.int64), f"s{k}") for k, s in
              enumerate([[-1, 5, 1], [-1, 1, 5], [-1, 25], [-1, n_nodes, 3]])]
    mk = h.make_node
    nodes = [mk("Reshape", ["activations", "s0"], ["ac"]), mk("Reshape", ["activations", "s1"], ["ar"]),
             mk("Mul", ["ac", "ar"], ["outer"]), mk("Reshape", ["outer", "s2"], ["of"]),
             mk("MatMul", ["of", "sel"], ["quad"]), mk("Concat", ["activations", "quad"], ["f"], axis=1),
             mk("MatMul", ["f", "W"], ["p0"]), mk("Add", ["p0", "b"], ["p1"]), mk("Reshape", ["p1", "s3"], ["positions"]),
             mk("MatMul", ["f", "Wa"], ["a0"]), mk("Add", ["a0", "ba"], ["elbow_angle_deg"])]
    return _graph_model(nodes, [h.make_tensor_value_info("activations", T.FLOAT, ["batch", 5])],
                        [h.make_tensor_value_info("positions", T.FLOAT, ["batch", n_nodes, 3]),
                         h.make_tensor_value_info("elbow_angle_deg", T.FLOAT, ["batch", 1])], inits)


def _sigmoid_model(name: str, width: int, weights: np.ndarray, bias: np.ndarray, clip=None):
    from onnx import TensorProto as T
    from onnx import helper as h
    from onnx import numpy_helper as nh

    inits = [nh.from_array(weights.astype(np.float32), "w"), nh.from_array(bias.astype(np.float32), "bb")]
    nodes, x = [], name
    if clip is not None:
        inits += [nh.from_array(np.float32(clip[0]), "lo"), nh.from_array(np.float32(clip[1]), "hi")]
        nodes.append(h.make_node("Clip", [name, "lo", "hi"], ["c"]))
        x = "c"
    nodes += [h.make_node("MatMul", [x, "w"], ["z0"]), h.make_node("Add", ["z0", "bb"], ["z"]),
              h.make_node("Sigmoid", ["z"], ["activations"])]
    return _graph_model(nodes, [h.make_tensor_value_info(name, T.FLOAT, ["batch", width])],
                        [h.make_tensor_value_info("activations", T.FLOAT, ["batch", 5])], inits)


def _cylinder(p0, p1, r, n=12):
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = (p1 - p0) / np.linalg.norm(p1 - p0)
    u = np.cross(d, [1.0, 0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    ring = [r * (np.cos(a) * u + np.sin(a) * v) for a in np.linspace(0, 2 * np.pi, n, endpoint=False)]
    pts = [p0 + q for q in ring] + [p1 + q for q in ring] + [p0, p1]
    tris = [t for j in range(n) for t in ([j, (j + 1) % n, n + (j + 1) % n], [j, n + (j + 1) % n, n + j])]
    tris += [[2 * n, (j + 1) % n, j] for j in range(n)] + [[2 * n + 1, n + j, n + (j + 1) % n] for j in range(n)]
    return {"points": np.round(pts, 4).tolist(), "triangles": tris}


def build_contract_export(folder: Path) -> Path:
    """An export folder per docs/deployment.md from real analytic-simulator states."""
    import onnx
    from onnxconverter_common import float16
    from onnxruntime.quantization import QuantType, quantize_dynamic

    from persival.campaign.analytic import AnalyticSimulator
    from persival.vocabulary import MUSCLES

    folder.mkdir(parents=True, exist_ok=True)
    sim = AnalyticSimulator(mesh_size=10.0)
    ref = sim.reference()
    alphas = np.random.default_rng(0).uniform(0, 1, (N_STATES, 5))
    results = [sim.simulate(a)[0] for a in alphas]
    pos = np.stack([np.concatenate([r.surfaces[m] for m in MUSCLES]) for r in results])
    angles = np.array([r.elbow_angle_deg for r in results])
    iu = np.triu_indices(5)
    feats = np.hstack([alphas, (alphas[:, :, None] * alphas[:, None, :])[:, iu[0], iu[1]], np.ones((N_STATES, 1))])
    coef = np.linalg.lstsq(feats, np.hstack([pos.reshape(N_STATES, -1), angles[:, None]]), rcond=None)[0]
    n_nodes = pos.shape[1]
    model = _deformation_model(coef[:-1].astype(np.float32), coef[-1].astype(np.float32), n_nodes)
    onnx.save(model, folder / "deformation.onnx")
    with warnings.catch_warnings():  # "number truncated to 1e-07": tiny weights, expected in float16
        warnings.simplefilter("ignore")
        onnx.save(float16.convert_float_to_float16(model, keep_io_types=True), folder / "deformation.float16.onnx")
    quantize_dynamic(str(folder / "deformation.onnx"), str(folder / "deformation.int8.onnx"), weight_type=QuantType.QInt8)
    lo, hi = float(angles.min()), float(angles.max())
    onnx.save(_sigmoid_model("elbow_angle_deg", 1, np.array([[0.03, 0.02, 0.02, -0.03, -0.01]]),
                             np.array([-1.5, -1.2, -1.0, 1.0, 0.5]), clip=(lo, hi)), folder / "activation_angle.onnx")
    onnx.save(_sigmoid_model("motion", 4, np.vstack([[0.03, 0.02, 0.02, -0.03, -0.01], np.full((2, 5), 1e-3),
                                                     [0.3, 0.25, 0.2, 0.05, 0.02]]),
                             np.array([-1.5, -1.2, -1.0, 1.0, 0.5])), folder / "activation_motion.onnx")
    surfaces, start, tstart, tris = [], 0, 0, []
    for m in MUSCLES:
        s = ref.surfaces[m]
        surfaces.append({"name": m, "node_start": start, "node_count": s.n_nodes, "triangle_start": tstart,
                         "triangle_count": len(s.triangles)})
        tris.append(s.triangles + start)
        start, tstart = start + s.n_nodes, tstart + len(s.triangles)
    bones = [{"name": n, "segment": seg, **_cylinder(a, b, r)} for n, seg, a, b, r in
             [("humerus", "upper_arm", (0, 0, -10), (0, 0, -295), 9), ("ulna", "forearm", (-6, 4, -305), (-4, 10, -560), 6),
              ("radius", "forearm", (8, 8, -310), (14, 16, -555), 5.5)]]
    variants = {t: {"file": f, "bytes": (folder / f).stat().st_size, "accuracy": {}} for t, f in
                [("float32", "deformation.onnx"), ("float16", "deformation.float16.onnx"), ("int8", "deformation.int8.onnx")]}
    meta = {
        "format": "persival-export", "format_version": 1, "units": {"length": "mm", "angle": "deg", "load": "kg"},
        "muscles": list(MUSCLES), "n_nodes": n_nodes, "surfaces": surfaces,
        "reference_points": np.concatenate([ref.surfaces[m].reference_points for m in MUSCLES]).tolist(),
        "triangles": np.concatenate(tris).tolist(),
        "skeleton": {"hinge": {"centre": [0.0, 0.0, -300.0], "axis": [0.0, -1.0, 0.0]}, "bones": bones},
        "elbow_angle_range_deg": [lo, hi],
        "models": {"deformation": {"inputs": {"activations": [None, 5]},
                                   "outputs": {"positions": [None, n_nodes, 3], "elbow_angle_deg": [None, 1]},
                                   "variants": variants, "architecture": "quadratic least squares (test fixture)"},
                   "activation_angle": {"file": "activation_angle.onnx", "input": "elbow_angle_deg",
                                        "output": "activations", "range_deg": [lo, hi]},
                   "activation_motion": {"file": "activation_motion.onnx", "input": "motion", "output": "activations",
                                         "max_load_kg": 5.0}},
        "provenance": {"simulator": {"kind": "analytic"}, "dataset_sha256": "test", "training": {}, "created": "test"},
    }
    (folder / "metadata.json").write_text(json.dumps(meta))
    return folder


@pytest.fixture(scope="session")
def export_dir(small_run) -> Path:
    return small_run / "export"


@pytest.fixture(scope="session")
def motion_export_dir(tmp_path_factory) -> Path:
    return build_contract_export(tmp_path_factory.mktemp("export") / "export")


# --- a real uvicorn server on a free loopback port ----------------------------------------------

class LiveServer:
    def __init__(self, app) -> None:
        import uvicorn

        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        self.server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=self.port, log_level="warning",
                                                    ws_max_size=65536))
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 30
        while not self.server.started and time.monotonic() < deadline:
            time.sleep(0.05)
        self.url = f"http://127.0.0.1:{self.port}"

    def raw_get(self, target: str) -> tuple[int, bytes]:
        """GET with the request target sent as is (clients would normalise /../ away)."""
        with socket.create_connection(("127.0.0.1", self.port), timeout=10) as s:
            s.sendall(f"GET {target} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n".encode())
            data = b""
            while chunk := s.recv(65536):
                data += chunk
        head, _, body = data.partition(b"\r\n\r\n")
        return int(head.split()[1]), body

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)


@pytest.fixture(scope="module")
def client(export_dir):
    from fastapi.testclient import TestClient

    from persival.deploy.server import create_app

    with TestClient(create_app(export_dir)) as c:
        yield c


@pytest.fixture(scope="module")
def motion_client(motion_export_dir):
    from fastapi.testclient import TestClient

    from persival.deploy.server import create_app

    with TestClient(create_app(motion_export_dir)) as c:
        yield c


def run_page_script(export: Path, script: Path, *args: str, timeout: float = 240, env: dict | None = None) -> dict:
    """A browser script (tests/viewer/*.mjs) against a live server of ``export``: the JSON of its
    last output line, checked to have run (exit 0, ``ok``)."""
    import subprocess

    from persival.deploy.server import create_app

    server = LiveServer(create_app(export))
    try:
        proc = subprocess.run(["node", str(script), server.url + "/", *args], capture_output=True, text=True,
                              timeout=timeout, env=env)
    finally:
        server.stop()
    assert proc.returncode == 0, proc.stderr[-3000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["ok"], result.get("error")
    return result


@pytest.fixture(scope="module")
def live(export_dir):
    from persival.deploy.server import create_app

    server = LiveServer(create_app(export_dir))
    yield server
    server.stop()


# --- the API ---------------------------------------------------------------------------------------

def test_health(client, export_dir):
    body = client.get("/health").json()
    meta = json.loads((export_dir / "metadata.json").read_text())
    assert body["status"] == "ok" and body["n_nodes"] == meta["n_nodes"]
    assert body["tiers"] == ["float32", "float16", "int8"] and body["motion"] is False


def test_predict_matches_onnxruntime(client, export_dir):
    import onnxruntime as ort

    a = [0.1, 0.7, 0.3, 0.2, 0.9]
    body = client.post("/api/predict", json={"activations": a}).json()
    sess = ort.InferenceSession(str(export_dir / "deformation.onnx"), providers=["CPUExecutionProvider"])
    positions, angle = sess.run(None, {"activations": np.array([a], np.float32)})
    meta = json.loads((export_dir / "metadata.json").read_text())
    assert list(body["muscles"]) == meta["muscles"]
    got = np.concatenate([np.asarray(body["muscles"][m]) for m in meta["muscles"]])
    np.testing.assert_array_equal(got, positions[0])  # float32 round-trips through JSON exactly
    assert body["elbow_angle_deg"] == pytest.approx(float(angle[0, 0]))
    assert body["activations"] == pytest.approx(a)


def test_predict_from_angle(client, small_run):
    from persival.surrogate.activation_model import AngleActivationModel

    lo, hi = client.get("/health").json()["angle_range_deg"]
    body = client.post("/api/predict", json={"angle_deg": (lo + hi) / 2}).json()
    model = AngleActivationModel.load(small_run / "inverse" / "activation_model.json")
    np.testing.assert_allclose(body["activations"], model.predict([(lo + hi) / 2])[0], atol=1e-6)
    refused = client.post("/api/predict", json={"angle_deg": (lo + hi) / 2, "load_kg": 1})
    assert refused.status_code == 422 and "load_kg" in refused.json()["error"]


def test_a_load_is_refused_by_an_export_whose_deformation_takes_none(motion_client):
    """A held load must reach the arm (SPEC 9): an export whose deformation model has no load
    input cannot honour it, so it is refused, not answered with the arm unloaded
    (tests/deploy/test_contract.py checks the load on a deployed model that takes it)."""
    client = motion_client
    assert client.get("/health").json()["motion"] is True
    lo, hi = client.get("/health").json()["angle_range_deg"]
    still = client.post("/api/predict", json={"angle_deg": (lo + hi) / 2}).json()
    assert len(still["activations"]) == 5 and all(0 <= v <= 1 for v in still["activations"])
    loaded = client.post("/api/predict", json={"angle_deg": (lo + hi) / 2, "load_kg": 4})
    assert loaded.status_code == 422 and "takes no load" in loaded.json()["error"]


BAD_BODIES = [
    (b'{"activations": [0, 0, 0, 0, 1.5]}', 422, "outside"),
    (b'{"activations": [0, 0, 0, 0, -0.1]}', 422, "outside"),
    (b'{"activations": [NaN, 0, 0, 0, 0]}', 400, "NaN"),
    (b'{"activations": [1e999, 0, 0, 0, 0]}', 422, "finite"),
    (b'{"activations": [0, 0, 0, 0]}', 422, "5 numbers"),
    (b'{"activations": ["0.5", 0, 0, 0, 0]}', 422, "number"),
    (b'{"activations": [true, 0, 0, 0, 0]}', 422, "number"),
    (b'{"activations": {"a": 1}}', 422, "5 numbers"),
    (b'{"activations": [0, 0, 0, 0, 0], "angle_deg": 50}', 422, "exactly one"),
    (b'{}', 422, "exactly one"),
    (b'{"activations": [0, 0, 0, 0, 0], "rm": 1}', 422, "unknown"),
    (b'{"angle_deg": 1000}', 422, "range"),
    (b'{"angle_deg": "90"}', 422, "number"),
    (b'{"angle_deg": 60, "load_kg": 50}', 422, "load_kg"),
    (b'{"activations": [0, 0, 0, 0, 0], "load_kg": 1}', 422, "load_kg"),
    (b'{"activations": [0, 0, 0, 0, 0], "tier": "float64"}', 422, "tier"),
    (b'[0, 0, 0, 0, 0]', 422, "object"),
    (b'{"activations": [0, 0', 400, "JSON"),
    (b'\xff\xfe', 400, "JSON"),
    (b'{"activations": [' + b'0,' * 3000 + b'0]}', 413, "larger"),
]


@pytest.mark.parametrize("body, status, words", BAD_BODIES)
def test_bad_request_is_refused_and_server_stays_up(client, body, status, words):
    r = client.post("/api/predict", content=body, headers={"content-type": "application/json"})
    assert r.status_code == status, r.text
    assert words in r.json()["error"]
    assert client.post("/api/predict", json={"activations": [0.5] * 5}).status_code == 200


def test_chunked_oversized_body_is_refused(live):
    import httpx

    def chunks():
        for _ in range(64):
            yield b" " * 1024

    r = httpx.post(live.url + "/api/predict", content=chunks(), headers={"content-type": "application/json"})
    assert r.status_code == 413
    assert httpx.get(live.url + "/health").status_code == 200


def test_rate_limit(export_dir):
    from fastapi.testclient import TestClient

    from persival.deploy.server import ServerLimits, create_app

    with TestClient(create_app(export_dir, limits=ServerLimits(http_rate=0.1, http_burst=3))) as c:
        codes = [c.post("/api/predict", json={"activations": [0] * 5}).status_code for _ in range(5)]
    assert codes[:3] == [200] * 3 and codes[3:] == [429, 429]


def test_websocket_json_binary_and_errors(client):
    from persival.deploy.protocol import BINARY_HEADER

    a = [0.2, 0.4, 0.6, 0.8, 1.0]
    rest = client.post("/api/predict", json={"activations": a}).json()
    with client.websocket_connect("/ws") as ws:
        ws.send_text(json.dumps({"id": 1, "activations": a}))
        assert ws.receive_json()["muscles"] == rest["muscles"]
        for bad in ["nope", '{"activations": [2, 0, 0, 0, 0]}', "x" * 10000, '{"id": -1, "activations": [0, 0, 0, 0, 0],'
                    ' "encoding": "binary"}']:
            ws.send_text(bad)
            reply = ws.receive_json()
            assert 400 <= reply["status"] < 500 and reply["error"]
        ws.send_bytes(b"\x00\x01")
        assert ws.receive_json()["status"] == 400
        ws.send_text(json.dumps({"id": 9, "activations": a, "encoding": "binary"}))
        data = ws.receive_bytes()
    rid, angle, *acts = BINARY_HEADER.unpack_from(data)
    positions = np.frombuffer(data, "<f4", offset=BINARY_HEADER.size).reshape(-1, 3)
    assert rid == 9 and angle == pytest.approx(rest["elbow_angle_deg"]) and acts == pytest.approx(a)
    np.testing.assert_array_equal(positions, np.concatenate([np.asarray(v) for v in rest["muscles"].values()]))


# --- files: only the viewer's and the artifacts' -------------------------------------------------

TRAVERSALS = ["/../pyproject.toml", "/../../../../etc/passwd", "/%2e%2e/%2e%2e/etc/passwd", "/%2E%2E%2Fpyproject.toml",
              "/artifacts/../metadata.json", "/artifacts/%2e%2e/%2e%2e/pyproject.toml", "/artifacts/..%2f..%2fcli.py",
              "/%252e%252e/%252e%252e/etc/passwd", "/..%5c..%5cetc%5cpasswd", "/artifacts/%2e%2e%5cmetadata.json",
              "//etc/passwd", "/artifacts//etc/passwd", "/.%2e/.%2e/etc/passwd", "/artifacts/deformation.onnx%00.json",
              "/artifacts/metadata.json/..", "/artifacts/", "/etc/passwd", "/persival/deploy/server.py",
              "/node_modules/three/package.json"]


@pytest.mark.parametrize("target", TRAVERSALS)
def test_no_file_outside_the_app(live, target):
    status, body = live.raw_get(target)
    assert status in (400, 404), (target, status)
    assert b"root:" not in body and b"[project]" not in body and b"import" not in body
    assert live.raw_get("/health")[0] == 200


def test_own_files_are_served(live, export_dir):
    import httpx

    from persival.deploy.server import WEB_DIST

    r = httpx.get(live.url + "/artifacts/metadata.json")
    assert r.status_code == 200 and r.json()["format"] == "persival-export"
    assert r.headers["x-content-type-options"] == "nosniff" and "default-src 'self'" in r.headers["content-security-policy"]
    assert httpx.get(live.url + "/artifacts/deformation.int8.onnx").content == (export_dir / "deformation.int8.onnx").read_bytes()
    if (WEB_DIST / "index.html").is_file():
        assert "PerSival" in httpx.get(live.url + "/").text
        wasm = httpx.get(live.url + "/ort/ort-wasm-simd-threaded.wasm")
        assert wasm.status_code == 200 and wasm.headers["content-type"] == "application/wasm"


# --- artifact folders that cannot be served -------------------------------------------------------

def _broken(export_dir: Path, tmp_path: Path, how: str) -> Path:
    folder = tmp_path / "broken"
    shutil.copytree(export_dir, folder)
    meta = json.loads((folder / "metadata.json").read_text())
    if how == "no metadata":
        (folder / "metadata.json").unlink()
    elif how == "bad json":
        (folder / "metadata.json").write_text("{not json")
    elif how == "version":
        meta["format_version"] = 99
    elif how == "missing model":
        (folder / "deformation.float16.onnx").unlink()
    elif how == "corrupt model":
        (folder / "deformation.onnx").write_bytes(b"\x08\x01garbage" * 100)
    elif how == "node count":
        meta["n_nodes"] += 3
        meta["surfaces"][-1]["node_count"] += 3
        meta["reference_points"] += [[0.0, 0.0, 0.0]] * 3
    if how in ("version", "node count"):
        (folder / "metadata.json").write_text(json.dumps(meta))
    return folder


@pytest.mark.parametrize("how, words", [
    ("no metadata", "metadata.json: missing"), ("bad json", "not valid JSON"), ("version", "format version 99"),
    ("missing model", "deformation.float16.onnx: file missing"), ("corrupt model", "not a loadable ONNX"),
    ("node count", "do not belong together")])
def test_broken_artifacts_are_reported(export_dir, tmp_path, how, words):
    from persival.deploy.artifacts import ArtifactError
    from persival.deploy.server import create_app

    with pytest.raises(ArtifactError, match=words):
        create_app(_broken(export_dir, tmp_path, how))


def test_serve_refuses_a_missing_folder(tmp_path):
    from typer.testing import CliRunner

    from persival.cli import app

    result = CliRunner().invoke(app, ["serve", "--artifacts", str(tmp_path / "nowhere")])
    assert result.exit_code == 2
    assert "no such artifact folder" in " ".join(result.output.split())


# --- the load test --------------------------------------------------------------------------------

def test_bench_serve_small_load(export_dir):
    from persival.deploy.bench_serve import run_load_test

    summary = run_load_test(export_dir, clients=4, rate=30, duration_s=2, bad_every=5).summary()
    print("\nbench serve (4 clients x 30 states/s, 2 s):", json.dumps({k: summary[k] for k in
          ("states", "states_per_s", "p50_ms", "p99_ms", "errors", "bad_sent", "bad_refused", "server_peak_rss_mb")}))
    assert summary["errors"] == 0, summary["first_errors"]
    assert summary["bad_sent"] > 0 and summary["bad_refused"] == summary["bad_sent"]
    assert summary["states"] >= 0.8 * 4 * 30 * 2 * (1 - 1 / 5)
    with pytest.raises(ValueError):
        run_load_test(export_dir, clients=1000)
