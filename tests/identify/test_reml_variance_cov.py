"""The REML variances' covariance 2 (tr(P V_i P V_j))^-1 of identify.handeye_fit computed in O(N) (sums over the
poses) equals the dense formula with the (N m)^2 projector P built explicitly."""

import numpy as np
import pytest
from scipy.linalg import block_diag

from vision_calib.identify.reml import reml_variance_cov


def _dense(J, known, blocks, theta):
    n, m, _ = J.shape
    C = known + np.einsum("i,inab->nab", theta, blocks)
    W = block_diag(*np.linalg.inv(C))
    Jf = J.reshape(n * m, -1)
    P = W - W @ Jf @ np.linalg.pinv(Jf.T @ W @ Jf) @ Jf.T @ W
    V = [block_diag(*b) for b in blocks]
    T = np.array([[np.trace(P @ Vi @ P @ Vj) for Vj in V] for Vi in V])
    return 2.0 * np.linalg.pinv(T)


@pytest.mark.parametrize("n, k", [(12, 2), (40, 7)])
def test_variance_cov_equals_the_dense_formula(n, k):
    rng = np.random.default_rng(n + k)
    J = rng.normal(size=(n, 6, 12))
    A = rng.normal(size=(n, 6, 6))
    known = 0.1 * A @ np.swapaxes(A, 1, 2)
    B = rng.normal(size=(k, n, 6, 3))
    blocks = B @ np.swapaxes(B, 2, 3)
    theta = rng.uniform(0.1, 1.0, k)
    ref = _dense(J, known, blocks, theta)
    np.testing.assert_allclose(reml_variance_cov(J, known, blocks, theta), ref, rtol=1e-9,
                               atol=1e-12 * np.abs(ref).max())


def _dense_negll(J, r, known, blocks, theta):
    """The penalised REML -log-likelihood with the (N m)^2 matrices built explicitly."""
    n, m, _ = J.shape
    C = block_diag(*(known + np.einsum("i,inab->nab", theta, blocks)))
    W = np.linalg.inv(C)
    Jf, rf = J.reshape(n * m, -1), r.reshape(-1)
    A = Jf.T @ W @ Jf
    P = W - W @ Jf @ np.linalg.inv(A) @ Jf.T @ W
    return 0.5 * (np.linalg.slogdet(C)[1] + np.linalg.slogdet(A)[1] + rf @ P @ rf) - 0.5 * np.sum(np.log(theta))


def test_reml_likelihood_its_gradient_and_its_batched_grid():
    """reml_negll against the dense formula; its analytic gradient against central differences; reml_negll_many
    (the grid's batched evaluation) equal to it row by row, inf where C is not positive definite."""
    from vision_calib.identify.reml import reml_negll, reml_negll_many

    rng = np.random.default_rng(5)
    n, k = 9, 3
    J = rng.normal(size=(n, 6, 5))
    r = rng.normal(size=(n, 6))
    A = rng.normal(size=(n, 6, 6))
    known = 0.1 * A @ np.swapaxes(A, 1, 2) + 0.01 * np.eye(6)
    B = rng.normal(size=(k, n, 6, 2))
    blocks = B @ np.swapaxes(B, 2, 3)
    theta = np.array([0.3, 1.2, 0.05])
    f, g = reml_negll(theta, J, r, known, blocks, grad=True)
    assert f == pytest.approx(_dense_negll(J, r, known, blocks, theta), rel=1e-10)
    assert reml_negll(theta, J, r, known, blocks) == f
    h = 1e-6 * theta
    fd = [(reml_negll(theta + h[i] * e, J, r, known, blocks) - reml_negll(theta - h[i] * e, J, r, known, blocks))
          / (2 * h[i]) for i, e in enumerate(np.eye(k))]
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-6 * np.abs(g).max())
    grid = np.exp(rng.uniform(-6, 2, size=(40, k)))
    grid[7] = [-50.0, -50.0, -50.0]  # C = known - 50 (...): not positive definite
    many = reml_negll_many(grid, J, r, known, blocks)
    one = np.array([reml_negll(t, J, r, known, blocks) for t in grid])
    assert np.isinf(many[7]) and np.isinf(one[7])
    ok = np.isfinite(one)
    np.testing.assert_allclose(many[ok], one[ok], rtol=1e-12, atol=1e-12)


