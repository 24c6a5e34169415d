"""``process-poses`` with the motion-consistency check of ``process`` (experiment/checks.py) inside the
gross-error diagnosis (experiment/gross.py): a wrong ``measured:`` direction, a joint's sign reversed or a
wrong length scale end in exit 3 with the reading that fits named and no calibrated model; a pose whose joints
are wrong is rejected and named; a clean file gives exactly the figures of the fit without the check."""

import json

import numpy as np
import pytest

from vision_calib import cli
from vision_calib import frames as F
from vision_calib.experiment.checks import motion_consistency
from vision_calib.experiment.gross import GROSS_CHI2_DOF
from vision_calib.experiment.poses import process_poses
from vision_calib.experiment.steps import identify_measurements, rngs, scene_truth
from vision_calib.io.measured_poses import read_measured_poses
from vision_calib.io.measured_poses_writer import write_measured_poses
from vision_calib.rig import SCENES_DIR, Measurements, load_scene, scene_poses

RX90 = str(SCENES_DIR / "rx90_eye_in_hand.yaml")
ST, SR = 1e-4, float(np.radians(0.02))  # 0.1 mm, 0.02 deg per component
N = 40


@pytest.fixture(scope="module")
def rx90():
    """(scene, q (N, 6) rad, T_cam_target (N, 4, 4) with N(0, ST/SR) noise) of the RX-90 truth."""
    scene = load_scene(RX90)
    rp, rn, _ = rngs(4)
    q = scene_poses(scene, rp, N)
    T = scene.setup.T_cam_target(q, scene_truth(scene))
    d = np.concatenate([rn.normal(scale=ST, size=(N, 3)), rn.normal(scale=SR, size=(N, 3))], axis=1)
    return scene, q, F.perturb_pose(T, d)


def _write(tmp_path, q, T, measured="T_cam_target"):
    return write_measured_poses(tmp_path / "m.yaml", RX90, [f"p{i:03d}" for i in range(len(q))], q, T, measured,
                                units={"length": "mm", "angle": "deg"}, default_sigma=(ST, SR))


def _run(tmp_path, path, capsys):
    rc = cli.main(["process-poses", str(path), "--out", str(tmp_path / "out"), "--no-plots"])
    err = capsys.readouterr().err
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    return rc, err, rep


def test_clean_file_same_figures_as_without_the_check(tmp_path, rx90):
    """A clean file passes the check (no refusal, no pose dropped) and its identified parameters and std are
    exactly those of the fit of the same measurements without it."""
    scene, q, T = rx90
    p = _write(tmp_path, q, T)
    rep = process_poses(p, tmp_path / "out", plots=False)
    mp = read_measured_poses(p)
    ref = identify_measurements(scene.setup, mp.measurements, "lse", mp.residual, where=str(p)).result
    assert rep["verdict"]["status"] == "ok" and "failure" not in rep
    mc = rep["motion_check"]
    assert "refusal" not in mc and mc["inconsistent_poses"] == [] and abs(mc["scale"] - 1) < 0.01
    np.testing.assert_array_equal([r["identified"] for r in rep["parameters"]], ref.identified)
    assert (tmp_path / "out" / "calibrated_model.yaml").is_file()


def test_motion_check_cannot_see_an_inverted_pose_set(rx90):
    """Why the reversed direction is left to the refits: inverting every pose keeps each relative motion's
    angle and |pitch|, so the check's figures are the same for both readings."""
    scene, q, T = rx90
    cov = np.broadcast_to(np.diag([ST**2] * 3 + [SR**2] * 3), (N, 6, 6))
    a = motion_consistency(scene.setup, Measurements(q, q, T, cov, None))
    b = motion_consistency(scene.setup, Measurements(q, q, F.inv_T(T), cov, None))
    assert np.isclose(a["scale"], b["scale"], rtol=1e-9)
    assert np.isclose(a["angle_mismatch_median_deg"], b["angle_mismatch_median_deg"], rtol=1e-9, atol=1e-12)


