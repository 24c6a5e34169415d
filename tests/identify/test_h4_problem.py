"""H4 identification problems (IGM joint residuals, forward-model pose residuals): residual/Jacobian
consistency, noise model, identifiability, recovery of truth."""

from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import least_squares

from vision_calib.errors import DataError, UnreachablePoseError
from vision_calib.frames import pose_error
from vision_calib.identify import analyze, solve_lse
from vision_calib.identify.h4_problem import h4_igm_problem, h4_pose_problem, synthetic_h4_measurements
from vision_calib.identify.problem import NOISE_ESTIMATED
from vision_calib.kinematics import h4_variants
from vision_calib.kinematics.h4 import random_workspace_poses
from vision_calib.kinematics.h4_io import load_h4_robot
from vision_calib.kinematics.h4_variants import with_tilt_params

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "robots" / "h4.yaml"


@pytest.fixture(scope="module")
def r12():
    return load_h4_robot(SCENE)  # variant D: 19 free


def truth(robot, rng, k=3.0):
    """True parameters: free ones perturbed by k * scale * N(0,1); fixed ones at nominal."""
    x = robot.params.nominal.copy()
    f = robot.params.free_index
    x[f] += k * robot.params.scale[f] * rng.standard_normal(len(f))
    return x


def solve(problem, x0):
    """Whitened Gauss-Newton with scipy on the free parameters (scaled by params.scale)."""
    p = problem.params
    f, sc = p.free_index, p.scale[p.free_index]
    W = problem.whitening()

    def full(z):
        x = x0.copy()
        x[f] = x0[f] + z * sc
        return x

    def res(z):
        return np.einsum("kij,kj->ki", W, problem.residual(full(z))).ravel()

    def jac(z):
        J = problem.jacobian(full(z))[..., f] * sc
        return np.einsum("kij,kjn->kin", W, J).reshape(-1, len(f))

    sol = least_squares(res, np.zeros(len(f)), jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    Jw = jac(sol.x)
    cov = np.linalg.inv(Jw.T @ Jw) * np.outer(sc, sc)
    return full(sol.x), cov


def test_residual_zero_at_truth_and_jacobian_is_its_derivative(r12):
    rng = np.random.default_rng(0)
    x_true = truth(r12, rng)
    X = random_workspace_poses(15, rng)
    q, T = synthetic_h4_measurements(r12, X, x_true, rng)
    prob = h4_igm_problem(r12, q, T, sigma_q_rad=1e-4)
    assert prob.residual_kind == "joint" and prob.m == 4 and prob.n_obs == 15
    np.testing.assert_allclose(prob.residual(x_true), 0.0, atol=1e-12)
    x = r12.params.nominal
    J = prob.jacobian(x, idx=[1, 4])
    Jfd = np.zeros_like(J)
    for k in range(len(x)):
        e = np.zeros(len(x))
        e[k] = 1e-6
        Jfd[..., k] = (prob.residual(x + e, [1, 4]) - prob.residual(x - e, [1, 4])) / 2e-6
    np.testing.assert_allclose(J, Jfd, atol=1e-8 * np.abs(J).max())
    sub = prob.subset([3, 7])
    np.testing.assert_allclose(sub.residual(x), prob.residual(x)[[3, 7]])


@pytest.mark.parametrize("variant", ["D", "H"])
def test_recovers_truth_from_noise_free_data(r12, variant):
    """Model 12 (variant D, 19 parameters) and model 31 (variant H, 36 parameters): geometric
    and external parameters identified together from the 81-pose grid."""
    robot = h4_variants.variant(r12, variant)
    rng = np.random.default_rng(1)
    x_true = truth(robot, rng)
    q, T = synthetic_h4_measurements(robot, robot.pose_grid(), x_true, rng)
    prob = h4_igm_problem(robot, q, T, sigma_q_rad=1e-4)
    x0 = robot.params.nominal
    assert np.abs(prob.residual(x0)).max() > 1e-3  # the nominal model is visibly wrong
    x_hat, _ = solve(prob, x0)
    err = (x_hat - x_true) / robot.params.scale
    print(f"\nH4 variant {variant}: {robot.params.n_free} free, max |error| {np.abs(err).max():.2e} x scale")
    assert np.abs(err).max() < 1e-6
    np.testing.assert_allclose(prob.residual(x_hat), 0.0, atol=1e-10)


def test_obs_cov_matches_monte_carlo_residuals(r12):
    """obs_cov = sigma_q^2 I + G Sigma G^T predicts the covariance of the residuals at the truth."""
    rng = np.random.default_rng(2)
    x_true = r12.params.nominal
    X = np.repeat(r12.pose_grid()[[0, 40, 80]], 4000, axis=0)
    sq, st, sr = 2e-4, 2e-4, np.deg2rad(0.03)  # seed §5: 0.2 mm, 0.03 deg
    q, T = synthetic_h4_measurements(r12, X, x_true, rng, sq, st, sr)
    S = np.diag([st**2] * 3 + [sr**2] * 3)
    prob = h4_igm_problem(r12, q, T, sigma_q_rad=sq, pose_cov=S)
    r = prob.residual(x_true)
    for k, sl in enumerate((slice(0, 4000), slice(4000, 8000), slice(8000, 12000))):
        emp = np.cov(r[sl].T)
        pred = prob.obs_cov[sl].mean(axis=0)
        d = np.sqrt(np.diag(pred))
        # 4000 samples: ~2-3 % standard error on variances and correlations
        np.testing.assert_allclose(np.diag(emp) / np.diag(pred), 1.0, atol=0.1)
        np.testing.assert_allclose(emp / np.outer(d, d), pred / np.outer(d, d), atol=0.08)
    # the pose term dominates the joint term here: weighting by sigma_q alone would be wrong
    assert np.diag(prob.obs_cov[0]).min() > 2 * sq**2


def test_predicted_covariance_matches_spread(r12):
    """Monte Carlo (40 runs, 81 poses, model 12): the spread of the estimates agrees with the
    covariance predicted from obs_cov within sampling error."""
    rng = np.random.default_rng(3)
    x_true = truth(r12, rng)
    X = r12.pose_grid()
    sq, st, sr = 1e-4, 2e-4, np.deg2rad(0.03)
    S = np.diag([st**2] * 3 + [sr**2] * 3)
    est = []
    for _ in range(40):
        q, T = synthetic_h4_measurements(r12, X, x_true, rng, sq, st, sr)
        x_hat, cov = solve(h4_igm_problem(r12, q, T, sigma_q_rad=sq, pose_cov=S), r12.params.nominal)
        est.append(x_hat[r12.params.free_index])
    est = np.array(est)
    pred_std = np.sqrt(np.diag(cov))
    ratio = est.std(axis=0, ddof=1) / pred_std
    print(f"\nH4 model 12 MC spread / predicted std: min {ratio.min():.2f}, max {ratio.max():.2f}")
    # 40 runs: std of a std estimate ~11 %; allow a generous band
    assert 0.6 < ratio.min() and ratio.max() < 1.5
    bias = (est.mean(axis=0) - x_true[r12.params.free_index]) / pred_std
    assert np.abs(bias).max() < 5 / np.sqrt(40)  # no bias beyond 5 sigma of a 40-run mean


def test_bad_input(r12):
    rng = np.random.default_rng(4)
    X = random_workspace_poses(5, rng)
    q, T = synthetic_h4_measurements(r12, X, r12.params.nominal, rng)
    qn = q.copy()
    qn[2, 1] = np.nan
    with pytest.raises(DataError, match="q_meas: pose 2"):
        h4_igm_problem(r12, qn, T)
    with pytest.raises(DataError, match="4 poses|has 4"):
        h4_igm_problem(r12, q, T[:4])
    with pytest.raises(DataError, match="positive definite"):
        h4_igm_problem(r12, q, T, sigma_q_rad=0.0)
    with pytest.raises(DataError, match="pose_cov"):
        h4_igm_problem(r12, q, T, pose_cov=np.eye(5))
    Tfar = r12.camera_measurement(np.array([[0.0, 0.0, -0.65, 0.0]] * 5))
    Tfar[3, 2, 3] += 1.0  # target 1 m farther from the camera: nacelle far below reach
    with pytest.raises(UnreachablePoseError, match="pose 3"):
        h4_igm_problem(r12, q, Tfar)


# ----------------------------------------------------------------------------- pose-residual problem (lse)
def _fd(prob, x, idx, h=1e-6):
    J = np.zeros(prob.jacobian(x, idx=idx).shape)
    for k in range(len(x)):
        e = np.zeros(len(x))
        e[k] = h
        J[..., k] = (prob.residual(x + e, idx) - prob.residual(x - e, idx)) / (2 * h)
    return J


@pytest.mark.parametrize("kind", ["12", "12+tilts", "31"])
def test_pose_problem_residual_and_jacobian(r12, kind):
    """Pose residual = 0 at the truth; analytic Jacobian (implicit FGM + camera-measurement Jacobian) equals
    central finite differences over every parameter, geometric, external and tilt, away from the truth."""
    robot = {"12": r12, "12+tilts": with_tilt_params(r12, [0.01, -0.02, 0.015, 0.005], [True] * 4),
             "31": h4_variants.variant(r12, "H")}[kind]
    rng = np.random.default_rng(5)
    x_true = truth(robot, rng)
    X = random_workspace_poses(12, rng)
    q, T = synthetic_h4_measurements(robot, X, x_true, rng)
    prob = h4_pose_problem(robot, q, T, sigma_q_rad=1e-4, pose_cov=np.diag([1e-8] * 3 + [1e-7] * 3))
    assert prob.residual_kind == "pose" and prob.m == 6 and prob.n_obs == 12
    np.testing.assert_allclose(prob.residual(x_true), 0.0, atol=1e-11)
    x = robot.params.nominal
    J, Jfd = prob.jacobian(x, idx=[0, 5, 9]), _fd(prob, x, [0, 5, 9])
    assert np.abs(prob.residual(x)).max() > 1e-4  # far from the truth: the rotation residual's Jr^-1 matters
    np.testing.assert_allclose(J, Jfd, atol=1e-7 * np.abs(J).max())


def test_camera_measurement_jacobian_matches_finite_differences(r12):
    robot = with_tilt_params(r12, [0.01, -0.02, 0.015, 0.005])
    rng = np.random.default_rng(6)
    x = truth(robot, rng) + 0.01 * rng.standard_normal(len(robot.params)) * robot.params.scale
    X = random_workspace_poses(6, rng)
    JX, Jx = robot.camera_measurement_jacobian(X, x)
    T0 = robot.camera_measurement(X, x)
    h = 1e-6
    for k in range(4):
        dX = np.zeros(4)
        dX[k] = h
        fd = (pose_error(T0, robot.camera_measurement(X + dX, x)) - pose_error(T0, robot.camera_measurement(X - dX, x)))
        np.testing.assert_allclose(JX[..., k], fd / (2 * h), atol=1e-8)
    for k in range(len(x)):
        e = np.zeros(len(x))
        e[k] = h
        fd = (pose_error(T0, robot.camera_measurement(X, x + e)) - pose_error(T0, robot.camera_measurement(X, x - e)))
        np.testing.assert_allclose(Jx[..., k], fd / (2 * h), atol=1e-8, err_msg=robot.names[k])


@pytest.mark.parametrize("tilts", [False, True])
def test_pose_and_igm_problems_identify_the_same_base_set(r12, tilts):
    """Model 12 (variant D): 19 identifiable parameters with either residual, also with (fixed) mount tilts."""
    robot = with_tilt_params(r12, [0.01, -0.02, 0.015, 0.005]) if tilts else r12
    rng = np.random.default_rng(7)
    q, T = synthetic_h4_measurements(robot, robot.pose_grid(), robot.params.nominal, rng)
    S = np.diag([1e-8] * 3 + [1e-7] * 3)
    a_igm = analyze(h4_igm_problem(robot, q, T, pose_cov=S), selection="order")
    a_pose = analyze(h4_pose_problem(robot, q, T, pose_cov=S), selection="order")
    assert a_igm.rank == a_pose.rank == 19
    assert a_igm.base_parameters == a_pose.base_parameters


def test_pose_problem_obs_cov_matches_monte_carlo_residuals(r12):
    """obs_cov = Sigma_pose + sigma_q^2 (d delta/dq)(d delta/dq)^T predicts the residuals' covariance at the truth."""
    rng = np.random.default_rng(8)
    X = np.repeat(r12.pose_grid()[[0, 80]], 4000, axis=0)
    sq, st, sr = 2e-4, 2e-4, np.deg2rad(0.03)
    q, T = synthetic_h4_measurements(r12, X, r12.params.nominal, rng, sq, st, sr)
    prob = h4_pose_problem(r12, q, T, sigma_q_rad=sq, pose_cov=np.diag([st**2] * 3 + [sr**2] * 3))
    r = prob.residual(r12.params.nominal)
    for sl in (slice(0, 4000), slice(4000, 8000)):
        emp, pred = np.cov(r[sl].T), prob.obs_cov[sl].mean(axis=0)
        d = np.sqrt(np.diag(pred))
        np.testing.assert_allclose(np.diag(emp) / np.diag(pred), 1.0, atol=0.1)
        np.testing.assert_allclose(emp / np.outer(d, d), pred / np.outer(d, d), atol=0.08)
    # the joint noise through the FGM is not negligible against the pose noise here (+30 % variance)
    assert np.diag(prob.obs_cov[0])[:3].max() > 1.2 * st**2


@pytest.mark.parametrize("kind", ["joint", "pose"])
def test_both_methods_recover_the_truth_within_their_std(r12, kind):
    """Noisy synthetic data, 81 poses, 12 draws: each estimate's error against the truth, in units of its
    predicted std, is standard normal (mean of z^2 ~ 1 over 12 x 19 values)."""
    build = h4_igm_problem if kind == "joint" else h4_pose_problem
    rng = np.random.default_rng(9)
    x_true = truth(r12, rng)
    sq, st, sr = 1e-4, 2e-4, np.deg2rad(0.03)
    S = np.diag([st**2] * 3 + [sr**2] * 3)
    z = []
    for _ in range(12):
        q, T = synthetic_h4_measurements(r12, r12.pose_grid(), x_true, rng, sq, st, sr)
        res = solve_lse(build(r12, q, T, sigma_q_rad=sq, pose_cov=S))
        assert res.converged and res.residual_kind == kind
        z.append((res.identified - x_true)[res.free] / res.std[res.free])
    z = np.array(z)
    print(f"\n{kind}: mean z^2 {np.mean(z**2):.2f}, max |z| {np.abs(z).max():.2f}")
    assert 0.75 < np.mean(z**2) < 1.3  # 228 values: std of the mean of z^2 ~ 0.09
    assert np.abs(z).max() < 4.5


def test_pose_problem_bad_input(r12):
    rng = np.random.default_rng(10)
    q, T = synthetic_h4_measurements(r12, random_workspace_poses(5, rng), r12.params.nominal, rng)
    with pytest.raises(DataError, match="pose residual needs pose_cov"):
        h4_pose_problem(r12, q, T, sigma_q_rad=1e-4)  # an exact camera: two rotation components without noise
    prob = h4_pose_problem(r12, q, T)  # no noise given: relative weights, the scale from the residuals
    assert prob.meta.get("noise") == NOISE_ESTIMATED
