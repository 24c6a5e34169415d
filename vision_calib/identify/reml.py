"""Variance components by penalised REML, for one linearised model or many at once.

A model linearised at x: residuals r (N, m) with Jacobian J (N, m, p), each pose's covariance
``C_n = known_n + sum_i theta_i V_in`` (k unknown variances theta, blocks V_i). :func:`reml_terms` gives the
penalised REML -log-likelihood ``0.5 (log|C| + log|J^T C^-1 J| + r^T P r) - 0.5 sum_i log theta_i`` (P = W - W J
(J^T W J)^-1 J^T W, W = C^-1), its gradient and Hessian in theta, for K problems (or K values of theta) in one
array pass; the last term is the boundary-avoiding prior of Chung et al. (2013, Psychometrika 78: a Gamma(2,
rate -> 0) density on each std, ``log s_i``): it vanishes against the likelihood where the data resolve a
component and keeps its estimate off 0 (about one standard error above it) where they do not.
:func:`reml_max` maximises it over a box of std (a log grid unless a start is given, then the projected Newton
search :func:`newton_in_box`, L-BFGS-B where that does not settle); :func:`reml_newton` runs that search for K
problems at once (the hand-eye deletion test, :mod:`.handeye_loo`); :func:`reml_variance_cov` is the inverse
Fisher information at the maximum. Used by :mod:`.handeye_fit` (the robot's pose-error variances, the measured
poses' per-axis noise). numpy / scipy only.
"""

from __future__ import annotations

import numpy as np

from .problem import lower_triangular_inverse

#: the grid of :func:`reml_max` is evaluated in chunks of at most this many (grid point, pose) pairs
REML_GRID_CHUNK = 1 << 15
#: the Newton search has settled when half its Newton decrement (the predicted decrease of the -log-likelihood) is
#: below this
REML_NEWTON_TOL = 1e-10


def _rows(a: np.ndarray, sel, axis: int = 0) -> np.ndarray:
    """a's rows ``sel`` along ``axis``, or a itself when that axis has length 1 (shared by every problem)."""
    return a if a.shape[axis] == 1 else np.take(a, sel, axis=axis)


