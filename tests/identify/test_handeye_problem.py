"""Hand-eye identification (flange poses known): Jacobian, closed form, recovery of truth, real ViSP data."""

import json
from types import SimpleNamespace
import os
from pathlib import Path

import numpy as np
import pytest

from vision_calib import frames
from vision_calib.errors import ConfigError, DataError
from vision_calib.identify import solve_lse
from vision_calib.identify.handeye_problem import (handeye_initial_guess, handeye_problem,
                                                   solve_handeye, stack_measurements, transforms_from_x)
from vision_calib.report.handeye import handeye_report


# ----------------------------------------------------------------------------- synthetic scenes
def _random_T(rng, t_scale, angle_max=np.pi):
    rv = rng.normal(size=3)
    rv *= rng.uniform(0.1, angle_max) / np.linalg.norm(rv)
    return frames.T_from_xyz_rotvec(np.r_[rng.normal(scale=t_scale, size=3), rv])


def _scene(rng, mount, N=15):
    """Truth (A, B), flange poses (N, 4, 4) with rotations of +-30 deg about varied axes, and the
    noise-free camera measurements M_k = A G_k B."""
    F = np.array([frames.T_from_xyz_rotvec(np.r_[rng.uniform([0.3, -0.3, 0.2], [0.7, 0.3, 0.6]),
                                                 frames.xyz_rotvec_from_T(frames.make_T(frames.rot_x(np.pi)))[3:]
                                                 + rng.normal(scale=0.3, size=3)]) for _ in range(N)])
    if mount == "fixed":
        A = frames.inv_T(frames.T_from_xyz_rpy([1.0, 0.1, 0.5], np.radians([-90, 0, 90])))  # T_cam_base
        B = _random_T(rng, 0.05)  # T_flange_target
        G = F
    else:
        A = frames.inv_T(_random_T(rng, 0.05))  # T_cam_flange
        B = frames.T_from_xyz_rpy([0.5, 0.0, 0.0], [0.0, 0.0, 0.3])  # T_base_target
        G = frames.inv_T(F)
    return A, B, F, A @ G @ B


def _random_cov(rng, N, sigma_t=1e-3, sigma_r=2e-3):
    """(N, 6, 6) anisotropic, correlated SPD covariances."""
    S = np.diag([sigma_t] * 3 + [sigma_r] * 3)
    L = S @ (np.eye(6) + 0.4 * rng.normal(size=(N, 6, 6)))
    return L @ np.swapaxes(L, 1, 2)


def _noisy(rng, M, cov):
    d = np.einsum("kij,kj->ki", np.linalg.cholesky(cov), rng.normal(size=(M.shape[0], 6)))
    return frames.perturb_pose(M, d)


# ----------------------------------------------------------------------------- Jacobian
@pytest.mark.parametrize("mount", ["fixed", "eye_in_hand"])
def test_analytic_jacobian_matches_central_differences(mount):
    rng = np.random.default_rng(1)
    A, B, F, M = _scene(rng, mount, N=6)
    pb = handeye_problem(F, _noisy(rng, M, _random_cov(rng, 6)), mount, A0=A, B0=B, sigma_t_m=1e-3,
                         sigma_rot_rad=1e-3)
    # a random point far from the nominal: large residuals (rotation ~ 0.5 rad), so the
    # inverse right Jacobian of the rotation residual matters
    x = pb.params.nominal + np.r_[rng.normal(scale=0.05, size=3), rng.normal(scale=0.3, size=3),
                                  rng.normal(scale=0.05, size=3), rng.normal(scale=0.5, size=3)]
    assert np.linalg.norm(pb.residual(x)[:, 3:], axis=1).mean() > 0.2
    J = pb.jacobian(x)
    h = 1e-6
    Jn = np.zeros_like(J)
    for i in range(12):
        e = np.zeros(12)
        e[i] = h
        Jn[:, :, i] = (pb.residual(x + e) - pb.residual(x - e)) / (2 * h)
    assert J.shape == (6, 6, 12)
    np.testing.assert_allclose(J, Jn, atol=1e-7, rtol=1e-6)
    # a subset of observations gives the same rows
    np.testing.assert_allclose(pb.jacobian(x, np.array([4, 1])), J[[4, 1]], atol=0)
    np.testing.assert_allclose(pb.residual(x, np.array([4, 1])), pb.residual(x)[[4, 1]], atol=0)


