"""Library guarantees: what converged means (EKF), a pose-independent base set, never a confident
wrong answer on non-finite data, single-threaded BLAS inside the solvers."""

import dataclasses

import numpy as np
import pytest
from toy_models import h4_problem, linear_problem, planar_problem, true_deviation

from vision_calib.errors import DataError
from vision_calib.identify import (
    STATUS_MAX_ITERATIONS,
    STATUS_NOT_FINITE,
    analyze,
    base_problem,
    solve_ekf,
    solve_lse,
)

TOL = 1e-3


def _distance(res, lse):
    fi = lse.free
    return float(np.max(np.abs(res.identified - lse.identified)[fi] / lse.std[fi]))


def _check_flag_matches_distance(prob, max_passes=5):
    """For 1..max_passes passes, converged is True exactly when the EKF is within TOL std of LSE
    (a factor-3 band around TOL is not judged: the criterion is first order)."""
    lse = solve_lse(prob)
    flags = []
    for p in range(1, max_passes + 1):
        res = solve_ekf(prob, passes=p, tol=TOL)
        d = _distance(res, lse)
        assert res.info["passes"] == p
        if not TOL / 3 < d < 3 * TOL:
            assert res.converged == (d < TOL), (p, d, res.message)
        assert res.status == (1 if res.converged else STATUS_MAX_ITERATIONS)
        flags.append(res.converged)
    auto = solve_ekf(prob, tol=TOL)  # default: passes until converged
    assert auto.converged and auto.status == 1 and "converged after" in auto.message
    assert _distance(auto, lse) < TOL
    assert np.allclose(auto.std[lse.free], lse.std[lse.free], rtol=0.01)
    return flags, auto


def test_ekf_converged_flag_on_well_conditioned_problem():
    rng = np.random.default_rng(22)
    prob, _ = planar_problem(true_deviation(rng), n_poses=25, rng=rng)
    flags, auto = _check_flag_matches_distance(prob)
    assert flags[-1] and auto.info["passes"] <= 3


def test_ekf_converged_flag_on_ill_conditioned_h4_problem():
    prob, _ = h4_problem("D", sigma_q_rad=1e-4, n_poses=40, seed=3)
    flags, auto = _check_flag_matches_distance(prob)
    assert not flags[0]  # one pass is honestly not converged on H4 (> 0.1 std from LSE)
    assert flags[-1]
    # a pass limit that stops early says so
    early = solve_ekf(prob, max_passes=1)
    assert not early.converged and early.status == STATUS_MAX_ITERATIONS
    assert "max_passes=1" in early.message and any("max_passes" in w for w in early.warnings)


def test_base_set_is_the_same_over_pose_subsets_of_one_robot():
    """Default selection 'order': the dropped parameters depend on the robot, not on which poses."""
    from vision_calib.identify.serial_problem import serial_problem, synthetic_pose_measurements
    from vision_calib.kinematics.serial import SerialChain

    dh = np.array([[0, 0, 0, 0.3], [np.pi / 2, 0.05, 0, 0], [0, 0.45, 0, 0], [-np.pi / 2, 0.02, 0, 0.45],
                   [np.pi / 2, 0, 0, 0], [-np.pi / 2, 0, 0, 0.08]])
    chain = SerialChain.build("arm", dh, hayati=(3,))
    rng = np.random.default_rng(5)
    q = rng.uniform(-1.5, 1.5, (114, 6))
    x_true = chain.params.nominal + chain.params.scale * rng.uniform(-2, 2, len(chain.params))
    T = synthetic_pose_measurements(chain, q, x_true, 1e-4, 1e-4, rng)
    prob = serial_problem(chain, q, T)
    sets = set()
    for seed in range(5):
        idx = np.sort(np.random.default_rng(seed).permutation(114)[:40])
        sub = prob.subset(idx)
        rep = analyze(sub)
        assert rep.non_identifiable  # the base mount and the first joint overlap: something is dropped
        assert base_problem(sub)[1].non_identifiable == rep.non_identifiable
        fixed = set(sub.params.free_names) - set(solve_lse(sub).info["identifiability"].names)
        assert fixed == set(rep.non_identifiable)
        sets.add(rep.non_identifiable)
    assert len(sets) == 1, sets
    # "pivot" stays available by name
    assert len(analyze(prob, selection="pivot").non_identifiable) == len(next(iter(sets)))


def _linear(seed=0):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((12, 2, 3))
    cov = np.broadcast_to(1e-4 * np.eye(2), (12, 2, 2)).copy()
    y = np.einsum("kmn,n->km", A, [0.1, -0.2, 0.3]) + 1e-2 * rng.standard_normal((12, 2))
    return y, A, cov


def test_absurd_measurement_is_a_clear_error_not_a_confident_answer():
    y, A, cov = _linear()
    y[4, 1] = 1e300  # finite, but its squared whitened residual overflows: cost = inf
    prob = linear_problem(A, y, cov, ["a", "b", "c"], [0.1] * 3)
    for solve in (solve_lse, solve_ekf):
        with pytest.raises(DataError, match="obs4"):
            solve(prob)


def test_non_finite_jacobian_at_the_solution_gives_status_not_finite():
    y, A, cov = _linear(1)
    good = linear_problem(A, y, cov, ["a", "b", "c"], [0.1] * 3)

    def jac(x, idx=None):  # analytic Jacobian broken away from the start for observation 7
        J = good.jacobian(x, idx)
        sel = np.arange(12) if idx is None else np.asarray(idx, int)
        if abs(x[0]) > 0.05:
            J[sel == 7] = np.nan
        return J

    prob = dataclasses.replace(good, jacobian=jac)
    res = solve_lse(prob, jac="2-point")  # the solve itself does not use the analytic Jacobian
    assert not res.converged and res.status == STATUS_NOT_FINITE
    assert "Jacobian" in res.message and "obs7" in res.message
    assert res.to_dict()["status"] == STATUS_NOT_FINITE and res.to_dict()["message"] == res.message
    ok = solve_lse(good)
    assert ok.converged and ok.status == 1 and ok.message.startswith("Levenberg-Marquardt (normal equations)")
    assert ok.dof == 24 - 3 and ok.chi2_dof == pytest.approx(2 * ok.cost_final / 21)
    assert ok.pose_chi2.shape == (12,) and ok.pose_chi2.sum() == pytest.approx(2 * ok.cost_final)


def test_solvers_run_single_threaded_blas_and_restore_it():
    tp = pytest.importorskip("threadpoolctl")
    from vision_calib.identify.pose_selection import select_poses
    from vision_calib.identify.threads import SMALL_MAX_ENTRIES, blas_threads, small_blas

    if blas_threads() is None:
        pytest.skip("no BLAS library visible to threadpoolctl")
    rng = np.random.default_rng(2)
    prob, _ = planar_problem(true_deviation(rng), n_poses=20, rng=rng)
    seen = []

    def residual(x, idx=None):
        seen.append(blas_threads())
        return prob.residual(x, idx)

    spy = dataclasses.replace(prob, residual=residual)
    with tp.threadpool_limits(2, user_api="blas"):
        before = blas_threads()
        solve_lse(spy)
        solve_ekf(spy, passes=2)
        analyze(spy)
        select_poses(spy.with_params(spy.params.fix(["q0_1"])), 6)
        assert blas_threads() == before  # restored after each call
        with small_blas(SMALL_MAX_ENTRIES + 1):  # large problems keep the caller's threading
            assert blas_threads() == before
    assert seen and set(seen) == {1}