def reml_terms(theta, J, r, known, blocks, grad: bool = False, hess: bool = False):
    """The penalised REML -log-likelihood (module docstring) of K problems: theta (K, k); J (K or 1, N, m, p),
    r (K or 1, N, m), known (K or 1, N, m, m), blocks (k, K or 1, N, m, m) (a length-1 axis is shared by all K,
    e.g. one problem at K values of theta; a pose left out of problem j: zero J, r and blocks, identity known).
    Returns f (K,), with ``grad`` also the gradient (K, k) in theta, ``0.5 (tr(P V_i) - (P r)^T V_i (P r)) - 0.5 /
    theta_i`` with ``tr(P V_i) = tr(W V_i) - tr(A^-1 J^T W V_i W J)``, A = J^T W J, and with ``hess`` the Hessian
    (K, k, k) ``(P r)^T V_i P V_j (P r) - 0.5 tr(P V_i P V_j) + 0.5 delta_ij / theta_i^2``: O(N) sums over the
    poses, never the (N m)^2 matrix P. f inf (gradient 0, Hessian I) where C or A is not positive definite."""
    theta = np.asarray(theta, float)
    K, k = theta.shape
    f, g_out, H_out = np.full(K, np.inf), np.zeros((K, k)), np.tile(np.eye(k), (K, 1, 1))

    def out():
        return (f,) + ((g_out,) if grad else ()) + ((H_out,) if grad and hess else ())

    def by_rows(ok):  # some problems not positive definite: the others alone
        if ok.any():
            sub = reml_terms(theta[ok], _rows(J, ok), _rows(r, ok), _rows(known, ok), _rows(blocks, ok, 1), grad,
                             hess)
            f[ok] = sub[0]
            if grad:
                g_out[ok] = sub[1]
            if grad and hess:
                H_out[ok] = sub[2]
        return out()

    C = known + np.sum(theta.T[:, :, None, None, None] * blocks, axis=0)  # (K, N, m, m)
    try:
        L = np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        if K == 1:
            return out()
        return by_rows(np.array([np.all(np.linalg.eigvalsh(0.5 * (c + np.swapaxes(c, 1, 2)))[:, 0] > 0) for c in C]))
    Li = lower_triangular_inverse(L)
    Jw = Li @ J
    rw = (Li @ r[..., None])[..., 0]
    N, m, p = Jw.shape[1:]
    Jf, rf = Jw.reshape(K, N * m, p), rw.reshape(K, N * m)
    A = np.swapaxes(Jf, 1, 2) @ Jf
    g = (np.swapaxes(Jf, 1, 2) @ rf[..., None])[..., 0]
    try:
        cA = np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        if K == 1:
            return out()
        return by_rows(np.array([np.all(np.linalg.eigvalsh(0.5 * (a + a.T)) > 0) for a in A]))
    Ai = np.linalg.inv(A)
    beta = (Ai @ g[..., None])[..., 0]
    th = np.maximum(theta, 1e-300)
    f[:] = 0.5 * (2.0 * np.sum(np.log(np.diagonal(L, axis1=2, axis2=3)), axis=(1, 2))
                  + 2.0 * np.sum(np.log(np.diagonal(cA, axis1=1, axis2=2)), axis=1)
                  + np.sum(rf**2, axis=1) - np.sum(g * beta, axis=1)) - 0.5 * np.sum(np.log(th), axis=1)
    if not grad:
        return out()
    e = (rw - (Jw @ beta[:, None, :, None])[..., 0]).reshape(K, N * m)  # whitened P r
    LV = Li[None] @ blocks @ np.swapaxes(Li, 2, 3)[None]  # (k, K, N, m, m): L^-1 V_i L^-T
    LVJ = (LV @ Jw[None]).reshape(k, K, N * m, p)  # whitened V_i W J, the poses' rows stacked
    JLV = np.swapaxes(Jf, 1, 2)[None] @ LVJ  # (k, K, p, p): J^T W V_i W J
    u = (LV @ e.reshape(K, N, m)[None, ..., None])[..., 0].reshape(k, K, N * m)  # whitened V_i P r
    trWV = np.trace(LV, axis1=3, axis2=4).sum(axis=2).T  # (K, k)
    g_out[:] = 0.5 * (trWV - np.einsum("kpq,ikqp->ki", Ai, JLV) - np.einsum("kx,ikx->ki", e, u)) - 0.5 / th
    if not hess:
        return out()
    b = (u[..., None, :] @ Jf[None])[..., 0, :]  # (k, K, p)
    LVf = LV.reshape(k, K, N * m * m)
    tWW = np.einsum("ikx,jkx->kij", LVf, LVf)  # sum_n tr(W V_i W V_j) (LV symmetric)
    # tr(A^-1 G_ij), G_ij = sum_n J^T W V_i W V_j W J: the rows of (W V_i W J) A^-1 against those of W V_j W J
    trAG = np.einsum("ikx,jkx->kij", (LVJ @ Ai[None]).reshape(k, K, -1), LVJ.reshape(k, K, -1))
    AH = Ai[None] @ JLV  # (k, K, p, p)
    T = tWW - 2.0 * trAG + np.einsum("ikpq,jkqp->kij", AH, AH)  # tr(P V_i P V_j)
    H = np.einsum("ikx,jkx->kij", u, u) - np.einsum("ikp,kpq,jkq->kij", b, Ai, b) - 0.5 * T
    H = H + np.eye(k)[None] * (0.5 / th**2)[:, None, :]
    H_out[:] = 0.5 * (H + np.swapaxes(H, 1, 2))
    return out()


def reml_negll(theta, J, r, known, blocks, grad: bool = False, hess: bool = False):
    """:func:`reml_terms` of one problem: theta (k,), J (N, m, p), r (N, m), known (N, m, m), blocks (k, N, m, m).
    Returns the value, with ``grad`` (value, gradient (k,)), with ``hess`` also the Hessian (k, k)."""
    out = reml_terms(np.asarray(theta, float)[None], J[None], r[None], known[None], blocks[:, None], grad, hess)
    vals = tuple(o[0] for o in out)
    return float(vals[0]) if not grad else (float(vals[0]),) + vals[1:]


