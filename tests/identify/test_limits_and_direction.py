"""The library path applies the same joint-limit check as the pipelines, and the measured pose's direction
(the transform the rows and their noise hold) is stated, so equal sigmas give equal answers."""

from pathlib import Path

import numpy as np
import pytest

from vision_calib import frames
from vision_calib.errors import DataError, ParameterError
from vision_calib.identify import solve_lse
from vision_calib.identify.serial_problem import serial_problem
from vision_calib.kinematics.serial_file import load_serial_robot
from vision_calib.rig import SCENES_DIR, load_scene

ROBOTS = Path(__file__).resolve().parents[2] / "scenes" / "robots"


def _data(n=40, seed=0):
    ch = load_serial_robot(ROBOTS / "thesis_arm_camera_table.yaml")  # eye-in-hand chain: T_target_cam
    rng = np.random.default_rng(seed)
    lo, hi = ch.joint_limits[:, 0], ch.joint_limits[:, 1]
    q = rng.uniform(np.maximum(lo, -np.pi), np.minimum(hi, np.pi), (n, ch.n_joints))
    x_true = ch.params.nominal + ch.params.free * 1e-3 * rng.normal(size=len(ch.params))
    T_ct = frames.inv_T(ch.forward(q, x_true))  # what solvePnP measures: T_cam_target
    d = np.concatenate([1e-4 * rng.normal(size=(n, 3)), 3e-4 * rng.normal(size=(n, 3))], 1)
    return ch, q, frames.perturb_pose(T_ct, d)  # noise isotropic in the T_cam_target direction


def test_library_refuses_out_of_limit_joints_like_the_pipeline():
    ch, q, T = _data(6)
    q = q.copy()
    q[3, 1] = ch.joint_limits[1, 1] + 0.5
    labels = [f"p{k}" for k in range(6)]
    with pytest.raises(DataError, match=r"pose 'p3' joint q2 = .* is outside the robot's limits") as lib:
        serial_problem(ch, q, frames.inv_T(T), sigma_t_m=1e-4, sigma_r_rad=1e-4, labels=labels)
    sc = load_scene(SCENES_DIR / "thesis_arm_eye_in_hand.yaml")
    with pytest.raises(DataError) as pipe:
        sc.setup.check_joints(q, "poses.csv", labels)
    assert str(pipe.value).split(": ", 1)[1] == str(lib.value).split(": ", 2)[2]  # same message after `where`
    serial_problem(ch, q, frames.inv_T(T), sigma_t_m=1e-4, sigma_r_rad=1e-4, check_limits=False)  # opt-out


def test_noise_direction_is_stated_and_carried_exactly():
    ch, q, T_ct = _data()
    st, sr = 1e-4, 3e-4
    # the rows and their sigmas given as T_cam_target (the solvePnP direction)
    a = solve_lse(serial_problem(ch, q, T_ct, sigma_t_m=st, sigma_r_rad=sr, measured="T_cam_target"))
    # the same data converted by hand into the chain's direction with the mapped covariance
    G = frames.inverse_error_map(T_ct)
    C = G @ np.diag([st] * 3 + [sr] * 3) ** 2 @ np.swapaxes(G, 1, 2)
    b = solve_lse(serial_problem(ch, q, frames.inv_T(T_ct), obs_cov=C))
    np.testing.assert_allclose(a.identified, b.identified, atol=1e-10)
    np.testing.assert_allclose(a.std, b.std, rtol=1e-8)
    # the same sigmas read in the other direction are another noise model: another answer
    c = solve_lse(serial_problem(ch, q, frames.inv_T(T_ct), sigma_t_m=st, sigma_r_rad=sr))
    assert np.nanmax(np.abs(c.std / a.std - 1)) > 0.5
    with pytest.raises(ParameterError, match="give 'T_target_cam' or 'T_cam_target'"):
        serial_problem(ch, q, T_ct, sigma_t_m=st, sigma_r_rad=sr, measured="T_cam_flange")
