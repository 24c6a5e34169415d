"""Identifiability analysis on toy problems with known deficiencies and hand-computable figures."""

import json

import numpy as np
import pytest
from toy_models import NOMINAL, linear_problem, planar_params, planar_problem, true_deviation

from vision_calib.errors import DataError, IdentifiabilityError, ParameterError
from vision_calib.identify import analyze, base_problem, equivalent_base_values, observability_indices


def _problem(**kw):
    rng = np.random.default_rng(7)
    return planar_problem(true_deviation(rng), rng=rng, **kw)[0]


def test_base_rotation_and_first_joint_offset_are_confounded():
    prob = _problem(n_poses=20)
    rep = analyze(prob)
    assert rep.n_params == 9 and rep.rank == 8
    # default selection "order": base.theta comes first in name order and is kept, q0_1 dropped
    # (pivoted QR agrees here: base.theta has the larger scale, 2 mrad vs 1 mrad)
    assert rep.non_identifiable == ("q0_1",)
    assert analyze(prob, selection="pivot").non_identifiable == ("q0_1",)
    assert set(rep.base_parameters) == set(prob.params.names) - {"q0_1"}
    c = rep.coupling_of("q0_1")
    # one scale of q0_1 (1 mrad) == 0.5 scale of base.theta (2 mrad); SI ratio 1
    assert list(c["combination"]) == ["base.theta"]
    assert c["combination"]["base.theta"] == pytest.approx(0.5, abs=1e-9)
    assert c["combination_si"]["base.theta"] == pytest.approx(1.0, abs=1e-9)
    assert c["fit_residual"] < 1e-9
    # null space (scaled units): 2 * z_theta + z_q01 = 0
    ns = rep.null_space[:, 0]
    i, j = rep.names.index("base.theta"), rep.names.index("q0_1")
    expected = np.zeros(9)
    expected[i], expected[j] = 1.0, -2.0
    expected /= np.linalg.norm(expected)
    assert abs(abs(ns @ expected) - 1.0) < 1e-9
    assert rep.singular_values[-1] < 1e-9 * rep.singular_values[0]
    assert np.isfinite(rep.condition_number) and rep.condition_number >= 1


def test_selection_pivot_follows_scale_and_order_follows_names():
    prob = _problem(n_poses=20)
    p = prob.params.with_scale({"base.theta": 1e-3, "q0_1": 3e-3})
    prob2 = prob.with_params(p)
    assert analyze(prob2, selection="pivot").non_identifiable == ("base.theta",)
    rep = analyze(prob2)  # default "order": the scale does not change the choice
    assert rep.non_identifiable == analyze(prob2, selection="order").non_identifiable
    assert rep.non_identifiable == ("q0_1",)
    assert rep.coupling_of("q0_1")["combination_si"]["base.theta"] == pytest.approx(1.0, abs=1e-9)
    with pytest.raises(ParameterError):
        analyze(prob2, selection="random")


def test_position_only_with_frozen_last_joint_loses_link_parameters():
    rng = np.random.default_rng(3)
    q = rng.uniform(-np.pi, np.pi, size=(25, 3))
    c3 = 0.3
    q[:, 2] = c3  # joint 3 never moves: link 2 + link 3 is one rigid vector v in link-2 frame (length + angle)
    prob, _ = planar_problem(true_deviation(rng), q=q, measure="position", rng=rng)
    rep = analyze(prob, selection="order")
    # identifiable: base.x, base.y, base.theta+q0_1, L1, |v|, angle of v (+q0_2)
    assert rep.rank == 6
    # greedy in name order keeps L2 and L3 (two directions of the link-2 plane), drops the offsets
    assert rep.non_identifiable == ("q0_1", "q0_2", "q0_3")
    # hand: effect of q0_2 = R90 v = a * (effect of L2 = u(phi2)) + b * (effect of L3 = u(phi2 + c3))
    L2, L3 = NOMINAL[4], NOMINAL[5]
    b = (L2 + L3 * np.cos(c3)) / np.sin(c3)
    a = -L3 * np.sin(c3) - b * np.cos(c3)
    c02 = rep.coupling_of("q0_2")
    assert set(c02["combination_si"]) == {"L2", "L3"}
    assert c02["combination_si"]["L2"] == pytest.approx(a, rel=1e-9)
    assert c02["combination_si"]["L3"] == pytest.approx(b, rel=1e-9)
    assert max(c["fit_residual"] for c in rep.couplings) < 1e-8
    # same poses with orientation measured: the tool angle gives one more combination (q0_2 + q0_3)
    prob_pose, _ = planar_problem(true_deviation(rng), q=q, measure="pose", rng=rng)
    assert analyze(prob_pose, selection="order").non_identifiable == ("q0_1", "q0_3")


