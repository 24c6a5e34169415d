"""Gross input errors in the hand-eye route (experiment/handeye_gross.py, issue 28 item 3): a simulated eye-in-hand
flange-pose recording damaged as users damage theirs -- the board declared twice its size, the flange quaternions
written scalar-first, the wrong camera mount -- ends in exit 3 with the reading that fits named and no calibrated
model; the clean recording passes."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import yaml
from flange_folder import flange_pose_folder, simulated_flange_recording

from vision_calib.cli import main

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def flange_rec(tmp_path_factory):
    return simulated_flange_recording(tmp_path_factory.mktemp("hegross"), 5, 16, 0.1, 0.01, 3)


def _damaged(src, dst, edit_yaml=None, edit_csv=None):
    shutil.copytree(src, dst)
    if edit_yaml:
        doc = yaml.safe_load((dst / "recording.yaml").read_text())
        edit_yaml(doc)
        (dst / "recording.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    if edit_csv:
        lines = (dst / "poses.csv").read_text().splitlines()
        (dst / "poses.csv").write_text("\n".join([lines[0]] + [edit_csv(ln) for ln in lines[1:]]) + "\n")
    return dst


def _run(folder, out, capsys):
    rc = main(["process", str(folder), "--out", str(out), "--no-plots"])
    err = capsys.readouterr().err
    return rc, err, json.loads((out / "report.json").read_text())


def test_clean_recording_passes(flange_rec, tmp_path, capsys):
    rc, err, rep = _run(flange_rec, tmp_path / "out", capsys)
    assert rc == 0 and "failure" not in rep, err


def test_exact_flange_poses_do_not_warn(flange_rec, tmp_path, capsys):
    """Perfect flange poses (issue 28 item 5): the chi-square band reads the image-measured poses' covariance as
    trusted within IMAGE_COV_SCALE, as the robot-chain route does: no misfit warning."""
    exact, _, _ = flange_pose_folder(flange_rec.parent / "rec", tmp_path / "exact", robot_std_mm=0.0, robot_std_deg=0.0)
    rc, err, rep = _run(exact, tmp_path / "out", capsys)
    assert rc == 0 and rep["verdict"]["status"] == "ok", (rep["verdict"], err)
    assert rep["adequacy"]["verdict"] == "consistent" and rep["adequacy"]["cov_scale"] == [0.55, 1.3]


def _scale(doc):
    doc["target"]["square_m"] *= 2
    doc["target"]["marker_m"] *= 2


def _scalar_first(line):
    f = line.split(",")
    return ",".join(f[:4] + [f[7], f[4], f[5], f[6]])


def _rows_edit(edit):
    """An edit of poses.csv's data rows as a whole (a function of the list of rows)."""
    def apply(src, dst):
        shutil.copytree(src, dst)
        lines = (dst / "poses.csv").read_text().splitlines()
        (dst / "poses.csv").write_text("\n".join([lines[0]] + edit(lines[1:])) + "\n")
        return dst
    return apply


def _shifted(rows):  # each pose id gets the NEXT row's flange pose; the last row is dropped
    vals = [r.split(",", 1)[1] for r in rows]
    return [f"{r.split(',', 1)[0]},{v}" for r, v in zip(rows[:-1], vals[1:])]


def _one_scalar_first(rows):
    return [_scalar_first(r) if i == 3 else r for i, r in enumerate(rows)]


def _two_swapped(rows):
    a, b = rows[4].split(",", 1), rows[9].split(",", 1)
    return [f"{a[0]},{b[1]}" if i == 4 else f"{b[0]},{a[1]}" if i == 9 else r for i, r in enumerate(rows)]


def test_pairing_off_by_one_named(flange_rec, tmp_path, capsys):
    """poses.csv one row off against the images: not read as a 55 mm robot error, named as the pairing."""
    folder = _rows_edit(_shifted)(flange_rec, tmp_path / "bad")
    rc, err, rep = _run(folder, tmp_path / "out", capsys)
    assert rc == 3, err
    hits = [t["candidate"] for t in rep["failure"]["tests"] if t["fits"]]
    assert hits and hits[0].startswith("the images paired one row off (each with the PREVIOUS"), hits
    assert not (tmp_path / "out" / "calibrated_model.yaml").exists()


@pytest.mark.parametrize("edit, bad", [(_one_scalar_first, {"003"}), (_two_swapped, {"004", "009"})],
                         ids=["one quaternion scalar-first", "two rows swapped"])
def test_single_bad_rows_named_as_outliers(flange_rec, tmp_path, capsys, edit, bad):
    """One or two damaged rows among 16: each named as an outlier (tested against the fit without it), the
    others kept, the mounts within their std of the truth."""
    from flange_folder import assert_mounts_within_std, true_mounts

    folder = _rows_edit(edit)(flange_rec, tmp_path / "bad")
    rc, err, rep = _run(folder, tmp_path / "out", capsys)
    assert rc == 0, err
    assert {o["pose_id"] for o in rep["outliers"]} == bad, rep["outliers"]
    assert_mounts_within_std(rep["handeye"]["transforms"], true_mounts(flange_rec.parent / "rec"))


@pytest.mark.parametrize("damage, needle", [
    (dict(edit_yaml=_scale), "the board's size off by 2"),
    (dict(edit_csv=_scalar_first), "the flange quaternions read scalar-first"),
    (dict(edit_yaml=lambda d: d.update(camera_mount="fixed")), "the camera mount eye_in_hand"),
], ids=["board x2", "quaternion scalar-first", "mount fixed"])
def test_damage_named_and_refused(flange_rec, tmp_path, capsys, damage, needle):
    folder = _damaged(flange_rec, tmp_path / "bad", **damage)
    rc, err, rep = _run(folder, tmp_path / "out", capsys)
    assert rc == 3, err
    f = rep["failure"]
    hits = [t["candidate"] for t in f["tests"] if t["fits"]]
    assert hits and hits[0].startswith(needle), (hits, f["message"])
    assert needle in err
    assert not (tmp_path / "out" / "calibrated_model.yaml").exists()
    if "size" in needle:
        scale = [t["scale"] for t in f["tests"] if "scale" in t][0]
        assert np.isclose(scale, 2.0, rtol=0.02)
