"""The order to drive the planned poses in: a short open tour in joint space (nearest neighbour, then 2-opt), with
the straight joint-space moves between consecutive poses checked for collisions.

Travel time of a move q_a -> q_b [s]: max_j |q_b,j - q_a,j| / v_max (every joint at most v_max rad/s, the slowest
joint sets the time: a synchronous point-to-point move, acceleration neglected). A move is sampled every
``step`` rad of its largest joint change (its ends excluded: they are planned poses, already checked); a sample
closer to an obstacle or to another link than the clearance makes the move collide. Colliding moves get a
prohibitive cost and the tour is searched again (:data:`REORDER_ROUNDS` times); a move that still collides is
returned, for the plan to name in a warning.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

#: cost [s] of a move found colliding (the tour search avoids it when any other order exists)
COLLIDING_COST = 1e6
REORDER_ROUNDS = 5


def travel_times(q: np.ndarray, v_max: float) -> np.ndarray:
    """(N, N) [s] travel time between joint sets q (N, n) rad at joint speed v_max [rad/s]."""
    q = np.asarray(q, float)
    return np.max(np.abs(q[:, None, :] - q[None, :, :]), axis=2) / float(v_max)


def path_cost(order, C: np.ndarray) -> float:
    order = list(order)
    return float(sum(C[a, b] for a, b in zip(order[:-1], order[1:])))


def nearest_neighbour(C: np.ndarray, start: int) -> list[int]:
    n = C.shape[0]
    order, left = [start], set(range(n)) - {start}
    while left:
        last = order[-1]
        nxt = min(left, key=lambda j: (C[last, j], j))
        order.append(nxt)
        left.remove(nxt)
    return order


def two_opt(order: list[int], C: np.ndarray, fixed_start: bool = True) -> list[int]:
    """2-opt on an open path (reversing order[i:j+1]) until no reversal shortens it; the first pose stays first
    when ``fixed_start``."""
    order = list(order)
    n = len(order)
    improved = True
    while improved:
        improved = False
        for i in range(1 if fixed_start else 0, n - 1):
            for j in range(i + 1, n):
                a = C[order[i - 1], order[i]] if i > 0 else 0.0
                b = C[order[j], order[j + 1]] if j < n - 1 else 0.0
                a2 = C[order[i - 1], order[j]] if i > 0 else 0.0
                b2 = C[order[i], order[j + 1]] if j < n - 1 else 0.0
                if a2 + b2 < a + b - 1e-12:
                    order[i:j + 1] = order[i:j + 1][::-1]
                    improved = True
    return order


def best_tour(C: np.ndarray, start: int | None = None) -> list[int]:
    """Shortest open tour found: nearest neighbour from ``start`` (or from every pose when None) + 2-opt."""
    starts = range(C.shape[0]) if start is None else [start]
    best, cost = None, np.inf
    for s in starts:
        o = two_opt(nearest_neighbour(C, s), C, fixed_start=start is not None)
        c = path_cost(o, C)
        if c < cost - 1e-12:
            best, cost = o, c
    return best


def move_samples(qa: np.ndarray, qb: np.ndarray, step: float) -> np.ndarray:
    """(k, n) joint sets strictly between qa and qb (n,) on the straight joint-space move, every ``step`` rad of
    its largest joint change (none for a move shorter than a step)."""
    k = int(np.ceil(np.max(np.abs(qb - qa)) / step))
    if k <= 1:
        return np.zeros((0, qa.size))
    t = np.arange(1, k) / k
    return qa[None, :] + t[:, None] * (qb - qa)[None, :]


def plan_tour(q: np.ndarray, v_max: float, step: float, check: Callable | None = None, start: int | None = None
              ) -> dict:
    """Order the joint sets q (N, n) rad: {order (N,) indices, times_s (N-1,) per move, total_s, length_rad (the sum
    of the moves' largest joint changes), colliding: [(from index, to index, why)] of moves still colliding,
    rounds}. check(q (k, n)) -> (ok (k,) bool, why list): the collision check of joint sets (None: moves not
    checked)."""
    q = np.asarray(q, float)
    C = travel_times(q, v_max)
    if len(q) < 2:
        return {"order": list(range(len(q))), "times_s": [], "total_s": 0.0, "length_rad": 0.0, "colliding": [],
                "rounds": 0, "moves_checked": check is not None, "move_samples": 0}
    checked: dict = {}  # (a, b) with a < b -> None (clear) or (why, where along the move)
    n_samples = 0
    order = best_tour(C, start)
    rounds = 0
    for rounds in range(REORDER_ROUNDS + 1):
        found = False
        for a, b in zip(order[:-1], order[1:]):
            key = (min(a, b), max(a, b))
            if check is None:
                break
            if key not in checked:
                S = move_samples(q[a], q[b], step)
                n_samples += len(S)
                ok, why = check(S) if len(S) else (np.ones(0, bool), [])
                checked[key] = None
                if not np.all(ok):
                    k = int(np.flatnonzero(~ok)[0])
                    checked[key] = (why[k], float((k + 1) / (len(S) + 1)))
            found = found or checked[key] is not None
        if not found or rounds == REORDER_ROUNDS:
            break
        Cp = C.copy()
        for (a, b), v in checked.items():
            if v is not None:
                Cp[a, b] = Cp[b, a] = COLLIDING_COST
        order = best_tour(Cp, start)
    colliding = []
    for a, b in zip(order[:-1], order[1:]):
        key = (min(a, b), max(a, b))
        if checked.get(key) is not None:
            colliding.append((a, b, checked[key]))
    times = [float(C[a, b]) for a, b in zip(order[:-1], order[1:])]
    return {"order": [int(i) for i in order], "times_s": times, "total_s": float(sum(times)),
            "length_rad": float(sum(np.max(np.abs(q[b] - q[a])) for a, b in zip(order[:-1], order[1:]))),
            "colliding": colliding, "rounds": rounds, "moves_checked": check is not None, "move_samples": n_samples}


__all__ = ["plan_tour", "travel_times", "move_samples", "best_tour", "two_opt", "nearest_neighbour", "path_cost"]
