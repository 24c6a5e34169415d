"""Leave-one-out refits of a hand-eye fit, every subset at once (the deletion test of
``experiment.handeye_step``).

For a fit of N poses at x with the robot's variances theta, the fit without pose k (k = 1..N) is
(:func:`vision_calib.identify.handeye_fit.deletion_fit`, the same steps): the weights at x, Gauss-Newton from x to
the subset's minimum under them, the robot's variances re-estimated there (REML refined from theta, when they are
estimated), the weights at that point with those variances, and Gauss-Newton to the minimum under them, whose
normal matrix gives the covariance. Here the subsets' models, residuals and Jacobians are evaluated together
(``handeye_problem.model_many``: K parameter vectors x N poses in one array pass), and their Gauss-Newton steps
(:func:`gauss_newton_many`) and REML searches (:func:`reml_newton_many`) are batched. The answers are those of
``deletion_fit`` to rounding; a subset whose steps do not settle is reported as such and the caller refits it with
``deletion_fit``. numpy only.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .handeye_fit import GN_TOL_STD, THETA_BOUNDS
from .handeye_problem import model_many, robot_pose_cov
from .problem import IdentificationProblem, lower_triangular_inverse


def _whitening(cov: np.ndarray) -> np.ndarray:
    """Inverse Cholesky factors (..., 6, 6) of the symmetrised covariances cov (..., 6, 6)."""
    return lower_triangular_inverse(np.linalg.cholesky(0.5 * (cov + np.swapaxes(cov, -1, -2))))


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


def reml_terms_many(theta, J, r, known, blocks):
    """:func:`.handeye_fit.reml_negll` with its gradient and Hessian (hess=True) for K problems at once: theta (K, k),
    J (K, N, m, p), r (K, N, m), known (K, N, m, m), blocks (k, K, N, m, m) (a pose left out of problem j: zero J,
    r and blocks, identity known). Returns (f (K,), gradient (K, k), Hessian (K, k, k)); f inf where a covariance
    or the normal matrix is not positive definite."""
    theta = np.asarray(theta, float)
    K, N, m, p = J.shape
    k = theta.shape[1]
    C = known + np.einsum("ki,iknab->knab", theta, blocks)
    f = np.full(K, np.inf)
    g_out = np.zeros((K, k))
    H_out = np.tile(np.eye(k), (K, 1, 1))
    try:
        L = np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        ok = np.array([np.all(np.linalg.eigvalsh(c)[..., 0] > 0) for c in C])
        if not ok.any():
            return f, g_out, H_out
        f[ok], g_out[ok], H_out[ok] = reml_terms_many(theta[ok], J[ok], r[ok], known[ok], blocks[:, ok])
        return f, g_out, H_out
    Li = lower_triangular_inverse(L)
    Jw = Li @ J
    rw = (Li @ r[..., None])[..., 0]
    Jf, rf = Jw.reshape(K, N * m, p), rw.reshape(K, N * m)
    A = np.swapaxes(Jf, 1, 2) @ Jf
    g = (np.swapaxes(Jf, 1, 2) @ rf[..., None])[..., 0]
    try:
        cA = np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        ok = np.array([np.all(np.linalg.eigvalsh(a)[0] > 0) for a in A])
        if ok.any():
            f[ok], g_out[ok], H_out[ok] = reml_terms_many(theta[ok], J[ok], r[ok], known[ok], blocks[:, ok])
        return f, g_out, H_out
    Ai = np.linalg.inv(A)
    beta = (Ai @ g[..., None])[..., 0]
    e = rw - (Jw @ beta[:, None, :, None])[..., 0]  # whitened P r (K, N, m)
    rPr = np.sum(rf**2, axis=1) - np.sum(g * beta, axis=1)
    logC = 2.0 * np.sum(np.log(np.diagonal(L, axis1=2, axis2=3)), axis=(1, 2))
    logA = 2.0 * np.sum(np.log(np.diagonal(cA, axis1=1, axis2=2)), axis=1)
    th = np.maximum(theta, 1e-300)
    f = 0.5 * (logC + logA + rPr) - 0.5 * np.sum(np.log(th), axis=1)
    LV = Li[None] @ blocks @ np.swapaxes(Li, 2, 3)[None]  # (k, K, N, m, m)
    trWV = np.trace(LV, axis1=3, axis2=4).sum(axis=2).T  # (K, k)
    LVJ = (LV @ Jw[None]).reshape(k, K, N * m, p)  # whitened V_i W J, the poses' rows stacked
    JLV = np.swapaxes(Jf, 1, 2)[None] @ LVJ  # (k, K, p, p)
    trAH = np.einsum("kpq,ikqp->ki", Ai, JLV)
    u = (LV @ e[None, ..., None])[..., 0].reshape(k, K, N * m)  # whitened V_i P r
    ePe = np.einsum("kx,ikx->ki", e.reshape(K, N * m), u)
    grad = 0.5 * (trWV - trAH - ePe) - 0.5 / th
    b = (u[..., None, :] @ Jf[None])[..., 0, :]  # (k, K, p)
    LVf = LV.reshape(k, K, N * m * m)
    tWW = np.einsum("ikx,jkx->kij", LVf, LVf)
    Z = (LVJ @ Ai[None]).reshape(k, K, -1)
    trAG = np.einsum("ikx,jkx->kij", Z, LVJ.reshape(k, K, -1))
    AH = Ai[None] @ JLV  # (k, K, p, p)
    trHH = np.einsum("ikpq,jkqp->kij", AH, AH)
    bAb = np.einsum("ikp,kpq,jkq->kij", b, Ai, b)
    H = np.einsum("ikx,jkx->kij", u, u) - bAb - 0.5 * (tWW - 2.0 * trAG + trHH)
    H = H + np.eye(k)[None] * (0.5 / th**2)[:, None, :]
    return f, grad, 0.5 * (H + np.swapaxes(H, 1, 2))


def reml_newton_many(J, r, known, blocks, theta0, bounds, max_iter: int = 40):
    """The REML variances of K problems (:func:`reml_terms_many`' arguments) from theta0 (k,), by the projected
    Newton search of :func:`.handeye_fit.reml_max` (from a start: no grid), batched: in log theta over the box
    ``bounds`` ((lo, hi) std per component), the components at a bound with the gradient pointing out held there,
    the Hessian's eigenvalues raised to 1e-8 of the largest, a backtracking (Armijo) line search per problem.
    Returns (theta (K, k), settled (K,) bool: False where the search did not settle, to be redone alone)."""
    from .handeye_fit import REML_NEWTON_TOL

    K = J.shape[0]
    lo = np.log([b[0] ** 2 for b in bounds])
    hi = np.log([b[1] ** 2 for b in bounds])

    def fgh(u, sel):
        th = np.exp(u)
        v, g, H = reml_terms_many(th, J[sel], r[sel], known[sel], blocks[:, sel])
        return v, th * g, th[:, :, None] * H * th[:, None, :] + th[:, :, None] * np.eye(len(lo))[None] * g[:, None, :]

    u = np.tile(np.clip(np.log(np.maximum(np.asarray(theta0, float), 1e-300)), lo, hi), (K, 1))
    f, g, H = fgh(u, np.arange(K))
    active = np.isfinite(f)
    settled = np.zeros(K, bool)
    for _ in range(max_iter):
        idx = np.flatnonzero(active)
        if not idx.size:
            break
        ua, ga, Ha = u[idx], g[idx], H[idx]
        free = ~(((ua <= lo) & (ga > 0)) | ((ua >= hi) & (ga < 0)))
        Hm = np.where(free[:, :, None] & free[:, None, :], Ha, np.eye(len(lo))[None])
        gm = np.where(free, ga, 0.0)
        lam, V = np.linalg.eigh(Hm)
        lam = np.abs(lam)
        lam = np.maximum(lam, 1e-8 * np.maximum(lam.max(axis=1, keepdims=True), 1e-300))
        d = -(V @ ((np.swapaxes(V, 1, 2) @ gm[..., None])[..., 0] / lam)[..., None])[..., 0]
        d = np.where(free, d, 0.0)
        dec = -np.sum(ga * d, axis=1)
        done = dec < 2 * REML_NEWTON_TOL
        settled[idx[done]] = True
        active[idx[done]] = False
        idx, d, dec = idx[~done], d[~done], dec[~done]
        t = np.ones(len(idx))
        search = np.ones(len(idx), bool)
        for _ in range(40):
            if not search.any():
                break
            s = np.flatnonzero(search)
            un = np.clip(u[idx[s]] + t[s, None] * d[s], lo, hi)
            fn, gn, Hn = fgh(un, idx[s])
            acc = np.isfinite(fn) & (fn <= f[idx[s]] - 1e-4 * t[s] * dec[s])
            a = idx[s][acc]
            u[a], f[a], g[a], H[a] = un[acc], fn[acc], gn[acc], Hn[acc]
            search[s[acc]] = False
            t[s[~acc]] *= 0.5
        stuck = idx[search]  # no decrease found: settled to rounding when the decrease left was tiny, else not
        tiny = dec[search] < 1e-6
        settled[stuck[tiny]] = True
        active[stuck] = False
    return np.exp(u), settled


#: the subsets are fitted in chunks of at most this many (subset, pose) pairs (memory: ~1 kB per pair)
LOO_CHUNK = 4096


def leave_one_out(problem: IdentificationProblem, x: ArrayLike, theta: ArrayLike, estimate: bool):
    """The N fits without one pose each (module docstring) of ``problem`` (a hand-eye problem of N poses, camera
    covariance in ``meta["camera_cov"]``, all 12 parameters free) from its fit x (12,) with the robot's variances
    theta (2,) (m^2, rad^2); ``estimate``: re-estimate them per subset. Subsets in chunks of :data:`LOO_CHUNK`
    (subset, pose) pairs. Returns (X (N, 12), covariance (N, 12, 12), theta (N, 2), settled (N,) bool: where False,
    the caller refits that subset with ``handeye_fit.deletion_fit``)."""
    x = np.asarray(x, float)
    theta = np.asarray(theta, float)
    cam = np.asarray(problem.meta["camera_cov"], float)
    N = cam.shape[0]
    _, _, D0 = model_many(problem, x[None])
    R0 = robot_pose_cov(np.sqrt(max(theta[0], 0.0)), np.sqrt(max(theta[1], 0.0)))
    W0 = _whitening(cam + D0[0] @ R0 @ np.swapaxes(D0[0], 1, 2))[None]  # the weights at x, shared
    X, cov = np.tile(x, (N, 1)), np.full((N, 12, 12), np.nan)
    thetas, settled = np.tile(theta, (N, 1)), np.zeros(N, bool)
    step = max(1, LOO_CHUNK // N)
    for a in range(0, N, step):
        ks = np.arange(a, min(a + step, N))
        mask = np.arange(N)[None, :] != ks[:, None]  # (K, N): the poses of each subset
        Xk, ck, ok = gauss_newton_many(problem, X[ks], W0, mask)
        if estimate:
            r, J, D = model_many(problem, Xk)
            w = mask[..., None].astype(float)
            Dm = D * w[..., None]  # the left-out pose: no residual, Jacobian or robot blocks, identity camera part
            known = np.where(mask[..., None, None], cam[None], np.eye(6))
            blocks = np.stack([Dm[..., :3] @ np.swapaxes(Dm[..., :3], 2, 3),
                               Dm[..., 3:] @ np.swapaxes(Dm[..., 3:], 2, 3)])
            th, ok2 = reml_newton_many(J * w[..., None], r * w, known, blocks, theta, THETA_BOUNDS)
            thetas[ks] = np.where(ok2[:, None], th, theta)
            C = known + np.einsum("ki,iknab->knab", thetas[ks], blocks)  # camera + robot part at each point
            Xk, ck, ok3 = gauss_newton_many(problem, Xk, _whitening(C), mask)
            ok = ok & ok2 & ok3
        X[ks], cov[ks], settled[ks] = Xk, ck, ok
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
    th = np.asarray(thetas, float)
    R = np.zeros((K, 6, 6))
    R[:, [0, 1, 2], [0, 1, 2]] = th[:, :1]
    R[:, [3, 4, 5], [3, 4, 5]] = th[:, 1:2]
    C = np.asarray(problem.meta["camera_cov"], float)[ks] + D @ R @ np.swapaxes(D, 1, 2)
    S = 0.5 * (C + np.swapaxes(C, 1, 2)) + J @ np.asarray(cov, float) @ np.swapaxes(J, 1, 2)
    d = np.full(K, np.inf)
    for k in range(K):
        try:
            d[k] = float(r[k] @ np.linalg.solve(S[k], r[k]))
        except np.linalg.LinAlgError:
            pass
    return d


__all__ = ["gauss_newton_many", "reml_terms_many", "reml_newton_many", "leave_one_out",
           "deletion_statistics"]
