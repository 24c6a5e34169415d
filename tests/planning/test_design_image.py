"""Planning under the image measurement (issue 34): the pose covariance of the image model, the validation
criterion's exchange (Woodbury gains against direct inverses, no single swap left that improves it), the first-order
RMS quantiles against a Monte Carlo of the synthetic identification, the view limits no stricter than the scene's
own sampler, and a self-collision model that accepts every pose of the shipped scenes' own sampler."""

import inspect

import numpy as np
import pytest

from vision_calib.planning import design as D
from vision_calib.rig import SCENES_DIR, load_scene
from vision_calib.rig.base import Setup
from vision_calib.rig.cell import DEFAULT_MARGIN_PX, DEFAULT_MAX_INCIDENCE_DEG

UR5E = SCENES_DIR / "ur5e_eye_in_hand.yaml"


def test_pose_covariance_adds_a_systematic_floor_that_frames_do_not_average():
    sc = load_scene(UR5E)
    q = sc.setup.sample_poses(np.random.default_rng(3), 4)
    c1, c10, c1000 = (D.pose_covariances(sc, q, f) for f in (1, 10, 1000))
    d1, d10, d1000 = (np.diagonal(c, axis1=1, axis2=2) for c in (c1, c10, c1000))
    assert np.all(d1 > d10) and np.all(d10 > d1000)  # the random part averages over frames
    # the systematic part does not: with many frames the covariance tends to s^2 (J^T J)^-1, not to zero
    from vision_calib.measure.pnp import reprojection_jacobian
    from vision_calib.targets import load_target

    _, p = load_target(sc.target_path).corner_points()
    T = sc.setup.T_cam_target(q, sc.setup.params.nominal)
    floor = np.array([D.SYSTEMATIC_CORNER_PX**2 * np.linalg.inv(reprojection_jacobian(Tk, p, sc.setup.camera).T
                                                                 @ reprojection_jacobian(Tk, p, sc.setup.camera))
                      for Tk in T])
    np.testing.assert_allclose(c1000, floor, rtol=0.05, atol=1e-15)
    for c in c1:
        assert np.all(np.linalg.eigvalsh(c) > 0)


def test_systematic_corner_error_grows_with_the_view_angle():
    """s(theta): the constant part on a board facing the camera, s0^2 + c^2 tan^2 theta when its normal leans theta
    away from the line of sight to the pattern's centre (view.incidence_rad, the same whatever the axis it leans
    about), larger the steeper."""
    from vision_calib import frames as F
    from vision_calib.planning.view import incidence_rad
    from vision_calib.targets import load_target

    target = load_target(load_scene(UR5E).target_path)
    w, h = target.pattern_size_m()

    def seen(theta_deg, axis):  # the pattern's centre 0.6 m ahead on the optical axis, the board turned about it
        R = F.T_from_xyz_rotvec(np.r_[0.0, 0.0, 0.0, np.radians(theta_deg) * np.asarray(axis, float)])[:3, :3]
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, np.array([0.0, 0.0, 0.6]) - R @ np.array([w / 2, h / 2, 0.0])
        return D.systematic_corner_px(incidence_rad(T[None], target))[0]

    assert seen(0, [1, 0, 0]) == pytest.approx(D.SYSTEMATIC_CORNER_PX, rel=1e-9)
    for th in (20, 45, 60):
        want = np.hypot(D.SYSTEMATIC_CORNER_PX, D.OBLIQUE_CORNER_PX * np.tan(np.radians(th)))
        assert seen(th, [1, 0, 0]) == pytest.approx(want, rel=1e-9)
        assert seen(th, [0, 1, 0]) == pytest.approx(want, rel=1e-9)
    assert seen(20, [1, 0, 0]) < seen(45, [1, 0, 0]) < seen(60, [1, 0, 0])


def _blocks(rng, K=40, m=6, L=9):
    A = rng.normal(size=(K, m, L)) * rng.uniform(0.2, 2.0, size=(K, 1, 1))
    G = rng.normal(size=(30, 3, L))
    return A, D.validation_weight(G)


def test_add_gains_match_direct_inverses():
    rng = np.random.default_rng(0)
    A, W = _blocks(rng)
    sel = np.arange(5)
    Mi = np.linalg.inv(D.info_matrix(A, sel))
    g = D.add_gains(A[10:20], Mi, W)
    direct = [np.trace(W @ Mi) - np.trace(W @ np.linalg.inv(D.info_matrix(A, np.r_[sel, k]))) for k in range(10, 20)]
    np.testing.assert_allclose(g, direct, rtol=1e-8)


