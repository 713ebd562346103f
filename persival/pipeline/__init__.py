"""`persival run`: the end-to-end job, one stage after the other, each reading the last one's artifact.

    1 model     OUT/model/     geometry.json, mesh_*.vtu, bone_*.vtu (the built-in arm or --model, chosen profile)
    2 tables    OUT/tables/    the FE arm's per-muscle response tables (kept in the state cache) + moments.npz
    3 fe        OUT/fe/        three FE equilibria of the arm (state.json + VTU) and arm.png
    4 campaign  OUT/campaign/  campaign.zarr (sparse-grid design) + held_out.zarr (random states)
    5 anatomy   OUT/anatomy/   bodies inside each other, muscles off their beds: FE and held-out states
    6 structured OUT/structured/ per-muscle shape and moment models from the tables: the deployed model
    7 sg        OUT/sg/        B-spline SG of all five muscles' surfaces + the elbow angle
    8 inverse   OUT/inverse/   activation_model.json (Theta -> alpha_opt) + plot
    9 motion    OUT/motion/    (angle, velocity, acceleration, load) -> alpha, from the FE moments
   10 data      OUT/data/      SG training data (alpha_opt(Theta) and random alpha)
   11 train     OUT/networks/  pod/ (all muscles) and paper/ (the paper's net, biceps)
   12 export    OUT/export/    ONNX models + metadata.json (docs/deployment.md)
   13 evaluate  OUT/evaluate/  the paper's tables and figures
   14 report    OUT/report/    index.html + results.json

Resumable stage by stage: every stage leaves ``OUT/<stage>/stage.json`` with the digest of its
inputs (its own settings, the model file's content hash with the physics version, the package
version, and the digests of the stages it reads); a stage whose digest is unchanged is skipped, so an edited
model file, a new physics version or another release of the code reruns exactly the stages after
it. An interrupted campaign stage (killed, or stopped by states that failed)
is resumed where it stopped by the next run with the same settings. The campaign's simulator is
named everywhere its numbers appear.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from persival.pipeline import stages

__all__ = ["RunConfig", "run", "STAGES"]


@dataclass
class RunConfig:
    profile: str = "quick"
    model: str | None = None  # model file (absolute path); None: the built-in arm
    model_hash: str | None = None  # its hash (text, surface files, physics version); None: `run` computes it
    simulator: str = "arm"  # the FE arm from its response tables; "analytic": the closed-form stand-in (tests)
    level: int = 1  # sparse-grid level of the campaign (1: 243 states, 2: 1053)
    held_out: int = 25  # random states of the same simulator for the error-propagation table
    campaign_store: str | None = None  # reuse a finished campaign instead of running one
    held_out_store: str | None = None
    moment_table: str | None = None  # FE moment table of the same arm; default: the tables stage's
    samples: int = 4000  # SG training states
    angle_fraction: float = 0.5
    pod_folds: int = 5
    pod_epochs: int = 100
    paper_folds: int = 1
    paper_epochs: int = 8
    seed: int = 0
    fe_states: bool = True  # the three showcase FE equilibria
    bench: bool = True  # the speed table in the evaluate stage
    # seconds per campaign state before it is recorded as failed (None: no limit). Not in any
    # digest: it changes whether a state finishes, never what a finished state holds.
    state_timeout_s: float | None = 900.0


#: (name, what it does, the stages whose artifacts it reads)
STAGES = [
    ("model", "validate and mesh the arm of the model file", []),
    ("tables", "the FE arm's per-muscle response tables (built once per model)", []),
    ("fe", "three FE equilibria of the arm (hanging, biceps 0.5, flexors 1)", ["model", "tables"]),
    ("campaign", "sparse-grid campaign + random held-out states", ["tables"]),
    ("anatomy", "bodies inside each other and muscles off their beds (FE and held-out states)", ["fe", "campaign"]),
    ("structured", "per-muscle shape and moment models from the tables: the deployed model", ["tables", "campaign"]),
    ("sg", "B-spline sparse grid of five muscle surfaces + elbow angle", ["campaign"]),
    ("inverse", "least-effort activations: the angle activation model", ["sg"]),
    ("motion", "motion-and-load activation model from the FE moments", ["sg", "tables"]),
    ("data", "SG training data at alpha_opt(Theta) and random alpha", ["sg", "inverse"]),
    ("train", "POD network (five muscles) and the paper's network (biceps)", ["data"]),
    ("export", "ONNX models + metadata.json", ["structured", "train", "inverse", "motion"]),
    ("evaluate", "the paper's accuracy and speed tables", ["export", "campaign", "structured", "sg", "train", "data"]),
    ("report", "HTML report", ["evaluate", "anatomy", "fe", "model"]),
]


#: stages whose folder is not named after them
FOLDERS = {"train": "networks"}

#: stages that resume what an interrupted run of theirs left (the campaign's stores resume state
#: by state and refuse another design or simulator); every other stage starts from an empty folder
RESUMABLE = {"campaign"}


def _digest(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


def code_versions() -> dict:
    """What of the code every stage's result depends on beyond its inputs: the package release (the
    physics version is part of the model hash, which the stages that read the arm hold)."""
    import persival

    return {"persival": persival.__version__}


def _stage_inputs(name: str, config: RunConfig, done: dict) -> dict:
    keys = stages.SETTINGS[name]
    upstream = dict((s[0], s[2]) for s in STAGES)[name]
    settings = {k: getattr(config, k) for k in keys}
    # a stage left out of this run (fe with --no-fe-states) is no input
    return {"settings": settings, "code": code_versions(),
            "upstream": {u: done[u]["digest"] for u in upstream if u in done}}


def run(out: str | Path, config: RunConfig | None = None, console=None) -> dict:
    """Every stage in order; returns {stage: its summary}. ``console``: where the log goes (the
    command line passes rich's Console; by default plain lines, persival.progress.PlainConsole)."""
    from persival.progress import PlainConsole

    config = config or RunConfig()
    if config.model_hash is None:  # the model file's content is an input of every stage that reads it
        from dataclasses import replace

        from persival.model.arm.model_file import load_model_file

        config = replace(config, model_hash=load_model_file(config.model)[1])
    console = console or PlainConsole()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    done: dict[str, dict] = {}
    started = time.perf_counter()
    active = [s for s in STAGES if config.fe_states or s[0] != "fe"]
    for k, (name, what, _) in enumerate(active, 1):
        folder = out / FOLDERS.get(name, name)
        inputs = _stage_inputs(name, config, done)
        digest = _digest(inputs)
        marker, started_marker = folder / "stage.json", folder / "started.json"
        if marker.exists() and json.loads(marker.read_text()).get("digest") == digest:
            done[name] = json.loads(marker.read_text())
            console.rule(f"{k}/{len(active)} {name}: {what} [dim](unchanged, skipped)[/dim]")
            continue
        resume = (name in RESUMABLE and not marker.exists() and started_marker.exists()
                  and json.loads(started_marker.read_text()).get("digest") == digest)
        console.rule(f"{k}/{len(active)} {name}: {what}" + (" [dim](resumed)[/dim]" if resume else ""))
        if folder.exists() and not resume:
            shutil.rmtree(folder)  # inputs changed: stale artifacts must not mix with new ones
        folder.mkdir(parents=True, exist_ok=True)
        if name in RESUMABLE:  # other stages want their folder empty
            started_marker.write_text(json.dumps({"digest": digest}))
        t0 = time.perf_counter()
        summary = stages.RUNNERS[name](out, config, console)
        record = {"stage": name, "digest": digest, "inputs": inputs, "wall_time_s": time.perf_counter() - t0,
                  "summary": summary}
        marker.write_text(json.dumps(record, indent=2, default=float))
        done[name] = record
        console.print(f"  [dim]{name} took {record['wall_time_s']:.1f} s[/dim]")
    total = time.perf_counter() - started
    (out / "run.json").write_text(json.dumps({"config": asdict(config), "wall_time_s": total,
                                              "stages": {n: d["wall_time_s"] for n, d in done.items()}}, indent=2))
    stages.print_results(out, console, total, sum(d["wall_time_s"] for d in done.values()))
    return done
