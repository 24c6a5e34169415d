"""Refits of a hand-eye fit on subsets of its poses, every subset at once: the leave-one-out fits of the deletion
test (``experiment.handeye_step``) and the training sets of the held-out folds (``experiment.poses.pair_holdout``).

For a fit of N poses at x with the robot's variances theta, the fit without pose k (k = 1..N) is
(:func:`vision_calib.identify.handeye_fit.deletion_fit`, the same steps): the weights at x, Gauss-Newton from x to
the subset's minimum under them, the robot's variances re-estimated there (REML refined from theta, when they are
estimated), the weights at that point with those variances, and Gauss-Newton to the minimum under them, whose
normal matrix gives the covariance. Here the subsets' models, residuals and Jacobians are evaluated together
(``handeye_problem.model_many``: K parameter vectors x N poses in one array pass), and their Gauss-Newton steps
(:func:`gauss_newton_many`) and REML searches (``reml.reml_newton``) are batched. The answers are those of
``deletion_fit`` to rounding; a subset whose steps do not settle is reported as such and the caller refits it with
``deletion_fit``.

A held-out fold's training set is fitted by :func:`subset_fits`: the iteration of ``handeye_fit.fit_handeye`` (the
minimum under the weights, the variances re-estimated, reweighting, until the point and the variances stop moving),
started from the fit of all the poses instead of a closed form, every fold at once. numpy only.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .handeye_fit import GN_TOL_STD, THETA_BOUNDS, THETA_TOL_STD, X_TOL_STD
from .handeye_problem import model_many, robot_blocks, robot_weighted_cov
from .reml import reml_newton
from .problem import IdentificationProblem, whitening_of


def gauss_newton_many(problem: IdentificationProblem, X: ArrayLike, W: np.ndarray, mask: np.ndarray,
                      max_iter: int = 8):
    """Each row k of X (K, 12) moved to the minimum of the weighted cost of the poses ``mask[k]`` (K, N) bool with
    the whitening W (K or 1, N, 6, 6), by undamped Gauss-Newton steps (those of
    :func:`.handeye_fit.gauss_newton_refit`, batched). Returns (X (K, 12), covariance (K, 12, 12) at the last
    step, settled (K,) bool: False where a step was singular, raised the cost, or the steps did not settle)."""
    X = np.array(X, float)
    K = X.shape[0]
    w = mask[..., None].astype(float)  # the left-out pose contributes nothing
    cost = np.full(K, np.inf)
    active = np.ones(K, bool)
    settled = np.zeros(K, bool)
    cov = np.full((K, 12, 12), np.nan)
    for _ in range(max_iter):
        if not active.any():
            break
        idx = np.flatnonzero(active)
        r, J, _ = model_many(problem, X[idx], flange_map=False)
        Wa = W[idx] if W.shape[0] == K else W
        rw = (Wa @ r[..., None])[..., 0] * w[idx]
        c = np.einsum("kni,kni->k", rw, rw)
        bad = ~np.isfinite(c) | (c > cost[idx] * (1 + 1e-12) + 1e-300)
        cost[idx] = c
        Jw = ((Wa @ J) * w[idx][..., None]).reshape(len(idx), -1, 12)
        Aw = np.swapaxes(Jw, 1, 2) @ Jw
        g = (np.swapaxes(Jw, 1, 2) @ rw.reshape(len(idx), -1, 1))[..., 0]
        good = ~bad & np.all(np.isfinite(Aw), axis=(1, 2))
        Li = np.full_like(Aw, np.nan)
        if good.any():
            try:
                Li[good] = np.linalg.inv(np.linalg.cholesky(Aw[good]))
            except np.linalg.LinAlgError:  # one subset singular: factor them one by one
                for j in np.flatnonzero(good):
                    try:
                        Li[j] = np.linalg.inv(np.linalg.cholesky(Aw[j]))
                    except np.linalg.LinAlgError:
                        good[j] = False
        dx = -(np.swapaxes(Li, 1, 2) @ (Li @ g[..., None]))[..., 0]
        std = np.sqrt(np.sum(Li**2, axis=1))
        fail = idx[~good]
        active[fail] = False
        ok = idx[good]
        X[ok] += dx[good]
        done = good & np.all(np.abs(dx) <= GN_TOL_STD * std, axis=1)
        settled[idx[done]] = True
        active[idx[done]] = False
        cov[idx[done]] = np.swapaxes(Li[done], 1, 2) @ Li[done]
    return X, cov, settled


#: the subsets are fitted in chunks of at most this many (subset, pose) pairs (memory: ~1 kB per pair)
LOO_CHUNK = 4096


def leave_one_out(problem: IdentificationProblem, x: ArrayLike, theta: ArrayLike, estimate: bool,
                  which: ArrayLike | None = None):
    """The N fits without one pose each (module docstring) of ``problem`` (a hand-eye problem of N poses, camera
    covariance in ``meta["camera_cov"]``, all 12 parameters free) from its fit x (12,) with the robot's variances
    theta (2,) (m^2, rad^2); ``estimate``: re-estimate them per subset. Subsets in chunks of :data:`LOO_CHUNK`
    (subset, pose) pairs. which: the poses whose fits are made (default all; the other rows stay x, NaN, theta,
    False). Returns (X (N, 12), covariance (N, 12, 12), theta (N, 2), settled (N,) bool: where False, the caller
    refits that subset with ``handeye_fit.deletion_fit``)."""
    x = np.asarray(x, float)
    theta = np.asarray(theta, float)
    cam = np.asarray(problem.meta["camera_cov"], float)
    N = cam.shape[0]
    W0 = subset_weights(problem, x[None], theta[None])  # the weights at x, shared
    X, cov = np.tile(x, (N, 1)), np.full((N, 12, 12), np.nan)
    thetas, settled = np.tile(theta, (N, 1)), np.zeros(N, bool)
    which = np.arange(N) if which is None else np.asarray(which, int).reshape(-1)
    step = max(1, LOO_CHUNK // N)
    for a in range(0, which.size, step):
        ks = which[a:a + step]
        mask = np.arange(N)[None, :] != ks[:, None]  # (K, N): the poses of each subset
        Xk, ck, ok = gauss_newton_many(problem, X[ks], W0, mask)
        if estimate:
            r, J, D = model_many(problem, Xk)
            w = mask[..., None].astype(float)
            known, blocks = _subset_terms(cam, D, mask)
            th, ok2 = reml_newton(J * w[..., None], r * w, known, blocks, theta, THETA_BOUNDS)
            thetas[ks] = np.where(ok2[:, None], th, theta)
            C = known + np.einsum("ki,iknab->knab", thetas[ks], blocks)  # camera + robot part at each point
            Xk, ck, ok3 = gauss_newton_many(problem, Xk, whitening_of(C), mask)
            ok = ok & ok2 & ok3
        X[ks], cov[ks], settled[ks] = Xk, ck, ok
    return X, cov, thetas, settled


def linearized_deletion(problem: IdentificationProblem, x: ArrayLike, theta: ArrayLike):
    """The N fits without one pose each of ``problem`` (as :func:`leave_one_out`) in closed form for the model
    linearised at its fit x (12,), with the weights at x and the robot's variances theta (2,) of all the poses
    (not re-estimated): with A_n = W_n J_n and e_n = W_n r_n whitened, N = sum A_n^T A_n and H_k = A_k N^-1 A_k^T,
    the fit without k is x + N^-1 A_k^T (I - H_k)^-1 e_k, its covariance (N - A_k^T A_k)^-1 = N^-1 + N^-1 A_k^T
    (I - H_k)^-1 A_k N^-1, and pose k's deletion statistic e_k^T (I - H_k)^-1 e_k (Cook and Weisberg's
    externally studentised residual, per 6-vector pose): O(N) time, exact for a linear model with fixed weights.
    Returns (X (N, 12), covariance (N, 12, 12), d (N,); inf where I - H_k is singular)."""
    x = np.asarray(x, float)
    r, J, D = model_many(problem, x[None])
    W = subset_weights(problem, x[None], np.asarray(theta, float)[None], D)[0]
    A = W @ J[0]  # (N, 6, 12)
    e = (W @ r[0][..., None])[..., 0]
    Ninv = np.linalg.inv(np.einsum("nai,naj->ij", A, A))
    NA = A @ Ninv  # (N, 6, 12): A_k N^-1
    IH = np.eye(6)[None] - NA @ np.swapaxes(A, 1, 2)
    n = e.shape[0]
    d, X, cov = np.full(n, np.inf), np.tile(x, (n, 1)), np.full((n, 12, 12), np.nan)
    ok = np.all(np.isfinite(IH), axis=(1, 2))
    try:
        s = np.linalg.solve(IH[ok], e[ok][..., None])[..., 0]  # (I - H_k)^-1 e_k
        T = np.linalg.solve(IH[ok], NA[ok])  # (I - H_k)^-1 A_k N^-1
    except np.linalg.LinAlgError:  # a pose that alone determines a direction: its rows one by one
        s, T = np.full((int(ok.sum()), 6), np.nan), np.full((int(ok.sum()), 6, 12), np.nan)
        for j, k in enumerate(np.flatnonzero(ok)):
            try:
                s[j], T[j] = np.linalg.solve(IH[k], e[k]), np.linalg.solve(IH[k], NA[k])
            except np.linalg.LinAlgError:
                pass
    fine = np.all(np.isfinite(s), axis=1)
    k = np.flatnonzero(ok)[fine]
    d[k] = np.einsum("na,na->n", e[k], s[fine])
    X[k] = x + np.einsum("nai,na->ni", NA[k], s[fine])
    cov[k] = Ninv[None] + np.swapaxes(NA[k], 1, 2) @ T[fine]
    return X, cov, d


def subset_weights(problem: IdentificationProblem, X: ArrayLike, thetas: ArrayLike,
                   D: np.ndarray | None = None) -> np.ndarray:
    """W (K, N, 6, 6): the whitening of every pose's camera covariance plus the robot's pose error at each row of X
    (K, 12) with the variances thetas (K, 2) (m^2, rad^2): the weights of ``handeye_problem.reweighted``. D: the
    flange error maps (K, N, 6, 6) at X when the caller has them (else a model pass here)."""
    if D is None:
        _, _, D = model_many(problem, X, jacobian=False)
    cam = np.asarray(problem.meta["camera_cov"], float)[None]
    return whitening_of(robot_weighted_cov(cam, D, _robot_covs(thetas)[:, None]))


def _robot_covs(thetas: ArrayLike) -> np.ndarray:
    """(K, 6, 6) diag(s_t^2 I3, s_r^2 I3) of each row of thetas (K, 2): ``handeye_problem.robot_pose_cov``, batched."""
    th = np.asarray(thetas, float)
    R = np.zeros((th.shape[0], 6, 6))
    R[:, [0, 1, 2], [0, 1, 2]] = th[:, :1]
    R[:, [3, 4, 5], [3, 4, 5]] = th[:, 1:2]
    return R


def _subset_terms(cam: np.ndarray, D: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(known (K, N, 6, 6), blocks (2, K, N, 6, 6)) of the REML terms (``reml.reml_terms``) of the pose subsets
    ``mask`` (K, N) with the flange error maps D (K, N, 6, 6): a pose out of a subset has no robot blocks and an
    identity camera part (it contributes nothing)."""
    known = np.where(mask[..., None, None], cam[None], np.eye(6))
    return known, np.stack(robot_blocks(D * mask[..., None, None]))