# ----------------------------------------------------------------------------- closed form
@pytest.mark.parametrize("mount", ["fixed", "eye_in_hand"])
def test_closed_form_exact_on_noise_free_data(mount):
    """The numpy closed form (OpenCV's are compared with it in tests/measure/test_handeye_closed_forms.py)."""
    rng = np.random.default_rng(2)
    A, B, F, M = _scene(rng, mount, N=8)
    A0, B0 = handeye_initial_guess(F, M, mount)
    np.testing.assert_allclose(frames.pose_error(A, A0), 0, atol=1e-7)
    np.testing.assert_allclose(frames.pose_error(B, B0), 0, atol=1e-7)


def test_closed_form_breaks_on_scrambled_pairs():
    rng = np.random.default_rng(3)
    A, B, F, M = _scene(rng, "fixed", N=8)
    A0, _ = handeye_initial_guess(F, M[rng.permutation(8)], "fixed")
    assert np.linalg.norm(frames.pose_error(A, A0)[:3]) > 1e-2


# ----------------------------------------------------------------------------- identification
@pytest.mark.parametrize("mount", ["fixed", "eye_in_hand"])
def test_recovers_truth_within_predicted_std(mount):
    rng = np.random.default_rng(4)
    N = 20
    A, B, F, M = _scene(rng, mount, N)
    cov = _random_cov(rng, N)
    Mn = _noisy(rng, M, cov)
    # start far from the truth (5 cm, ~10 deg): the LSE must still converge
    A0 = frames.perturb_pose(A, [0.05, -0.03, 0.04, 0.1, -0.12, 0.08])
    B0 = frames.perturb_pose(B, [-0.02, 0.05, 0.01, -0.15, 0.05, 0.1])
    res, Ah, Bh, pb = solve_handeye(F, Mn, mount, pose_cov=cov, A0=A0, B0=B0, labels=[f"p{k}" for k in range(N)])
    assert res.converged and res.free.all() and not res.warnings
    # whitened cost ~ chi2(6N - 12) / 2
    dof = 6 * N - 12
    assert abs(2 * res.cost_final - dof) < 5 * np.sqrt(2 * dof)
    # the truth, in the problem's own parameters, within 4 predicted std of the estimate
    # (R = R_nominal Exp(r): r = rotvec(R_nominal^T R))
    x_true = np.r_[A[:3, 3], frames.xyz_rotvec_from_T(frames.inv_T(A0) @ A)[3:],
                   B[:3, 3], frames.xyz_rotvec_from_T(frames.inv_T(B0) @ B)[3:]]
    z = (res.identified - x_true) / res.std
    assert np.all(np.abs(z) < 4), z
    assert np.all(res.std[[0, 1, 2, 6, 7, 8]] < 2e-3) and np.all(res.std[[3, 4, 5, 9, 10, 11]] < 3e-3)
    # the returned transforms are the parameters'
    A2, B2 = transforms_from_x(pb, res.identified)
    np.testing.assert_allclose(A2, Ah, atol=1e-12)
    np.testing.assert_allclose(B2, Bh, atol=1e-12)
    # closed-form start converges to the same optimum
    res2, A3, B3, _ = solve_handeye(F, Mn, mount, pose_cov=cov)
    np.testing.assert_allclose(frames.pose_error(Ah, A3), 0, atol=1e-7)
    np.testing.assert_allclose(frames.pose_error(Bh, B3), 0, atol=1e-7)
    assert res2.cost_final == pytest.approx(res.cost_final, rel=1e-6)


def test_predicted_covariance_matches_monte_carlo():
    """Over 150 noise draws the normalised error (x - x_true)^T C^-1 (x - x_true) averages 12."""
    rng = np.random.default_rng(5)
    N = 10
    A, B, F, M = _scene(rng, "fixed", N)
    cov = _random_cov(rng, N)
    pb = handeye_problem(F, M, "fixed", A0=A, B0=B, pose_cov=cov)
    x_true = pb.params.nominal.copy()
    m2 = []
    for _ in range(150):
        pbn = handeye_problem(F, _noisy(rng, M, cov), "fixed", A0=A, B0=B, pose_cov=cov)
        r = solve_lse(pbn)
        d = r.identified - x_true
        m2.append(d @ np.linalg.solve(r.covariance, d))
    m2 = np.array(m2)
    assert abs(m2.mean() - 12) < 4 * np.sqrt(2 * 12 / m2.size) * 1.5  # chi2(12): mean 12, var 24


