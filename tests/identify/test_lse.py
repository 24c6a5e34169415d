"""LSE on toy problems: exact recovery, Monte Carlo vs predicted std, FD baseline, bad inputs."""

import numpy as np
import pytest
from toy_models import NOMINAL, SCALE, linear_problem, planar_problem, true_deviation

from vision_calib.errors import ConfigError, DataError, IdentifiabilityError, ParameterError
from vision_calib.identify import analyze, equivalent_base_values, solve_ekf, solve_lse, solve_lse_fd

# correlated measurement noise (m, rad): exercises the whitening
COV = np.array([[1.0e-8, 0.4e-8, 0.0], [0.4e-8, 2.0e-8, 0.5e-8], [0.0, 0.5e-8, 4.0e-8]])


def _assert_recovered(res, expected, rel=1e-9):
    """Relative error <= rel, or absolute <= rel * scale where the value is ~0 (SI)."""
    tol = rel * np.maximum(np.abs(expected), SCALE)
    err = np.abs(res.identified - expected)
    bad = [f"{n}: {e:.3g} > {t:.3g}" for n, e, t in zip(res.names, err, tol) if e > t]
    assert not bad, bad


@pytest.mark.parametrize("measure", ["pose", "position"])
def test_noise_free_recovery(measure):
    rng = np.random.default_rng(5)
    x_true = true_deviation(rng)
    prob, _ = planar_problem(x_true, n_poses=25, measure=measure, rng=rng, noise=False)
    res = solve_lse(prob)
    assert res.converged and res.method == "lse"
    rep = analyze(prob)
    expected = equivalent_base_values(prob, rep, x_true)  # theta absorbs the q0_1 deviation
    _assert_recovered(res, expected)
    assert res.cost_final < 1e-18 * max(res.cost_initial, 1.0)
    assert np.abs(res.residuals).max() < 1e-12
    # the non-identifiable parameter stayed at x0 (nominal) and is named in a warning
    j = res.names.index("q0_1")
    assert res.identified[j] == NOMINAL[j] and not res.free[j] and np.isnan(res.std[j])
    assert any("q0_1" in w for w in res.warnings)


def test_noise_free_recovery_from_other_start_and_with_fixed_parameter():
    rng = np.random.default_rng(6)
    x_true = true_deviation(rng)
    prob, _ = planar_problem(x_true, n_poses=25, rng=rng, noise=False)
    x0 = NOMINAL + SCALE * 5.0
    x0[6] = x_true[6]  # q0_1 (fixed, non-identifiable) started at its true value
    x0[5] = x_true[5]  # L3 fixed by the user at its true value
    res = solve_lse(prob, x0=x0, fix=["L3"])
    assert not res.free[5] and res.identified[5] == x_true[5]
    _assert_recovered(res, x_true)


def test_analytic_and_finite_difference_give_same_solution():
    rng = np.random.default_rng(8)
    prob, _ = planar_problem(true_deviation(rng), n_poses=30, cov=COV, rng=rng)
    a = solve_lse(prob)
    f = solve_lse_fd(prob)
    f3 = solve_lse(prob, jac="3-point")
    fi = a.free
    assert a.info["jac"] == "analytic" and f.info["jac"] == "2-point"
    for other in (f, f3):
        assert np.all(np.abs(other.identified - a.identified)[fi] < 1e-3 * a.std[fi])
        assert np.allclose(other.std[fi], a.std[fi], rtol=1e-4)
    assert a.cost_final <= f.cost_final * (1 + 1e-9)


