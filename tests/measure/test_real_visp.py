"""Real images (ViSP eye-to-hand example, Franka + one AprilTag 36h11 of 48 mm, id 10), read in place."""

import os
from pathlib import Path

import numpy as np
import pytest

from vision_calib import frames
from vision_calib.errors import ConfigError, DataError
from vision_calib.io.visp import read_visp_camera_xml, read_visp_pose_yaml
from vision_calib.measure import measure_images
from vision_calib.measure.handeye import hand_eye_consistency
from vision_calib.targets.spec import TargetSpec

DATA = Path(os.environ["VISION_CALIB_SHARED_DATA"]) / "real" / "visp_eye_to_hand_apriltag"  # tests/conftest.py
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason="real ViSP data not available")

TAG = TargetSpec(kind="apriltag_grid", name="franka_tag36h11_10", rows=1, cols=1, dictionary="DICT_APRILTAG_36h11",
                 tag_m=0.048, spacing_m=0.01, first_id=10)


def _measure_all():
    intr = read_visp_camera_xml(DATA / "franka_camera.xml")
    ms, dets, flange = [], [], []
    for i in range(1, 9):
        m, d = measure_images([DATA / f"franka_image-{i}.png"], TAG, intr, pose_id=i)
        ms.append(m)
        dets.append(d[0])
        flange.append(read_visp_pose_yaml(DATA / f"franka_pose_rPe_{i}.yaml"))
    return intr, ms, dets, np.array(flange)


def test_visp_readers():
    intr = read_visp_camera_xml(DATA / "franka_camera.xml")
    assert intr.size == (640, 480) and intr.fx == pytest.approx(607.593, abs=1e-3) and intr.cy == pytest.approx(243.255, abs=1e-3)
    T = read_visp_pose_yaml(DATA / "franka_pose_rPe_1.yaml")
    assert np.allclose(frames.xyz_rotvec_from_T(T), [0.719437, -0.0332613, 0.412152, 3.05894, 0.00390122, 0.105226],
                       atol=1e-6)


def test_visp_readers_bad_files(tmp_path):
    (tmp_path / "bad.xml").write_text("<root><camera><image_width>640</image_width></camera></root>")
    with pytest.raises(ConfigError, match="bad.xml"):
        read_visp_camera_xml(tmp_path / "bad.xml")
    (tmp_path / "bad.yaml").write_text("rows: 5\ncols: 1\ndata:\n  - [1]\n  - [2]\n")
    with pytest.raises(DataError, match="6 numbers"):
        read_visp_pose_yaml(tmp_path / "bad.yaml")


def test_real_tag_poses_and_hand_eye_consistency():
    intr, ms, dets, flange = _measure_all()
    for m, d in zip(ms, dets):
        assert d.valid and d.diagnostics["marker_ids"] == [10] and d.n_corners == 4
        assert m.valid, m.reason
        assert m.reprojection_rms_px < 0.6
        assert 0.1 < m.T_cam_target[2, 3] < 0.4  # tag ~ 130 px wide at f ~ 608 px -> ~0.2 m
    T = np.array([m.T_cam_target for m in ms])
    he = hand_eye_consistency(flange, T, setup="eye_to_hand")
    # the 8 tag poses fit one rigid (T_base_cam, T_flange_target) pair to a few mm / ~1 deg
    # (single 48 mm tag at ~0.2 m: its tilt is known to ~1 deg per image, see PoseMeasurement.std)
    assert he["rms_t_m"] < 4e-3 and np.degrees(he["rms_rot_rad"]) < 2.0
    # an independent solution of the same data, OpenCV's Tsai/Park hand-eye solver (eye-to-hand: the
    # inverted flange poses make it return the camera in the base frame), agrees with ours
    import cv2

    G = np.linalg.inv(flange)  # T_flange_base
    R_cam2base, t_cam2base = cv2.calibrateHandEye(G[:, :3, :3], G[:, :3, 3], T[:, :3, :3], T[:, :3, 3],
                                                  method=cv2.CALIB_HAND_EYE_PARK)
    dt = np.linalg.norm(t_cam2base.ravel() - he["T_base_cam"][:3, 3])
    dr = np.degrees(np.linalg.norm(frames.xyz_rotvec_from_T(frames.make_T(R_cam2base.T @ he["T_base_cam"][:3, :3]))[3:]))
    assert dt < 5e-3 and dr < 1.0, (dt, dr)
    # scrambled correspondences break the rigid relation (the check can fail)
    bad = hand_eye_consistency(flange, T[[1, 0, 3, 2, 5, 4, 7, 6]], setup="eye_to_hand")
    assert bad["rms_t_m"] > 3 * he["rms_t_m"]


def test_real_images_wrong_target_and_size():
    intr = read_visp_camera_xml(DATA / "franka_camera.xml")
    wrong_id = TargetSpec(kind="apriltag_grid", name="t", rows=1, cols=1, dictionary="DICT_APRILTAG_36h11",
                          tag_m=0.048, spacing_m=0.01, first_id=3)
    m, d = measure_images([DATA / "franka_image-1.png"], wrong_id, intr)
    assert not d[0].valid and "do not belong" in d[0].reason and not m.valid
    from vision_calib.camera import CameraIntrinsics
    m, d = measure_images([DATA / "franka_image-1.png"], TAG, CameraIntrinsics(1024, 768, 900, 900, 512, 384))
    assert not d[0].valid and "does not match" in d[0].reason and not m.valid


def test_one_tag_cannot_calibrate_the_camera_said_before_any_image_is_read(monkeypatch):
    """One tag has 4 corners, fewer than a usable calibration view needs: calibrate_from_images says so, naming the
    target, before it decodes anything (the real images given; no decode is made)."""
    import importlib

    from vision_calib.measure.intrinsics import CalibrationConfig, calibrate_from_images

    D = importlib.import_module("vision_calib.measure.detect")
    monkeypatch.setattr(D, "load_gray", lambda *a, **k: pytest.fail("an image was decoded"))
    files = [DATA / f"franka_image-{i}.png" for i in range(1, 9)]
    with pytest.raises(DataError, match="franka_tag36h11_10.* has 4 corners, a usable view needs at least 8"):
        calibrate_from_images(files, TAG)
    with pytest.raises(DataError, match="has 4 corners, a usable view needs at least 5"):
        calibrate_from_images(files, TAG, config=CalibrationConfig(min_corners=5))