def test_report_is_json_ready_and_consistent():
    rng = np.random.default_rng(6)
    N = 8
    A, B, F, M = _scene(rng, "eye_in_hand", N)
    res, Ah, Bh, pb = solve_handeye(F, _noisy(rng, M, _random_cov(rng, N)), "eye_in_hand",
                                    sigma_t_m=1e-3, sigma_rot_rad=2e-3)
    rep = handeye_report(res, Ah, Bh, pb)
    json.dumps(rep, allow_nan=False)
    assert rep["A"] == "T_cam_flange" and rep["B"] == "T_base_target" and rep["n_poses"] == N
    tr = rep["transforms"]
    np.testing.assert_allclose(np.array(tr["T_flange_cam"]["matrix"]), frames.inv_T(Ah), atol=1e-12)
    np.testing.assert_allclose(np.array(tr["T_target_base"]["matrix"]), frames.inv_T(Bh), atol=1e-12)
    for d in tr.values():
        T = frames.T_from_xyz_rpy(d["xyz_m"], np.radians(d["rpy_deg"]))
        np.testing.assert_allclose(T, d["matrix"], atol=1e-12)
        np.testing.assert_allclose(frames.T_from_xyz_quat(d["xyz_m"], d["quat_xyzw"]), d["matrix"], atol=1e-12)
        assert all(np.isfinite(d["std_xyz_m"])) and all(np.isfinite(d["std_rot_deg"]))
    # translation std of A is the parameter std (translation parameters are the translation itself)
    np.testing.assert_allclose(tr["T_cam_flange"]["std_xyz_m"], res.std[:3], rtol=1e-12)
    pp = rep["residuals"]["per_pose"]
    assert len(pp) == N
    t_mm = np.array([p["translation_mm"] for p in pp])
    np.testing.assert_allclose(t_mm, 1e3 * np.linalg.norm(res.residuals[:, :3], axis=1))
    assert rep["residuals"]["rms_translation_mm"] == pytest.approx(np.sqrt(np.mean(t_mm**2)))


def test_inverse_std_by_monte_carlo_propagation():
    """Std of the inverse transform (report) agrees with sampling the parameter covariance."""
    rng = np.random.default_rng(7)
    A, B, F, M = _scene(rng, "fixed", 8)
    res, Ah, Bh, pb = solve_handeye(F, _noisy(rng, M, _random_cov(rng, 8)), "fixed", sigma_t_m=2e-3,
                                    sigma_rot_rad=5e-3)
    rep = handeye_report(res, Ah, Bh, pb)
    xs = rng.multivariate_normal(res.identified, res.covariance, size=4000)
    Ainv = np.array([frames.inv_T(transforms_from_x(pb, x)[0]) for x in xs])
    e = frames.pose_error(frames.inv_T(Ah), Ainv)
    s = e.std(axis=0)
    d = rep["transforms"]["T_base_cam"]
    np.testing.assert_allclose(s[:3], d["std_xyz_m"], rtol=0.1)
    np.testing.assert_allclose(np.degrees(s[3:]), d["std_rot_deg"], rtol=0.1)


def test_single_rotation_axis_is_degenerate():
    """Rotations about one axis only: no closed form, and the LSE fixes what it cannot see."""
    N = 8
    ang = np.linspace(-1.0, 1.0, N)
    F = np.array([frames.make_T(frames.rot_z(a), [0.5 + 0.1 * np.cos(a), 0.1 * np.sin(a), 0.4])
                  @ frames.make_T(frames.rot_x(np.pi)) for a in ang])
    A = frames.inv_T(frames.T_from_xyz_rpy([1.0, 0.1, 0.5], np.radians([-80, 5, 90])))
    B = frames.T_from_xyz_rotvec([0.02, 0.01, 0.08, 0.1, 0.2, 0.3])
    M = A @ F @ B
    with pytest.raises(DataError, match="non-parallel axes"):
        handeye_initial_guess(F, M, "fixed")
    res, Ah, Bh, pb = solve_handeye(F, M, "fixed", A0=frames.perturb_pose(A, [0.01] * 6), B0=B)
    assert res.warnings and not res.free.all()
    fixed = [n for n, f in zip(res.names, res.free) if not f]
    assert all(n in " ".join(res.warnings) for n in fixed)
    rep = handeye_report(res, Ah, Bh, pb)
    json.dumps(rep, allow_nan=False)
    stds = [rep["transforms"][n][k] for n in rep["transforms"] for k in ("std_xyz_m", "std_rot_deg")]
    assert any(v is None for s in stds for v in s)  # components the fixed parameters enter


def test_stack_measurements_pools_sigma():
    cov = np.eye(6) * 1e-6
    ms = [SimpleNamespace(pose_id=k, valid=v, T_cam_target=np.eye(4), cov=cov * s**2, sigma_px=s)
          for k, (v, s) in enumerate([(True, 0.1), (True, 0.7), (False, 5.0)])]
    T, C, labels, valid = stack_measurements(ms)
    np.testing.assert_allclose(C[1], cov * 0.49)
    T, C, labels, valid = stack_measurements(ms, pool_sigma=True)
    pooled2 = (0.1**2 + 0.7**2) / 2
    np.testing.assert_allclose(C[0], cov * pooled2)
    np.testing.assert_allclose(C[1], cov * pooled2)
    np.testing.assert_allclose(C[2], cov * 25.0)  # invalid: untouched
    assert labels == (0, 1, 2) and valid.tolist() == [True, True, False] and T.shape == (3, 4, 4)


