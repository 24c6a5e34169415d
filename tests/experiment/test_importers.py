"""Importers of folders other tools write: ROS-I industrial_calibration data sets (io/rosi.py) and ViSP
chessboard hand-eye folders (io/visp.py), with their unit and frame checks."""

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from vision_calib import frames as F
from vision_calib.cli import main
from vision_calib.errors import ConfigError, DataError
from vision_calib.io.recording import read_recording
from vision_calib.config import ALLOW_ENV
from vision_calib.io.rosi import import_rosi
from vision_calib.io.visp import import_visp_chessboard

from flange_folder import assert_mounts_within_std, flange_pose_folder, true_mounts  # noqa: E402 (tests/experiment helper)

REPO = Path(__file__).resolve().parents[2]


# ----------------------------------------------------------------------------- ROS-I: the documented format
def _rosi_set(d: Path, n=3, size=(64, 48), **over) -> Path:
    """A ROS-I data set like examples/data/test_set_charuco (static camera, DICT_6X6_250 = 10)."""
    (d / "images").mkdir(parents=True)
    (d / "poses").mkdir()
    data = []
    for i in range(n):
        cv2.imwrite(str(d / "images" / f"{i}.png"), np.full((size[1], size[0]), 100 + i, np.uint8))
        q = np.array([0.1 * i, -0.2, 0.3, 0.9])
        q /= np.linalg.norm(q)
        pose = {"x": 0.1 * i, "y": -0.5, "z": 0.8, "qw": float(q[3]), "qx": float(q[0]), "qy": float(q[1]),
                "qz": float(q[2])}
        (d / "poses" / f"{i}.yaml").write_text(yaml.safe_dump(pose))
        data.append({"image": f"images/{i}.png", "pose": f"poses/{i}.yaml"})
    doc = {"data": data, "intrinsics": {"fx": 60.0, "fy": 61.0, "cx": 32.0, "cy": 24.0},
           "homography_threshold": 2.0, "static_camera": True,
           "target_finder": {"type": "CharucoGridTargetFinder", "rows": 7, "cols": 5, "chessboard_dim": 0.036195,
                             "aruco_marker_dim": 0.018256, "dictionary": 10}} | over
    (d / "cal_data.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return d


def test_rosi_mapping(tmp_path):
    src = _rosi_set(tmp_path / "rosi")
    rec = read_recording(import_rosi(src, tmp_path / "rec"))
    assert rec.camera_mount == "fixed" and rec.pose_kind == "flange_pose"
    assert (rec.camera.width, rec.camera.height, rec.camera.fx, rec.camera.fy) == (64, 48, 60.0, 61.0)
    t = rec.target
    assert (t.kind, t.rows, t.cols, t.dictionary, t.square_m, t.marker_m, t.legacy_pattern) == (
        "charuco", 7, 5, "DICT_6X6_250", 0.036195, 0.018256, True)
    # the pose file's qw, qx, qy, qz (named keys) are the rotation of T_base_flange
    p = yaml.safe_load((src / "poses" / "2.yaml").read_text())
    want = F.T_from_xyz_quat([p["x"], p["y"], p["z"]], [p["qx"], p["qy"], p["qz"], p["qw"]])
    np.testing.assert_allclose(rec.poses[rec.pose_ids.index("2")], want, atol=1e-15)
    assert rec.images["1"][0].read_bytes() == (src / "images" / "1.png").read_bytes()
    # eye_in_hand key of the newer GUI configs; the target finder in its own file
    src2 = _rosi_set(tmp_path / "rosi2", static_camera=None)
    doc = yaml.safe_load((src2 / "cal_data.yaml").read_text())
    del doc["static_camera"]
    doc["eye_in_hand"] = True
    (src2 / "target_finder.yaml").write_text(yaml.safe_dump(doc.pop("target_finder")))
    (src2 / "cal_data.yaml").write_text(yaml.safe_dump(doc))
    assert read_recording(import_rosi(src2 / "cal_data.yaml", tmp_path / "rec2")).camera_mount == "eye_in_hand"


def _edit_pose(src, i, **kv):
    p = src / "poses" / f"{i}.yaml"
    d = yaml.safe_load(p.read_text()) | kv
    p.write_text(yaml.safe_dump(d))
    return p


@pytest.mark.parametrize("case,pattern", [
    ("mm", r"poses/1.yaml: keys x, y, z: 1200 m .*millimetres"),
    ("quat", r"poses/2.yaml: keys qw, qx, qy, qz: quaternion norm 1.0\d+ is not 1"),
    ("size", r"images/1.png: image size 32x48 differs from the majority 64x48 \(2 of 3 images\)"),
    ("missing", r"data\[0\]: file not found: .*images/0.png"),
    ("aruco_grid", r"type 'ArucoGridTargetFinder' is not supported"),
    ("no-mount", r"neither 'static_camera' nor 'eye_in_hand'"),
])
def test_rosi_bad_input_is_named_at_the_cli(tmp_path, capsys, case, pattern):
    import re

    src = _rosi_set(tmp_path / "rosi")
    if case == "mm":
        _edit_pose(src, 1, x=1200.0)
    elif case == "quat":
        _edit_pose(src, 2, qw=yaml.safe_load((src / "poses" / "2.yaml").read_text())["qw"] + 0.01)
    elif case == "size":
        cv2.imwrite(str(src / "images" / "1.png"), np.zeros((48, 32), np.uint8))
    elif case == "missing":
        (src / "images" / "0.png").unlink()
    else:
        doc = yaml.safe_load((src / "cal_data.yaml").read_text())
        if case == "aruco_grid":
            doc["target_finder"] = {"type": "ArucoGridTargetFinder", "rows": 5, "cols": 7,
                                    "aruco_marker_dim": 0.025, "marker_gap": 0.005, "dictionary": 10}
        else:
            del doc["static_camera"]
        (src / "cal_data.yaml").write_text(yaml.safe_dump(doc))
    assert main(["import-rosi", str(src), str(tmp_path / "rec")]) == 2
    err = capsys.readouterr().err
    assert re.search(pattern, err), err
    assert not (tmp_path / "rec" / "recording.yaml").exists()


def test_rosi_small_quaternion_error_is_renormalised(tmp_path):
    src = _rosi_set(tmp_path / "rosi")
    p = yaml.safe_load((src / "poses" / "2.yaml").read_text())
    _edit_pose(src, 2, qw=p["qw"] * (1 + 5e-4), qx=p["qx"] * (1 + 5e-4), qy=p["qy"] * (1 + 5e-4),
               qz=p["qz"] * (1 + 5e-4))
    rec = read_recording(import_rosi(src, tmp_path / "rec"))
    R = rec.poses[rec.pose_ids.index("2")][:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)


# ----------------------------------------------------------------------------- ROS-I: round trip through process
@pytest.mark.slow
def test_rosi_export_import_round_trip_processes_identically(tmp_path):
    """simulated recording -> flange poses (nominal forward kinematics) -> export_rosi -> import_rosi ->
    process: the identified hand-eye transforms equal those of the original folder exactly."""
    from vision_calib.experiment.simulate import run_simulation

    run_simulation(REPO / "scenes" / "rx90_eye_in_hand.yaml", out_dir=tmp_path / "sim", seed=3, n_poses=8, frames=2,
                   export_recording=tmp_path / "rec", workers=1, progress=False, plots=False)
    flange, _, _ = flange_pose_folder(tmp_path / "rec", tmp_path / "flange", robot_std_mm=0.2, robot_std_deg=0.02)

    assert main(["export-rosi", str(flange), str(tmp_path / "rosi")]) == 0
    assert (tmp_path / "rosi" / "cal_data.yaml").is_file()
    assert main(["import-rosi", str(tmp_path / "rosi"), str(tmp_path / "back")]) == 0
    back = read_recording(tmp_path / "back")
    assert back.frames_per_pose == 2 and back.camera == read_recording(flange).camera
    reports = []
    for folder in (flange, tmp_path / "back"):
        assert main(["process", str(folder), "--out", str(tmp_path / f"out_{folder.name}"), "--json", "--no-plots"]) == 0
        reports.append(json.loads((tmp_path / f"out_{folder.name}" / "report.json").read_text()))
    a, b = (r["handeye"]["transforms"] for r in reports)
    assert a.keys() == b.keys()
    for k in a:
        assert np.array_equal(np.array(a[k]["matrix"]), np.array(b[k]["matrix"])), k
        assert np.array_equal(a[k]["std_xyz_m"], b[k]["std_xyz_m"]), k
    # the true flange poses with a 0.2 mm / 0.02 deg robot error: the mounts are the truth within their std
    assert_mounts_within_std(a, true_mounts(tmp_path / "rec"))


# ----------------------------------------------------------------------------- ViSP chessboard folders
def _chessboard_image(inner=(9, 6), sq=20, size=(320, 240)):
    img = np.full((size[1], size[0]), 255, np.uint8)
    x0, y0 = 40, 40
    for r in range(inner[1] + 1):
        for c in range(inner[0] + 1):
            if (r + c) % 2 == 0:
                img[y0 + r * sq:y0 + (r + 1) * sq, x0 + c * sq:x0 + (c + 1) * sq] = 0
    return cv2.GaussianBlur(img, (3, 3), 0.8)


def _visp_chessboard(d: Path, n=3) -> Path:
    d.mkdir()
    (d / "camera.xml").write_text(
        "<root><camera><name>Camera</name><image_width>320</image_width><image_height>240</image_height>"
        "<model><type>perspectiveProjWithoutDistortion</type><px>300</px><py>300</py><u0>160</u0><v0>120</v0>"
        "</model></camera></root>")
    for i in range(1, n + 1):
        (d / f"pose_fPe_{i}.yaml").write_text("rows: 6\ncols: 1\ndata:\n" + "".join(
            f"  - [{v}]\n" for v in (0.3, 0.1 * i, 0.5, 0.0, 0.1 * i, 0.0)))
        cv2.imwrite(str(d / f"image-{i}.png"), _chessboard_image())
    return d


def test_visp_chessboard_import(tmp_path):
    src = _visp_chessboard(tmp_path / "visp")
    assert main(["import-visp", str(src), "--out", str(tmp_path / "rec"), "--chessboard", "9x6",
                 "--square-m", "0.03"]) == 0
    doc = yaml.safe_load((tmp_path / "rec" / "recording.yaml").read_text())
    assert doc["target"] == {"kind": "chessboard", "rows": 7, "cols": 10, "square_m": 0.03, "margin_m": 0.03}
    assert doc["camera_mount"] == "eye_in_hand" and doc["poses"] == "flange_pose"
    rows = (tmp_path / "rec" / "poses.csv").read_text().splitlines()
    assert rows[0] == "pose_id,x,y,z,qx,qy,qz,qw" and len(rows) == 4
    T2 = F.T_from_xyz_rotvec([0.3, 0.2, 0.5, 0.0, 0.2, 0.0])
    xyz, q = F.xyz_quat_from_T(T2)
    np.testing.assert_allclose([float(v) for v in rows[2].split(",")[1:]], [*xyz, *q], atol=1e-15)
    assert (tmp_path / "rec" / "images" / "3" / "00.png").is_file()
    rec = import_visp_chessboard(src, tmp_path / "rec2", 9, 6, 0.03, mount="fixed")
    assert yaml.safe_load((rec / "recording.yaml").read_text())["camera_mount"] == "fixed"


def test_visp_chessboard_checks(tmp_path, capsys):
    src = _visp_chessboard(tmp_path / "visp")
    with pytest.raises(DataError, match=r"image-1.png: no chessboard of 8x6 inner corners"):
        import_visp_chessboard(src, tmp_path / "r1", 8, 6, 0.03)
    with pytest.raises(ConfigError, match=r"square size must be in \(0, 1\] m, got 30.0 \(millimetres\?\)"):
        import_visp_chessboard(src, tmp_path / "r2", 9, 6, 30.0)
    assert main(["import-visp", str(src), "--out", str(tmp_path / "r3"), "--chessboard", "9x6"]) == 2
    assert "--chessboard needs --square-m" in capsys.readouterr().err
    cv2.imwrite(str(src / "image-2.png"), np.zeros((240, 160), np.uint8))
    with pytest.raises(DataError, match=r"image-2.png: image size 160x240 does not match the camera intrinsics 320x240"):
        import_visp_chessboard(src, tmp_path / "r4", 9, 6, 0.03)
    cv2.imwrite(str(src / "image-2.png"), _chessboard_image())
    (src / "pose_fPe_3.yaml").write_text("rows: 6\ncols: 1\ndata:\n" + "".join(f"  - [{v}]\n" for v in (300, 0, 500, 0, 0, 0)))
    with pytest.raises(DataError, match=r"pose_fPe_3.yaml: data: translation 500 m .*millimetres"):
        import_visp_chessboard(src, tmp_path / "r5", 9, 6, 0.03)
    assert not (tmp_path / "r5").exists()


# ----------------------------------------------------------------------------- joint units without limits
def test_free_revolute_joints_in_degrees_are_refused():
    """A robot without joint limits: |q| beyond a turn (+0.1 rad) is degrees read as radians."""
    from dataclasses import replace

    from vision_calib.rig import load_scene

    setup = load_scene(REPO / "scenes" / "rx90_eye_in_hand.yaml").setup
    free = replace(setup, chain=replace(setup.chain, joint_limits=None))
    q = np.full((2, free.n_joints), 0.5)
    free.check_joints(q, "poses.csv", ["a", "b"])  # within a turn: accepted
    q[1, 2] = 2 * np.pi + 0.2
    with pytest.raises(DataError, match=r"poses.csv: pose 'b' joint q3 = 6.483 rad is more than a turn.*degrees"):
        free.check_joints(q, "poses.csv", ["a", "b"])


# ----------------------------------------------------------------------------- ViSP chessboard: end to end
@pytest.mark.slow
def test_visp_chessboard_round_trip_processes_like_the_direct_folder(tmp_path, monkeypatch):
    """A simulated eye-in-hand recording of a chessboard (targets/chessboard_a4.yaml, no lens distortion:
    ViSP's kud/kdu model is refused) written as a ViSP hand-eye folder (camera.xml, image-N.png,
    pose_fPe_N.yaml flange poses as translation + theta-u), imported with ``import-visp --chessboard`` and
    processed: the hand-eye transforms equal those of the same data processed as our own flange-pose
    folder (to rounding of the theta-u conversion)."""
    monkeypatch.setenv(ALLOW_ENV, str(tmp_path))  # the simulated recording names the scene written beside it
    from vision_calib.experiment.simulate import run_simulation

    scene = yaml.safe_load((REPO / "scenes" / "rx90_eye_in_hand.yaml").read_text())
    scene["robot"] = str(REPO / "scenes" / "robots" / "rx90.yaml")
    scene["target"] = str(REPO / "targets" / "chessboard_a4.yaml")
    scene["camera"]["dist"] = [0.0] * 5
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(scene))
    run_simulation(tmp_path / "scene.yaml", out_dir=tmp_path / "sim", seed=5, n_poses=10, frames=1,
                   export_recording=tmp_path / "rec", workers=1, progress=False, plots=False)
    flange, rec, T = flange_pose_folder(tmp_path / "rec", tmp_path / "flange", robot_std_mm=0.2,
                                        robot_std_deg=0.02)  # our own folder, same data
    c = rec.camera
    visp = tmp_path / "visp"
    visp.mkdir()
    (visp / "camera.xml").write_text(
        f"<root><camera><name>Camera</name><image_width>{c.width}</image_width><image_height>{c.height}"
        f"</image_height><model><type>perspectiveProjWithoutDistortion</type><px>{c.fx!r}</px><py>{c.fy!r}</py>"
        f"<u0>{c.cx!r}</u0><v0>{c.cy!r}</v0></model></camera></root>")
    for i, (pid, Ti) in enumerate(zip(rec.pose_ids, T), start=1):
        v = F.xyz_rotvec_from_T(Ti)
        (visp / f"pose_fPe_{i}.yaml").write_text("rows: 6\ncols: 1\ndata:\n" + "".join(f"  - [{x!r}]\n" for x in map(float, v)))
        shutil.copy(rec.images[pid][0], visp / f"image-{i}.png")
    tgt = yaml.safe_load((REPO / "targets" / "chessboard_a4.yaml").read_text())
    assert main(["import-visp", str(visp), "--out", str(tmp_path / "back"), "--chessboard",
                 f"{tgt['cols'] - 1}x{tgt['rows'] - 1}", "--square-m", str(tgt["square_m"])]) == 0
    reports = []
    for folder in (flange, tmp_path / "back"):
        out = tmp_path / f"out_{folder.name}"
        assert main(["process", str(folder), "--out", str(out), "--json", "--no-plots"]) == 0
        reports.append(json.loads((out / "report.json").read_text()))
    a, b = (r["handeye"]["transforms"] for r in reports)
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_allclose(np.array(b[k]["matrix"]), np.array(a[k]["matrix"]), rtol=0, atol=1e-9, err_msg=k)
    assert_mounts_within_std(a, true_mounts(tmp_path / "rec"))  # the truth, within the reported std


