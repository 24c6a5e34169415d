"""H4 camera axis from the measured nacelle rotation axis (seed 000 §4.1): exact recovery,
z-scores against the predicted covariance, and its effect on the identification."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from vision_calib.errors import DataError
from vision_calib.frames import perturb_pose, skew, so3_exp
from vision_calib.identify import solve_lse
from vision_calib.identify.camera_axis import estimate_camera_axis, robot_with_camera_axis
from vision_calib.identify.h4_problem import h4_igm_problem, synthetic_h4_measurements
from vision_calib.kinematics import h4_variants
from vision_calib.kinematics.h4 import random_workspace_poses
from vision_calib.kinematics.h4_camera import yaw_of
from vision_calib.kinematics.h4_io import load_h4_robot

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "robots" / "h4.yaml"
EZ = np.array([0.0, 0.0, 1.0])
SIG_T, SIG_R, SIG_Q = 2e-4, np.deg2rad(0.03), 1e-4  # paper §5: about 0.2 mm and 0.03 deg


@pytest.fixture(scope="module")
def r12():
    return load_h4_robot(SCENE)


def tilted(robot, rng, cam_deg=0.5, target_deg=0.3):
    """Truth robot with a camera tilt of cam_deg (random direction orthogonal to the camera's
    nominal z_B axis, camera frame) and a target tilt of target_deg; returns (robot, w_cam)."""
    d = rng.normal(size=2)
    w = np.deg2rad(cam_deg) * d / np.linalg.norm(d)
    e = rng.normal(size=2)
    wt = np.deg2rad(target_deg) * e / np.linalg.norm(e)
    truth = replace(robot, R_BC0=robot.R_BC0 @ so3_exp(np.r_[w, 0.0]), R_ME0=so3_exp(np.r_[wt, 0.0]) @ robot.R_ME0)
    return truth, w


def noisy(T, rng):
    N = len(T)
    return perturb_pose(T, np.concatenate([rng.normal(0, SIG_T, (N, 3)), rng.normal(0, SIG_R, (N, 3))], 1))


def test_exact_axes_from_noise_free_poses(r12):
    truth, w = tilted(r12, np.random.default_rng(0))
    X = r12.pose_grid()
    est = estimate_camera_axis(truth.camera_measurement(X), rot_cov=1e-8 * np.eye(3))
    np.testing.assert_allclose(est.z_B_cam, truth.R_BC0.T @ EZ, atol=1e-12)
    np.testing.assert_allclose(est.n_target, truth.T_target_nacelle()[:3, :3] @ EZ, atol=1e-12)
    np.testing.assert_allclose(est.tilt_cam_rad, w, atol=1e-12)
    np.testing.assert_allclose(est.theta_rad, X[:, 3] - X[0, 3], atol=1e-12)
    # the robot built from it reproduces the true camera axis and target normal exactly
    r = robot_with_camera_axis(r12, est)
    np.testing.assert_allclose(r.R_BC0.T @ EZ, truth.R_BC0.T @ EZ, atol=1e-12)
    np.testing.assert_allclose(r.T_target_nacelle()[:3, :3] @ EZ, est.n_target, atol=1e-12)
    # and its camera yaw stays with B_T_C.theta: the pose is the truth's up to a z-rotation
    dR = r.T_base_cam()[:3, :3] @ truth.T_base_cam()[:3, :3].T
    np.testing.assert_allclose(dR @ EZ, EZ, atol=1e-12)


def test_tilt_recovered_within_predicted_std(r12):
    """0.5 deg camera tilt, 81 poses with paper-level noise: z-scores over 20 seeds."""
    chi2, chi2_n, est_sig = [], [], []
    for seed in range(20):
        rng = np.random.default_rng(100 + seed)
        truth, w = tilted(r12, rng)
        T = noisy(truth.camera_measurement(r12.pose_grid()), rng)
        est = estimate_camera_axis(T, rot_cov=SIG_R**2 * np.eye(3))
        e = est.tilt_cam_rad - w
        chi2.append(e @ np.linalg.solve(est.cov_tilt_cam, e))
        en = est.n_target - truth.T_target_nacelle()[:3, :3] @ EZ
        U = np.linalg.svd(est.cov_n_target)[0][:, :2]  # its tangent plane (the covariance has rank 2)
        chi2_n.append((U.T @ en) @ np.linalg.solve(U.T @ est.cov_n_target @ U, U.T @ en))
        est_sig.append(estimate_camera_axis(T).sigma_r_rad)  # noise level from the residuals
    std_deg = np.rad2deg(est.tilt_cam_std_rad)
    print(f"\ncamera tilt 0.5 deg, 81 poses, sigma_r 0.03 deg: predicted std {std_deg.round(4)} deg; "
          f"mean chi2 (2 dof) camera {np.mean(chi2):.2f}, target {np.mean(chi2_n):.2f}")
    # 40 dof in all: the mean of chi2_2 over 20 seeds is 2 +- 0.45; 1..3.4 fails < 1 % of the time
    assert 1.0 < np.mean(chi2) < 3.4
    assert 1.0 < np.mean(chi2_n) < 3.4
    assert np.all(np.array(chi2) < 18.4)  # chi2_2 quantile 0.9999
    assert np.all(std_deg < 0.02) and np.all(std_deg > 0.005)  # the precision the grid gives (about 0.012)
    np.testing.assert_allclose(np.mean(est_sig), SIG_R, rtol=0.05)


def test_needs_different_theta(r12):
    X = r12.pose_grid()
    T = r12.camera_measurement(X[X[:, 3] == 0])
    with pytest.raises(DataError, match="different theta"):
        estimate_camera_axis(T)
    with pytest.raises(DataError, match="at least 2"):
        estimate_camera_axis(T[:1])
    with pytest.raises(DataError, match=r"\(N, 4, 4\)"):
        estimate_camera_axis(T[:, :3])


def _validation_error_mm(robot, seed, tilt_deg, use_estimate):
    """RMS position error (mm) of the FGM of the identified model on 100 validation poses,
    after identifying variant D from the noisy 81-pose grid of a truth with a camera tilt."""
    rng = np.random.default_rng(seed)
    x_true = robot.params.nominal.copy()
    f = robot.params.free_index
    x_true[f] += 3.0 * robot.params.scale[f] * rng.standard_normal(len(f))
    truth, _ = tilted(robot, rng, tilt_deg, 0.0)
    q, T = synthetic_h4_measurements(truth, robot.pose_grid(), x_true, rng, SIG_Q, SIG_T, SIG_R)
    init = robot
    if use_estimate:
        init = robot_with_camera_axis(robot, estimate_camera_axis(T, SIG_R**2 * np.eye(3), robot.R_BC0, robot.R_ME0))
    cov = np.diag([SIG_T**2] * 3 + [SIG_R**2] * 3)
    res = solve_lse(h4_igm_problem(init, q, T, sigma_q_rad=SIG_Q, pose_cov=cov))
    Xv = random_workspace_poses(100, np.random.default_rng(1000 + seed))
    e = np.linalg.norm(init.fgm(truth.igm(Xv, x_true), res.identified)[:, :3] - Xv[:, :3], axis=1)
    return 1e3 * np.sqrt(np.mean(e**2))


def test_estimated_axis_restores_accuracy_under_a_camera_tilt(r12):
    """Same seeds (same parameters, noise and poses) with no tilt, with an unmodelled 0.5 deg
    tilt, and with the tilt estimated from the rotation axis before identification."""
    robot = h4_variants.variant(r12, "D")
    seeds = range(5)
    base = np.mean([_validation_error_mm(robot, s, 0.0, False) for s in seeds])
    blind = np.mean([_validation_error_mm(robot, s, 0.5, False) for s in seeds])
    fixed = np.mean([_validation_error_mm(robot, s, 0.5, True) for s in seeds])
    print(f"\nvalidation RMS position error, variant D, 81 noisy poses, 5 seeds: no tilt {base:.3f} mm, "
          f"0.5 deg tilt unmodelled {blind:.3f} mm, 0.5 deg tilt estimated first {fixed:.3f} mm")
    assert base < 1.0  # noise-limited
    assert blind > 5.0 * base  # the tilt matters (about 10 mm per degree at 0.7 m)
    assert fixed < 2.0 * base


# ----------------------------------------------------------------------------- dense reference
# The estimator as it was before the per-pose nacelle angles were eliminated (Schur complement): one
# Gauss-Newton step solves the whole whitened (3N, 4 + N) system with lstsq, the covariance is the 4 x 4
# block of inv(J^T J). Self-contained (O(N^3)): only here to check the O(N) solver gives the same answer.
def _rotvec(R):
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_rotvec()


def _rz(phi):
    c, s, z, o = np.cos(phi), np.sin(phi), np.zeros_like(phi), np.ones_like(phi)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def _basis(a):
    u = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    return np.column_stack([u, np.cross(a, u)])


def _min_rot(a, b):
    v = np.cross(a, b)
    s = np.linalg.norm(v)
    return np.eye(3) if s < 1e-15 else so3_exp(v / s * np.arctan2(s, a @ b))


def _axis(Q, ref):
    M = Q - np.eye(3)
    a = np.linalg.eigh(np.einsum("kji,kjl->il", M, M))[1][:, 0]
    return a if a @ ref >= 0 else -a


def dense_camera_axis(T, rot_cov, R_BC0, R_ME0, max_iter=20):
    """Dense Gauss-Newton: {c, n, cov_c, cov_n, cov_tilt_cam, cov_tilt_target, theta, r, sigma}."""
    R, N = T[:, :3, :3], len(T)
    c_nom, n_nom = R_BC0.T @ EZ, R_ME0 @ EZ
    A = _min_rot(c_nom, _axis(R @ R[0].T, c_nom)) @ R_BC0.T
    B = (_min_rot(n_nom, _axis(np.swapaxes(R[0], -1, -2) @ R, n_nom)) @ R_ME0).T
    phi = yaw_of(A.T @ R @ B.T)
    S = np.broadcast_to(np.eye(3) if rot_cov is None else rot_cov, (N, 3, 3))
    W = np.swapaxes(np.linalg.cholesky(np.linalg.inv(S)), -1, -2)

    def system(A, B, phi):
        Rm = A @ _rz(phi) @ B
        r = _rotvec(R @ np.swapaxes(Rm, -1, -2))
        Uc, Un = _basis(A @ EZ), _basis(B.T @ EZ)
        J = np.zeros((N, 3, 4 + N))
        J[:, :, 0:2], J[:, :, 2:4] = -Uc, -Rm @ Un
        J[np.arange(N), :, 4 + np.arange(N)] = -(A @ EZ)
        return np.einsum("kij,kjn->kin", W, J).reshape(3 * N, -1), np.einsum("kij,kj->ki", W, r).ravel(), r, Uc, Un

    for _ in range(max_iter):
        Jw, rw, r, Uc, Un = system(A, B, phi)
        step = -np.linalg.lstsq(Jw, rw, rcond=None)[0]
        A, B, phi = so3_exp(Uc @ step[0:2]) @ A, B @ so3_exp(Un @ step[2:4]), phi + step[4:]
        if np.abs(step).max() < 1e-13:
            break
    Jw, rw, r, Uc, Un = system(A, B, phi)
    s2 = rw @ rw / (2 * N - 3) if rot_cov is None else 1.0
    C = np.linalg.inv(Jw.T @ Jw) * s2
    c, n = A @ EZ, B.T @ EZ
    Gc, Gn = -skew(c) @ Uc, -skew(n) @ Un
    cov_c, cov_n = Gc @ C[0:2, 0:2] @ Gc.T, Gn @ C[2:4, 2:4] @ Gn.T
    Tc, Tn = -np.eye(3)[:, :2].T @ skew(c_nom), np.eye(3)[:, :2].T @ skew(n_nom)
    return {"z_B_cam": c, "n_target": n, "cov_z_B_cam": cov_c, "cov_n_target": cov_n,
            "cov_tilt_cam": Tc @ cov_c @ Tc.T, "cov_tilt_target": Tn @ cov_n @ Tn.T,
            "theta_rad": np.unwrap(phi) - phi[0], "residuals_rad": r, "sigma_r_rad": np.sqrt(s2)}


def _random_spd(rng, n, sigma):
    """n random covariances (n, 3, 3), eigenvalues sigma^2 * [0.2, 5], random orientations."""
    Q = np.linalg.qr(rng.normal(size=(n, 3, 3)))[0]
    return sigma**2 * np.einsum("kij,kj,klj->kil", Q, rng.uniform(0.2, 5.0, (n, 3)), Q)


@pytest.mark.parametrize("case", ["per_pose", "one_cov", "estimated"])
@pytest.mark.parametrize("seed", range(3))
def test_schur_solver_equals_dense_reference(r12, case, seed):
    """Random truth tilts, nominal tilts, 10..200 random poses with per-pose anisotropic rotation noise:
    the O(N) estimator gives the dense solver's axes, angles, residuals and covariances to ~1e-10."""
    rng = np.random.default_rng(40 + seed)
    N = [10, 60, 200][seed]
    truth, _ = tilted(r12, rng, cam_deg=rng.uniform(0.1, 2.0), target_deg=rng.uniform(0.1, 2.0))
    R_BC0, R_ME0 = (r12.R_BC0 @ so3_exp(np.r_[rng.normal(0, 0.01, 2), 0.0]),
                    so3_exp(np.r_[rng.normal(0, 0.01, 2), 0.0]) @ r12.R_ME0)  # nominal != truth != default
    cov = _random_spd(rng, N, SIG_R)
    if case == "one_cov":  # one (3, 3) covariance for all poses
        cov = np.broadcast_to(cov[0], (N, 3, 3))
    T = truth.camera_measurement(random_workspace_poses(N, rng))
    delta = np.einsum("kij,kj->ki", np.linalg.cholesky(cov), rng.normal(size=(N, 3)))
    T = perturb_pose(T, np.concatenate([np.zeros((N, 3)), delta], 1))
    rot_cov = {"per_pose": cov, "one_cov": cov[0], "estimated": None}[case]
    est = estimate_camera_axis(T, rot_cov, R_BC0, R_ME0)
    ref = dense_camera_axis(T, None if rot_cov is None else np.broadcast_to(rot_cov, (N, 3, 3)), R_BC0, R_ME0)
    assert est.estimated_sigma == (case == "estimated")
    for key in ("z_B_cam", "n_target", "theta_rad", "residuals_rad"):
        np.testing.assert_allclose(getattr(est, key), ref[key], rtol=0, atol=1e-10, err_msg=key)
    for key in ("cov_z_B_cam", "cov_n_target", "cov_tilt_cam", "cov_tilt_target"):
        scale = np.abs(ref[key]).max()
        np.testing.assert_allclose(getattr(est, key), ref[key], rtol=0, atol=1e-10 * scale, err_msg=key)
    if case == "estimated":
        np.testing.assert_allclose(est.sigma_r_rad, ref["sigma_r_rad"], rtol=1e-10)
    np.testing.assert_allclose(est.rms_residual_rad, np.sqrt(np.mean(np.sum(ref["residuals_rad"] ** 2, 1))),
                               rtol=1e-9)
    # the residuals are at the noise level the covariances predict (a fit of the data, not only equal to the
    # reference): chi2 (2N - 3 dof) below its 0.999 quantile
    assert est.consistency(cov)["p_value"] > 1e-3