def subset_fits(problem: IdentificationProblem, x: ArrayLike, theta: ArrayLike, estimate: bool, mask: ArrayLike,
                max_iter: int = 50):
    """The fits of the pose subsets ``mask`` (K, N) bool of ``problem`` (a hand-eye problem of N poses, camera
    covariance in ``meta["camera_cov"]``, all 12 parameters free) from its fit x (12,) with the robot's variances
    theta (2,) (m^2, rad^2), each by the iteration of ``handeye_fit.fit_handeye``: the minimum under the weights at
    x (Gauss-Newton), then, until no parameter moves by more than ``X_TOL_STD`` of its std and no variance by more
    than ``THETA_TOL_STD`` of its std (in log theta, observed information): the variances re-estimated there (REML
    refined from the last ones, when ``estimate``), the weights at the point with them, the minimum under those.
    Returns (X (K, 12), covariance (K, 12, 12) of the last minimum, theta (K, 2), settled (K,) bool: False where a
    step failed or the iteration did not settle within ``max_iter``: the caller fits that subset alone)."""
    x = np.asarray(x, float)
    theta = np.asarray(theta, float)
    mask = np.asarray(mask, bool)
    K = mask.shape[0]
    cam = np.asarray(problem.meta["camera_cov"], float)
    w = mask[..., None].astype(float)
    X, cov, active = gauss_newton_many(problem, np.tile(x, (K, 1)), subset_weights(problem, x[None], theta[None]),
                                       mask)
    thetas, settled = np.tile(theta, (K, 1)), np.zeros(K, bool)
    for _ in range(max_iter):
        idx = np.flatnonzero(active)
        if not idx.size:
            break
        r, J, D = model_many(problem, X[idx])
        known, blocks = _subset_terms(cam, D, mask[idx])
        if estimate:
            th, ok, lc = reml_newton(J * w[idx][..., None], r * w[idx], known, blocks, thetas[idx], THETA_BOUNDS,
                                     log_cov=True)
            du = np.abs(np.log(th) - np.log(thetas[idx]))
            su = np.sqrt(np.clip(np.diagonal(lc, axis1=1, axis2=2), 0, None))
            dt = np.where(du > 0, du / np.where(su > 0, su, 1e-300), 0.0)
        else:
            th, ok, dt = thetas[idx], np.ones(idx.size, bool), np.zeros((idx.size, 2))
        C = known + np.einsum("ki,iknab->knab", th, blocks)
        Xn, cn, ok2 = gauss_newton_many(problem, X[idx], whitening_of(C), mask[idx])
        std = np.sqrt(np.clip(np.diagonal(cn, axis1=1, axis2=2), 0, None))
        dx = np.abs(Xn - X[idx]) / np.where(std > 0, std, 1e-300)
        good = ok & ok2
        X[idx], cov[idx], thetas[idx] = Xn, cn, th
        done = good & np.all(dx < X_TOL_STD, axis=1) & np.all(dt < THETA_TOL_STD, axis=1)
        settled[idx[done]] = True
        active[idx[done | ~good]] = False
    return X, cov, thetas, settled


