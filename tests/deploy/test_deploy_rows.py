"""Deploy commands a controller can trust (issue 33): compensate row by row (rows outside the joint limits named,
the rest written, near-singular rows flagged with their figures, exit 3 only when no row is corrected, the damped
correction never larger than the exact one), inverse keeping the branch asked for (--near), and the help examples
of compensate / inverse / export run as written."""

import argparse
import csv
import shlex
import shutil

import numpy as np
import pytest

from vision_calib import frames as F
from vision_calib.cli import build_parser, main
from vision_calib.deploy.robot import MAX_CORRECTION_DEG
from vision_calib.deploy.solve import levenberg_marquardt

from deploy_helpers import workspace_joints


def _joint_csv(path, q, ids, unit="deg"):
    f = np.degrees if unit == "deg" else (lambda v: v)
    lines = ["pose_id," + ",".join(f"q{j}_{unit}" for j in range(1, q.shape[1] + 1))]
    lines += [f"{i}," + ",".join(repr(float(v)) for v in f(row)) for i, row in zip(ids, q)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _pose_csv(path, T, ids):
    xyz, quat = F.xyz_quat_from_T(T)
    path.write_text("pose_id,x_m,y_m,z_m,qx,qy,qz,qw\n" + "".join(
        f"{i}," + ",".join(repr(float(v)) for v in (*a, *b)) + "\n" for i, a, b in zip(ids, xyz, quat)))
    return path


def _rows(path):
    rows = list(csv.DictReader(path.read_text().splitlines()))
    return rows


def test_compensate_writes_every_row_it_can_and_names_the_others(results, tmp_path, capsys):
    res = results["rx90_eye_in_hand"]
    r = res.robot
    q = workspace_joints(r, res.run.setup, 12)
    q[3, 4] = 0.0  # wrist singularity (q5 = 0)
    q[4, 2] = np.pi / 2  # q3 = 90 deg
    q[5, 1] = np.radians(400.0)  # beyond q2's limit
    ids = [f"p{k}" for k in range(12)]
    ids[5] = "too_far"
    _joint_csv(tmp_path / "joints.csv", q, ids)
    assert main(["compensate", str(res.folder), str(tmp_path / "joints.csv"), "--out", str(tmp_path / "c.csv")]) == 0
    cap = capsys.readouterr()
    assert ("row 6 (pose_id 'too_far', joints.csv line 7): joint q2 = 6.98132 rad (400 deg) outside its limits"
            in cap.err), cap.err
    written = _rows(tmp_path / "c.csv")
    report = {w["pose_id"]: w for w in _rows(tmp_path / "c_report.csv")}
    assert list(report) == ids
    assert report["too_far"]["status"] == "outside_limits" and "outside its limits" in report["too_far"]["why"]
    for k in (3, 4):  # at a singularity: corrected (flagged), or named with the correction it would need
        w = report[ids[k]]
        assert float(w["amplification_deg_per_mm"]) > 1.0
        assert w["status"] == "near_singularity" or (
            w["status"] == "not_corrected" and "near a singularity" in w["why"] and f"pose_id '{ids[k]}'" in cap.err)
    keep = [k for k in range(12) if report[ids[k]]["status"] in ("corrected", "near_singularity")]
    assert len(keep) >= 9 and [w["pose_id"] for w in written] == [ids[k] for k in keep]  # the rest all written
    qc = np.radians(np.array([[float(w[f"q{j}_deg"]) for j in range(1, 7)] for w in written]))
    # each written row is what the model gives: the tool within the reported remaining error and the accuracy
    e = F.pose_error(r.nominal.forward(q[keep])[0], r.forward(qc)[0])
    rem = np.array([float(report[ids[k]]["remaining_mm"]) for k in keep]) * 1e-3
    acc = np.array([float(report[ids[k]]["accuracy_mm"]) for k in keep]) * 1e-3
    np.testing.assert_allclose(np.linalg.norm(e[:, :3], axis=1), rem, rtol=1e-3, atol=1e-9)
    assert np.all(rem <= acc)
    assert np.degrees(np.abs(qc - q[keep]).max()) <= MAX_CORRECTION_DEG
    flagged = [k for k in keep if report[ids[k]]["status"] == "near_singularity"]
    for k in flagged:  # named on stderr with their figure (first 10)
        if flagged.index(k) < 10:
            assert f"pose_id '{ids[k]}'" in cap.err and "deg of joint motion per mm" in cap.err
        assert float(report[ids[k]]["amplification_deg_per_mm"]) > 1.0
    assert f"{len(keep)} of 12 joint sets" in cap.out


def test_compensate_exits_3_only_when_no_row_is_corrected(results, tmp_path, capsys):
    res = results["rx90_eye_in_hand"]
    q = workspace_joints(res.robot, res.run.setup, 2)
    q[:, 1] = np.radians(400.0)
    _joint_csv(tmp_path / "joints.csv", q, ["a", "b"])
    assert main(["compensate", str(res.folder), str(tmp_path / "joints.csv"), "--out", str(tmp_path / "c.csv")]) == 3
    err = capsys.readouterr().err
    assert "no row could be compensated" in err and "pose_id 'a'" in err and "pose_id 'b'" in err
    assert not (tmp_path / "c.csv").exists() and not (tmp_path / "c_report.csv").exists()


def test_a_damped_correction_is_never_larger_than_the_exact_one(results):
    """Near a singularity the correction is damped along the near-null directions: never larger than the exact
    solution's (Levenberg-Marquardt from the same joints), and it leaves what it reports."""
    res = results["rx90_eye_in_hand"]
    r = res.robot
    q = workspace_joints(r, res.run.setup, 60)
    c = r.compensate_rows(q)
    near = np.flatnonzero(c.status == "near_singularity")
    assert near.size
    T = r.kin.tool(q[near], r.x_nominal)
    qe, _, ok = levenberg_marquardt(lambda qq: r.kin.tool(qq, r.x), T, q[near], r.kin.joint_limits)
    assert ok.all()
    d_damped = np.linalg.norm(c.q_corrected[near] - q[near], axis=1)
    d_exact = np.linalg.norm(qe - q[near], axis=1)
    assert np.all(d_damped <= d_exact * (1 + 1e-6) + 1e-12), (d_damped / d_exact).max()


def test_joint_jacobian_matches_central_differences(result):
    from vision_calib.deploy.solve import joint_jacobian

    r = result.robot
    if r.kin.closed_form:
        pytest.skip("the H4's compensation is its closed-form inverse (no joint Jacobian)")
    q = workspace_joints(r, result.run.setup, 20)
    f = lambda qq: r.kin.tool(qq, r.x)  # noqa: E731
    np.testing.assert_allclose(r.kin.joint_jacobian(q, r.x), joint_jacobian(f, q, f(q)), atol=1e-8)


@pytest.mark.parametrize("name", ["rx90_eye_in_hand", "ur5e_eye_in_hand"])
def test_inverse_near_keeps_the_branch_asked_for(results, tmp_path, name):
    res = results[name]
    r = res.robot
    q = workspace_joints(r, res.run.setup, 20)
    ids = [f"p{k}" for k in range(20)]
    _pose_csv(tmp_path / "poses.csv", r.forward(q)[0], ids)
    _joint_csv(tmp_path / "near.csv", q, ids, unit="rad")
    assert main(["inverse", str(res.folder), str(tmp_path / "poses.csv"), "--out", str(tmp_path / "j.csv"),
                 "--near", str(tmp_path / "near.csv")]) == 0
    qi = np.array([[float(w[f"q{j}_rad"]) for j in range(1, 7)] for w in _rows(tmp_path / "j.csv")])
    assert np.abs(qi - q).max() <= 1e-6
    # one joint set for all: the poses of joint sets around it come back as those joint sets
    qs = q[0] + np.random.default_rng(1).uniform(-0.1, 0.1, size=(8, 6))
    _pose_csv(tmp_path / "poses1.csv", r.forward(qs)[0], ids[:8])
    _joint_csv(tmp_path / "near1.csv", q[:1], ["current"], unit="rad")
    assert main(["inverse", str(res.folder), str(tmp_path / "poses1.csv"), "--out", str(tmp_path / "j1.csv"),
                 "--near", str(tmp_path / "near1.csv")]) == 0
    qi = np.array([[float(w[f"q{j}_rad"]) for j in range(1, 7)] for w in _rows(tmp_path / "j1.csv")])
    assert np.abs(qi - qs).max() <= 1e-6


def test_inverse_near_with_another_row_count_is_named(results, tmp_path, capsys):
    res = results["rx90_eye_in_hand"]
    q = workspace_joints(res.robot, res.run.setup, 3)
    _pose_csv(tmp_path / "poses.csv", res.robot.forward(q)[0], ["a", "b", "c"])
    _joint_csv(tmp_path / "near.csv", q[:2], ["a", "b"], unit="rad")
    assert main(["inverse", str(res.folder), str(tmp_path / "poses.csv"), "--out", str(tmp_path / "j.csv"),
                 "--near", str(tmp_path / "near.csv")]) == 2
    assert "near.csv: 2 joint sets for the 3 poses of poses.csv" in capsys.readouterr().err


def _examples(command):
    ap = build_parser()
    sub = next(a for a in ap._actions if isinstance(a, argparse._SubParsersAction))
    return [ln.strip() for ln in sub.choices[command].epilog.splitlines() if ln.strip().startswith("vision-calib ")]


def test_the_help_examples_run_as_written(results, tmp_path, monkeypatch, capsys):
    """Every `vision-calib compensate / inverse / export` line of their --help, run as written in a folder holding
    the files it names (out/run: the RX-90 result, out/ur5e: the UR5e one, out/handeye: a result with mounts)."""
    rx, ur = results["rx90_eye_in_hand"], results["ur5e_eye_in_hand"]
    for src, dst in ((rx.folder, "out/run"), (ur.folder, "out/ur5e"), (rx.folder, "out/handeye")):
        shutil.copytree(src, tmp_path / dst)
    q = workspace_joints(rx.robot, rx.run.setup, 6)
    ids = [f"p{k}" for k in range(6)]
    _joint_csv(tmp_path / "joints.csv", q, ids)
    _pose_csv(tmp_path / "poses.csv", rx.robot.forward(q)[0], ids)
    _joint_csv(tmp_path / "current_joints.csv", q[:1], ["now"], unit="rad")
    monkeypatch.chdir(tmp_path)
    lines = [ln for c in ("compensate", "inverse", "export") for ln in _examples(c)]
    assert len(lines) >= 8 and any("--tcp" in ln for ln in lines) and any("--near" in ln for ln in lines)
    for ln in lines:
        code = main(shlex.split(ln)[1:])
        assert code == 0, (ln, capsys.readouterr().err)


def test_chunks_give_the_same_answers_and_report_progress(results, monkeypatch):
    import vision_calib.deploy.kinematics as kin_mod
    import vision_calib.deploy.robot as robot_mod

    res = results["ur5e_eye_in_hand"]
    r = res.robot
    q = workspace_joints(r, res.run.setup, 23)
    whole = r.compensate_rows(q)
    q_inv = r.inverse(r.forward(q)[0], q_start=q)
    monkeypatch.setattr(robot_mod, "CHUNK_ROWS", 5)
    monkeypatch.setattr(robot_mod, "INVERSE_CHUNK_ROWS", 5)
    seen = []
    chunked = r.compensate_rows(q, progress=lambda done, total: seen.append((done, total)))
    assert seen == [(5, 23)] * 4 + [(3, 23)]
    np.testing.assert_array_equal(chunked.q_corrected, whole.q_corrected)
    np.testing.assert_array_equal(chunked.status, whole.status)
    seen.clear()
    np.testing.assert_array_equal(r.inverse(r.forward(q)[0], q_start=q, progress=lambda d, t: seen.append(d)), q_inv)
    assert sum(seen) == 23 and len(seen) == 5
    # without a start (the nominal solution, the stored starts by blocks of goals): the same joints chunked or not
    monkeypatch.setattr(robot_mod, "INVERSE_CHUNK_ROWS", 32768)
    T = r.forward(q)[0]
    q_free = r.inverse(T)
    monkeypatch.setattr(robot_mod, "INVERSE_CHUNK_ROWS", 5)
    monkeypatch.setattr(kin_mod, "SEED_BLOCK", 3)
    np.testing.assert_array_equal(r.inverse(T), q_free)
