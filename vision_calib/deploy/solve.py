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


def levenberg_marquardt(f: Callable, T_goal: np.ndarray, q0: np.ndarray, limits: np.ndarray | None = None,
                        max_iter: int = 100) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint values q (N, n) with f(q) (N, 4, 4) = T_goal (N, 4, 4), from q0 (N, n) inside ``limits`` (n, 2)
    [min, max] (None: none). Levenberg damping lam I, divided by 10 after an accepted step, multiplied by 10 after a
    rejected one; a goal stops when reached (TOL_T_M, TOL_R_RAD), stalled (STALL_STEP, STALL_GAIN: a minimum off
    the goal, e.g. out of reach or held by a joint limit), after max_iter steps, or when lam passes 1e12.
    Returns (q (N, n), residual (N, 6) [m, rad] at q, reached (N,) bool)."""
    q = np.array(q0, float)
    N, n = q.shape
    lo, hi = (np.full(n, -np.inf), np.full(n, np.inf)) if limits is None else (limits[:, 0], limits[:, 1])
    q = np.clip(q, lo, hi)
    r = pose_error(T_goal, f(q))
    cost = np.sum(r * r, axis=1)
    lam = np.full(N, 1e-3)

    def done(res):
        return (np.linalg.norm(res[:, :3], axis=1) <= TOL_T_M) & (np.linalg.norm(res[:, 3:], axis=1) <= TOL_R_RAD)

    ok = done(r)
    stalled = np.zeros(N, bool)
    for _ in range(max_iter):
        act = np.flatnonzero(~ok & ~stalled & (lam < 1e12))
        if not act.size:
            break
        qa = q[act]
        J = joint_jacobian(f, qa, T_goal[act])
        JtJ = np.einsum("kin,kim->knm", J, J)
        g = np.einsum("kin,ki->kn", J, r[act])
        A = JtJ + lam[act, None, None] * np.eye(n)
        step = -np.linalg.solve(A, g[..., None])[..., 0]
        qt = np.clip(qa + step, lo, hi)
        rt = pose_error(T_goal[act], f(qt))
        ct = np.sum(rt * rt, axis=1)
        better = ct < cost[act]
        idx = act[better]
        # a local minimum off the goal: the accepted step, or its relative gain, vanishes (a goal being reached
        # gains orders of magnitude per step)
        stalled[idx] = ((np.abs(qt[better] - qa[better]).max(axis=1) < STALL_STEP)
                        | ((ct[better] > (1.0 - STALL_GAIN) * cost[idx]) & (ct[better] > TOL_T_M**2)))
        q[idx], r[idx], cost[idx] = qt[better], rt[better], ct[better]
        lam[idx] = np.maximum(lam[idx] * 0.1, 1e-12)
        lam[act[~better]] *= 10.0
        ok = done(r)
    return q, r, ok

