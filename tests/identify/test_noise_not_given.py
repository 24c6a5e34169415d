"""No invented noise: with no measurement noise given, the builders weight relatively and the solvers
estimate the noise scale from the residuals (a-posteriori variance factor), marked in the result."""

from pathlib import Path

import numpy as np
import pytest

from vision_calib import frames
from vision_calib.identify import solve_ekf, solve_lse
from vision_calib.identify.h4_problem import h4_igm_problem, synthetic_h4_measurements
from vision_calib.identify.handeye_problem import solve_handeye
from vision_calib.report.handeye import handeye_report
from vision_calib.identify.problem import NOISE_ESTIMATED
from vision_calib.identify.serial_problem import serial_problem, synthetic_pose_measurements
from vision_calib.kinematics.h4 import random_workspace_poses
from vision_calib.kinematics.h4_io import load_h4_robot
from vision_calib.kinematics.serial_file import load_serial_robot

ROBOTS = Path(__file__).resolve().parents[2] / "scenes" / "robots"


def _serial_data(sigma_t, sigma_r, n=120, seed=0):
    ch = load_serial_robot(ROBOTS / "thesis_arm_camera_table.yaml")
    rng = np.random.default_rng(seed)
    lo, hi = ch.joint_limits[:, 0], ch.joint_limits[:, 1]
    q = rng.uniform(np.maximum(lo, -np.pi), np.minimum(hi, np.pi), (n, ch.n_joints))
    x_true = ch.params.nominal + ch.params.free * 1e-3 * rng.normal(size=len(ch.params))
    return ch, q, synthetic_pose_measurements(ch, q, x_true, sigma_t, sigma_r, rng)


@pytest.mark.parametrize("solver", [solve_lse, solve_ekf])
def test_serial_noise_estimated_from_residuals(solver):
    # true noise 0.2 mm / 0.2 mrad: 5x below the old silent default of 1 mm / 1 mrad
    ch, q, T = _serial_data(2e-4, 2e-4)
    given = solver(serial_problem(ch, q, T, sigma_t_m=2e-4, sigma_r_rad=2e-4))
    est = solver(serial_problem(ch, q, T))
    assert given.noise == "given" and est.noise == NOISE_ESTIMATED
    assert any(w.startswith(f"noise: {NOISE_ESTIMATED}") for w in est.warnings)
    assert est.to_dict()["noise"] == NOISE_ESTIMATED
    ok = np.isfinite(given.std)
    # the estimated variance factor is chi2/dof with ~700 dof: within ~10 % of the true noise
    np.testing.assert_allclose(est.std[ok], given.std[ok], rtol=0.1)
    np.testing.assert_allclose(est.identified, given.identified, atol=1e-9)


def test_serial_one_sigma_only_is_refused():
    ch, q, T = _serial_data(2e-4, 2e-4, n=10)
    with pytest.raises(Exception, match="give both sigma_t_m and sigma_r_rad"):
        serial_problem(ch, q, T, sigma_t_m=1e-4)
    assert "noise" not in serial_problem(ch, q, T, sigma_t_m=1e-4, residual="position").meta


def test_handeye_noise_estimated_from_residuals():
    rng = np.random.default_rng(3)
    N = 40
    F = np.array([frames.T_from_xyz_rotvec(np.r_[rng.uniform([0.3, -0.3, 0.2], [0.7, 0.3, 0.6]),
                                                 [np.pi, 0, 0] + rng.normal(scale=0.3, size=3)]) for _ in range(N)])
    A = frames.inv_T(frames.T_from_xyz_rpy([1.0, 0.1, 0.5], np.radians([-90, 0, 90])))
    B = frames.T_from_xyz_rpy([0.01, 0.02, 0.1], [0.1, 0.0, 0.2])
    st, sr = 3e-4, np.radians(0.03)  # the ratio of the relative weights (1 mm : 0.1 deg)
    d = np.concatenate([st * rng.normal(size=(N, 3)), sr * rng.normal(size=(N, 3))], 1)
    M = frames.perturb_pose(A @ F @ B, d)
    given, *_ = solve_handeye(F, M, "fixed", sigma_t_m=st, sigma_rot_rad=sr)
    est, Ae, Be, pb = solve_handeye(F, M, "fixed")
    assert est.noise == NOISE_ESTIMATED and given.noise == "given"
    np.testing.assert_allclose(est.std, given.std, rtol=0.15)
    assert handeye_report(est, Ae, Be, pb)["noise"]["noise"] == NOISE_ESTIMATED


def test_h4_noise_estimated_from_residuals():
    robot = load_h4_robot(ROBOTS / "h4.yaml")
    rng = np.random.default_rng(1)
    X = random_workspace_poses(150, rng, robot.center, robot.size)
    x_true = robot.params.nominal + robot.params.free * robot.params.scale * rng.normal(size=len(robot.params))
    q, T = synthetic_h4_measurements(robot, X, x_true, rng, sigma_q_rad=2e-5)
    pb = h4_igm_problem(robot, q, T)
    assert pb.meta["noise"] == NOISE_ESTIMATED
    est = solve_lse(pb)
    given = solve_lse(h4_igm_problem(robot, q, T, sigma_q_rad=2e-5))
    assert est.noise == NOISE_ESTIMATED and given.noise == "given"
    ok = np.isfinite(given.std)
    np.testing.assert_allclose(est.std[ok], given.std[ok], rtol=0.1)
