"""End-to-end accuracy on rendered images (slow: pyrender + 50 poses x 11 frames)."""

import numpy as np
import pytest

from vision_calib.camera import CameraIntrinsics
from vision_calib.sim.accuracy import accuracy_study, random_view_pose
from vision_calib.sensor import SensorEffects
from vision_calib.targets.spec import TargetSpec

INTR = CameraIntrinsics(1024, 768, 1100.0, 1100.0, 515.3, 380.7, (-0.1, 0.05, 0.0005, -0.0005, 0.0))
CHARUCO = TargetSpec(kind="charuco", name="c", rows=7, cols=10, dictionary="DICT_5X5_100", square_m=0.03,
                     marker_m=0.022)


def test_random_view_pose_keeps_target_in_view():
    rng = np.random.default_rng(0)
    for _ in range(20):
        T = random_view_pose(rng, CHARUCO, INTR, (0.4, 0.8), 35.0)
        assert 0.3 < T[2, 3] < 0.9
        assert np.degrees(np.arccos(np.clip(T[2, 2], -1, 1))) <= 35.0 + 1e-9


@pytest.mark.slow
def test_accuracy_vs_truth_bound_and_covariance():
    res = accuracy_study(CHARUCO, INTR, SensorEffects(), n_poses=50, n_frames=10, seed=0)
    for mode in ("corners", "poses"):
        s = res[mode]
        assert s["n_valid"] == 50
        # random part (noisy 10-frame mean minus the noise-free measurement) vs the bound from the image
        # model alone (covariance.image_bound_pose_cov, not from the frames): it cannot beat the bound
        # (>= 1, with ~10 % sampling error over 50 poses: > 0.9); cv2.cornerSubPix reaches 2.2x the bound on
        # a synthetic saddle (test_covariance.py) and the rendered chain measured 2.3-3.1: tolerance < 4
        assert np.all(s["random_over_bound"] > 0.9) and np.all(s["random_over_bound"] < 4.0), s["random_over_bound"]
        # the systematic part dominates the error (the reason the covariance models it)
        assert np.all(s["bias_over_random"] > 3), s["bias_over_random"]
        # the pose covariance whitens the error vs truth; the frame-scatter-only one did not
        assert np.all(s["z_new_rms"] < 1.6) and np.all(s["z_new_rms"] > 0.3) and np.all(s["z_new_max"] < 4), \
            (s["z_new_rms"], s["z_new_max"])
        assert np.all(s["z_old_rms"] > 3), s["z_old_rms"]
        # totals (dominated by the render's systematic corner error at supersample 2, see the report)
        assert np.all(s["rms"][:3] < 0.2e-3), s["rms"]
        assert np.all(np.degrees(s["rms"][3:]) < 0.05), np.degrees(s["rms"][3:])
    assert 0.002 < res["sigma_px"] < 0.1