def test_observability_indices_on_diagonal_case_match_hand_values():
    # two observations of 3 components; J_k diagonal -> column i has entries d1_i, d2_i only
    d1 = np.array([3.0, 0.0, 1.0])
    d2 = np.array([4.0, 2.0, 0.0])
    A = np.stack([np.diag(d1), np.diag(d2)])
    sigma = np.array([0.5, 0.5, 0.5])
    cov = np.stack([np.diag(sigma**2)] * 2)
    scale = np.array([1e-3, 2e-3, 4e-3])
    prob = linear_problem(A, np.zeros((2, 3)), cov, ["p1", "p2", "p3"], scale)
    rep = analyze(prob)
    # hand: column norms sqrt(d1^2 + d2^2) = (5, 2, 1), times scale / sigma
    s = np.sort(np.array([5.0, 2.0, 1.0]) * scale / 0.5)[::-1]  # (0.016, 0.008, 0.01) -> sorted
    assert np.allclose(rep.singular_values, s, rtol=1e-12)
    M, L = 2, 3
    hand = {
        "O1": (s[0] * s[1] * s[2]) ** (1 / L) / np.sqrt(M),
        "O2": s[-1] / s[0],
        "O3": s[-1],
        "O4": s[-1] ** 2 / s[0],
        "O5": 1 / (1 / s[0] + 1 / s[1] + 1 / s[2]),
    }
    for k, v in hand.items():
        assert rep.observability[k] == pytest.approx(v, rel=1e-12), k
    assert rep.condition_number == pytest.approx(s[0] / s[-1], rel=1e-12)
    assert rep.rank == 3 and rep.non_identifiable == ()
    # normalised columns: all singular values 1 for an orthogonal design
    assert np.allclose(analyze(prob, normalize=True).singular_values, 1.0)
    assert observability_indices(np.array([2.0, 0.0]), 3)["O3"] == 0.0


def test_whitening_uses_full_covariance():
    # one observation, correlated noise: the scaled whitened Jacobian is L^-1 A diag(scale)
    rng = np.random.default_rng(0)
    A = rng.standard_normal((3, 4, 2))
    B = rng.standard_normal((3, 4, 4))
    cov = B @ np.swapaxes(B, 1, 2) + 0.1 * np.eye(4)
    scale = np.array([1e-3, 5e-3])
    prob = linear_problem(A, np.zeros((3, 4)), cov, ["a", "b"], scale)
    info = sum(A[k].T @ np.linalg.inv(cov[k]) @ A[k] for k in range(3))
    expected = np.sqrt(np.linalg.eigvalsh(np.diag(scale) @ info @ np.diag(scale)))[::-1]
    assert np.allclose(analyze(prob).singular_values, expected, rtol=1e-10)


def test_too_few_equations_names_counts():
    prob = _problem(n_poses=2)  # 2 poses x 3 components = 6 equations, 9 parameters
    with pytest.raises(IdentifiabilityError, match=r"6 scalar equations.*9 free parameters"):
        analyze(prob)


def test_nan_measurement_names_pose():
    prob = _problem(n_poses=10)
    prob.meta["y"][4, 1] = np.nan
    with pytest.raises(DataError, match="pose004"):
        analyze(prob)


def test_unknown_parameter_and_nothing_free():
    prob = _problem(n_poses=10)
    with pytest.raises(ParameterError, match="L9"):
        prob.params.fix(["L9"])
    with pytest.raises(ParameterError):
        analyze(prob.with_params(prob.params.only_free([])))


def test_base_problem_fixes_and_names_dropped_parameters():
    rng = np.random.default_rng(11)
    x_true = true_deviation(rng)
    prob, _ = planar_problem(x_true, rng=rng, n_poses=15)
    bp, rep, warnings = base_problem(prob)
    assert not bp.params.free[bp.params.index("q0_1")]
    assert bp.params.n_free == 8
    assert len(warnings) == 1 and "q0_1" in warnings[0] and "base.theta" in warnings[0]
    assert analyze(bp).rank == 8 and analyze(bp).non_identifiable == ()
    # identifiable problem: unchanged, no warning
    bp2, _, w2 = base_problem(bp)
    assert bp2 is bp and w2 == ()
    # equivalent values: theta absorbs the q0_1 deviation, q0_1 at nominal
    eq = equivalent_base_values(prob, rep, x_true)
    i, j = prob.params.index("base.theta"), prob.params.index("q0_1")
    assert eq[j] == NOMINAL[j]
    assert eq[i] == pytest.approx(x_true[i] + x_true[j] - NOMINAL[j], abs=1e-15)


def test_report_to_dict_is_json():
    rep = analyze(_problem(n_poses=10))
    d = json.loads(json.dumps(rep.to_dict()))
    assert d["rank"] == 8 and d["non_identifiable"] == ["q0_1"]
    assert "whitened" in d["scaling"]
    assert "q0_1" in rep.summary()


def test_scale_independence_of_rank():
    prob = _problem(n_poses=12)
    p = planar_params().with_scale({"L1": 1.0, "q0_3": 1e-6})
    assert analyze(prob.with_params(p)).rank == 8


# ----------------------------------------------------------------------------- real H4 builder
def test_h4_model12_external_parameters_expected_rank():
    from toy_models import h4_problem

    prob, _ = h4_problem("D", all_free=True)  # 12 geometric + 8 external, all free
    rep = analyze(prob, selection="order")
    assert rep.n_params == 20 and rep.rank == 19  # paper §4.2: 12 + 7
    assert rep.non_identifiable == ("M_T_E.z",)
    c = rep.coupling_of("M_T_E.z")
    assert list(c["combination_si"]) == ["B_T_C.z"]
    assert abs(c["combination_si"]["B_T_C.z"]) == pytest.approx(1.0, abs=1e-9)


def test_h4_model31_identifiable_count():
    from toy_models import h4_problem

    prob, _ = h4_problem("H", all_free=True)
    rep = analyze(prob)
    assert rep.n_params == 39 and rep.rank == 36  # paper §4.2: 36 identifiable
    assert "M_T_E.z" in rep.non_identifiable or "B_T_C.z" in rep.non_identifiable
    assert all(c["fit_residual"] < 1e-6 for c in rep.couplings)
