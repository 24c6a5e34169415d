"""Degenerate motion on the hand-eye routes (experiment/checks.py handeye_motions, pair_copies; issue 32 item 4):
fewer than 3 distinct flange poses, translations only, or rotations about one axis are a DataError naming the
degenerate motion before any fit (exit 2 from process-poses, never a model); a pair written twice is named and
counted once, so the result and its std are those of the set written once; genuine repeats (the same flange pose,
measured again) are kept."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vision_calib import frames
from vision_calib.cli import main
from vision_calib.errors import DataError
from vision_calib.experiment.checks import (COPY_M, DEGENERATE_MOTION, MIN_AXIS_SPREAD_DEG, handeye_motions,
                                            pair_copies)
from vision_calib.experiment.handeye_sim import simulate_pose_pairs
from vision_calib.experiment.handeye_step import identify_handeye
from vision_calib.io.transform_pairs import write_transform_pairs


def _pairs_cli(tmp_path, T1, T2, name):
    src = write_transform_pairs(tmp_path / f"{name}.yml", T1, T2)
    out = tmp_path / name / "pairs.yaml"
    assert main(["import-pairs", str(src), "--mount", "fixed", "--out", str(out)]) == 0
    return out


def test_ten_copies_of_one_pair_exit_2_naming_the_degenerate_motion(tmp_path, capsys):
    d = simulate_pose_pairs(12, 4, "fixed")
    p = _pairs_cli(tmp_path, np.repeat(d.T_base_flange[:1], 10, 0), np.repeat(d.T_cam_target[:1], 10, 0), "c10")
    capsys.readouterr()
    assert main(["process-poses", str(p), "--out", str(tmp_path / "out"), "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert f"{DEGENERATE_MOTION}: the 10 pose pairs hold 1 distinct flange pose" in err
    assert not (tmp_path / "out" / "report.json").exists() and "Traceback" not in err


def test_pairs_written_twice_are_named_and_counted_once(tmp_path, capsys):
    """Every pair written twice: the copies named in a warning and the report's ``copies``; the estimate and its
    std equal those of the file written once (not 1/sqrt(2) smaller)."""
    d = simulate_pose_pairs(20, 4, "fixed")
    once = _pairs_cli(tmp_path, d.T_base_flange, d.T_cam_target, "once")
    twice = _pairs_cli(tmp_path, np.concatenate([d.T_base_flange] * 2), np.concatenate([d.T_cam_target] * 2), "twice")
    reps = {}
    for name, p in (("once", once), ("twice", twice)):
        assert main(["process-poses", str(p), "--out", str(tmp_path / f"out_{name}"), "--no-plots"]) == 0
        reps[name] = json.loads((tmp_path / f"out_{name}" / "report.json").read_text())
    out = capsys.readouterr().out
    assert "20 poses are copies of another pose (the same flange pose and measured pose" in out
    assert "p020 = p000" in out
    r1, r2 = reps["once"], reps["twice"]
    assert [c["pose_id"] for c in r2["measurements"]["copies"]] == [f"p{i:03d}" for i in range(20, 40)]
    assert r2["measurements"]["n_poses"] == 20 and r2["verdict"]["n_rejected_poses"] == 0
    s1, s2 = r1["handeye"]["stds"], r2["handeye"]["stds"]
    assert s1.keys() == s2.keys() and len(s1) == 12
    for k in s1:
        assert s2[k] == pytest.approx(s1[k], rel=1e-6), k


def test_near_copies_counted_once_and_repeats_kept():
    """A copy with 1e-6 m / 1e-6 rad jitter is a copy; the same flange pose measured again (the measured pose
    differing by the noise) is a repeat: kept, and it adds no distinct pose."""
    d = simulate_pose_pairs(8, 2, "fixed")
    F, M = d.T_base_flange, d.T_cam_target
    jitter = frames.perturb_pose(M[:3], np.tile([1e-6, -1e-6, 1e-6, 1e-6, -1e-6, 1e-6], (3, 1)))
    again = frames.perturb_pose(M[3:5], np.tile([3e-4, 2e-4, -5e-4, 1e-3, -1e-3, 5e-4], (2, 1)))
    F2, M2 = np.concatenate([F, F[:3], F[3:5]]), np.concatenate([M, jitter, again])
    labels = [f"p{i}" for i in range(len(F2))]
    keep, copies = pair_copies(F2, M2, None, labels)
    assert [c[0] for c in copies] == ["p8", "p9", "p10"] and keep == [*range(8), 11, 12]
    assert copies[0][1].startswith("a copy of pose p0 (the same flange pose and measured pose")
    # with the covariance given: the chi-square rule of the joint route
    cov = np.tile(np.diag([COPY_M**2 * 1e4] * 3 + [1e-6] * 3), (len(F2), 1, 1))
    assert [c[0] for c in pair_copies(F2, M2, cov, labels)[1]] == ["p8", "p9", "p10"]
    assert handeye_motions(F2, "fixed", labels, "x")["distinct_poses"] == 8


def _about_one_axis(n, axis, seed=0, tilt_deg=0.0):
    """n flange poses turned about one axis of the flange (rotations R0 Rot(axis, a_k)), random positions;
    tilt_deg: one pose tilted by that about a perpendicular axis."""
    rng = np.random.default_rng(seed)
    R0 = frames.so3_exp(np.array([0.3, -0.2, 0.5]))
    R = [R0 @ frames.so3_exp(np.asarray(axis, float) * a) for a in rng.uniform(-1.0, 1.0, n)]
    if tilt_deg:
        R[-1] = R[-1] @ frames.so3_exp(np.array([0.0, np.radians(tilt_deg), 0.0]))
    return frames.make_T(np.array(R), rng.uniform(-0.3, 0.3, (n, 3)))


@pytest.mark.parametrize("mount", ["fixed", "eye_in_hand"])
def test_rotations_about_one_axis_or_none_are_degenerate(mount):
    labels = [f"p{i}" for i in range(12)]
    F1 = _about_one_axis(12, [0, 0, 1])  # one axis in the flange frame is one axis in the base frame too
    with pytest.raises(DataError, match=rf"{DEGENERATE_MOTION}: every motion between the 12 distinct flange poses "
                                        r"rotates about one axis .*rank 1 of the 2 it needs"):
        handeye_motions(F1, mount, labels, "pairs.yaml")
    F0 = frames.make_T(np.tile(np.eye(3), (12, 1, 1)), np.random.default_rng(1).uniform(-0.3, 0.3, (12, 3)))
    with pytest.raises(DataError, match=rf"{DEGENERATE_MOTION}: the 12 distinct flange poses differ by translations "
                                        r"only .*rank 0"):
        handeye_motions(F0, mount, labels, "pairs.yaml")
    # a tilt about a second axis well above the resolution: not degenerate, the spread measured
    ok = handeye_motions(_about_one_axis(12, [0, 0, 1], seed=2, tilt_deg=20.0), "fixed", labels, "x")
    assert ok["rank"] >= 2 and ok["axis_spread_deg"] > MIN_AXIS_SPREAD_DEG


def test_identify_handeye_refuses_one_axis_before_any_fit():
    """The direct API (every route's fit) refuses too, where OpenCV's closed forms would only print."""
    F = _about_one_axis(10, [1, 0, 0], seed=3)
    M = frames.make_T(np.tile(np.eye(3), (10, 1, 1)), np.tile([0.0, 0.0, 0.5], (10, 1))) @ F
    with pytest.raises(DataError, match=DEGENERATE_MOTION):
        identify_handeye(F, M, "fixed", None, [str(i) for i in range(10)], noise_frame="target", where="w")


def test_simulated_cells_are_not_degenerate():
    """The simulator's cells (rotations of ~45 deg about several axes) pass with a wide margin."""
    for mount in ("fixed", "eye_in_hand"):
        d = simulate_pose_pairs(10, 1, mount)
        m = handeye_motions(d.T_base_flange, mount, d.labels, "x")
        assert m["rank"] == 3 and m["axis_spread_deg"] > 10 * MIN_AXIS_SPREAD_DEG, m
