"""Extended Kalman filter identification (the thesis' chapter 4 filter, done properly).

State: the free parameters, handled internally in scaled units ``z = (x_free - x0_free) / scale``.
Parameters are constant, so the prediction step is ``z_k|k-1 = z_k-1``, ``P_k|k-1 = P_k-1 + Q``
with ``Q = q_process * I`` in scaled units (i.e. ``q_process * diag(scale^2)`` in SI; default 0).

Measurement model of pose k: ``y_k = h_k(x) + v_k``, ``v_k ~ N(0, R_k)``, ``R_k = obs_cov[k]``.
With ``r_k(x) = y_k - h_k(x)`` (the problem's residual) and ``J_k = dr_k/dx = -dh_k/dx``, the
measurement is whitened by ``W_k`` (inverse Cholesky factor of R_k), so the filter sees R = I;
this is exactly the update with R_k.

Update (ONE per robot pose, in the order of the observations). ``iterations_per_update=1`` is
the plain EKF of the thesis (eqs. 4.2-4.9), linearised at the prediction::

    H = W_k J_k(z_k|k-1) diag(scale)         (m, n_free)  (= -dh/dz, whitened)
    S = H P Hᵀ + I;   K = -P Hᵀ S^-1         (gain for y - h; the sign comes from H = -dh/dz)
    z_k|k = z_k|k-1 + K W_k r_k(z_k|k-1)

``iterations_per_update > 1`` (default 5) is the iterated EKF (Gauss-Newton on the posterior of
that pose, Bell & Cathey 1993) with a backtracking line search on the pose's posterior cost
``0.5 |W_k r_k(z)|² + 0.5 (z - z_k|k-1)ᵀ P^-1 (z - z_k|k-1)`` (Skoglund, Hendeby & Axehill 2015),
which keeps the early poses -- where P is still the broad prior -- from oscillating::

    z_gn = z_k|k-1 + K(z_i) (W_k r_k(z_i) + H(z_i) (z_k|k-1 - z_i)),  z_{i+1} = z_i + a (z_gn - z_i)

stopping when the step is below STEP_TOL * max(1, |z|) or no descent is left. Covariance:
``P_k|k = (I - K H_h) P (I - K H_h)ᵀ + K Kᵀ`` (Joseph form, H_h = -H, R = I after whitening; K, H
at the final iterate).

P0 = diag(prior_std²) of the free parameters (``problem.prior_std``, default 100 x scale: an
essentially uninformative prior around x0).

Passes. Pass 1 is the sequential filter above. Its weak point: with a broad prior the first
poses fix the estimate only along the few directions they see, the estimate can wander far
(tens of scales on the ill-conditioned H4 models) and those poses' information stays linearised
there; on H4 variant D with 81 poses one pass differs from LSE by ~3 posterior std, while on
the well-conditioned toy arm it agrees to < 0.01 std. Passes 2.. (``passes > 1``) fix this:
each restarts ``P = P0`` with the prior mean at the previous pass's estimate ``z_p`` and
linearises EVERY pose at ``z_p`` (one linear update per pose). Such a pass is exactly one
Gauss-Newton step on the least-squares cost damped by ``P0^-1`` (a Levenberg-Marquardt step), so
passes converge to the LSE solution itself (no prior bias at the fixed point; the data are never
counted twice). The reported covariance is the final P of the last pass ((JᵀJ + P0^-1)^-1, i.e.
the LSE covariance up to the (std / prior std)² damping). ``converged``: pass 1 -- every iterated
update converged; later passes -- the last pass moved every parameter by < 1e-3 posterior std.
"""

from __future__ import annotations

import time
from typing import Iterable

import numpy as np

from ..errors import ConfigError, DataError, UnreachablePoseError
from .lse import finish_result, prepare, whitened_cost
from .problem import IdentificationProblem, IdentificationResult

STEP_TOL = 1e-9  # iterated update stops when ||z_{i+1} - z_i|| < STEP_TOL * max(1, ||z||) (scaled units)


