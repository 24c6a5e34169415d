"""Damped Newton (Levenberg-Marquardt) on joint values for a pose goal, vectorised over N goals (numpy only).

Residual of goal k: ``r_k(q) = frames.pose_error(T_goal_k, f(q)_k)`` = [dt (m), drot (rad)] (6,), both in the
goal's parent frame; the joint Jacobian by central differences (step :data:`FD_STEP`). Joint limits are a box:
each step is clipped into it, so a goal that needs a joint past its limit ends at the limit with a residual.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..frames import pose_error

#: central-difference step on the joints [rad or m]
FD_STEP = 1e-6
#: a goal is reached when |dt| <= TOL_T_M and |drot| <= TOL_R_RAD
TOL_T_M = 1e-11
TOL_R_RAD = 1e-11
#: an accepted step below this [rad or m] on every joint ends the iteration of that goal (a minimum off the goal)
STALL_STEP = 1e-13
#: ... or an accepted step gaining less than this fraction of the cost
STALL_GAIN = 1e-6


def joint_jacobian(f: Callable, q: np.ndarray, T_goal: np.ndarray) -> np.ndarray:
    """(N, 6, n) d r / d q of the residual above at q (N, n), central differences."""
    N, n = q.shape
    J = np.empty((N, 6, n))
    for j in range(n):
        dq = np.zeros(n)
        dq[j] = FD_STEP
        J[:, :, j] = (pose_error(T_goal, f(q + dq)) - pose_error(T_goal, f(q - dq))) / (2 * FD_STEP)
    return J


def levenberg_marquardt(f: Callable | None, T_goal: np.ndarray, q0: np.ndarray, limits: np.ndarray | None = None,
                        max_iter: int = 100, jac: Callable | None = None,
                        fj: Callable | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint values q (N, n) with f(q) (N, 4, 4) = T_goal (N, 4, 4), from q0 (N, n) inside ``limits`` (n, 2) [min,
    max] (None: none). Levenberg damping lam I, divided by 10 after an accepted step, multiplied by 10 after a
    rejected one; a goal stops when reached (TOL_T_M, TOL_R_RAD), stalled (STALL_STEP, STALL_GAIN: a minimum off the
    goal, e.g. out of reach or held by a joint limit), after max_iter steps, or when lam passes 1e12. jac(q (M, n))
    -> (M, 6, n): d r / d q (default :func:`joint_jacobian`, central differences); fj(q) -> (f(q), jac(q)) instead
    of both (one pass over the frames; the Jacobian of an accepted trial kept for the next step). Returns (q (N, n),
    residual (N, 6) [m, rad] at q, reached (N,) bool)."""
    q = np.array(q0, float)
    N, n = q.shape
    lo, hi = (np.full(n, -np.inf), np.full(n, np.inf)) if limits is None else (limits[:, 0], limits[:, 1])
    q = np.clip(q, lo, hi)
    if fj is not None:
        T, Jq = fj(q)
    else:
        T, Jq = f(q), None
    r = fast_pose_error(T_goal, T)
    cost = np.sum(r * r, axis=1)
    lam = np.full(N, 1e-3)

    def done(res):
        return (np.linalg.norm(res[:, :3], axis=1) <= TOL_T_M) & (np.linalg.norm(res[:, 3:], axis=1) <= TOL_R_RAD)

    ok = done(r)
    stalled = np.zeros(N, bool)
    eye = np.eye(n)
    for _ in range(max_iter):
        act = np.flatnonzero(~ok & ~stalled & (lam < 1e12))
        if not act.size:
            break
        qa = q[act]
        if Jq is not None:
            J = Jq[act]
        else:
            J = joint_jacobian(f, qa, T_goal[act]) if jac is None else jac(qa)
        JtJ = np.swapaxes(J, 1, 2) @ J
        g = np.einsum("kin,ki->kn", J, r[act])
        A = JtJ + lam[act, None, None] * eye
        step = -np.linalg.solve(A, g[..., None])[..., 0]
        qt = np.clip(qa + step, lo, hi)
        if Jq is not None:
            Tt, Jt = fj(qt)
        else:
            Tt = f(qt)
        rt = fast_pose_error(T_goal[act], Tt)
        ct = np.sum(rt * rt, axis=1)
        better = ct < cost[act]
        idx = act[better]
        # a local minimum off the goal: the accepted step, or its relative gain, vanishes (a goal being reached
        # gains orders of magnitude per step)
        stalled[idx] = ((np.abs(qt[better] - qa[better]).max(axis=1) < STALL_STEP)
                        | ((ct[better] > (1.0 - STALL_GAIN) * cost[idx]) & (ct[better] > TOL_T_M**2)))
        q[idx], r[idx], cost[idx] = qt[better], rt[better], ct[better]
        if Jq is not None:
            Jq[idx] = Jt[better]
        lam[idx] = np.maximum(lam[idx] * 0.1, 1e-12)
        lam[act[~better]] *= 10.0
        ok[act] = done(r[act])
    return q, r, ok