def deletion_statistics(problem: IdentificationProblem, X: ArrayLike, cov: ArrayLike, thetas: ArrayLike) -> np.ndarray:
    """d (K,): for each subset k (X[k] (12,), its covariance cov[k] (12, 12), robot variances thetas[k] (2,)), pose
    k's ``r^T (C + J cov J^T)^-1 r`` at X[k], C its camera covariance plus the robot's pose error there (the
    deletion statistic of ``experiment.handeye_step.pose_statistic``); inf where that matrix is singular."""
    X = np.asarray(X, float)
    K = X.shape[0]
    ks = np.arange(K)
    r, J, D = model_many(problem, X, poses=ks)
    r, J, D = r[:, 0], J[:, 0], D[:, 0]
    C = robot_weighted_cov(np.asarray(problem.meta["camera_cov"], float)[ks], D, _robot_covs(thetas))
    S = 0.5 * (C + np.swapaxes(C, 1, 2)) + J @ np.asarray(cov, float) @ np.swapaxes(J, 1, 2)
    d = np.full(K, np.inf)
    for k in range(K):
        try:
            d[k] = float(r[k] @ np.linalg.solve(S[k], r[k]))
        except np.linalg.LinAlgError:
            pass
    return d


__all__ = ["gauss_newton_many", "leave_one_out", "linearized_deletion", "subset_weights", "subset_fits",
           "deletion_statistics"]
