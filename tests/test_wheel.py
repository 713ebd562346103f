"""PerSival as an installed package: a wheel built from the source tree carries the packaged model
files and the built web viewer, and, installed into a fresh virtual environment, runs from an
empty folder (nothing of the source tree on its path).

The fresh environment takes the project's dependencies from the test's own environment through a
.pth line (installing torch and the rest again would take minutes and the network); persival
itself comes from the wheel only: the editable install's own .pth in that folder is not read
through a .pth line (site.py reads .pth files of site directories, not of the folders they add).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DIST = ROOT / "persival" / "deploy" / "web" / "dist"

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not (DIST / "index.html").is_file(), reason="needs the built viewer (make web)")]


def _source_copy(dest: Path) -> Path:
    """The files a wheel is built from (what git does not ignore, plus the built viewer)."""
    files = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split()
    for name in files:
        if name.startswith("persival/") or name in ("pyproject.toml", "README.md"):
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, dest / name)
    shutil.copytree(DIST, dest / "persival" / "deploy" / "web" / "dist")
    return dest


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    source = _source_copy(tmp_path_factory.mktemp("source"))
    out = tmp_path_factory.mktemp("wheelhouse")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation",
                    "-w", str(out), str(source)], check=True, capture_output=True, text=True)
    (found,) = out.glob("persival-*.whl")
    return found


def test_the_wheel_carries_the_models_and_the_viewer_not_the_sources(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for needed in ("persival/model/arm/default_arm.toml", "persival/model/arm/variants/spindle_arm.toml",
                   "persival/deploy/web/dist/index.html", "persival/deploy/web/dist/app.js",
                   "persival/cli/app.py", "persival/model/fe/solver.py"):
        assert needed in names, needed
    assert not any("node_modules" in n or n.startswith("tests/") or "/web/src/" in n for n in names)
    assert any(n.endswith("entry_points.txt") for n in names)


def test_installed_into_a_fresh_venv_it_runs_from_an_empty_folder(wheel, tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, check=True).stdout.strip())
    (site / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet", "--no-deps", str(wheel)],
                   check=True, capture_output=True, text=True)
    work = tmp_path / "empty"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PERSIVAL_CACHE"] = str(tmp_path / "cache")

    def persival(*args: str) -> str:
        proc = subprocess.run([str(venv / "bin" / "persival"), *args], cwd=work, env=env, capture_output=True,
                              text=True, timeout=300)
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
        return proc.stdout

    where = subprocess.run([str(python), "-c", "import persival, persival.deploy.server as s; "
                            "print(persival.__file__); print(s.WEB_DIST / 'index.html')"],
                           cwd=work, env=env, capture_output=True, text=True, check=True).stdout.split()
    assert where[0].startswith(str(venv)), f"persival imported from {where[0]}, not the wheel"
    assert Path(where[1]).is_file()  # the viewer `persival serve` serves
    assert "end to end" in persival("--help").lower()
    assert "spindle_arm" in persival("model", "list")
    persival("model", "init", "--out", "my_arm.toml")
    assert (work / "my_arm.toml").read_text().startswith("# PerSival's built-in arm")
    persival("campaign", "run", "--store", "small.zarr", "--simulator", "analytic", "--level", "1",
             "--scheduler", "inline", "--no-progress")
    status = persival("campaign", "status", "--store", "small.zarr")
    assert "243" in status and (work / "small.zarr").is_dir()