def test_exchange_ends_where_no_single_swap_improves_and_beats_its_start():
    rng = np.random.default_rng(1)
    A, W = _blocks(rng)
    start = np.arange(4)  # 24 equations for 9 parameters: identifiable
    sel = D.refine_for_validation(A, start, W)
    v = D.validation_mse(A, sel, W)
    assert v < D.validation_mse(A, start, W)
    for pos in range(len(sel)):
        for j in np.setdiff1d(np.arange(len(A)), sel):
            trial = sel.copy()
            trial[pos] = j
            assert D.validation_mse(A, trial, W) >= v * (1 - 1e-7)


def test_first_order_quantiles_match_the_quadratic_form():
    rng = np.random.default_rng(2)
    A, W = _blocks(rng)
    sel = np.arange(6)
    q = D.validation_rms_quantiles(A, sel, W, np.random.default_rng(3), 20000)
    C = np.linalg.inv(D.info_matrix(A, sel))
    d = np.random.default_rng(4).multivariate_normal(np.zeros(len(C)), C, size=20000)
    r = np.sqrt(np.einsum("ki,ij,kj->k", d, W, d)) * 1e3
    assert q["median_mm"] == pytest.approx(np.median(r), rel=0.03)
    assert q["p95_mm"] == pytest.approx(np.percentile(r, 95), rel=0.03)
    assert D.validation_rms_quantiles(A, [0], W, rng)["median_mm"] is None  # 6 equations, 9 parameters


def test_first_order_prediction_matches_the_synthetic_identification():
    """The plan's headline figure (first order) against identify-synthetic runs drawn from the same covariances."""
    from vision_calib.experiment.synthetic import run_synthetic

    sc = load_scene(UR5E)
    rng = np.random.default_rng(7)
    P = sc.setup.sample_poses(rng, 20)
    base, _ = D.base_mask(sc, sc.setup.sample_poses(rng, 200), rng)
    info = D.information(sc, P, base, frames=2)
    V = sc.setup.sample_poses(np.random.default_rng(8), 100, check_view=False)
    W = D.validation_weight(D.validation_blocks(sc, V, base))
    q = D.validation_rms_quantiles(info.A, np.arange(20), W, np.random.default_rng(9))
    rms = []
    for k in range(30):
        run = run_synthetic(sc, poses=P, validation=V, seed=100 + k, base=base, pose_cov=info.cov)
        rms.append(np.sqrt(np.mean(run.after.position_errors_mm**2)))
    # 30 draws: the sample median is within ~15 % of the true one
    assert np.median(rms) == pytest.approx(q["median_mm"], rel=0.2)


def test_view_limits_default_to_the_scene_sampler():
    sig = inspect.signature(Setup.visible).parameters
    assert DEFAULT_MARGIN_PX == sig["margin_px"].default
    assert DEFAULT_MAX_INCIDENCE_DEG == sig["max_tilt_deg"].default


@pytest.mark.parametrize("name", ["rx90_eye_in_hand.yaml", "thesis_arm_tripod_probe.yaml", "ur5e_eye_in_hand.yaml"])
def test_self_collision_accepts_the_scene_own_poses(name):
    pytest.importorskip("fcl")
    from vision_calib.planning.plan import collision_setup

    sc = load_scene(SCENES_DIR / name)
    model, checker = collision_setup(sc)
    q = sc.setup.sample_poses(np.random.default_rng(123), 400)  # not the draws the model was built on
    ok, why = checker.screen(sc.setup.link_frames(q))
    names = {b.name for b in model.bodies}
    # self pairs only: the scene's obstacles may still be in the way
    assert not [w for w in why if w is not None and w[1] in names]
    for a, b, why in model.disabled:  # every pair left out says why
        assert why
    # a pair the scene's poses bring closer than the clearance is still checked, at a reduced distance, named
    assert len(checker.self_allowed) == len(model.self_pairs)
    for a, b, d, why in model.reduced:
        assert d < sc.planning.clearance_m and why and f"{a} / {b} at {1e3 * d:.1f} mm" in model.warnings[-1]