def solve_ekf(
    problem: IdentificationProblem,
    x0=None,
    passes: int = 1,
    iterations_per_update: int = 5,
    q_process: float = 0.0,
    fix_unidentifiable: bool = True,
    free: Iterable[str] | None = None,
    fix: Iterable[str] = (),
    order=None,
) -> IdentificationResult:
    """Identify the free parameters with an (iterated) EKF, one measurement update per pose.

    x0: (n,) full starting vector (SI), default ``params.nominal`` (= prior mean of the first pass).
    passes: number of passes over the data (>= 1). iterations_per_update: >= 1 (1 = plain EKF).
    q_process: process noise variance per pose, in scaled units (fraction of scale², >= 0).
    order: optional (n_obs,) permutation of the observations (default: given order).
    Returns an IdentificationResult with method "ekf" and covariance = final P (SI, free parameters).
    ``info``: passes, iterations_per_update, updates, pass_estimates ((passes, n) full vectors),
    identifiability report.
    """
    t0 = time.perf_counter()
    if int(passes) < 1:
        raise ConfigError(f"solve_ekf: passes={passes}, expected >= 1")
    if int(iterations_per_update) < 1:
        raise ConfigError(f"solve_ekf: iterations_per_update={iterations_per_update}, expected >= 1")
    if not (np.isfinite(q_process) and q_process >= 0):
        raise ConfigError(f"solve_ekf: q_process={q_process}, expected a finite value >= 0")
    original = problem
    problem, x0, report, warnings = prepare(problem, x0, free, fix, fix_unidentifiable)
    params = problem.params
    fi = params.free_index
    n = fi.size
    s = params.scale[fi]
    W = problem.whitening()
    if problem.prior_std is None:
        prior = 100.0 * params.scale
    else:
        prior = np.asarray(problem.prior_std, float).reshape(-1)
        if prior.shape != (len(params),):
            raise DataError(f"prior_std has shape {prior.shape}, expected ({len(params)},)")
    prior_z = prior[fi] / s
    if not np.all(np.isfinite(prior_z) & (prior_z > 0)):
        bad = [params.free_names[i] for i in np.flatnonzero(~(np.isfinite(prior_z) & (prior_z > 0)))]
        raise DataError(f"prior_std must be finite and > 0 for free parameters; bad: {bad}")
    P0 = np.diag(prior_z**2)
    Q = q_process * np.eye(n)
    obs_order = np.arange(problem.n_obs) if order is None else np.asarray(order, int).reshape(-1)
    if obs_order.size == 0 or obs_order.min() < 0 or obs_order.max() >= problem.n_obs:
        raise ConfigError(f"solve_ekf: order must hold observation indices in [0, {problem.n_obs}), got {order!r}")
    x0_free = x0[fi]

    def x_of(z):
        x = x0.copy()
        x[fi] = x0_free + s * z
        return x

    cost0 = whitened_cost(problem, x0, W)
    labels = problem.labels

    def pose_terms(k, z_lin, need_jac=True):
        x = x_of(z_lin)
        r = W[k] @ np.asarray(problem.residual(x, np.array([k])), float)[0]
        if not np.all(np.isfinite(r)):
            lab = labels[k] if labels else f"#{int(k)}"
            raise DataError(f"EKF: residual of pose {lab} is not finite at the current estimate")
        if not need_jac:
            return r, None
        H = (W[k] @ np.asarray(problem.jacobian(x, np.array([k])), float)[0][:, fi]) * s[None, :]
        return r, H

    def gain(P, H):
        PHt = P @ H.T
        S = H @ PHt + np.eye(H.shape[0])
        return -np.linalg.solve(S, PHt.T).T  # K = -P Hᵀ S^-1 (gain for y - h, H = -dh/dz)

    z = np.zeros(n)
    P = P0.copy()
    eye = np.eye(n)
    updates = 0
    pass_estimates = []
    converged = True
    n_iter = int(iterations_per_update)
    for p in range(int(passes)):
        P = P0.copy()
        all_conv = True
        z_lin_pass = z.copy()  # passes >= 2: every pose linearised here (prior mean too)
        for k in obs_order:
            P = P + Q
            z_prior = z.copy()
            if p > 0:
                # damped Gauss-Newton pass: fixed linearisation point for all poses
                r, H = pose_terms(k, z_lin_pass)
                K = gain(P, H)
                zi = z_prior + K @ (r + H @ (z_prior - z_lin_pass))
                updates += 1
            elif n_iter == 1:
                # plain EKF (thesis eqs. 4.2-4.9), linearised at the prediction
                r, H = pose_terms(k, z_prior)
                K = gain(P, H)
                zi = z_prior + K @ r
                updates += 1
            else:
                # iterated EKF with backtracking on the pose's posterior cost
                # c(z) = 0.5 |W r(z)|^2 + 0.5 (z - z_prior)ᵀ P^-1 (z - z_prior)
                cP = np.linalg.cholesky(P)

                def post_cost(zz, rr):
                    d = np.linalg.solve(cP, zz - z_prior)
                    return 0.5 * float(rr @ rr + d @ d)

                zi = z_prior.copy()
                r, H = pose_terms(k, zi)
                ci = post_cost(zi, r)
                conv = False
                for _it in range(n_iter):
                    K = gain(P, H)
                    z_gn = z_prior + K @ (r + H @ (z_prior - zi))
                    step = z_gn - zi
                    updates += 1
                    alpha, accepted = 1.0, False
                    for _ls in range(12):
                        z_try = zi + alpha * step
                        try:
                            r_try, _ = pose_terms(k, z_try, need_jac=False)
                            c_try = post_cost(z_try, r_try)
                        except (UnreachablePoseError, DataError):  # trial point outside the model's domain
                            c_try = np.inf
                        if c_try <= ci:
                            accepted = True
                            break
                        alpha *= 0.5
                    small = np.linalg.norm(alpha * step) < STEP_TOL * max(1.0, np.linalg.norm(zi))
                    if not accepted or small:
                        conv = True  # no descent left: at the minimum to rounding
                        if accepted:
                            zi = z_try
                        break
                    zi, r, ci = z_try, r_try, c_try
                    _, H = pose_terms(k, zi)
                all_conv &= conv
                K = gain(P, H)  # gain at the final linearisation point
            if not np.all(np.isfinite(zi)):
                lab = labels[k] if labels else f"#{int(k)}"
                raise DataError(f"EKF update diverged (non-finite state) at pose {lab}")
            IKH = eye + K @ H  # I - K H_h with H_h = -H
            P = IKH @ P @ IKH.T + K @ K.T  # Joseph form (R = I after whitening)
            P = 0.5 * (P + P.T)
            z = zi
        if p > 0:
            d = np.abs(z - z_lin_pass) / np.sqrt(np.clip(np.diag(P), 1e-300, None))
            all_conv = bool(np.all(d < 1e-3))  # last pass moved less than 1e-3 posterior std
        converged = all_conv
        pass_estimates.append(x_of(z))
    x = x_of(z)
    cov = P * np.outer(s, s)
    info = {
        "passes": int(passes),
        "iterations_per_update": int(iterations_per_update),
        "updates": updates,
        "q_process": float(q_process),
        "pass_estimates": np.array(pass_estimates),
        "identifiability": report,
    }
    return finish_result("ekf", original, problem, x0, x, cov, cost0, updates, converged, warnings, t0, info, W)
