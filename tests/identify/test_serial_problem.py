"""Serial identification problem: residual/Jacobian contract, covariances, synthetic data, errors."""

from pathlib import Path

import numpy as np
import pytest

from vision_calib.errors import DataError, ParameterError
from vision_calib.frames import pose_error
from vision_calib.identify.problem import IdentificationProblem
from vision_calib.identify.serial_problem import serial_problem, so3_right_jacobian_inv, synthetic_pose_measurements
from vision_calib.kinematics.serial import so3_right_jacobian
from vision_calib.kinematics.serial_file import load_serial_robot

ROBOTS = Path(__file__).resolve().parents[2] / "scenes" / "robots"

#: parameters left fixed for a full-pose identification of an arm between two 6-parameter mounts:
#: joint 1 (absorbed by the left mount), theta6/d6 (absorbed by the right mount), d3 (Hayati), l's
NOT_IDENTIFIABLE = ("alpha1", "a1", "theta1", "d1", "theta6", "d6", "d3", "l2", "l5")


def _chain(name="thesis_arm_camera_table"):
    return load_serial_robot(ROBOTS / f"{name}.yaml")


def _q(chain, n, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = chain.joint_limits[:, 0], chain.joint_limits[:, 1]
    return rng.uniform(np.maximum(lo, -np.pi), np.minimum(hi, np.pi), (n, chain.n_joints))


def _free(chain):
    return [nm for nm in chain.params.names if nm not in NOT_IDENTIFIABLE]


def _x_true(chain, seed=1):
    rng = np.random.default_rng(seed)
    dev = {nm: rng.normal(0, 2e-3) for nm in _free(chain)}
    return chain.deviated(dev)


def _gauss_newton(problem, x0, iters=10):
    """Whitened Gauss-Newton on the free parameters (test-local, independent of identify/lse)."""
    W = problem.whitening()
    fi = problem.params.free_index
    x = x0.copy()
    for _ in range(iters):
        r = np.einsum("nij,nj->ni", W, problem.residual(x)).reshape(-1)
        J = np.einsum("nij,njk->nik", W, problem.jacobian(x)[:, :, fi]).reshape(-1, len(fi))
        dx, *_ = np.linalg.lstsq(J, -r, rcond=None)
        x[fi] += dx
    return x


def test_contract_shapes_and_zero_residual_at_truth():
    ch = _chain()
    q = _q(ch, 12)
    x_true = _x_true(ch)
    T = ch.forward(q, x_true)
    for kind, m in (("pose", 6), ("position", 3)):
        pb = serial_problem(ch, q, T, residual=kind, free=_free(ch))
        assert isinstance(pb, IdentificationProblem)
        assert pb.n_obs == 12 and pb.m == m and pb.residual_kind == kind
        assert pb.residual(ch.params.nominal).shape == (12, m)
        assert pb.jacobian(ch.params.nominal).shape == (12, m, len(ch.params))
        assert np.abs(pb.residual(x_true)).max() < 1e-14
        assert pb.residual(x_true, idx=[3, 5]).shape == (2, m)
        assert pb.labels == tuple(str(i) for i in range(12))
        assert pb.meta["measured"] == "T_target_cam" and pb.meta["frame"] == "T_target_base"
        assert set(pb.params.free_names) == set(_free(ch))
        # subset() of the shared problem type works with our functions
        sub = pb.subset([1, 4, 7])
        np.testing.assert_allclose(sub.residual(ch.params.nominal), pb.residual(ch.params.nominal)[[1, 4, 7]])


@pytest.mark.parametrize("kind", ["pose", "position"])
def test_jacobian_is_derivative_of_residual(kind):
    """d r / d x (every column) vs central differences of the residual, away from the truth so that
    the rotation residual is not small (exercises the inverse right Jacobian)."""
    ch = _chain("thesis_arm_tripod_probe")
    q = _q(ch, 5)
    rng = np.random.default_rng(7)
    T_meas = ch.forward(q, ch.params.nominal + rng.normal(0, 0.05, len(ch.params)))
    pb = serial_problem(ch, q, T_meas, residual=kind)
    x = ch.params.nominal + rng.normal(0, 0.03, len(ch.params))
    J = pb.jacobian(x)
    h = 1e-6
    for k, nm in enumerate(ch.params.names):
        e = np.zeros(len(x))
        e[k] = h
        fd = (pb.residual(x + e) - pb.residual(x - e)) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, atol=2e-8, err_msg=nm)
    # at zero residual it is exactly minus the model Jacobian
    pb0 = serial_problem(ch, q, ch.forward(q, x), residual=kind)
    np.testing.assert_allclose(pb0.jacobian(x), -ch.pose_jacobian(q, x)[:, : pb0.m], atol=1e-15)