def test_a_self_pair_at_a_reduced_distance_still_refuses_a_folded_arm():
    pytest.importorskip("fcl")
    from vision_calib.planning.plan import collision_setup

    sc = load_scene(SCENES_DIR / "thesis_arm_tripod_probe.yaml")
    model, checker = collision_setup(sc)
    assert model.reduced  # the board on the flange comes close to the forearm on the scene's own poses
    allowed = dict(zip(map(tuple, model.self_pairs.tolist()), checker.self_allowed))
    assert min(allowed.values()) < sc.planning.clearance_m
    names = [b.name for b in model.bodies]
    folded = np.radians([[78, 175, 162, 152, 71, 89]])  # shoulder and elbow folded: the forearm into the base
    ok, why = checker.screen(sc.setup.link_frames(folded))
    assert not ok[0] and why[0][0] in names and why[0][1] in names, why


def test_h4_axis_rows_give_the_axis_estimate_covariance():
    from vision_calib.identify.camera_axis import axis_information_rows, estimate_camera_axis

    sc = load_scene(SCENES_DIR / "h4_vision.yaml")
    st = sc.setup
    P = st.sample_poses(np.random.default_rng(3), 15)
    cov = D.pose_covariances(sc, P, 2)
    T = st.T_cam_target(P, st.params.nominal)
    R_BC0, R_ME0 = st.tilt_reference()
    rows = axis_information_rows(T, cov[:, 3:, 3:], R_BC0, R_ME0)
    C = np.linalg.inv(np.einsum("kmi,kmj->ij", rows, rows))
    est = estimate_camera_axis(T, rot_cov=cov[:, 3:, 3:], R_BC0=R_BC0, R_ME0=R_ME0)
    np.testing.assert_allclose(C[:2, :2], est.cov_tilt_cam, rtol=1e-6)
    np.testing.assert_allclose(C[2:, 2:], est.cov_tilt_target, rtol=1e-6)
    # the planner's prediction carries the tilts: never below the one that takes them as known
    V = st.sample_poses(np.random.default_rng(4), 20)
    base, _ = D.base_mask(sc, P, np.random.default_rng(0))
    info = D.information(sc, P, base, None, 2)
    A, W = D.with_axis_tilts(sc, P, base, info.cov, V)
    assert A.shape == (15, info.A.shape[1] + 3, info.A.shape[2] + 4)
    W0 = D.validation_weight(D.validation_blocks(sc, V, base))
    idx = np.arange(15)
    assert D.validation_mse(A, idx, W) > D.validation_mse(info.A, idx, W0)
    assert D.with_axis_tilts(load_scene(UR5E), P[:0], base, info.cov, V) is None


def test_clearance_figures_change_with_the_joints():
    pytest.importorskip("fcl")
    from vision_calib.planning.plan import collision_setup

    sc = load_scene(UR5E)
    _, checker = collision_setup(sc)
    q = sc.setup.sample_poses(np.random.default_rng(4), 6)
    c = checker.clearances(sc.setup.link_frames(q))
    assert np.ptp([r["clearance_m"] for r in c]) > 1e-3
    assert ["forearm_link", "camera (T_flange_cam)"] in checker.fixed["self"]  # fixed by the wrist: left out


def test_smallest_count_finds_the_first_count_that_reaches_the_target():
    from vision_calib.errors import DataError
    from vision_calib.planning.plan import smallest_count

    seen = []

    def q(c):  # p95 falling as 1 / sqrt(c)
        seen.append(c)
        return {"p95_mm": 1.0 / np.sqrt(c)}

    for target in (0.5, 0.3, 0.2, 0.1):
        n = smallest_count(q, target, 3, 200)
        assert 1 / np.sqrt(n) <= target < 1 / np.sqrt(n - 1) or n == 3
    assert len(set(seen)) < 60  # a search, not a scan of 3..200
    with pytest.raises(DataError, match="not reached with up to 200 poses"):
        smallest_count(q, 0.01, 3, 200)


def test_length_option_reads_units():
    import argparse

    from vision_calib.cli.plan import length_m

    assert length_m("0.1mm") == pytest.approx(1e-4) and length_m("100um") == pytest.approx(1e-4)
    assert length_m("0.0001 m") == pytest.approx(1e-4) and length_m("0.1") == pytest.approx(1e-4)
    for bad in ("fast", "-1mm", "nan", "0"):
        with pytest.raises(argparse.ArgumentTypeError):
            length_m(bad)