# ----------------------------------------------------------------------------- bad input
def test_bad_input_messages():
    rng = np.random.default_rng(8)
    A, B, F, M = _scene(rng, "fixed", 5)
    with pytest.raises(ConfigError, match="mount"):
        handeye_problem(F, M, "tripod")
    with pytest.raises(DataError, match="at least 3"):
        handeye_problem(F[:2], M[:2])
    with pytest.raises(DataError, match="4 poses, expected 5"):
        handeye_problem(F, M[:4])
    Mbad = M.copy()
    Mbad[3, 0, 0] = np.nan
    with pytest.raises(DataError, match="pose 3"):
        handeye_problem(F, Mbad)
    Fbad = F.copy()
    Fbad[2, :3, :3] *= 1.1
    with pytest.raises(DataError, match="T_base_flange: pose 2 is not a rigid"):
        handeye_problem(Fbad, M)
    cov = np.broadcast_to(np.eye(6) * 1e-6, (5, 6, 6)).copy()
    cov[1, 0, 0] = np.inf
    with pytest.raises(DataError, match="pose_cov of pose 1"):
        handeye_problem(F, M, A0=A, B0=B, pose_cov=cov)
    with pytest.raises(DataError, match="positive definite"):
        handeye_problem(F, M, A0=A, B0=B, sigma_t_m=1e-3, sigma_rot_rad=0.0)
    with pytest.raises(ConfigError, match="both A0 and B0"):
        handeye_problem(F, M, A0=A)
    with pytest.raises(ConfigError, match="mount"):
        handeye_initial_guess(F, M, "tripod")


# ----------------------------------------------------------------------------- real data (ViSP)
DATA = Path(os.environ["VISION_CALIB_SHARED_DATA"]) / "real" / "visp_eye_to_hand_apriltag"  # tests/conftest.py


@pytest.mark.skipif(not DATA.is_dir(), reason="real ViSP data not available")
def test_real_visp_eye_to_hand():
    from vision_calib.io.visp import read_visp_camera_xml, read_visp_pose_yaml
    from vision_calib.measure import measure_images
    from vision_calib.measure.handeye import opencv_closed_form
    from vision_calib.targets.spec import TargetSpec

    tag = TargetSpec(kind="apriltag_grid", name="franka_tag36h11_10", rows=1, cols=1,
                     dictionary="DICT_APRILTAG_36h11", tag_m=0.048, spacing_m=0.01, first_id=10)
    intr = read_visp_camera_xml(DATA / "franka_camera.xml")
    ms = [measure_images([DATA / f"franka_image-{i}.png"], tag, intr, pose_id=i)[0] for i in range(1, 9)]
    F = np.array([read_visp_pose_yaml(DATA / f"franka_pose_rPe_{i}.yaml") for i in range(1, 9)])
    T, cov, labels, valid = stack_measurements(ms, pool_sigma=True)
    assert valid.all() and labels == tuple(range(1, 9))
    # PnP covariance (one tag: pixel noise only) + 1 mm / 0.2 deg for what it does not see
    # (robot accuracy, intrinsics, tag size); a-posteriori variance factor for the stds
    res, A, B, pb = solve_handeye(F, T, "fixed", pose_cov=cov, sigma_t_m=1e-3, sigma_rot_rad=np.radians(0.2),
                                  labels=labels, scale_cov_by_residual=True)
    rep = handeye_report(res, A, B, pb)
    json.dumps(rep, allow_nan=False)
    assert res.converged and res.cost_final < res.cost_initial
    # the noise model is about right: chi2(36) / 2 within a broad band
    assert 5 < res.cost_final < 60
    r = rep["residuals"]
    assert r["rms_translation_mm"] < 3.0 and r["rms_rotation_deg"] < 2.0
    T_base_cam = rep["transforms"]["T_base_cam"]
    # camera about 1 m from the robot base, in front of it (x > 0), ~0.25 m from the flange
    assert 0.5 < np.linalg.norm(T_base_cam["xyz_m"]) < 1.5 and T_base_cam["xyz_m"][0] > 0.5
    d_cam_flange = np.linalg.norm(frames.inv_T(A)[:3, 3][None] - F[:, :3, 3], axis=1)
    assert np.all((0.1 < d_cam_flange) & (d_cam_flange < 0.6))
    # the tag sits on the flange: within 0.15 m of the flange origin
    assert np.linalg.norm(B[:3, 3]) < 0.15
    # stds finite and small: sub-2 mm / sub-1 deg for the camera, tag
    for n in ("T_base_cam", "T_flange_target"):
        d = rep["transforms"][n]
        assert np.all(np.isfinite(d["std_xyz_m"])) and max(d["std_xyz_m"]) < 3e-3
        assert max(d["std_rot_deg"]) < 1.0
    # agreement with OpenCV's closed forms within 4 std (in the frames.pose_error convention)
    for method in ("shah", "tsai"):
        A_cf, B_cf = opencv_closed_form(F, T, "fixed", method)
        for n, X, Y in (("T_base_cam", frames.inv_T(A), frames.inv_T(A_cf)), ("T_flange_target", B, B_cf)):
            d = rep["transforms"][n]
            z = frames.pose_error(X, Y) / np.r_[d["std_xyz_m"], np.radians(d["std_rot_deg"])]
            assert np.all(np.abs(z) < 4), (method, n, z)
    # wrong pairing (swapped neighbours) fits much worse
    perm = [1, 0, 3, 2, 5, 4, 7, 6]
    bad, *_ = solve_handeye(F, T[perm], "fixed", pose_cov=cov[perm], sigma_t_m=1e-3,
                            sigma_rot_rad=np.radians(0.2))
    assert bad.cost_final > 5 * res.cost_final