def test_reml_hessian_matches_differences_of_the_gradient_and_newton_finds_the_bounded_maximum():
    """reml_negll(hess=True) against central differences of its gradient; the REML search (projected Newton from the
    grid's best point) ends where a tight L-BFGS-B ends, and at the bound when a component pushes out of the box."""
    from scipy.optimize import minimize

    from vision_calib.identify.handeye_fit import THETA_BOUNDS
    from vision_calib.identify.reml import reml_max, reml_negll

    rng = np.random.default_rng(2)
    n, p = 30, 5
    J = rng.normal(size=(n, 6, p))
    Q = rng.normal(size=(n, 6, 6))
    known = 0.05 * Q @ np.swapaxes(Q, 1, 2) + 0.01 * np.eye(6)
    B = rng.normal(size=(2, n, 6, 3))
    blocks = B @ np.swapaxes(B, 2, 3)
    C = known + np.tensordot([0.3, 0.02], blocks, axes=1)
    r = (np.linalg.cholesky(C) @ rng.normal(size=(n, 6, 1)))[..., 0]
    theta = np.array([0.2, 0.05])
    _, _, H = reml_negll(theta, J, r, known, blocks, grad=True, hess=True)
    h = 1e-6 * theta
    Hd = np.array([(reml_negll(theta + h[i] * e, J, r, known, blocks, grad=True)[1]
                    - reml_negll(theta - h[i] * e, J, r, known, blocks, grad=True)[1]) / (2 * h[i])
                   for i, e in enumerate(np.eye(2))])
    np.testing.assert_allclose(H, Hd, rtol=1e-6, atol=1e-6 * np.abs(H).max())
    bounds = ((1e-3, 10.0), (1e-3, 10.0))
    lo, hi = np.log([b[0] ** 2 for b in bounds]), np.log([b[1] ** 2 for b in bounds])

    def fg(u):
        v, g = reml_negll(np.exp(u), J, r, known, blocks, grad=True)
        return v, g * np.exp(u)

    for start in (None, [1.0, 1e-3]):
        ours = reml_max(J, r, known, blocks, bounds, start)
        ref = minimize(fg, np.log(ours * 1.5), jac=True, method="L-BFGS-B", bounds=list(zip(lo, hi)),
                       options={"ftol": 1e-15, "gtol": 1e-12})
        assert reml_negll(ours, J, r, known, blocks) <= ref.fun + 1e-9
        np.testing.assert_allclose(ours, np.exp(ref.x), rtol=1e-4)
    # no information on the second component (its blocks ~0): the prior pushes it up to the box's top
    weak = reml_max(J, r, known, np.stack([blocks[0], 1e-12 * blocks[1]]), bounds)
    assert weak[1] == pytest.approx(bounds[1][1] ** 2)
    assert THETA_BOUNDS[0][0] > 0


def test_batched_newton_from_per_problem_starts_and_its_log_covariance():
    """reml_newton of K problems with one start per problem reaches each problem's own maximum (reml_max alone), and
    its log_cov is the inverse of the -log-likelihood's Hessian in log theta there (from reml_negll's Hessian and
    gradient: diag(theta) H diag(theta) + diag(theta g)), close to the expected information's covariance of log
    theta (reml_variance_cov / theta theta^T)."""
    from vision_calib.identify.reml import reml_max, reml_negll, reml_newton

    rng = np.random.default_rng(5)
    n, p, K = 40, 4, 3
    bounds = ((1e-3, 10.0), (1e-3, 10.0))
    Js, rs, knowns, blocks_k = [], [], [], []
    for k in range(K):
        J = rng.normal(size=(n, 6, p))
        Q = rng.normal(size=(n, 6, 6))
        known = 0.05 * Q @ np.swapaxes(Q, 1, 2) + 0.01 * np.eye(6)
        B = rng.normal(size=(2, n, 6, 3))
        blocks = B @ np.swapaxes(B, 2, 3)
        C = known + np.tensordot([0.3, 0.02 * (k + 1)], blocks, axes=1)
        Js.append(J)
        rs.append((np.linalg.cholesky(C) @ rng.normal(size=(n, 6, 1)))[..., 0])
        knowns.append(known)
        blocks_k.append(blocks)
    starts = np.array([[0.1, 0.1], [1.0, 1e-3], [0.3, 0.05]])
    th, ok, lc = reml_newton(np.stack(Js), np.stack(rs), np.stack(knowns), np.stack(blocks_k, axis=1), starts,
                             bounds, log_cov=True)
    assert ok.all()
    for k in range(K):
        alone = reml_max(Js[k], rs[k], knowns[k], blocks_k[k], bounds)
        np.testing.assert_allclose(th[k], alone, rtol=1e-5)
        _, g, H = reml_negll(th[k], Js[k], rs[k], knowns[k], blocks_k[k], grad=True, hess=True)
        Hu = th[k][:, None] * H * th[k][None, :] + np.diag(th[k] * g)
        np.testing.assert_allclose(lc[k], np.linalg.inv(Hu), rtol=1e-6)
        expected = reml_variance_cov(Js[k], knowns[k], blocks_k[k], th[k]) / np.outer(th[k], th[k])
        np.testing.assert_allclose(np.sqrt(np.diag(lc[k])), np.sqrt(np.diag(expected)), rtol=0.5)
