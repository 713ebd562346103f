"""Per-muscle FE moment tables (issue 17's first piece; SPEC 3.3, 8).

The physics checks read ``tests/data/moments_coarse.npz``: the coarse-profile table built by
``persival moments --profile coarse --angles 0:160:20 --levels 0,0.5,1`` (about 10 minutes, so
it is a fixture, not rebuilt here). One test solves real FE columns (one muscle, two angles) to
check the build, its kill-and-resume and its agreement with the fixture.
"""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from persival.model.arm.model_file import load_model_file
from persival.tables.moment_table import MomentTable, TableMismatchError, build_moment_table
from persival.vocabulary import MUSCLES

FIXTURE = Path(__file__).parents[1] / "data" / "moments_coarse.npz"


@pytest.fixture(scope="module")
def table():
    return MomentTable.load(FIXTURE)


def test_table_is_complete_and_finite(table):
    assert table.complete and table.meta["profile"] == "coarse"
    assert table.moments.shape == (5, len(table.angles_deg), len(table.levels))
    assert np.isfinite(table.tension).all() and np.isfinite(table.moments).all()


def test_flexors_pull_when_active_and_extensors_extend(table):
    mid = (table.angles_deg >= 20) & (table.angles_deg <= 100)
    for m, name in enumerate(MUSCLES):
        active, passive = table.moments[m, mid, -1], table.moments[m, mid, 0]
        if name in ("biceps", "brachialis", "brachioradialis"):
            assert np.all(active > 0) and np.all(active > passive + 100), name
        else:
            assert np.all(active < passive), name  # activation extends
    assert np.all(table.tension[:3, mid, -1] > 10.0)  # N: taut flexors


def test_interpolation_reproduces_the_table_and_is_smooth(table):
    for m, name in enumerate(MUSCLES):
        for j, a in enumerate(table.levels):
            got = table.moment(name, table.angles_deg, np.full(len(table.angles_deg), a))
            assert np.allclose(got, table.moments[m, :, j], rtol=1e-9, atol=1e-6), name
    fine = np.linspace(20, 100, 161)
    biceps = table.moment("biceps", fine, np.full(len(fine), 0.75))
    half, full = table.moment("biceps", fine, np.full(len(fine), 0.5)), table.moment("biceps", fine, np.ones(len(fine)))
    assert np.allclose(biceps, 0.5 * (half + full))  # linear between the levels
    assert np.isfinite(biceps).all() and np.abs(np.diff(biceps, 2)).max() < 20.0  # N mm per 0.5 deg: no kinks


def test_foreign_tables_are_refused(table, tmp_path):
    with pytest.raises(TableMismatchError, match="another model: model hash"):
        MomentTable.load(FIXTURE, model_hash="0" * 64)
    with pytest.raises(TableMismatchError, match="profile 'coarse', not 'quick'"):
        MomentTable.load(FIXTURE, profile="quick")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(TableMismatchError, match="not a moment table"):
        MomentTable.load(tmp_path / "other.npz")
    unfinished = replace(table, done=np.zeros_like(table.done))
    unfinished.save(tmp_path / "unfinished.npz")
    with pytest.raises(TableMismatchError, match="unfinished: 0 of 15 columns"):
        MomentTable.load(tmp_path / "unfinished.npz", complete=True)


class _Kill(Exception):
    pass


@pytest.mark.slow
def test_fe_columns_resume_after_a_kill_and_agree_with_the_fixture(table, tmp_path):
    """Real FE sweeps (triceps, 60 and 80 deg, passive and active): the build is killed after
    its first column, the rerun skips it and computes only the other."""
    from persival.model.arm.arm_model import ArmModel

    arm = ArmModel(profile="coarse")
    out = tmp_path / "t.npz"
    computed = []

    def kill_after_first(done, total, label):
        computed.append(label)
        if len(computed) == 1:
            raise _Kill

    with pytest.raises(_Kill):
        build_moment_table(arm, [60.0, 80.0], [0.0, 1.0], kill_after_first, out=out, muscles=["triceps"])
    assert MomentTable.load(out).done.sum() == 1  # the finished column was saved before the kill
    labels = []
    result = build_moment_table(arm, [60.0, 80.0], [0.0, 1.0], lambda d, t, label: labels.append(label), out=out,
                                muscles=["triceps"])
    assert labels == ["triceps a=0 (skipped: done)", "triceps a=1"]
    assert result.done[3].all() and not result.done[:3].any()
    with pytest.raises(TableMismatchError, match="asked for"):
        build_moment_table(arm, [60.0, 90.0], [0.0, 1.0], out=out, muscles=["triceps"])
    if table.meta["model_hash"] == load_model_file()[1]:  # the fixture is of today's model
        rows = [int(np.flatnonzero(table.angles_deg == t)[0]) for t in (60.0, 80.0)]
        expected = table.tension[3][np.ix_(rows, [0, -1])]
        assert np.allclose(result.tension[3], expected, rtol=1e-4, atol=1e-3)
    shutil.rmtree(tmp_path, ignore_errors=True)