# ----------------------------------------------------------------------------- robot pose error
@pytest.mark.parametrize("mount", ["fixed", "eye_in_hand"])
def test_flange_error_map_matches_central_differences(mount):
    """d r / d (flange pose error) of flange_error_map against re-built problems with perturbed flange poses, at a
    point far from the solution (rotation residuals ~0.3 rad)."""
    from vision_calib.identify.handeye_problem import flange_error_map

    rng = np.random.default_rng(11)
    A, B, F, M = _scene(rng, mount, N=5)
    pb = handeye_problem(F, _noisy(rng, M, _random_cov(rng, 5)), mount, A0=A, B0=B, sigma_t_m=1e-3, sigma_rot_rad=1e-3)
    x = pb.params.nominal + np.r_[rng.normal(scale=0.03, size=3), rng.normal(scale=0.2, size=3),
                                  rng.normal(scale=0.03, size=3), rng.normal(scale=0.2, size=3)]
    D = flange_error_map(pb, x)
    h = 1e-6
    Dn = np.zeros_like(D)
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        rp = handeye_problem(frames.perturb_pose(F, e), pb.meta["T_cam_target_meas"], mount, A0=A, B0=B).residual(x)
        rm = handeye_problem(frames.perturb_pose(F, -e), pb.meta["T_cam_target_meas"], mount, A0=A, B0=B).residual(x)
        Dn[:, :, i] = (rp - rm) / (2 * h)
    np.testing.assert_allclose(D, Dn, atol=1e-8)


def test_robot_cov_enters_the_weights_and_matches_monte_carlo():
    """obs_cov = camera part + D robot_cov D^T; the residual scatter of the true parameters over flange pose errors
    drawn with robot_cov matches it (eye_in_hand, lever arm of the target included)."""
    from vision_calib.identify.handeye_problem import reweighted, robot_pose_cov

    rng = np.random.default_rng(12)
    A, B, F, M = _scene(rng, "eye_in_hand", N=4)
    rc = robot_pose_cov(5e-4, 1e-3)
    pb = handeye_problem(F, M, "eye_in_hand", A0=A, B0=B, sigma_t_m=1e-6, sigma_rot_rad=1e-6, robot_cov=rc)
    np.testing.assert_allclose(pb.meta["camera_cov"], np.broadcast_to(np.eye(6) * 1e-12, (4, 6, 6)))
    x = pb.params.nominal
    R = []
    for _ in range(3000):  # reported flange = true flange perturbed by d (the model sees the reported one)
        d = rng.normal(size=(4, 6)) * np.r_[[5e-4] * 3, [1e-3] * 3]
        R.append(handeye_problem(frames.perturb_pose(F, d), M, "eye_in_hand", A0=A, B0=B).residual(x))
    R = np.array(R)
    emp = np.einsum("ski,skj->kij", R, R) / len(R)
    np.testing.assert_allclose(emp, pb.obs_cov, atol=0.08 * np.abs(pb.obs_cov).max())
    assert reweighted(pb, x).obs_cov == pytest.approx(pb.obs_cov)
    with pytest.raises(DataError, match="robot_cov"):
        handeye_problem(F, M, "eye_in_hand", A0=A, B0=B, sigma_t_m=1e-3, sigma_rot_rad=1e-3, robot_cov=-np.eye(6))


