"""Shipped scenes load, and their targets are seen where the scene says."""

from pathlib import Path

import numpy as np
import pytest

from vision_calib.rig import SCENES_DIR, load_scene, scene_poses
from vision_calib.targets import load_target


@pytest.mark.parametrize("path", sorted(Path(SCENES_DIR).glob("*.yaml")), ids=lambda p: p.stem)
def test_shipped_scenes_poses_identify_what_varied_poses_identify(path):
    """Each shipped scene's own pose set loses no parameter that 200 generic poses of the robot identify
    (the pipelines refuse a pose set that does), and leaves at least one equation per parameter to spare."""
    from vision_calib.experiment.steps import analyze_setup, structural_rank_check

    scene = load_scene(path)
    poses = scene_poses(scene, np.random.default_rng(0))
    rep, problem = analyze_setup(scene.setup, poses, scene.identification.residual)
    assert structural_rank_check(scene.setup, rep, scene.identification.residual, str(path)) == []
    assert problem.n_obs * problem.m > rep.rank > 0


def test_h4_board_fully_in_view_on_the_81_pose_grid():
    scene = load_scene(SCENES_DIR / "h4_vision.yaml")
    setup = scene.setup
    T = setup.T_cam_target(setup.robot.pose_grid(), setup.params.nominal)
    w, h = load_target(scene.target_path).pattern_size_m()
    outline = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], float)
    assert setup.visible(T, outline, margin_px=15).all()


def test_serial_random_poses_see_the_target():
    scene = load_scene(SCENES_DIR / "rx90_eye_in_hand.yaml")
    q = scene_poses(scene, np.random.default_rng(0), 20)
    T = scene.setup.T_cam_target(q, scene.setup.params.nominal)
    assert scene.setup.visible(T, scene.setup.target_outline).all()
    assert scene.setup.chain.within_limits(q).all()
