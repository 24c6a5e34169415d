"""Exports a controller can trust (issue 33): names written through real emitters (a hostile robot name adds no
YAML key and no CSV row), implausible values refused with the rule named, every export read back and its forward
kinematics compared with the calibrated model (and a file that differs caught), ros_tf of a pose-pair hand-eye
result, and an export that cannot apply after a good run only a warning."""

import csv
import io
import json
import re
import shutil
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from vision_calib.cli import main
from vision_calib.errors import DataError
from vision_calib.experiment.handeye_sim import simulate_pose_pairs
from vision_calib.deploy.export import (FORMATS, UR_JOINTS, VERIFY_TOL_M, export, export_verified,
                                               load_result, verify_export)
from vision_calib.io.measured_poses_writer import write_pose_pairs

HOSTILE = "evil\nhash: injected\nkinematics2: {a: 1}\n# x,y\r\nbase,0"


def _copy(results, name, tmp_path):
    dst = tmp_path / name
    shutil.copytree(results[name].folder, dst)
    return dst


def test_a_hostile_urdf_robot_name_adds_no_key_to_the_ur_yaml(results, tmp_path):
    run = _copy(results, "ur5e_eye_in_hand", tmp_path)
    urdf = next((run / "robot").glob("*.urdf"))
    text = urdf.read_text()
    text, n = re.subn(r'<robot name="[^"]*"', '<robot name="ur5e&#10;hash: injected&#10;kinematics2: {a: 1}&#10;#"',
                      text, count=1)
    assert n == 1
    urdf.write_text(text)
    assert "\n" in load_result(run).robot.name  # the URDF parser gives the newlines back: the name is hostile
    doc = yaml.safe_load(export(run, "ur_yaml", tmp_path / "kin.yaml").read_text())
    assert list(doc) == ["kinematics"] and list(doc["kinematics"]) == [*UR_JOINTS, "hash"]
    ET.fromstring(export(run, "urdf", tmp_path / "r.urdf").read_text().split("\n", 1)[1])  # well-formed XML


def test_a_hostile_dh_robot_name_adds_no_csv_row(results, tmp_path):
    run = _copy(results, "rx90_eye_in_hand", tmp_path)
    robot_file = next((run / "robot").glob("*.yaml"))
    doc = yaml.safe_load(robot_file.read_text())
    doc["name"] = HOSTILE
    robot_file.write_text(yaml.safe_dump(doc, sort_keys=False))
    text = export(run, "dh", tmp_path / "dh.csv").read_text()
    rows = list(csv.reader(io.StringIO("\n".join(ln for ln in text.splitlines() if not ln.startswith("#")))))
    assert [r[0] for r in rows] == ["frame", "base"] + [f"joint{i}" for i in range(1, 7)] + ["tool"]
    assert all(ln.startswith("#") for ln in text.splitlines()[:5])


@pytest.mark.parametrize("fmt", ["dh", "urdf"])
def test_an_implausible_length_is_refused_with_its_rule(results, tmp_path, capsys, fmt):
    run = _copy(results, "rx90_eye_in_hand", tmp_path)
    model = run / "calibrated_model.yaml"
    text, n = re.subn(r"^(  a3: \{value: )[^,]+", r"\g<1>1.0e9", model.read_text(), count=1, flags=re.M)
    assert n == 1
    model.write_text(text)
    code = main(["export", str(run), "--format", fmt, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and "parameter a3 = 1e+09 m is implausible (rule: a length within 0.1 m" in err, err
    assert not (tmp_path / "out").exists()


def test_a_non_finite_value_is_refused(results, tmp_path):
    """(the model file reader refuses NaN itself: a model built in memory)"""
    from dataclasses import replace

    res = load_result(results["rx90_eye_in_hand"].folder)
    x = res.x.copy()
    x[res.names.index("d4")] = np.inf
    with pytest.raises(DataError, match="parameter d4 = inf is not finite"):
        export(replace(res, x=x), "dh", tmp_path / "dh.csv")
    assert not (tmp_path / "dh.csv").exists()


def _perturb(fmt, text):
    """The text with one number changed by 1 mm (or its first transform moved 1 mm)."""
    if fmt == "dh":
        head = [ln for ln in text.splitlines() if ln.startswith("#")]
        rows = list(csv.reader(io.StringIO("\n".join(ln for ln in text.splitlines() if not ln.startswith("#")))))
        col = rows[0].index("a_m")
        rows[4][col] = repr(float(rows[4][col]) + 1e-3)
        return "\n".join(head + [",".join(r) for r in rows]) + "\n"
    if fmt == "urdf":
        decl, body = text.split("\n", 1)
        root = ET.fromstring(body)
        o = root.find("joint").find("origin")
        xyz = [float(v) for v in o.get("xyz").split()]
        o.set("xyz", " ".join(map(repr, [xyz[0] + 1e-3] + xyz[1:])))
        return ET.tostring(root, encoding="unicode")
    doc = yaml.safe_load(text)
    if fmt == "ur_yaml":
        doc["kinematics"]["forearm"]["x"] += 1e-3
    else:
        doc["transforms"][0]["translation"]["x"] += 1e-3
    return yaml.safe_dump(doc, sort_keys=False)


@pytest.mark.parametrize("name,fmt", [("rx90_eye_in_hand", "dh"), ("rx90_eye_in_hand", "urdf"),
                                      ("ur5e_eye_in_hand", "urdf"), ("ur5e_eye_in_hand", "ur_yaml"),
                                      ("ur5e_eye_in_hand", "ros_tf"), ("h4_vision", "ros_tf")])
def test_each_export_is_read_back_and_a_file_that_differs_is_caught(results, tmp_path, name, fmt):
    out = export_verified(results[name].folder, fmt, tmp_path / "out")
    v = out["verified"]
    assert v["max_m"] < 1e-9 and v["max_rad"] < 1e-9 and v["joint_sets"] == (0 if fmt == "ros_tf" else 64)
    res = load_result(results[name].folder)
    text = out["out"].read_text()
    assert verify_export(res, fmt, text)["max_m"] == v["max_m"]  # the check of the file as written
    with pytest.raises(DataError, match=r"read back differs from the calibrated model by 0\.001"):
        verify_export(res, fmt, _perturb(fmt, text))
    assert 1e-3 > VERIFY_TOL_M


def test_ros_tf_of_a_pose_pair_hand_eye_result(tmp_path, capsys):
    d = simulate_pose_pairs(30, 4, "fixed")
    path = write_pose_pairs(tmp_path / "pairs.yaml", d.labels, d.T_base_flange, d.T_cam_target, "fixed")
    out = tmp_path / "out"
    assert main(["process-poses", str(path), "--out", str(out), "--no-plots", "--export", "ros_tf"]) == 0
    err = capsys.readouterr().err
    assert "exported" in err and "read back and verified" in err, err
    rep = json.loads((out / "report.json").read_text())
    assert rep["kind"] == "process_pose_pairs"
    tf = {t["name"]: t for t in yaml.safe_load((out / FORMATS["ros_tf"].file).read_text())["transforms"]}
    assert list(tf) == ["T_base_cam", "T_flange_target"]
    for name, t in tf.items():
        M = np.asarray(rep["handeye"]["transforms"][name]["matrix"])
        assert np.allclose([t["translation"][k] for k in "xyz"], M[:3, 3], atol=1e-12)
    assert main(["export", str(out), "--format", "ros_tf", "--out", str(tmp_path / "tf.yaml")]) == 0
    assert "read back and verified: max" in capsys.readouterr().out