def test_monte_carlo_rms_error_matches_predicted_std_and_ekf_matches_lse():
    """100 seeded noise draws on fixed poses/truth: RMS error within +-25 % of predicted std."""
    rng = np.random.default_rng(123)
    x_true = true_deviation(rng)
    q = rng.uniform(-np.pi, np.pi, size=(20, 3))
    errs_lse, errs_ekf, stds, ekf_vs_lse, ekf_stds = [], [], [], [], []
    for seed in range(100):
        prob, _ = planar_problem(x_true, q=q, cov=COV, rng=np.random.default_rng(1000 + seed))
        if seed == 0:
            expected = equivalent_base_values(prob, analyze(prob), x_true)
        r = solve_lse(prob)
        e = solve_ekf(prob)
        fi = r.free
        errs_lse.append((r.identified - expected)[fi])
        errs_ekf.append((e.identified - expected)[fi])
        stds.append(r.std[fi])
        ekf_stds.append(e.std[fi])
        ekf_vs_lse.append(np.abs(e.identified - r.identified)[fi] / r.std[fi])
    std = np.mean(stds, axis=0)
    rms_lse = np.sqrt(np.mean(np.square(errs_lse), axis=0))
    rms_ekf = np.sqrt(np.mean(np.square(errs_ekf), axis=0))
    ratio_lse, ratio_ekf = rms_lse / std, rms_ekf / std
    assert np.all((ratio_lse > 0.75) & (ratio_lse < 1.25)), ratio_lse
    assert np.all((ratio_ekf > 0.75) & (ratio_ekf < 1.25)), ratio_ekf
    # same data: EKF (one pass, iterated update, broad prior) = LSE within a small fraction of the std
    assert np.max(ekf_vs_lse) < 0.05, np.max(ekf_vs_lse)
    assert np.allclose(np.mean(ekf_stds, axis=0), std, rtol=0.01)
    # mean error is consistent with zero (unbiased): |mean| < 4 std / sqrt(100)
    assert np.all(np.abs(np.mean(errs_lse, axis=0)) < 0.4 * std)


def test_covariance_is_inverse_normal_matrix_and_optional_residual_scaling():
    rng = np.random.default_rng(9)
    A = rng.standard_normal((12, 2, 3))
    cov = np.stack([np.diag([0.01, 0.04])] * 12)
    x_true = np.array([0.1, -0.2, 0.3])
    y = np.einsum("kmn,n->km", A, x_true) + rng.standard_normal((12, 2)) * np.sqrt([0.01, 0.04])
    prob = linear_problem(A, y, cov, ["a", "b", "c"], [0.1, 0.1, 0.1])
    res = solve_lse(prob)
    Wf = A / np.sqrt([0.01, 0.04])[None, :, None]
    N = Wf.reshape(-1, 3)
    assert np.allclose(res.covariance, np.linalg.inv(N.T @ N), rtol=1e-10)
    x_hat = np.linalg.lstsq(N, (y / np.sqrt([0.01, 0.04])).ravel(), rcond=None)[0]
    assert np.allclose(res.identified, x_hat, rtol=1e-10, atol=1e-12)
    res2 = solve_lse(prob, scale_cov_by_residual=True)
    factor = 2 * res.cost_final / (24 - 3)
    assert np.allclose(res2.covariance, res.covariance * factor, rtol=1e-10)


def test_correlation_warning_names_both_parameters():
    rng = np.random.default_rng(2)
    n_obs = 10
    A = np.zeros((n_obs, 1, 2))
    A[:, 0, 0] = 1.0 + 0.01 * rng.standard_normal(n_obs)
    A[:, 0, 1] = 1.0 + 0.01 * rng.standard_normal(n_obs)  # nearly collinear columns
    prob = linear_problem(A, rng.standard_normal((n_obs, 1)), np.full((n_obs, 1, 1), 1e-6), ["p", "q"], [1e-3, 1e-3])
    res = solve_lse(prob)
    assert len(res.correlation_warnings) == 1
    w = res.correlation_warnings[0]
    assert "p" in w and "q" in w and "corr" in w
    corr = res.covariance[0, 1] / np.sqrt(res.covariance[0, 0] * res.covariance[1, 1])
    assert f"{corr:+.3f}" in w and abs(corr) > 0.95


