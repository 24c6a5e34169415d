"""EKF: exact linear-Gaussian algebra, noise-free recovery, agreement with LSE, options, bad inputs."""

import dataclasses

import numpy as np
import pytest
from toy_models import NOMINAL, SCALE, linear_problem, planar_problem, true_deviation

from vision_calib.errors import ConfigError, DataError, ParameterError
from vision_calib.identify import analyze, equivalent_base_values, solve_ekf, solve_lse


def _linear(prior_std=None, seed=0):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((15, 2, 4))
    B = rng.standard_normal((15, 2, 2))
    cov = 1e-4 * (B @ np.swapaxes(B, 1, 2) + 0.2 * np.eye(2))
    x_true = np.array([0.3, -0.1, 0.05, 0.2])
    noise = np.einsum("kij,kj->ki", np.linalg.cholesky(cov), rng.standard_normal((15, 2)))
    y = np.einsum("kmn,n->km", A, x_true) + noise
    prob = linear_problem(A, y, cov, ["a", "b", "c", "d"], [0.1] * 4, nominal=np.full(4, 0.05))
    if prior_std is not None:
        prob = dataclasses.replace(prob, prior_std=np.asarray(prior_std, float))
    return prob, A, y, cov


def test_linear_gaussian_case_equals_batch_map():
    """For a linear model one pass of the filter is the exact Bayesian posterior (passes=1; later passes
    move to the least-squares optimum, so one pass with an informative prior is honestly 'not converged')."""
    prior_std = np.array([0.01, 0.02, 0.05, 0.1])  # informative: the prior matters
    prob, A, y, cov = _linear(prior_std)
    x0 = prob.params.nominal
    info = sum(A[k].T @ np.linalg.inv(cov[k]) @ A[k] for k in range(15)) + np.diag(1 / prior_std**2)
    rhs = sum(A[k].T @ np.linalg.inv(cov[k]) @ (y[k] - A[k] @ x0) for k in range(15))
    post_cov = np.linalg.inv(info)
    x_map = x0 + post_cov @ rhs
    for it in (1, 3):
        res = solve_ekf(prob, iterations_per_update=it, passes=1)
        assert res.method == "ekf"
        assert not res.converged and res.status == 0 and "1 pass" in res.message
        assert np.allclose(res.identified, x_map, rtol=1e-9, atol=1e-12)
        assert np.allclose(res.covariance, post_cov, rtol=1e-8, atol=1e-16)
        assert np.allclose(res.covariance, res.covariance.T)
        assert np.all(np.linalg.eigvalsh(res.covariance) > 0)
    # order of the poses does not matter when Q = 0
    perm = np.random.default_rng(1).permutation(15)
    assert np.allclose(solve_ekf(prob, order=perm, passes=1).identified, x_map, rtol=1e-9, atol=1e-12)


def test_broad_prior_matches_lse_on_linear_problem():
    prob, *_ = _linear()
    e = solve_ekf(prob)
    r = solve_lse(prob)
    assert np.all(np.abs(e.identified - r.identified) < 1e-4 * r.std)
    # the difference is the pull of the broad prior (std 100 x scale) towards x0: -P (P0^-1 (x - x0))
    prior_var = (100 * prob.params.scale) ** 2
    pull = -e.covariance @ ((r.identified - prob.params.nominal) / prior_var)
    assert np.allclose(e.identified - r.identified, pull, rtol=1e-3, atol=1e-13)
    assert np.allclose(e.std, r.std, rtol=1e-6)


def test_process_noise_inflates_covariance():
    prob, *_ = _linear()
    base = solve_ekf(prob)
    noisy = solve_ekf(prob, q_process=0.01)
    assert np.all(noisy.std > base.std)
    assert np.all(np.isfinite(noisy.identified))


@pytest.mark.parametrize("measure", ["pose", "position"])
def test_noise_free_recovery(measure):
    rng = np.random.default_rng(21)
    x_true = true_deviation(rng)
    prob, _ = planar_problem(x_true, n_poses=25, measure=measure, rng=rng, noise=False)
    expected = equivalent_base_values(prob, analyze(prob), x_true)
    res = solve_ekf(prob, passes=3)
    tol = 1e-9 * np.maximum(np.abs(expected), SCALE)
    err = np.abs(res.identified - expected)
    assert np.all(err <= tol), dict(zip(res.names, err))
    assert res.converged
    assert any("q0_1" in w for w in res.warnings)
    assert res.identified[res.names.index("q0_1")] == NOMINAL[res.names.index("q0_1")]
    # each pass gets closer; the first is already close (small non-linearity)
    est = res.info["pass_estimates"]
    d = [np.max(np.abs(p - expected) / SCALE) for p in est]
    assert d[0] < 1e-3 and d[2] <= d[0]


def test_plain_ekf_converges_to_lse_with_passes():
    rng = np.random.default_rng(22)
    prob, _ = planar_problem(true_deviation(rng), n_poses=25, rng=rng)
    lse = solve_lse(prob)
    fi = lse.free
    one = solve_ekf(prob, iterations_per_update=1, passes=1)
    three = solve_ekf(prob, iterations_per_update=1, passes=3)
    d1 = np.max(np.abs(one.identified - lse.identified)[fi] / lse.std[fi])
    d3 = np.max(np.abs(three.identified - lse.identified)[fi] / lse.std[fi])
    assert d3 < 0.01 and d3 <= d1
    assert np.allclose(three.std[fi], lse.std[fi], rtol=0.01)
    assert three.info["updates"] == 3 * 25
    # iterated update, one pass: same solution as LSE up to a small fraction of the std
    it = solve_ekf(prob, passes=1)
    assert np.max(np.abs(it.identified - lse.identified)[fi] / lse.std[fi]) < 0.05
    assert it.cost_final < it.cost_initial and it.residuals.shape == (25, 3)


def test_bad_inputs():
    rng = np.random.default_rng(23)
    prob, _ = planar_problem(true_deviation(rng), n_poses=10, rng=rng)
    with pytest.raises(ConfigError):
        solve_ekf(prob, passes=0)
    with pytest.raises(ConfigError):
        solve_ekf(prob, iterations_per_update=0)
    with pytest.raises(ConfigError):
        solve_ekf(prob, q_process=-1.0)
    with pytest.raises(ParameterError, match="L7"):
        solve_ekf(prob, free=["L7"])
    with pytest.raises(DataError):
        solve_ekf(dataclasses.replace(prob, prior_std=np.zeros(9)))
    prob.meta["y"][6, 0] = np.inf
    with pytest.raises(DataError, match="pose006"):
        solve_ekf(prob)


# ----------------------------------------------------------------------------- real H4 builder
def test_h4_passes_bring_ekf_to_lse():
    """Ill-conditioned H4 (variant D): one pass may differ from LSE by a few std (early poses
    linearised far away); Gauss-Newton passes converge to the LSE solution."""
    from toy_models import h4_problem

    prob, _ = h4_problem("D", sigma_q_rad=1e-4, n_poses=40, seed=3)
    lse = solve_lse(prob)
    fi = lse.free
    one = solve_ekf(prob, passes=1)
    three = solve_ekf(prob, passes=3)
    d1 = np.max(np.abs(one.identified - lse.identified)[fi] / lse.std[fi])
    d3 = np.max(np.abs(three.identified - lse.identified)[fi] / lse.std[fi])
    assert np.isfinite(d1) and d3 < 0.01 and d3 < d1
    assert np.allclose(three.std[fi], lse.std[fi], rtol=0.01)