@pytest.mark.parametrize("kind", ["pose", "position"])
def test_jacobian_factors_multiply_to_the_jacobian(kind):
    """problem.jacobian_factors (D, Jc): D @ Jc is the Jacobian, over all poses, a subset of them and a subset()
    problem; a nuisance-augmented problem has none (its Jacobian has extra columns)."""
    from vision_calib.identify.nuisance import with_nuisance

    ch = _chain("thesis_arm_tripod_probe")
    q = _q(ch, 7)
    rng = np.random.default_rng(8)
    pb = serial_problem(ch, q, ch.forward(q, ch.params.nominal + rng.normal(0, 0.05, len(ch.params))), residual=kind)
    x = ch.params.nominal + rng.normal(0, 0.03, len(ch.params))
    for prob, idx in ((pb, None), (pb, [5, 1, 2]), (pb.subset([6, 0, 3]), None), (pb.subset([6, 0, 3]), [2])):
        D, Jc = prob.jacobian_factors(x, idx)
        np.testing.assert_allclose(D @ Jc, prob.jacobian(x, idx), rtol=0, atol=1e-15)
    assert with_nuisance(pb, np.ones((7, pb.m, 1))).jacobian_factors is None


@pytest.mark.parametrize("n_poses", [40, 2500])
def test_lse_is_the_gauss_newton_minimum_and_its_covariance(n_poses):
    """solve_lse (chord steps, the Jacobian kept from the analysis; 2,500 poses: more than one block of
    identifiability.BLOCK_POSES) reaches the minimum a plain Gauss-Newton polishes, within 1e-6 of the std, and its
    covariance is (J^T J)^-1 of the whitened Jacobian there to 1e-6 of the std products."""
    from vision_calib.identify.identifiability import whitened_free_jacobian
    from vision_calib.identify.lse import solve_lse

    ch = _chain("thesis_arm_tripod_probe")
    q = _q(ch, n_poses, seed=11)
    x_true = _x_true(ch, seed=12)
    T_meas = synthetic_pose_measurements(ch, q, x_true, 2e-4, 5e-4, np.random.default_rng(13))
    pb = serial_problem(ch, q, T_meas, free=_free(ch), sigma_t_m=2e-4, sigma_r_rad=5e-4)
    res = solve_lse(pb)
    fi = pb.params.free_index
    x = _gauss_newton(pb, res.identified.copy(), iters=3)
    Jw = whitened_free_jacobian(pb, pb.jacobian(x))
    cov = np.linalg.inv(Jw.T @ Jw)
    std = np.sqrt(np.diag(cov))
    assert res.converged and np.max(np.abs(res.identified[fi] - x[fi]) / std) < 1e-6
    np.testing.assert_allclose(res.covariance / np.outer(std, std), cov / np.outer(std, std), rtol=0, atol=1e-6)


def test_so3_right_jacobian_inverse():
    rng = np.random.default_rng(3)
    for r in (rng.normal(0, 0.8, 3), np.array([0, 2e-7, 0]), np.zeros(3)):
        np.testing.assert_allclose(so3_right_jacobian_inv(r) @ so3_right_jacobian(r), np.eye(3), atol=1e-12)


@pytest.mark.parametrize("name", ["thesis_arm_camera_table", "rx90"])
def test_noise_free_identification_recovers_truth(name):
    """Gauss-Newton on the base parameter set recovers x_true from exact poses."""
    ch = _chain(name)
    if name == "rx90":  # a tool point off the last axis, as in the rank test
        ch = ch.with_params(ch.params.with_nominal({"T_flange_tool.tx": 0.05, "T_flange_tool.tz": 0.1}))
    q = _q(ch, 30)
    x_true = _x_true(ch)
    pb = serial_problem(ch, q, ch.forward(q, x_true), free=_free(ch))
    x = _gauss_newton(pb, ch.params.nominal.copy())
    np.testing.assert_allclose(x, x_true, atol=1e-10)