def test_robust_loss_resists_an_outlier_pose():
    rng = np.random.default_rng(4)
    x_true = true_deviation(rng)
    prob, _ = planar_problem(x_true, n_poses=30, rng=rng)
    prob.meta["y"][7] += np.array([5e-3, -5e-3, 1e-2])  # 50 sigma outlier
    expected = equivalent_base_values(prob, analyze(prob), x_true)
    lin = solve_lse(prob)
    hub = solve_lse(prob, loss="huber", f_scale=3.0)
    assert hub.info["scipy_method"] == "trf"
    fi = lin.free
    err_lin = np.abs(lin.identified - expected)[fi] / lin.std[fi]
    err_hub = np.abs(hub.identified - expected)[fi] / lin.std[fi]
    assert err_hub.max() < 5 and err_lin.max() > 3 * err_hub.max()
    # the outlier shows in the per-pose residuals (unwhitened, measured - model)
    assert np.argmax(np.abs(lin.residuals[:, 0])) == 7 or np.argmax(np.abs(hub.residuals[:, 0])) == 7


def test_keep_unidentifiable_free_warns():
    rng = np.random.default_rng(12)
    prob, _ = planar_problem(true_deviation(rng), n_poses=20, rng=rng)
    res = solve_lse(prob, fix_unidentifiable=False)
    assert res.free.sum() == 9
    assert any("q0_1" in w and "base.theta" not in w for w in res.warnings)
    assert any("pseudo-inverse" in w for w in res.warnings)


def test_bad_inputs():
    rng = np.random.default_rng(13)
    prob, _ = planar_problem(true_deviation(rng), n_poses=10, rng=rng)
    with pytest.raises(ParameterError, match="L9"):
        solve_lse(prob, fix=["L9"])
    with pytest.raises(ParameterError, match="nope"):
        solve_lse(prob, free=["L1", "nope"])
    with pytest.raises(ParameterError):
        solve_lse(prob, free=[])
    with pytest.raises(ConfigError):
        solve_lse(prob, method="lm", loss="huber")
    with pytest.raises(ConfigError):
        solve_lse(prob, jac="complex")
    few, _ = planar_problem(true_deviation(rng), n_poses=2, rng=rng)
    with pytest.raises(IdentifiabilityError, match=r"6 scalar equations.*9 free parameters"):
        solve_lse(few)
    # 2 poses are enough once only 4 parameters are free (6 equations >= 4)
    assert solve_lse(few, free=["base.x", "base.y", "L1", "L2"]).converged
    prob.meta["y"][3, 2] = np.nan
    with pytest.raises(DataError, match="pose003"):
        solve_lse(prob)
    with pytest.raises(ParameterError):
        solve_lse(prob, x0=np.zeros(4))


def test_result_summary_fields():
    rng = np.random.default_rng(14)
    prob, _ = planar_problem(true_deviation(rng), n_poses=15, rng=rng)
    res = solve_lse(prob)
    assert res.residuals.shape == (15, 3) and res.labels == prob.labels
    assert res.covariance.shape == (8, 8)
    assert res.cost_final < res.cost_initial
    assert res.iterations >= 1 and res.info["nfev"] >= 1 and res.seconds >= 0
    d = res.to_dict()
    assert d["method"] == "lse" and len(d["parameters"]) == 9
    assert np.allclose(res.residuals, prob.residual(res.identified))


# ----------------------------------------------------------------------------- real H4 builder
def test_h4_noise_free_recovery_variant_D():
    from toy_models import h4_problem

    prob, x_true = h4_problem("D", n_poses=40)
    full = prob.with_params(prob.params.with_free(prob.params.names))
    expected = equivalent_base_values(full, analyze(full), x_true)  # B_T_C.z absorbs M_T_E.z (exact)
    res = solve_lse(prob)
    assert res.converged
    fi = res.free
    tol = 1e-9 * np.maximum(np.abs(expected), prob.params.scale)
    assert np.all(np.abs(res.identified - expected)[fi] <= tol[fi])


