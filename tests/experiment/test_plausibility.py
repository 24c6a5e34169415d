"""Plausibility warnings fire on large moves the data do not explain, not on large moves that fit well."""

from dataclasses import replace
from pathlib import Path

import numpy as np

from vision_calib.experiment.steps import plausibility_warnings
from vision_calib.identify import solve_lse
from vision_calib.identify.serial_problem import serial_problem, synthetic_pose_measurements
from vision_calib.kinematics.serial_file import load_serial_robot

ROBOTS = Path(__file__).resolve().parents[2] / "scenes" / "robots"


def _fit(noise_factor: float, seed=0):
    """The thesis arm with its camera mount T_flange_cam.tx really 110 mm off the nominal (a roughly known
    mount); measurements with 0.1 mm / 0.1 mrad noise x noise_factor, identified with the 0.1 mm / 0.1 mrad
    sigmas."""
    ch = load_serial_robot(ROBOTS / "thesis_arm_camera_table.yaml")
    ps = ch.params
    rng = np.random.default_rng(seed)
    lo, hi = ch.joint_limits[:, 0], ch.joint_limits[:, 1]
    q = rng.uniform(np.maximum(lo, -np.pi), np.minimum(hi, np.pi), (80, ch.n_joints))
    x_true = ps.nominal.copy()
    x_true[ps.index("T_flange_cam.tx")] += 0.110
    T = synthetic_pose_measurements(ch, q, x_true, 1e-4 * noise_factor, 1e-4 * noise_factor, rng)
    problem = serial_problem(ch, q, T, sigma_t_m=1e-4, sigma_r_rad=1e-4)
    res = solve_lse(problem)
    return problem.params, res


def test_large_move_that_fits_well_is_not_warned():
    params, res = _fit(1.0)
    assert abs(res.value("T_flange_cam.tx") - params.nominal[params.index("T_flange_cam.tx")] - 0.110) < 1e-3
    assert res.chi2_dof < 2
    assert plausibility_warnings(params, res) == []


def test_large_move_with_large_residuals_is_warned():
    params, res = _fit(10.0)
    assert res.chi2_dof > 50
    w = plausibility_warnings(params, res)
    assert len(w) == 1 and w[0].startswith("T_flange_cam.tx moved by +1") and "chi2/dof" in w[0]


def test_large_move_along_an_undetermined_direction_is_warned():
    params, res = _fit(1.0)
    i = params.index("T_flange_cam.tx")
    std = res.std.copy()
    std[i] = 0.1  # 100 mm: the move is not determined by the data
    w = plausibility_warnings(params, replace(res, std=std))
    assert len(w) == 1 and "the data do not determine it" in w[0]