#: lever [m] at which a rotation counts as a displacement in the joint-space amplification (1 mrad ~ 1 mm)
LEVER_M = 1.0
#: joint change [deg] per mm of tool motion (:func:`amplification_deg_per_mm`) above which a joint set is near a
#: singularity: compensate damps its correction along the near-null directions and flags the row; inverse names it
#: beside a pose it does not reach
AMPLIFIED_DEG_PER_MM = 1.0
#: bisection steps on log10(mu) of :func:`damped_correction`, and its range [m/rad]
N_BISECT = 20
LOG_MU_RANGE = (-9.0, 3.0)


def fast_pose_error(T_a: np.ndarray, T_b: np.ndarray) -> np.ndarray:
    """``frames.pose_error`` (N, 6) of (N, 4, 4) poses: the rotation vector from the skew part of R_b R_a^T (exact
    below 3 rad; frames.pose_error, scipy, for the rows near pi)."""
    dR = T_b[:, :3, :3] @ np.swapaxes(T_a[:, :3, :3], 1, 2)
    ang = np.arccos(np.clip(0.5 * (np.trace(dR, axis1=1, axis2=2) - 1.0), -1.0, 1.0))
    w = np.stack([dR[:, 2, 1] - dR[:, 1, 2], dR[:, 0, 2] - dR[:, 2, 0], dR[:, 1, 0] - dR[:, 0, 1]], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        fac = np.where(ang < 1e-6, 0.5 + ang * ang / 12.0, ang / (2.0 * np.sin(ang)))
    out = np.concatenate([T_b[:, :3, 3] - T_a[:, :3, 3], fac[:, None] * w], axis=1)
    far = np.flatnonzero(ang > 3.0)
    if far.size:
        out[far] = pose_error(T_a[far], T_b[far])
    return out


def amplification_deg_per_mm(s_min: np.ndarray) -> np.ndarray:
    """Joint change [deg] per mm of tool motion in the weakest direction, from the smallest singular value s_min
    [m/rad] of the joint Jacobian with its rotation rows times :data:`LEVER_M`."""
    return np.degrees(1.0) / (1e3 * np.maximum(s_min, 1e-300))


def damped_correction(f: Callable, jac: Callable, T_goal: np.ndarray, q0: np.ndarray, tol: np.ndarray,
                      s_near: float, limits: np.ndarray | None = None, max_iter: int = 12,
                      target: float = 0.9) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The smallest joint correction q - q0 that puts f(q) (N, 4, 4) within ``tol`` of T_goal (N, 4, 4), exact in
    the well-conditioned directions, damped in the near-null ones.

    Gauss-Newton on r(q) = frames.pose_error(T_goal, f(q)) with jac(q) (N, 6, n) = dr/dq: at each step the SVD of
    S J (S: rotation rows times :data:`LEVER_M`) splits the joint space; along the right singular vectors with
    s_i >= s_near [m/rad] the step solves r exactly, along those with s_i < s_near it minimises
    (b_i + s_i d_i)^2 + mu^2 (c_i + d_i)^2 (b = U^T S r, c = V^T (q - q0)): Tikhonov damping of the total correction,
    mu per row the largest (bisection on log10 mu, mu = inf first: the near-null part of the correction dropped) that
    keeps the linearised residual within ``target`` x tol (tol (N, 2): [translation m, rotation rad]). Steps are
    clipped into ``limits`` (n, 2). Returns (q (N, n), residual (N, 6) [m, rad] at q, s_min (N,) [m/rad] of S J at
    q0)."""
    q0 = np.asarray(q0, float)
    N, n = q0.shape
    lo, hi = (np.full(n, -np.inf), np.full(n, np.inf)) if limits is None else (limits[:, 0], limits[:, 1])
    S = np.array([1.0, 1.0, 1.0, LEVER_M, LEVER_M, LEVER_M])
    q = np.clip(q0, lo, hi)
    r = fast_pose_error(T_goal, f(q))
    s_min = np.zeros(N)
    act = np.arange(N)
    for it in range(max_iter):
        if not act.size:
            break
        U, s, Vt = np.linalg.svd(jac(q[act]) * S[:, None])
        if it == 0:
            s_min = s[:, -1]  # (min(6, n) singular values: the smallest)
        k = s.shape[1]
        b = np.einsum("aji,aj->ai", U, r[act] * S)
        c = np.einsum("aij,aj->ai", Vt, q[act] - q0[act])[:, :k]
        near = s < s_near
        tt, tr = tol[act, 0], tol[act, 1]

        def trial(log_mu):
            """(step in the V basis (A, k), physical residual (A, 6), worst residual / tol (A,))."""
            mu2 = np.where(np.isposinf(log_mu), np.inf, 10.0 ** np.minimum(2 * log_mu, 300))[:, None]
            with np.errstate(invalid="ignore", divide="ignore"):
                a = np.where(near, np.where(np.isposinf(mu2), 1.0, mu2 / (s * s + mu2)), 0.0)  # damped share
                a = np.where(near & (s < 1e-300), 1.0, a)
                d = -(1.0 - a) * np.where(s > 0, b[:, :k] / np.where(s > 0, s, 1.0), 0.0) - a * c
            rho = b.copy()
            rho[:, :k] += s * d
            res = np.einsum("aij,aj->ai", U, rho) / S
            worst = np.maximum(np.linalg.norm(res[:, :3], axis=1) / tt, np.linalg.norm(res[:, 3:], axis=1) / tr)
            return d, worst

        d, worst = trial(np.full(act.size, np.inf))
        need = np.flatnonzero(worst > target)
        if need.size:  # bisection on the rows (need) whose near-null part cannot be dropped entirely
            sub = (U[need], s[need], b[need], c[need], near[need], tt[need], tr[need])
            U, s, b, c, near, tt, tr = sub
            lo_m, hi_m = np.full(need.size, LOG_MU_RANGE[0]), np.full(need.size, LOG_MU_RANGE[1])
            for _ in range(N_BISECT):
                mid = 0.5 * (lo_m + hi_m)
                ok = trial(mid)[1] <= target
                lo_m, hi_m = np.where(ok, mid, lo_m), np.where(ok, hi_m, mid)
            d[need] = trial(np.where(lo_m > LOG_MU_RANGE[0], lo_m, -np.inf))[0]  # -inf: mu = 0, the exact step
        dq = np.einsum("aji,aj->ai", Vt[:, :k], d)
        qn = np.clip(q[act] + dq, lo, hi)
        moved = np.abs(qn - q[act]).max(axis=1)
        q[act] = qn
        r[act] = fast_pose_error(T_goal[act], f(qn))
        act = act[moved > STALL_STEP]
    return q, r, s_min