def test_rosi_modified_circle_grid_mapping(tmp_path):
    """ROS-I's test_set_10x10 target finder (its own file, the plugin type name, circle_detector_params)
    -> a modified_circle_grid of 10 x 10 dots, spacing 25.4 mm, dot size unknown (0)."""
    finder = {"type": "industrial_calibration::ModifiedCircleGridTargetFinderPlugin", "rows": 10, "cols": 10,
              "spacing": 0.0254, "circle_detector_params": {"minThreshold": 20, "circleColor": 0}}
    src = _rosi_set(tmp_path / "rosi", static_camera=False)
    doc = yaml.safe_load((src / "cal_data.yaml").read_text())
    del doc["target_finder"]
    (src / "cal_data.yaml").write_text(yaml.safe_dump(doc))
    (src / "target_finder.yaml").write_text(yaml.safe_dump(finder))
    rec = read_recording(import_rosi(src, tmp_path / "rec"))
    t = rec.target
    assert (t.kind, t.rows, t.cols, t.spacing_m, t.diameter_m) == ("modified_circle_grid", 10, 10, 0.0254, 0.0)
    assert rec.camera_mount == "eye_in_hand"


@pytest.mark.parametrize("threshold, noise", [(2.0, 2.0 / 3), (0.5, 0.3), (None, 0.3)])
def test_rosi_homography_threshold_sets_the_view_rule(tmp_path, threshold, noise):
    """ROS-I's homography_threshold [px] -> corner_noise_px = threshold / 3 (the view rule then rejects a view at
    a homography residual std of about that threshold), never below our default 0.3 px; it reaches the pose
    measurement (Recording.measure_config)."""
    src = _rosi_set(tmp_path / "rosi")
    doc = yaml.safe_load((src / "cal_data.yaml").read_text())
    doc.pop("homography_threshold")
    if threshold is not None:
        doc["homography_threshold"] = threshold
    (src / "cal_data.yaml").write_text(yaml.safe_dump(doc))
    rec = read_recording(import_rosi(src, tmp_path / "rec"))
    assert rec.corner_noise_px == pytest.approx(noise) and rec.measure_config().corner_noise_px == rec.corner_noise_px
    doc["homography_threshold"] = -1.0
    (src / "cal_data.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(DataError, match="homography_threshold"):
        import_rosi(src, tmp_path / "rec2")


@pytest.mark.slow
def test_rosi_round_trip_with_a_modified_circle_grid(tmp_path, monkeypatch):
    """RX-90 eye-in-hand recording of the A4 modified circle grid -> flange poses -> export_rosi (diameters in the
    extension keys) -> import_rosi -> process: the same hand-eye transforms as the original folder; without
    the extension keys (a real ROS-I file) detection still works, the transforms move by less than 3 std."""
    monkeypatch.setenv(ALLOW_ENV, str(tmp_path))  # the simulated recording names the scene written beside it
    from vision_calib.experiment.simulate import run_simulation

    scene = yaml.safe_load((REPO / "scenes" / "rx90_eye_in_hand.yaml").read_text())
    scene["target"] = str(REPO / "targets" / "modified_circle_grid_a4.yaml")
    scene["robot"] = str((REPO / "scenes" / scene["robot"]).resolve())
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(scene, sort_keys=False))
    run_simulation(tmp_path / "scene.yaml", out_dir=tmp_path / "sim", seed=4, n_poses=10, frames=1,
                   export_recording=tmp_path / "rec", workers=1, progress=False, plots=False)
    # a 0.2 mm / 0.02 deg robot error: with exact flange poses the mounts' std (~2 um) are below the circle grid's
    # common depth error (T_cam_flange.tz off by 11 um, z = 7: a bias shared by all poses, that the chi-square
    # test cannot see)
    flange, _, _ = flange_pose_folder(tmp_path / "rec", tmp_path / "flange", robot_std_mm=0.2, robot_std_deg=0.02)
    assert main(["export-rosi", str(flange), str(tmp_path / "rosi")]) == 0
    cal = yaml.safe_load((tmp_path / "rosi" / "cal_data.yaml").read_text())
    assert cal["target_finder"]["type"] == "ModifiedCircleGridTargetFinder"
    bare = tmp_path / "rosi_bare"
    shutil.copytree(tmp_path / "rosi", bare)
    for k in ("diameter_m", "origin_diameter_m"):
        cal["target_finder"].pop(k, None)
    (bare / "cal_data.yaml").write_text(yaml.safe_dump(cal, sort_keys=False))
    reports = {}
    for name, folder in (("flange", flange), ("back", tmp_path / "rosi"), ("bare", bare)):
        if name != "flange":
            assert main(["import-rosi", str(folder), str(tmp_path / f"rec_{name}")]) == 0
            folder = tmp_path / f"rec_{name}"
        assert main(["process", str(folder), "--out", str(tmp_path / f"out_{name}"), "--json", "--no-plots"]) == 0
        reports[name] = json.loads((tmp_path / f"out_{name}" / "report.json").read_text())["handeye"]["transforms"]
    a, b, c = reports["flange"], reports["back"], reports["bare"]
    assert_mounts_within_std(a, true_mounts(tmp_path / "rec"))
    for k in a:
        assert np.array_equal(np.array(a[k]["matrix"]), np.array(b[k]["matrix"])), k
        # the bare target's frame is offset by (D / 2, d / 2) in the target plane: compare the rotations and
        # the camera mount (the flange side), which do not depend on it
        rot = np.degrees(np.linalg.norm(F.pose_error(np.array(a[k]["matrix"]), np.array(c[k]["matrix"]))[3:]))
        assert rot < 3 * np.linalg.norm(a[k]["std_rot_deg"]), (k, rot, a[k]["std_rot_deg"])


@pytest.mark.parametrize("value", [-0.1, 0.0, "x", 100.0])
def test_recording_corner_noise_px_is_checked(tmp_path, value):
    rec = import_rosi(_rosi_set(tmp_path / "rosi"), tmp_path / "rec")
    doc = yaml.safe_load((rec / "recording.yaml").read_text())
    doc["corner_noise_px"] = value
    (rec / "recording.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises((ConfigError, DataError), match="corner_noise_px"):
        read_recording(rec)


def test_visp_theta_u_in_degrees_is_refused(tmp_path):
    """A ViSP pose file with theta-u written in degrees (|theta-u| up to 175) is refused naming the file (a rotation
    vector's angle is at most pi), never read as a rotation of 175 rad."""
    from vision_calib.errors import DataError
    from vision_calib.io.visp import read_visp_pose_yaml

    p = tmp_path / "pose_rPe_1.yaml"
    p.write_text("rows: 6\ncols: 1\ndata:\n  - [0.1]\n  - [0.2]\n  - [0.3]\n  - [170.0]\n  - [5.0]\n  - [-20.0]\n")
    with pytest.raises(DataError, match=r"pose_rPe_1.yaml: theta-u .* more than pi"):
        read_visp_pose_yaml(p)
