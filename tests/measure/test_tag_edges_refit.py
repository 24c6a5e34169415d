"""AprilTag grids' corners fitted again to their edge samples under other intrinsics (measure.batch.refit_detection):
what a fresh detection with those intrinsics gives, no image read."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from vision_calib.camera import CameraIntrinsics
from vision_calib.measure.batch import detect_batch, refit_detection, refittable
from vision_calib.measure.detect import DetectConfig
from vision_calib.sim.intrinsics_views import calibration_poses, render_views
from vision_calib.targets.spec import load_target

TRUE = CameraIntrinsics(1024, 768, 1100.0, 1100.0, 515.3, 380.7, (-0.1, 0.05, 0.0005, -0.0005, 0.0))
TAG = load_target(Path(__file__).resolve().parents[2] / "targets" / "apriltag_grid.yaml")


@pytest.fixture(scope="module")
def views():
    poses = calibration_poses(TAG, TRUE, 4, seed=3, dist_range=(0.25, 0.45))
    return poses, render_views(TAG, TRUE, poses, seed=3)


def test_refit_under_other_intrinsics_is_the_fresh_detection(views):
    """Detected under wrong intrinsics (fx 2 % off, no distortion where k1 is -0.1), refitted under the true ones:
    within 0.005 px of a fresh detection with the true ones (the edge profiles placed a little apart), every
    marker kept; under the wrong ones the corners are 0.01-0.1 px off, so the refit moved them."""
    wrong = replace(TRUE, fx=1122.0, fy=1122.0, dist=(0.0,) * 5)
    ids_all, pts = TAG.corner_points()
    for T, im in zip(*views):
        given = detect_batch([im], TAG, wrong, DetectConfig())[0]
        fresh = detect_batch([im], TAG, TRUE, DetectConfig())[0]
        refit = refit_detection(given, TRUE, 4)
        assert given.valid and refittable([given]) and refit.valid and refit.edges is not None
        assert np.array_equal(refit.ids, fresh.ids) and np.array_equal(refit.ids, given.ids)
        assert np.max(np.abs(refit.uv_px - fresh.uv_px)) < 0.005
        assert np.max(np.abs(given.uv_px - fresh.uv_px)) > 0.01
        truth = TRUE.project(pts[np.searchsorted(ids_all, refit.ids)] @ T[:3, :3].T + T[:3, 3])
        assert np.sqrt(np.mean((refit.uv_px - truth) ** 2)) < 0.05


def test_refit_of_other_kinds_and_invalid_detections(views, charuco):
    """A ChArUco detection has no edge samples (None: detect again); an invalid detection comes back as it is; a
    refit asking for more corners than there are is invalid and says so."""
    poses, images = views
    det = detect_batch([images[0]], TAG, TRUE, DetectConfig())[0]
    blank = detect_batch([np.full((768, 1024), 128, np.uint8)], TAG, TRUE, DetectConfig())[0]
    assert not blank.valid and refit_detection(blank, TRUE) is blank and not refittable([blank])
    few = refit_detection(det, TRUE, min_corners=det.n_corners + 1)
    assert not few.valid and "too few corners after the edge refit" in few.reason
    board_view = render_views(charuco, TRUE, calibration_poses(charuco, TRUE, 1, seed=0), seed=0)
    board = detect_batch(board_view, charuco, TRUE, DetectConfig())[0]
    assert board.valid and board.edges is None and refit_detection(board, TRUE) is None
    assert not refittable([board])