# ----------------------------------------------------------------------------- refits from a nearby fit
@pytest.mark.parametrize("mount", ["fixed", "eye_in_hand"])
def test_gauss_newton_refit_of_a_subset_equals_the_lse_and_the_cached_residual_is_not_shared(mount):
    """The deletion test and the IRLS steps refit by Gauss-Newton from a nearby fit (identify.handeye_fit.
    gauss_newton_refit): on 11 of 12 poses, from the fit of all 12, the same minimum as solve_lse to 1e-8 std,
    with the same covariance. The problem's residual, cached for its Jacobian, is a copy the caller may change."""
    from vision_calib.identify.handeye_fit import gauss_newton_refit
    from vision_calib.identify.handeye_problem import robot_pose_cov

    rng = np.random.default_rng(11)
    A, B, F, M = _scene(rng, mount, N=12)
    cov = _random_cov(rng, 12)
    Mn = _noisy(rng, M, cov)
    full = handeye_problem(F, Mn, mount, A0=A, B0=B, pose_cov=cov, robot_cov=robot_pose_cov(2e-4, 3e-4))
    x_all = solve_lse(full).identified
    A1, B1 = transforms_from_x(full, x_all)
    keep = [k for k in range(12) if k != 4]
    sub = handeye_problem(F[keep], Mn[keep], mount, A0=A1, B0=B1, pose_cov=cov[keep],
                          robot_cov=robot_pose_cov(2e-4, 3e-4))
    x0 = sub.params.nominal
    ref = solve_lse(sub, x0)
    x, cov = gauss_newton_refit(sub, x0, with_cov=True)
    assert np.max(np.abs(x - x0) / ref.std) > 0.01  # pose 4 moved the fit
    assert np.max(np.abs(x - ref.identified) / ref.std) < 1e-8
    np.testing.assert_allclose(cov, ref.covariance, rtol=1e-7, atol=1e-9 * np.abs(ref.covariance).max())
    r = sub.residual(x)
    r[:] = 0.0
    assert np.abs(sub.residual(x)).max() > 0
    assert gauss_newton_refit(sub, x0, max_iter=1) is None  # not settled in one step: the caller runs the LSE


# ----------------------------------------------------------------------------- all leave-one-out fits at once
@pytest.mark.parametrize("mount", ["fixed", "eye_in_hand"])
def test_batched_model_equals_the_problem_closures(mount):
    """identify.handeye_problem.model_many at K parameter vectors equals the problem's residual, Jacobian and flange error
    map at each of them (one pose per row too)."""
    from vision_calib.identify.handeye_problem import model_many
    from vision_calib.identify.handeye_problem import flange_error_map

    rng = np.random.default_rng(4)
    A, B, F, M = _scene(rng, mount, N=7)
    pb = handeye_problem(F, _noisy(rng, M, _random_cov(rng, 7)), mount, A0=A, B0=B, pose_cov=_random_cov(rng, 7))
    X = pb.params.nominal + rng.normal(scale=0.01, size=(3, 12))
    r, J, D = model_many(pb, X)
    for k, x in enumerate(X):
        np.testing.assert_allclose(r[k], pb.residual(x), atol=1e-14)
        np.testing.assert_allclose(J[k], pb.jacobian(x), atol=1e-12)
        np.testing.assert_allclose(D[k], flange_error_map(pb, x), atol=1e-12)
    r1, J1, D1 = model_many(pb, X, poses=[4, 0, 6])
    for k, p in enumerate([4, 0, 6]):
        np.testing.assert_allclose(r1[k, 0], r[k, p], atol=1e-15)
        np.testing.assert_allclose(J1[k, 0], J[k, p], atol=1e-15)
        np.testing.assert_allclose(D1[k, 0], D[k, p], atol=1e-15)


@pytest.mark.parametrize("mount, estimate, chunk", [("fixed", True, 4096), ("eye_in_hand", True, 20),
                                                    ("eye_in_hand", False, 4096)])
