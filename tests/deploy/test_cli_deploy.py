"""The deploy commands: ``compensate``, ``inverse`` and ``export`` on a result folder, joint / pose tables with their
units in the header, named errors (file, line, column; exit 2), unreachable rows (named, the others written; exit
3 and nothing written only when no row is reached), and ``--export NAME`` after a run (process-poses)."""

import csv
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from vision_calib import frames as F
from vision_calib.cli import EXPORT_FORMATS, EXPORTING_RUNS, main
from vision_calib.deploy.export import FORMATS
from vision_calib.rig import SCENES_DIR

from deploy_helpers import workspace_joints

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiment"))
from flange_folder import measured_pose_file  # noqa: E402 (tests/experiment helper)


def _read(path):
    rows = list(csv.reader(path.read_text().splitlines()))
    return rows[0], rows[1:]


def test_compensate_command_in_degrees(results, tmp_path, capsys):
    res = results["rx90_eye_in_hand"]
    q = workspace_joints(res.robot, res.run.setup, 12)
    lines = ["pose_id," + ",".join(f"q{j}_deg" for j in range(1, 7))]
    lines += [f"p{k}," + ",".join(repr(float(v)) for v in np.degrees(row)) for k, row in enumerate(q)]
    (tmp_path / "joints.csv").write_text("\n".join(lines) + "\n")
    assert main(["compensate", str(res.folder), str(tmp_path / "joints.csv"), "--out", str(tmp_path / "c.csv")]) == 0
    assert "wrote" in capsys.readouterr().out
    head, rows = _read(tmp_path / "c.csv")
    assert head == lines[0].split(",") and [r[0] for r in rows] == [f"p{k}" for k in range(12)]
    qc = np.radians(np.array([[float(v) for v in r[1:]] for r in rows]))
    np.testing.assert_allclose(qc, res.robot.compensate(q), atol=1e-13)


def test_inverse_command_with_millimetres_and_a_tcp(results, tmp_path):
    from vision_calib.deploy import CalibratedRobot

    res = results["ur5e_eye_in_hand"]
    tcp = [0.0, 0.0, 0.12]
    robot = CalibratedRobot.load(res.folder, tcp=tcp)
    q = workspace_joints(robot, res.run.setup, 10)
    T, _ = robot.forward(q)
    xyz, quat = F.xyz_quat_from_T(T)
    lines = ["x_mm,y_mm,z_mm,qx,qy,qz,qw"] + [",".join(repr(float(v)) for v in (*a * 1e3, *b)) for a, b in zip(xyz, quat)]
    (tmp_path / "poses.csv").write_text("\n".join(lines) + "\n")
    assert main(["inverse", str(res.folder / "calibrated_model.yaml"), str(tmp_path / "poses.csv"), "--out",
                 str(tmp_path / "j.csv"), "--tcp", ",".join(map(str, tcp)), "--unit", "deg"]) == 0
    head, rows = _read(tmp_path / "j.csv")
    assert head == [f"q{j}_deg" for j in range(1, 7)]  # no pose_id column in, none out
    qi = np.radians(np.array([[float(v) for v in r] for r in rows], float))
    e = F.pose_error(T, robot.forward(qi)[0])
    assert np.abs(e).max() < 1e-9


