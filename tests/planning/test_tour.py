"""The tour (planning.tour): short in joint-space travel time, and a colliding move avoided by reordering or named."""

import itertools

import numpy as np
import pytest

from vision_calib.planning.tour import best_tour, move_samples, path_cost, plan_tour, travel_times


def test_tour_is_optimal_on_small_sets():
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = rng.uniform(-1, 1, size=(7, 3))
        C = travel_times(q, 1.0)
        best = min(path_cost(p, C) for p in itertools.permutations(range(7)))
        assert path_cost(best_tour(C), C) <= best * 1.05  # 2-opt from every start: optimal or nearly


def test_times_and_samples():
    q = np.radians([[0, 0], [30, -10]])
    assert travel_times(q, np.radians(60))[0, 1] == pytest.approx(0.5)  # the largest joint change at 60 deg/s
    S = move_samples(q[0], q[1], np.radians(2))
    assert len(S) == 14 and np.all(np.diff(S[:, 0]) > 0)  # every 2 deg, the ends excluded


def test_a_colliding_move_is_avoided_or_named():
    # four poses on a line; the straight move between the two middle ones crosses a "wall" at x = 0.5, y in (0.4, 0.6)
    q = np.array([[0.0, 0.0], [0.5, 0.0], [0.5, 1.0], [1.0, 1.0]])

    def check(S):
        bad = (np.abs(S[:, 0] - 0.5) < 1e-9) & (S[:, 1] > 0.4) & (S[:, 1] < 0.6)
        return ~bad, [("link", "wall", 0.0)] * len(S)

    t = plan_tour(q, 1.0, 0.05, check)
    pairs = {tuple(sorted(p)) for p in zip(t["order"][:-1], t["order"][1:])}
    assert (1, 2) not in pairs and t["colliding"] == []  # another order goes around
    # with two poses only, no order avoids the move: it is returned, named
    t = plan_tour(q[1:3], 1.0, 0.05, check)
    assert len(t["colliding"]) == 1 and t["colliding"][0][2][0] == ("link", "wall", 0.0)