def test_leave_one_out_at_once_equals_the_fits_one_by_one(mount, estimate, chunk, monkeypatch):
    """The deletion test's N fits without one pose each, batched (identify.handeye_loo.leave_one_out: chunks of
    subsets too) against handeye_fit.deletion_fit run per subset, with an outlier among the poses and the robot's
    variances re-estimated or not: the same parameters (1e-8 std), covariance, variances and deletion
    statistics (against experiment.handeye_step.pose_statistic)."""
    import vision_calib.identify.handeye_loo as loo
    from vision_calib.experiment.handeye_step import all_poses_problem, pose_statistic
    from vision_calib.identify.handeye_fit import deletion_fit, fit_handeye
    from vision_calib.identify.handeye_problem import x_from_transforms

    monkeypatch.setattr(loo, "LOO_CHUNK", chunk)
    rng = np.random.default_rng(9)
    N = 12
    A, B, F, M = _scene(rng, mount, N=N)
    cov = _random_cov(rng, N, 2e-4, 4e-4)
    Fr = frames.perturb_pose(F, np.concatenate([rng.normal(scale=3e-4, size=(N, 3)),
                                                rng.normal(scale=5e-4, size=(N, 3))], axis=1))  # robot error
    Mn = _noisy(rng, M, cov)
    Mn[5] = frames.perturb_pose(Mn[5], np.r_[0.01, 0, 0, 0, 0.02, 0])  # an outlier
    labels = [f"p{k}" for k in range(N)]
    fit = fit_handeye(Fr, Mn, mount, cov, labels, None if estimate else (3e-4, 5e-4))
    theta = np.square([fit.robot["translation_mm"] * 1e-3, np.radians(fit.robot["rotation_deg"])])
    allp = all_poses_problem(Fr, Mn, mount, cov, fit.A, fit.B)
    X, C, th, ok = loo.leave_one_out(allp, x_from_transforms(allp, fit.A, fit.B), theta, estimate)
    d = loo.deletion_statistics(allp, X, C, th)
    assert ok.all()
    for k in range(N):
        rest = [j for j in range(N) if j != k]
        _, rk, thk = deletion_fit(Fr[rest], Mn[rest], mount, cov[rest], [labels[j] for j in rest], fit.A, fit.B,
                                  theta, estimate)
        std = np.sqrt(np.diag(rk.covariance))
        assert np.max(np.abs(X[k] - rk.identified) / std) < 1e-8
        np.testing.assert_allclose(C[k], rk.covariance, rtol=1e-7, atol=1e-9 * np.abs(rk.covariance).max())
        np.testing.assert_allclose(th[k], thk, rtol=1e-6)
        ref = pose_statistic(Fr, Mn, mount, cov, k, fit.A, fit.B, (rk.identified, rk.covariance,
                                                                   np.asarray(rk.free, bool), thk), allp)
        assert d[k] == pytest.approx(ref, rel=1e-7)
    assert int(np.argmax(d)) == 5  # the outlier stands out


def test_candidate_costs_batched_equal_the_weighted_cost_one_by_one():
    """identify.handeye_fit.candidate_costs: the weighted cost of each closed form at its own weights (robot pose
    error given) and under the problem's weights, equal to weighted_cost of the reweighted problem, one by one; with
    a pose mask, the cost of the subset's own problem; with the whitening W given, the cost under those weights."""
    from vision_calib.identify.handeye_fit import candidate_costs, weighted_cost
    from vision_calib.identify.handeye_problem import reweighted, robot_pose_cov

    rng = np.random.default_rng(12)
    A, B, F, M = _scene(rng, "eye_in_hand", N=9)
    cov = _random_cov(rng, 9)
    R = robot_pose_cov(3e-4, 5e-4)
    pb = handeye_problem(F, _noisy(rng, M, cov), "eye_in_hand", A0=A, B0=B, pose_cov=cov, robot_cov=R)
    X = pb.params.nominal + rng.normal(scale=0.02, size=(5, 12))
    own = candidate_costs(pb, X, R)
    fixed = candidate_costs(pb, X)
    for k, x in enumerate(X):
        assert own[k] == pytest.approx(weighted_cost(reweighted(pb, x, R), x), rel=1e-12)
        assert fixed[k] == pytest.approx(weighted_cost(pb, x), rel=1e-12)
    assert not np.allclose(own, fixed)
    keep = [0, 2, 3, 7, 8]
    mask = np.isin(np.arange(9), keep)[None]
    masked = candidate_costs(pb, X, R, mask=mask)
    given = candidate_costs(pb, X, W=pb.whitening()[None], mask=mask)
    for k, x in enumerate(X):
        assert masked[k] == pytest.approx(weighted_cost(reweighted(pb, x, R).subset(keep), x), rel=1e-12)
        assert given[k] == pytest.approx(weighted_cost(pb.subset(keep), x), rel=1e-12)