def test_the_push_check_finds_the_built_in_arms_pushing_muscles_and_passes_a_pulling_table(table):
    """SPEC 3.3 "no muscle pushes": on the coarse built-in arm every muscle's least tension is
    below -2 N somewhere (the slack brachialis -20.6 N at 160 deg, the passive triceps -8.9 N at
    0 deg) and both passive extensors flex the elbow; with every tension a pull and the passive
    extensors' moments turned to extension the check passes."""
    from persival.tables.push_check import push_check

    report = push_check(table, ("triceps", "anconeus"))
    assert report["pushing"] == list(MUSCLES) and report["passive_extensors_flexing"] == ["triceps", "anconeus"]
    brachialis, triceps = report["muscles"]["brachialis"], report["muscles"]["triceps"]
    assert brachialis["least_tension_N"] == pytest.approx(np.nanmin(table.tension[1])) and brachialis["least_tension_N"] < -2.0
    assert brachialis["at_deg"] == 160.0 and triceps["at_deg"] == 0.0 and triceps["at_level"] == 0.0
    assert triceps["passive_moment_max_Nmm"] == pytest.approx(np.nanmax(table.moments[3, :, 0]))
    assert triceps["passive_moment_max_Nmm"] > 0.0
    moments = table.moments.copy()
    moments[3:, :, 0] = -np.abs(moments[3:, :, 0])
    pulling = replace(table, tension=np.abs(table.tension), moments=moments)
    clean = push_check(pulling, ("triceps", "anconeus"))
    assert clean["pushing"] == [] and clean["passive_extensors_flexing"] == []


def test_the_push_check_says_what_lies_within_the_joints_limits(table):
    """With the joint's limits the check also reads the angles inside them alone: on the coarse
    built-in arm held to 0-100 deg the brachioradialis' push (-3.8 N at 160 deg) is gone, the
    brachialis' least tension is its value at 100 deg, and the extensors' 0-deg pushes stay."""
    from persival.tables.push_check import push_check

    report = push_check(table, ("triceps", "anconeus"), (0.0, 100.0))
    inside = table.angles_deg <= 100.0
    brachialis = report["muscles"]["brachialis"]["in_joint_range"]
    assert brachialis["least_tension_N"] == pytest.approx(np.nanmin(table.tension[1][inside]))
    assert brachialis["at_deg"] == 100.0 and report["muscles"]["brachialis"]["at_deg"] == 160.0
    assert "brachioradialis" in report["pushing"] and "brachioradialis" not in report["pushing_in_joint_range"]
    assert report["pushing_in_joint_range"] == ["biceps", "brachialis", "triceps", "anconeus"]
    assert report["muscles"]["triceps"]["in_joint_range"] == {k: v for k, v in report["muscles"]["triceps"].items()
                                                              if k != "in_joint_range"}
    assert report["joint_limits_deg"] == [0.0, 100.0] and "pushing_in_joint_range" not in push_check(table, ())


def test_the_tables_stage_says_which_muscles_push(table, capsys):
    """The run's tables stage reports the check in one line, with the extensors from the model file."""
    from persival.pipeline.arm_stages import _pushes
    from persival.progress import PlainConsole

    report = _pushes(table, None, PlainConsole())
    line = capsys.readouterr().out
    assert report["passive_extensors_flexing"] == ["triceps", "anconeus"]
    assert "brachialis pushes -20.6 N at 160 deg" in line and "passive triceps flexes 188 N mm at 20 deg" in line
    assert "at least -2 N" in line and line.count("\n") == 1
