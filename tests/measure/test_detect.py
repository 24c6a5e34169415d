import json

import cv2
import numpy as np
import pytest

from vision_calib import frames
from vision_calib.camera import CameraIntrinsics
from vision_calib.measure import DetectConfig, detect, detect_batch, measure_images, measure_pose
from vision_calib.measure.pnp import target_lookup
from vision_calib.sensor import SensorEffects, apply_effects
from vision_calib.targets.spec import TargetSpec

from measure_helpers import random_pose, warp_view

DIST_INTR = CameraIntrinsics(1024, 768, 1100.0, 1090.0, 515.3, 380.7, (-0.12, 0.05, 0.0008, -0.0005, 0.0))


def _frames(target, intr, T, n=3, seed=0, **kw):
    eff = SensorEffects(**kw)
    return apply_effects(warp_view(target, intr.without_distortion(), T), eff, n, seed, intr)


@pytest.mark.parametrize("name", ["charuco", "aprilgrid"])
def test_detected_corners_match_projection_with_distortion(name, request):
    """Rendered (ideal) + distortion/blur/noise: detected corners match intr.project of the true
    corners (pixel-centre convention end to end) and the measured pose recovers the truth."""
    target = request.getfixturevalue(name)
    lookup = target_lookup(target)
    rng = np.random.default_rng(10)
    for k in range(2):
        T = random_pose(rng, target)
        imgs = _frames(target, DIST_INTR, T, n=3, seed=k)
        m, dets = measure_images(imgs, target, DIST_INTR, pose_id=k)
        assert all(d.valid for d in dets)
        for d in dets:
            p = np.array([lookup[int(i)] for i in d.ids])
            err = d.uv_px - DIST_INTR.project(frames.transform_points(T, p))
            assert np.sqrt(np.mean(err**2)) < 0.15 and np.abs(err.mean(0)).max() < 0.05
        assert m.valid and m.n_frames_used == 3 and m.reprojection_rms_px < 0.3
        e = frames.pose_error(T, m.T_cam_target)
        assert np.abs(e[:3]).max() < 0.5e-3 and np.degrees(np.abs(e[3:]).max()) < 0.05
        json.dumps(m.to_dict())
        json.dumps(dets[0].to_dict())


def test_apriltag_refinement_offset_restores_pixel_centre_convention(aprilgrid, intr):
    lookup = target_lookup(aprilgrid)
    T = random_pose(np.random.default_rng(11), aprilgrid)
    img = _frames(aprilgrid, intr, T, n=1, apply_distortion=False)[0]
    means = {}
    for off in (0.0, -0.5):
        d = detect(img, aprilgrid, intr, config=DetectConfig(refine="apriltag", apriltag_offset_px=off))
        p = np.array([lookup[int(i)] for i in d.ids])
        means[off] = (d.uv_px - intr.project(frames.transform_points(T, p))).mean(0)
    assert np.all(np.abs(means[0.0] - 0.5) < 0.15)  # OpenCV's raw AprilTag corners: ~ +0.5 px
    assert np.all(np.abs(means[-0.5]) < 0.1)


def test_bad_inputs_give_invalid_detections(tmp_path, charuco, aprilgrid, intr):
    T = random_pose(np.random.default_rng(12), charuco)
    good = _frames(charuco, intr, T, n=1)[0]
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"\x89PNG\r\n\x1a\n" + b"garbage" * 20)
    cases = {
        "not found": str(tmp_path / "missing.png"),
        "corrupt": corrupt,
        "empty": np.zeros((0, 0), np.uint8),
        "does not match the camera intrinsics": good[:400, :500],
        "target not visible": np.full((intr.height, intr.width), 128, np.uint8),
        "NaN": np.full((intr.height, intr.width), np.nan),
    }
    for reason, img in cases.items():
        d = detect(img, charuco, intr)
        assert not d.valid and reason in d.reason, (reason, d.reason)
    # wrong dictionary: a ChArUco (5x5) image searched for an AprilTag grid
    d = detect(good, aprilgrid, intr)
    assert not d.valid and ("not visible" in d.reason or "do not belong" in d.reason)
    # markers of the right dictionary but another board's ids
    other = TargetSpec(kind="charuco", name="other", rows=7, cols=10, dictionary="DICT_5X5_100",
                       square_m=0.03, marker_m=0.022, first_id=50)
    d = detect(good, other, intr)
    assert not d.valid
    # too few corners: half the board hidden and a high minimum
    d = detect(good, charuco, intr, config=DetectConfig(min_corners=60))
    assert not d.valid and "too few corners" in d.reason and d.n_corners > 0
    # a batch with a mix of bad and good frames: the pose is measured from the good ones
    batch = [str(tmp_path / "missing.png"), good, corrupt, np.zeros((5, 5), np.uint8)]
    dets = detect_batch(batch, charuco, intr)
    assert [d.valid for d in dets] == [False, True, False, False]
    m = measure_pose(dets, charuco, intr, pose_id="p3")
    assert m.valid and m.n_frames_used == 1 and len(m.frames) == 4
    assert [f["valid"] for f in m.frames] == [False, True, False, False]
    m = measure_pose([dets[0], dets[2]], charuco, intr, pose_id="p4")
    assert not m.valid and "no valid frame" in m.reason and "not found" in m.reason
    json.dumps(m.to_dict())


def test_colour_and_16bit_images_accepted(charuco, intr):
    T = random_pose(np.random.default_rng(13), charuco)
    g = _frames(charuco, intr, T, n=1)[0]
    for img in (cv2.cvtColor(g, cv2.COLOR_GRAY2BGR), g.astype(np.uint16) * 257, g.astype(np.float32)):
        d = detect(img, charuco, intr)
        assert d.valid and d.n_corners == charuco.n_corners