def test_noisy_identification_is_close_and_noise_statistics():
    ch = _chain("thesis_arm_tripod_probe")
    q = _q(ch, 200, seed=5)
    x_true = _x_true(ch)
    rng = np.random.default_rng(42)
    T_meas = synthetic_pose_measurements(ch, q, x_true, 2e-4, 5e-4, rng)
    d = pose_error(ch.forward(q, x_true), T_meas)
    np.testing.assert_allclose(d.std(axis=0), [2e-4] * 3 + [5e-4] * 3, rtol=0.15)
    assert np.abs(d.mean(axis=0)).max() < 1e-4
    pb = serial_problem(ch, q, T_meas, sigma_t_m=2e-4, sigma_r_rad=5e-4, free=_free(ch))
    np.testing.assert_allclose(pb.obs_cov[0], np.diag([4e-8] * 3 + [2.5e-7] * 3))
    x = _gauss_newton(pb, ch.params.nominal.copy())
    fi = pb.params.free_index
    assert np.abs(x[fi] - x_true[fi]).max() < 5e-4  # noise-level errors, deviations were ~2 mm / 2 mrad
    # same seed -> same measurements
    again = synthetic_pose_measurements(ch, q, x_true, 2e-4, 5e-4, np.random.default_rng(42))
    np.testing.assert_array_equal(again, T_meas)


def test_covariance_inputs():
    ch = _chain()
    q = _q(ch, 4)
    T = ch.forward(q)
    pb = serial_problem(ch, q, T)
    assert pb.meta["obs_cov_source"] == pb.meta["noise"] == "estimated from residuals, not given"
    np.testing.assert_allclose(pb.obs_cov[2], np.eye(6) * 1e-6)
    C = np.diag([1e-8, 2e-8, 3e-8, 1e-6, 2e-6, 3e-6])
    pb = serial_problem(ch, q, T, obs_cov=np.broadcast_to(C, (4, 6, 6)), residual="position")
    assert pb.obs_cov.shape == (4, 3, 3)
    np.testing.assert_allclose(pb.obs_cov[1], C[:3, :3])
    pb = serial_problem(ch, q, T, obs_cov=C)
    assert pb.obs_cov.shape == (4, 6, 6)
    bad = np.broadcast_to(C, (4, 6, 6)).copy()
    bad[3, 0, 0] = -1.0
    with pytest.raises(DataError, match="pose 3"):
        serial_problem(ch, q, T, obs_cov=bad)
    with pytest.raises(ParameterError, match="not both"):
        serial_problem(ch, q, T, obs_cov=C, sigma_t_m=1e-3)


def test_errors_name_pose_and_parameter():
    ch = _chain()
    q = _q(ch, 5)
    T = ch.forward(q)
    Tbad = T.copy()
    Tbad[3, 1, 3] = np.nan
    with pytest.raises(DataError, match="pose 3"):
        serial_problem(ch, q, Tbad)
    Tbad = T.copy()
    Tbad[1, :3, :3] *= 2.0
    with pytest.raises(DataError, match="pose 1 does not hold a rotation"):
        serial_problem(ch, q, Tbad)
    qbad = q.copy()
    qbad[4, 2] = np.inf
    with pytest.raises(DataError, match="pose 4"):
        serial_problem(ch, qbad, T)
    with pytest.raises(DataError, match="4 poses but there are 5"):
        serial_problem(ch, q, T[:4])
    with pytest.raises(ParameterError, match="'a9'"):
        serial_problem(ch, q, T, free=["a2", "a9"])
    with pytest.raises(ParameterError, match="d3 and beta3 cannot both be free"):
        serial_problem(ch, q, T, free=["beta3", "d3"])
    with pytest.raises(ParameterError, match="l5 and d4 cannot both be free"):
        serial_problem(ch, q, T, free=["l5", "d4"])
    with pytest.raises(ParameterError, match="residual"):
        serial_problem(ch, q, T, residual="joint")
    with pytest.raises(DataError, match="labels"):
        serial_problem(ch, q, T, labels=["a", "b"])
    with pytest.raises(ParameterError, match="Generator"):
        synthetic_pose_measurements(ch, q, ch.params.nominal, 1e-3, 1e-3, rng=0)