def test_wrong_measured_direction_exit_3_names_the_reading(tmp_path, rx90, capsys):
    """T_cam_target rows declared as T_target_cam: exit 3, the message names the direction and the reading
    that fits (checked for motion consistency too), the report is kept, no calibrated model."""
    scene, q, T = rx90
    rc, err, rep = _run(tmp_path, _write(tmp_path, q, T, measured="T_target_cam"), capsys)
    assert rc == 3
    assert "each checked for motion consistency" in err
    assert "the rows read as T_cam_target (measured: direction reversed): chi2/dof" in err
    hit = [t for t in rep["failure"]["tests"] if t["fits"]]
    assert [t["candidate"] for t in hit] == ["the rows read as T_cam_target (measured: direction reversed)"]
    assert hit[0]["motions_follow_joints"] is True and hit[0]["chi2_dof"] < 3
    assert rep["verdict"]["status"] == "failed" and not (tmp_path / "out" / "calibrated_model.yaml").exists()


def test_joint_sign_reversed_keeps_the_diagnosis(tmp_path, rx90, capsys):
    """Joint 2's readings negated: the motion check refuses the data, and that refusal enters the diagnosis
    instead of pre-empting it: exit 3, the refusal and the refit that fits (joint 2 negated) both named."""
    scene, q, T = rx90
    q = q.copy()
    q[:, 1] *= -1
    rc, err, rep = _run(tmp_path, _write(tmp_path, q, T), capsys)
    assert rc == 3
    assert "the measured rotations between poses do not follow the commanded joints" in err
    assert "joint 2's readings negated (its sign reversed in the input): chi2/dof" in err and "-- this fits" in err
    f = rep["failure"]
    assert f["motion_check"] and rep["motion_check"]["refusal"] == f["motion_check"]
    assert [t["candidate"][:7] for t in f["tests"] if t["fits"]] == ["joint 2"]
    assert not (tmp_path / "out" / "calibrated_model.yaml").exists()


def test_length_scale_absorbed_by_the_fit_is_refused(tmp_path, rx90, capsys):
    """Positions 10 % too large (a wrong scale, e.g. a mis-sized target in the logger): the robot's lengths
    absorb it (chi2/dof near 1, a calibrated model before this check); the motion check measures the scale
    against the nominal robot: exit 3 naming it, no model."""
    scene, q, T = rx90
    T = T.copy()
    T[:, :3, 3] *= 1.1
    rc, err, rep = _run(tmp_path, _write(tmp_path, q, T), capsys)
    f = rep["failure"]
    assert rc == 3 and f["kind"] == "inconsistent motions"
    assert f["chi2_dof"] < 2 < GROSS_CHI2_DOF  # the fit alone sees nothing
    assert abs(rep["motion_check"]["scale"] - 1.1) < 0.01
    assert "the measured motions are 1.1 x the commanded ones" in err and "(none fits)" in err
    assert not (tmp_path / "out" / "calibrated_model.yaml").exists()


def test_pose_with_a_wrong_joint_reading_rejected_and_named(tmp_path, rx90):
    """One pose whose joint 4 reading is 0.5 rad off: named as inconsistent, counted once among the rejected
    poses, kept out of the fit and of every training fold but still held out."""
    scene, q, T = rx90
    q = q.copy()
    q[3, 3] += 0.5
    rep = process_poses(_write(tmp_path, q, T), tmp_path / "out", plots=False)
    assert [r["pose_id"] for r in rep["motion_check"]["inconsistent_poses"]] == ["p003"]
    assert [o["pose_id"] for o in rep["outliers"]] == ["p003"] and rep["verdict"]["n_rejected_poses"] == 1
    assert "does not follow its joints" in rep["outliers"][0]["reason"]
    kf = rep["holdout"]
    assert kf["overall"]["n_poses"] == N and kf["without_outliers"]["excluded"] == ["p003"]
    assert rep["verdict"]["status"] == "ok"


def test_swapped_joint_columns_named_as_such(tmp_path, rx90, capsys):
    """Joints 2 and 3 in each other's columns (issue 28): the motion check reads it as a length scale (0.54 x);
    the diagnosis refits every pair of columns swapped and names the one that fits first: exit 3, no model."""
    scene, q, T = rx90
    q = q.copy()
    q[:, [1, 2]] = q[:, [2, 1]]
    rc, err, rep = _run(tmp_path, _write(tmp_path, q, T), capsys)
    assert rc == 3
    hits = [t["candidate"] for t in rep["failure"]["tests"] if t["fits"]]
    assert hits and hits[0].startswith("joints 2 and 3 swapped"), hits
    assert "joints 2 and 3 swapped (their columns in the wrong order in the input): that reading of the input fits" \
        in rep["failure"]["message"].split(". ")[0] + ". " + rep["failure"]["message"]
    assert not (tmp_path / "out" / "calibrated_model.yaml").exists()
