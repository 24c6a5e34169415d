"""The thesis-arm scenes (eye-in-hand step 01, tripod + probe section 6.3) see their board in every
configured pose, so that rendering and identification can work on them."""

import numpy as np
import pytest

from vision_calib.rig import SCENES_DIR, load_scene, scene_poses, true_parameters
from vision_calib.experiment.simulate import run_simulation
from vision_calib.kinematics.serial_file import load_serial_robot
from vision_calib.targets import load_target

SCENES = ["thesis_arm_eye_in_hand.yaml", "thesis_arm_tripod_probe.yaml"]


def _outline(scene):
    """(4, 3) corners of the board's squares area [m, target frame]."""
    w, h = load_target(scene.target_path).pattern_size_m()
    return np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], float)


@pytest.mark.parametrize("name", SCENES)
def test_whole_board_in_view_in_all_configured_poses(name):
    scene = load_scene(SCENES_DIR / name)
    setup = scene.setup
    q = scene_poses(scene, np.random.default_rng(0))
    assert len(q) == 10
    outline = _outline(scene)
    x_true = true_parameters(scene, np.random.default_rng(scene.truth.seed))
    for x in (setup.params.nominal, x_true):  # nominal geometry and a perturbed (true) robot
        T = setup.T_cam_target(q, x)
        assert setup.visible(T, outline, margin_px=10.0, max_tilt_deg=60.0).all()
        assert setup.visible(T, setup.target_outline, margin_px=10.0, max_tilt_deg=60.0).all()
        centre = T[:, :3, :3] @ outline.mean(axis=0) + T[:, :3, 3]
        dist = np.linalg.norm(centre, axis=1)
        assert np.all((dist > 0.3) & (dist < 1.2)), dist


@pytest.mark.parametrize("name", SCENES)
def test_scene_mounts_keep_the_thesis_translations(name):
    """The scene overrides only the mount rotations of the robot file (the thesis' geometry): the
    board/camera origin in the base frame and the camera/board origin in the flange frame stay."""
    scene = load_scene(SCENES_DIR / name)
    robot = load_serial_robot(scene.setup.meta["robot_path"])
    assert scene.setup.chain.mount_names == robot.mount_names
    (L_scene, R_scene), (L_robot, R_robot) = scene.setup.chain.nominal_transforms(), robot.nominal_transforms()
    np.testing.assert_allclose(np.linalg.inv(L_scene)[:3, 3], np.linalg.inv(L_robot)[:3, 3], atol=1e-9)
    np.testing.assert_allclose(R_scene[:3, 3], R_robot[:3, 3], atol=1e-9)
    assert not np.allclose(L_scene[:3, :3], L_robot[:3, :3])
    # the robot file's own orientation does not see the board: the override is what makes the scene usable
    setup = scene.setup
    q = scene_poses(scene, np.random.default_rng(0))
    T_chain = robot.forward(q)
    T_cam = np.linalg.inv(T_chain) if setup.mount == "eye_in_hand" else T_chain
    assert not setup.visible(T_cam, _outline(scene)).any()


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENES)
def test_simulate_two_frames_keeps_the_poses_and_converges(name):
    report = run_simulation(SCENES_DIR / name, frames=2, seed=0)
    m = report["measurements"]
    assert m["n_valid"] >= 9, m["rejected"]
    assert report["identification"]["converged"]
    acc = report["accuracy"]
    assert acc["after"]["position_rms_mm"] < 0.5 * acc["before"]["position_rms_mm"]