def test_levenberg_marquardt_matches_minpack_on_a_nonlinear_fit():
    """The normal-equations LM (solve_lse's method "lm") reaches MINPACK's minimum (scipy method "lm") on a badly
    scaled, non-zero-residual exponential fit from a far start: same cost, same x within 1e-7 of its std (and
    within 1e-8 std of the minimum polished by Gauss-Newton steps); an exact fit stops on gtol; max_nfev stops it
    unconverged (status 0), a Jacobian turning non-finite with status -1."""
    from scipy.optimize import least_squares

    from vision_calib.identify.lm import levenberg_marquardt

    t = np.linspace(0, 4, 60)
    y = 3e3 * np.exp(-1.3 * t) + 0.02 * np.sin(7 * t) + 5e-4 * np.cos(3 * t) * 1e3

    def fun(z):
        return (z[0] * 1e3 * np.exp(-z[1] * t) + z[2] - y) / 10.0

    def jac(z):
        e = np.exp(-z[1] * t)
        return np.column_stack([1e3 * e, -z[0] * 1e3 * t * e, np.ones_like(t)]) / 10.0

    z0 = np.array([1.0, 0.2, 0.0])
    ref = least_squares(fun, z0, jac=jac, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12)
    ours = levenberg_marquardt(fun, jac, z0)
    assert ours.status in (1, 2, 3, 4) and ours.cost == pytest.approx(ref.cost, rel=1e-12)
    std = np.sqrt(np.diag(np.linalg.inv(jac(ref.x).T @ jac(ref.x))))
    z = ref.x.copy()
    for _ in range(10):
        z = z - np.linalg.lstsq(jac(z), fun(z), rcond=None)[0]
    assert np.max(np.abs(ours.x - ref.x) / std) < 1e-7 and np.max(np.abs(ours.x - z) / std) < 1e-8
    exact = levenberg_marquardt(lambda z: jac(z) @ (z - [2.0, 1.0, 3.0]), jac, z0 * 0 + [2.0, 1.0, 3.0])
    assert exact.status == 1 and exact.cost == 0.0
    short = levenberg_marquardt(fun, jac, z0, max_nfev=2)
    assert short.status == 0 and short.nfev == 2 and short.cost < 0.5 * np.sum(fun(z0) ** 2)
    broken = levenberg_marquardt(fun, lambda z: jac(z) * (np.nan if z[1] != 0.2 else 1.0), z0)
    assert broken.status == -1 and "not finite" in broken.message and broken.njev == 2


def test_whitening_is_the_inverse_cholesky_factor():
    """problem.whitening's batched triangular inverse (identify.problem.lower_triangular_inverse) equals
    np.linalg.inv of the factor for sizes 1..6 and badly scaled covariances; a zero pivot gives non-finite
    entries (check_problem then names the pose)."""
    from vision_calib.identify.problem import lower_triangular_inverse

    rng = np.random.default_rng(5)
    for m in range(1, 7):
        A = rng.standard_normal((9, m, m))
        S = np.diag(np.logspace(-5, 0, m))
        C = S @ (A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(m)) @ S
        L = np.linalg.cholesky(C)
        W = lower_triangular_inverse(L)
        np.testing.assert_allclose(W, np.linalg.inv(L), rtol=1e-10, atol=1e-13 * np.abs(W).max())
        np.testing.assert_allclose(W @ C @ np.swapaxes(W, 1, 2), np.broadcast_to(np.eye(m), C.shape), atol=1e-12)
    L = np.broadcast_to(np.eye(3), (2, 3, 3)).copy()
    L[1, 1, 1] = 0.0
    W = lower_triangular_inverse(L)
    assert np.all(np.isfinite(W[0])) and not np.all(np.isfinite(W[1]))