def test_export_command(results, tmp_path, capsys):
    assert main(["export", str(results["rx90_eye_in_hand"].folder), "--format", "dh", "--out",
                 str(tmp_path / "dh.csv"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["format"] == "dh" and out["out"] == str(tmp_path / "dh.csv")
    assert out["verified"]["joint_sets"] > 0 and out["verified"]["max_m"] < 1e-9 and out["verified"]["max_rad"] < 1e-9
    assert (tmp_path / "dh.csv").read_text().count("\njoint") == 6
    assert main(["export", str(results["h4_vision"].folder), "--format", "dh", "--out", str(tmp_path / "h.csv")]) == 2
    err = capsys.readouterr().err
    assert "format 'dh' cannot represent this h4 robot" in err and err.count("\n") == 1
    assert set(EXPORT_FORMATS) == set(FORMATS)  # the CLI's list is the library's


@pytest.mark.parametrize("content,match", [
    ("pose_id,q1,q2,q3,q4,q5,q6\na,0,0,0,0,0,0\n", "column 'q1' has no unit: write q1_rad or q1_deg"),
    ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg\n0,0,0,0,0\n", "missing joint column(s) q6"),
    ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg\n0,0,0,0,0,0,0\n", "column 'q7_deg': the robot has 6 joints"),
    ("q1_grad,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0\n", "column 'q1_grad': unknown unit 'grad'"),
    ("q1_m,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0\n", "joint 1 is revolute: its unit must be rad or deg"),
    ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0,0\n0,0,x,0,0,0\n", "line 3: column q3_deg: not a number"),
    ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,0\n", "line 2: 5 values, expected 6"),
    ("q1_rad,q2_rad,q3_rad,q4_rad,q5_rad,q6_rad\n0,0,300,0,0,0\n", "line 2: column q3_rad: implausible value 300"),
    ("pose_id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\na,0,0,0,0,0,0\na,1,0,0,0,0,0\n", "duplicate pose ids"),
    ("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n", "no rows"),
])
def test_bad_joint_tables_are_named(results, tmp_path, capsys, content, match):
    (tmp_path / "joints.csv").write_text(content)
    code = main(["compensate", str(results["rx90_eye_in_hand"].folder), str(tmp_path / "joints.csv"), "--out",
                 str(tmp_path / "c.csv")])
    err = capsys.readouterr().err
    assert code == 2 and match in err and "joints.csv" in err, err
    assert not (tmp_path / "c.csv").exists()


@pytest.mark.parametrize("content,match", [
    ("x,y,z,qx,qy,qz,qw\n0,0,0,0,0,0,1\n", "column 'x' has no unit: write x_m"),
    ("x_m,y_mm,z_m,qx,qy,qz,qw\n0,0,0,0,0,0,1\n", "x, y, z in different units"),
    ("x_m,y_m,z_m,qx,qy,qz,qw\n0,0,0,0,0,0,2\n", "line 2: quaternion (qx, qy, qz, qw) norm 2.0000 is not 1"),
    ("x_m,y_m,z_m,qx,qy,qz\n0,0,0,0,0,0\n", "missing column(s) qw"),
    ("x_m,y_m,z_m,qx,qy,qz,qw,roll\n0,0,0,0,0,0,1,0\n", "unknown column 'roll'"),
    ("x_m,y_m,z_m,qx,qy,qz,qw\n500,0,0,0,0,0,1\n", "line 2: position 500 m from the base is implausible"),
])
def test_bad_pose_tables_are_named(results, tmp_path, capsys, content, match):
    (tmp_path / "poses.csv").write_text(content)
    code = main(["inverse", str(results["rx90_eye_in_hand"].folder), str(tmp_path / "poses.csv"), "--out",
                 str(tmp_path / "j.csv")])
    err = capsys.readouterr().err
    assert code == 2 and match in err and "poses.csv" in err, err


def _far_table(res, path, far):
    """A pose table of poses of the workspace (pose_id ok<k>) where the rows ``far`` are moved 3 m: out of reach.
    Returns (T (N, 4, 4), ids)."""
    q = workspace_joints(res.robot, res.run.setup, 4)
    T, _ = res.robot.forward(q)
    ids = [f"far{k}" if k in far else f"ok{k}" for k in range(len(T))]
    T[far, 0, 3] += 3.0
    xyz, quat = F.xyz_quat_from_T(T)
    path.write_text("pose_id,x_m,y_m,z_m,qx,qy,qz,qw\n" + "".join(
        f"{pid}," + ",".join(repr(float(v)) for v in (*a, *b)) + "\n" for pid, a, b in zip(ids, xyz, quat)))
    return T, ids


@pytest.mark.parametrize("name", ["rx90_eye_in_hand", "h4_vision"])
def test_an_unreachable_pose_is_named_and_the_others_written(results, tmp_path, capsys, name):
    res = results[name]
    T, ids = _far_table(res, tmp_path / "poses.csv", [1, 2])
    code = main(["inverse", str(res.folder), str(tmp_path / "poses.csv"), "--out", str(tmp_path / "j.csv")])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    for k in (1, 2):
        assert f"warning: pose row {k + 1} (pose_id 'far{k}', poses.csv line {k + 2})" in cap.err
    assert cap.err.count("not reached") == 2
    assert "2 of 4 joint sets; 2 poses not reached" in cap.out
    head, rows = _read(tmp_path / "j.csv")
    assert [r[0] for r in rows] == ["ok0", "ok3"]
    qi = np.array([[float(v) for v in r[1:]] for r in rows])
    assert np.abs(F.pose_error(T[[0, 3]], res.robot.forward(qi)[0])).max() < 1e-9


def test_inverse_exits_3_only_when_no_pose_is_reached(results, tmp_path, capsys):
    res = results["rx90_eye_in_hand"]
    _far_table(res, tmp_path / "poses.csv", [0, 1, 2, 3])
    code = main(["inverse", str(res.folder), str(tmp_path / "poses.csv"), "--out", str(tmp_path / "j.csv")])
    err = capsys.readouterr().err
    assert code == 3 and "no pose could be reached" in err and "pose row 4 (pose_id 'far3', poses.csv line 5)" in err
    assert not (tmp_path / "j.csv").exists()


def test_output_over_an_input_is_refused(results, tmp_path, capsys):
    (tmp_path / "joints.csv").write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,35,100,0,50,0\n")
    code = main(["compensate", str(results["rx90_eye_in_hand"].folder), str(tmp_path / "joints.csv"), "--out",
                 str(tmp_path / "joints.csv")])
    assert code == 2 and "is the input file" in capsys.readouterr().err


def test_export_option_after_a_run(tmp_path, capsys):
    assert "process-poses" in EXPORTING_RUNS
    mp = measured_pose_file(tmp_path / "in" / "measured.yaml", SCENES_DIR / "rx90_eye_in_hand.yaml", n=30)
    out = tmp_path / "out"
    assert main(["process-poses", str(mp), "--out", str(out), "--no-plots", "--json", "--export", "dh"]) == 0
    assert "exported" in capsys.readouterr().err
    assert (out / FORMATS["dh"].file).read_text().startswith("# modified-DH table")
    out2 = tmp_path / "out2"
    # an export that cannot apply after a good calibration: a warning, the run's exit code (0)
    assert main(["process-poses", str(mp), "--out", str(out2), "--no-plots", "--json", "--export", "ur_yaml"]) == 0
    err = capsys.readouterr().err
    assert "warning: --export ur_yaml not written: " in err and "format 'ur_yaml' cannot represent this serial robot" in err
    assert not (out2 / FORMATS["ur_yaml"].file).exists()
    assert f"the run's outputs in {out2} are kept" in err
    assert (out2 / "report.json").is_file() and (out2 / "calibrated_model.yaml").is_file()  # the run's outputs kept


def test_the_runs_take_export_and_check_its_name(capsys):
    from vision_calib.cli import build_parser

    ap = build_parser()
    for run in EXPORTING_RUNS:
        extra = {"simulate": ["s.yaml", "--out", "o"], "process": ["f", "--out", "o"],
                 "process-poses": ["m.yaml", "--out", "o"]}[run]
        assert ap.parse_args([run, *extra, "--export", "urdf"]).export == "urdf"
        with pytest.raises(SystemExit) as e:
            ap.parse_args([run, *extra, "--export", "step"])
        assert e.value.code == 2 and "invalid choice: 'step'" in capsys.readouterr().err