def reml_negll_many(thetas, J, r, known, blocks) -> np.ndarray:
    """:func:`reml_negll` (values only) of one problem at each row of thetas (G, k), in chunks of
    :data:`REML_GRID_CHUNK` (row, pose) pairs."""
    thetas = np.atleast_2d(np.asarray(thetas, float))
    step = max(1, REML_GRID_CHUNK // max(J.shape[0], 1))
    return np.concatenate([reml_terms(thetas[s:s + step], J[None], r[None], known[None], blocks[:, None])[0]
                           for s in range(0, len(thetas), step)]) if len(thetas) else np.zeros(0)


def newton_in_box(fgh, u0, lo, hi, max_iter: int = 40, hessian: bool = False):
    """u (K, k) minimising K functions over the box [lo, hi] (k,) from u0 (K, k): projected Newton steps (the
    components at a bound with the gradient pointing out held there) with a backtracking (Armijo) line search per
    problem, the Hessian made positive definite by raising its eigenvalues to 1e-8 of the largest. fgh(u (K', k),
    rows (K',)) -> (f (K',), gradient (K', k), Hessian (K', k, k)) of the problems ``rows``. Returns (u, settled
    (K,) bool: False where the search did not settle, the caller's fallback), and with ``hessian`` the Hessian
    (K, k, k) at u."""
    u = np.clip(np.array(u0, float), lo, hi)
    K, k = u.shape
    f, g, H = fgh(u, np.arange(K))
    active = np.isfinite(f)
    settled = np.zeros(K, bool)
    for _ in range(max_iter):
        idx = np.flatnonzero(active)
        if not idx.size:
            break
        ua, ga = u[idx], g[idx]
        free = ~(((ua <= lo) & (ga > 0)) | ((ua >= hi) & (ga < 0)))
        Hm = np.where(free[:, :, None] & free[:, None, :], H[idx], 0.0)  # the free components' block
        lam, V = np.linalg.eigh(Hm)
        lam = np.maximum(np.abs(lam), 1e-8 * np.maximum(np.abs(lam).max(axis=1, keepdims=True), 1e-300))
        d = -(V @ ((np.swapaxes(V, 1, 2) @ np.where(free, ga, 0.0)[..., None])[..., 0] / lam)[..., None])[..., 0]
        d = np.where(free, d, 0.0)
        dec = -np.sum(ga * d, axis=1)  # the Newton decrement squared
        done = dec < 2 * REML_NEWTON_TOL
        settled[idx[done]] = True
        active[idx[done]] = False
        idx, d, dec = idx[~done], d[~done], dec[~done]
        t, search = np.ones(len(idx)), np.ones(len(idx), bool)
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
        settled[stuck[dec[search] < 1e-6]] = True
        active[stuck] = False
    return (u, settled, H) if hessian else (u, settled)


def _log_terms(J, r, known, blocks):
    """fgh(u, rows) of :func:`newton_in_box` for :func:`reml_terms` in u = log theta: g_u = theta g, H_u =
    diag(theta) H diag(theta) + diag(theta g)."""
    def fgh(u, rows):
        th = np.exp(u)
        v, g, H = reml_terms(th, _rows(J, rows), _rows(r, rows), _rows(known, rows), _rows(blocks, rows, 1),
                             grad=True, hess=True)
        return v, th * g, th[:, :, None] * H * th[:, None, :] + np.eye(th.shape[1])[None] * (th * g)[:, None, :]
    return fgh


def _log_box(bounds) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) in log theta of ``bounds`` ((lo, hi) std per component)."""
    return np.log([b[0] ** 2 for b in bounds]), np.log([b[1] ** 2 for b in bounds])


def reml_newton(J, r, known, blocks, theta0, bounds, max_iter: int = 40, log_cov: bool = False):
    """The variances maximising :func:`reml_terms` for K problems (its arguments) over the box ``bounds`` ((lo, hi)
    std per component), by :func:`newton_in_box` in log theta from theta0 (k,) (every problem) or (K, k) (no grid).
    Returns (theta (K, k), settled (K,) bool: False where the search did not settle, to be redone alone), and with
    ``log_cov`` the inverse Hessian (K, k, k) of the -log-likelihood in log theta there (the covariance of
    log theta, observed information; pseudo-inverse)."""
    lo, hi = _log_box(bounds)
    K = max(J.shape[0], r.shape[0], known.shape[0], blocks.shape[1])
    u0 = np.clip(np.log(np.maximum(np.asarray(theta0, float), 1e-300)), lo, hi)
    u0 = np.array(np.broadcast_to(u0, (K, u0.shape[-1])))
    out = newton_in_box(_log_terms(J, r, known, blocks), u0, lo, hi, max_iter, hessian=log_cov)
    return (np.exp(out[0]), out[1], np.linalg.pinv(out[2], hermitian=True)) if log_cov else (np.exp(out[0]), out[1])


def reml_max(J, r, known, blocks, bounds, start=None, grid_axes=None):
    """theta (k,): the variances maximising :func:`reml_negll` of one problem (J (N, m, p), r (N, m), known (N, m,
    m), blocks (k, N, m, m)) over the box ``bounds`` ((lo, hi) std per component, squared here), searched in log
    theta from the best point of a log grid (17 points per axis) over the components ``grid_axes`` (default: all
    when no ``start``, none with one), the other components at ``start`` (k,) or at the geometric middle of their
    bounds; then :func:`newton_in_box` (the bounded quasi-Newton L-BFGS-B where it does not settle)."""
    from itertools import product

    from scipy.optimize import minimize

    lo, hi = _log_box(bounds)
    if start is not None:
        base = np.clip(np.log(np.maximum(np.asarray(start, float), 1e-300)), lo, hi)
        axes = [] if grid_axes is None else list(grid_axes)
    else:
        base = 0.5 * (lo + hi)
        axes = list(range(len(bounds))) if grid_axes is None else list(grid_axes)
    u0, f0 = base, reml_negll(np.exp(base), J, r, known, blocks)
    if axes:  # the grid's best point (the first of equal ones), all points in one batched evaluation
        grid = np.repeat(base[None], 17 ** len(axes), axis=0)
        grid[:, axes] = np.array(list(product(*[np.linspace(lo[i], hi[i], 17) for i in axes])))
        fg_ = reml_negll_many(np.exp(grid), J, r, known, blocks)
        b = int(np.argmin(fg_))
        if fg_[b] < f0:
            u0, f0 = grid[b], float(fg_[b])
    u, settled = newton_in_box(_log_terms(J[None], r[None], known[None], blocks[:, None]), u0[None], lo, hi)
    if settled[0]:
        return np.exp(u[0])

    def fg(v):  # value and gradient in log theta
        th = np.exp(v)
        val, gr = reml_negll(th, J, r, known, blocks, grad=True)
        return val, gr * th

    opt = minimize(fg, u0, jac=True, method="L-BFGS-B", bounds=list(zip(lo, hi)))
    return np.exp(opt.x if np.isfinite(opt.fun) and opt.fun <= f0 else u0)


def reml_variance_cov(J, known, blocks, theta) -> np.ndarray:
    """2 (tr(P V_i P V_j))^-1 (k, k) over the variances theta (k,) of the blocks (k, N, m, m) (pseudo-inverse: an
    unseen component gets 0, not inf). P = W - U M U^T with W = blockdiag(C_n^-1), U = W J, M = (J^T W J)^+, so
    tr(P V_i P V_j) = sum_n tr(W_n V_in W_n V_jn) - tr(M G_ij) - tr(M G_ji) + tr(M H_i M H_j), G_ij =
    sum_n U_n^T V_in W_n V_jn U_n, H_i = sum_n U_n^T V_in U_n: sums over the poses, O(N) time and memory (never
    the (N m)^2 matrix P)."""
    blocks = np.asarray(blocks, float)
    k, n, m = blocks.shape[:3]
    p = J.shape[-1]
    C = known + np.tensordot(np.asarray(theta, float), blocks, axes=1)
    W = np.linalg.inv(C)  # (N, m, m)
    U = W @ J  # (N, m, p)
    M = np.linalg.pinv(J.reshape(-1, p).T @ U.reshape(-1, p))
    WV = W[None] @ blocks  # (k, N, m, m): W_n V_in
    VU = (blocks @ U[None]).reshape(k, n * m, p)  # V_in U_n, the poses' rows stacked
    WVU = (W[None] @ VU.reshape(k, n, m, p)).reshape(k, n * m, p)  # W_n V_in U_n
    H = [U.reshape(-1, p).T @ VU[i] for i in range(k)]  # (p, p) each: sum_n U_n^T V_in U_n
    T = np.empty((k, k))
    for i in range(k):
        for j in range(k):
            t1 = float(np.sum(WV[i] * np.swapaxes(WV[j], 1, 2)))
            G = VU[i].T @ WVU[j]  # sum_n U_n^T V_in W_n V_jn U_n
            T[i, j] = t1 - 2.0 * float(np.sum(M * G.T)) + float(np.sum((M @ H[i]) * (M @ H[j]).T))
    T = 0.5 * (T + T.T)
    return 2.0 * np.linalg.pinv(T)


__all__ = ["REML_GRID_CHUNK", "REML_NEWTON_TOL", "reml_terms", "reml_negll", "reml_negll_many", "newton_in_box",
           "reml_newton", "reml_max", "reml_variance_cov"]
