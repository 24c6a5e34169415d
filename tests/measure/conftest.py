"""Fixtures for measure tests (helpers in measure_helpers.py)."""

import pytest

from vision_calib.camera import CameraIntrinsics
from vision_calib.targets.spec import TargetSpec


@pytest.fixture
def charuco():
    return TargetSpec(kind="charuco", name="test_charuco", rows=7, cols=10, dictionary="DICT_5X5_100",
                      square_m=0.03, marker_m=0.022)


@pytest.fixture
def aprilgrid():
    return TargetSpec(kind="apriltag_grid", name="test_grid", rows=4, cols=5, dictionary="DICT_APRILTAG_36h11",
                      tag_m=0.04, spacing_m=0.012)


@pytest.fixture
def intr():
    return CameraIntrinsics(1024, 768, 1100.0, 1100.0, 515.3, 380.7)


@pytest.fixture
def chessboard():
    return TargetSpec(kind="chessboard", name="test_chessboard", rows=7, cols=10, square_m=0.03)