@pytest.mark.parametrize("mount, estimate", [("fixed", True), ("eye_in_hand", True), ("eye_in_hand", False)])
def test_subset_fits_at_once_reach_the_fits_from_the_closed_forms(mount, estimate):
    """identify.handeye_loo.subset_fits (the held-out folds' training sets, fitted together from the fit of all the
    poses) against fit_handeye of each subset alone (started from its closed forms): the same minimum to the
    iteration's tolerance (1e-3 std each, so 1e-2 std here), the same robot variances (1 %), and the same
    covariance; the start of the iteration (the fit of all) is far from each subset's minimum."""
    from vision_calib.experiment.handeye_step import all_poses_problem
    from vision_calib.identify.handeye_fit import fit_handeye
    from vision_calib.identify.handeye_loo import subset_fits
    from vision_calib.identify.handeye_problem import x_from_transforms
    from vision_calib.measure.handeye import closed_forms

    rng = np.random.default_rng(21)
    N = 15
    A, B, F, M = _scene(rng, mount, N=N)
    cov = _random_cov(rng, N, 2e-4, 4e-4)
    Fr = frames.perturb_pose(F, np.concatenate([rng.normal(scale=3e-4, size=(N, 3)),
                                                rng.normal(scale=5e-4, size=(N, 3))], axis=1))
    Mn = _noisy(rng, M, cov)
    labels = [f"p{k}" for k in range(N)]
    given = None if estimate else (3e-4, 5e-4)
    fit = fit_handeye(Fr, Mn, mount, cov, labels, given)
    theta = np.square([fit.robot["translation_mm"] * 1e-3, np.radians(fit.robot["rotation_deg"])])
    allp = all_poses_problem(Fr, Mn, mount, cov, fit.A, fit.B)
    subsets = [np.arange(0, 12), np.arange(3, 15), np.r_[0:5, 8:15]]
    mask = np.zeros((3, N), bool)
    for j, s in enumerate(subsets):
        mask[j, s] = True
    X, C, th, ok = subset_fits(allp, x_from_transforms(allp, fit.A, fit.B), theta, estimate, mask)
    assert ok.all()
    x_all = x_from_transforms(allp, fit.A, fit.B)
    for j, s in enumerate(subsets):
        ref = fit_handeye(Fr[s], Mn[s], mount, cov[s], [labels[i] for i in s], given,
                          candidates=closed_forms(Fr[s], Mn[s], mount))
        xr = x_from_transforms(allp, ref.A, ref.B)
        std = np.sqrt(np.diag(C[j]))
        assert np.max(np.abs(x_all - xr) / std) > 0.05  # the start is not the answer
        assert np.max(np.abs(X[j] - xr) / std) < 1e-2
        np.testing.assert_allclose(std, ref.result.std, rtol=1e-2)
        t_ref = np.square([ref.robot["translation_mm"] * 1e-3, np.radians(ref.robot["rotation_deg"])])
        np.testing.assert_allclose(th[j], t_ref, rtol=1e-2)


def test_linearized_deletion_equals_the_exact_leave_one_out_with_given_weights():
    """identify.handeye_loo.linearized_deletion (closed form, O(N)) against leave_one_out (each subset refitted by
    Gauss-Newton) with the robot's variances given: the same fits without each pose (1e-2 std), covariances (1 %)
    and deletion statistics (1 %), the corrupted pose standing out in both."""
    import vision_calib.identify.handeye_loo as loo
    from vision_calib.experiment.handeye_step import all_poses_problem
    from vision_calib.identify.handeye_fit import fit_handeye
    from vision_calib.identify.handeye_problem import x_from_transforms

    rng = np.random.default_rng(9)
    N = 40
    A, B, F, M = _scene(rng, "fixed", N=N)
    cov = _random_cov(rng, N, 2e-4, 4e-4)
    Fr = frames.perturb_pose(F, np.concatenate([rng.normal(scale=3e-4, size=(N, 3)),
                                                rng.normal(scale=5e-4, size=(N, 3))], axis=1))
    Mn = _noisy(rng, M, cov)
    Mn[5] = frames.perturb_pose(Mn[5], np.r_[0.01, 0, 0, 0, 0.02, 0])
    fit = fit_handeye(Fr, Mn, "fixed", cov, [f"p{k}" for k in range(N)], (3e-4, 5e-4))
    allp = all_poses_problem(Fr, Mn, "fixed", cov, fit.A, fit.B)
    x = x_from_transforms(allp, fit.A, fit.B)
    X, C, th, ok = loo.leave_one_out(allp, x, fit.robot_variances, False)
    d = loo.deletion_statistics(allp, X, C, th)
    Xl, Cl, dl = loo.linearized_deletion(allp, x, fit.robot_variances)
    assert ok.all()
    std = np.sqrt(np.einsum("nii->ni", C))
    assert np.max(np.abs(X - Xl) / std) < 1e-2
    np.testing.assert_allclose(Cl, C, rtol=1e-2, atol=1e-2 * np.abs(C).max())
    np.testing.assert_allclose(dl, d, rtol=1e-2)
    assert int(np.argmax(dl)) == int(np.argmax(d)) == 5
