"""The view figures of the planner (planning.view) on a board seen square on, tilted, from its back, too close."""

import numpy as np
import pytest

from vision_calib.camera import CameraIntrinsics
from vision_calib.frames import make_T, so3_exp
from vision_calib.planning.view import MIN_SQUARE_PX, ViewLimits, measurable, view_figures
from vision_calib.rig import SCENES_DIR
from vision_calib.targets import load_target

TARGET = load_target(SCENES_DIR.parent / "targets" / "charuco_a5.yaml")  # 7 x 5 squares of 25 mm, 10 mm margin
CAM = CameraIntrinsics(1024, 768, 1000.0, 1000.0, 511.5, 383.5, (0.0,) * 5)


def _facing(d, R=np.eye(3)):
    """T_cam_target: the pattern's centre on the optical axis at depth d, board turned by R about its centre."""
    w, h = TARGET.pattern_size_m()
    c = np.array([w / 2, h / 2, 0])
    return make_T(R, np.array([0, 0, d]) - R @ c)


def test_square_on_board_figures():
    d = 0.5
    f = view_figures(_facing(d)[None], CAM, TARGET)
    w, h = TARGET.pattern_size_m()
    assert f["front"][0] and f["distance_m"][0] == pytest.approx(d) and f["incidence_deg"][0] == pytest.approx(0, abs=1e-6)
    assert f["square_px"][0] == pytest.approx(1000 * 0.025 / d, rel=1e-9)
    _, pts = TARGET.corner_points()  # the measured corners' bounding box (what the scene's sampler keeps in view)
    half = (pts.max(axis=0) - pts.min(axis=0))[:2] / 2
    assert np.allclose((pts.max(axis=0) + pts.min(axis=0))[:2] / 2, [w / 2, h / 2])  # centred on the pattern
    assert f["margin_px"][0] == pytest.approx(min(511.5 - 1000 * half[0] / d, 383.5 - 1000 * half[1] / d), rel=1e-9)


def test_tilt_back_side_and_limits():
    tilt = so3_exp(np.array([np.radians(40), 0, 0]))
    back = so3_exp(np.array([np.pi, 0, 0]))
    T = np.array([_facing(0.5, tilt), _facing(0.5, back), _facing(0.05), _facing(6.0)])
    f = view_figures(T, CAM, TARGET)
    assert f["incidence_deg"][0] == pytest.approx(40, abs=0.5)
    assert not f["front"][1]  # seen from its back
    lim = ViewLimits(margin_px=20, distance_m=(0.2, 1.5), max_incidence_rad=np.radians(30))
    ok, fails = measurable(f, lim)
    assert not ok.any()
    assert fails["incidence"][0] and fails["behind"][1] and fails["outside"][2] and fails["distance"][3]
    assert fails["square"][3]  # 25 mm at 6 m: ~4 px
    assert MIN_SQUARE_PX == 6.0
