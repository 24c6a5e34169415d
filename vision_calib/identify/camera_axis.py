"""H4: camera and target tilt from the measured rotation axis of the nacelle (seed 000 §4.1).

The nacelle only rotates about z_B. With the H4Robot conventions (kinematics/h4.py)

    R_CM,k = R_BC^T Rz(theta_k) R_ME^T          (rotation of the measured T_cam_target, pose k)

so every relative rotation R_CM,i R_CM,j^T = R_BC^T Rz(theta_i - theta_j) R_BC turns about the
same axis c = R_BC^T e_z (z_B in the camera frame), and R_CM,j^T R_CM,i about n = R_ME e_z
(the rotation axis, i.e. the nacelle normal, in the target frame). Both are fixed by the
rotations alone, before any identification, once two poses differ in theta: the paper
measures the camera axis this way and identifies only the yaw B_T_C.theta.

Estimator: maximum likelihood (Gauss-Newton) on all N measured rotations at once, model
R_CM,k = A Rz(phi_k) B with A = R_BC^T, B = R_ME^T; unknowns: the 2 tilt angles of c, the 2 of
n and the N nacelle angles phi_k (their common offset and the yaws of A and B are gauge). Each phi_k
only enters its own pose's 3 residuals: it is eliminated in closed form (Schur complement), so each
Gauss-Newton step solves a 4-unknown problem and costs O(N) time and memory.
Measurement noise: R_meas = exp([delta]) R_CM, delta ~ N(0, Sigma_r) in the camera frame
(the :func:`vision_calib.frames.perturb_pose` convention). Starting point: the eigenvector of
least eigenvalue of sum_k (Q_k - I)^T (Q_k - I), Q_k the relative rotations to a reference pose.
The covariance of c and n is the inverse of the Gauss-Newton normal matrix (Sigma_r given) or
that matrix scaled by the residual variance (Sigma_r estimated from the residuals).

:func:`robot_with_camera_axis` turns the estimate into an H4Robot whose fixed tilts R_BC0,
R_ME0 carry the measured axes (the yaws stay with B_T_C.theta / M_T_E.theta, identified later).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from ..errors import DataError
from ..frames import skew, so3_exp
from ..kinematics.h4 import H4Robot
from ..kinematics.h4_camera import yaw_of

EZ = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class CameraAxisEstimate:
    """Result of :func:`estimate_camera_axis`.

    z_B_cam (3,): unit rotation axis z_B in the camera frame; cov_z_B_cam (3, 3) (rank 2).
    n_target (3,): unit rotation axis (nacelle normal) in the target frame; cov_n_target (3, 3).
    tilt_cam_rad (2,), cov_tilt_cam (2, 2): camera tilt w (components along the camera x and y
    axes, rad) relative to the nominal: R_BC0 = R_BC0_nominal so3_exp(w), i.e. z_B_cam =
    so3_exp(-w) R_BC0_nominal^T e_z (w orthogonal to that axis).
    tilt_target_rad (2,), cov_tilt_target (2, 2): rotation vector (target x and y components,
    rad) taking the nominal axis R_ME0_nominal e_z to n_target (M_T_E.theta = 0 in the nominal).
    theta_rad (N,): nacelle angles relative to the first pose. sigma_r_rad: rotation noise std
    used (given, or estimated from the residuals when ``estimated_sigma``). rms_residual_rad:
    RMS of the rotation residuals. theta_span_rad: max - min of theta_rad.
    """

    z_B_cam: np.ndarray
    cov_z_B_cam: np.ndarray
    n_target: np.ndarray
    cov_n_target: np.ndarray
    tilt_cam_rad: np.ndarray
    cov_tilt_cam: np.ndarray
    tilt_target_rad: np.ndarray
    cov_tilt_target: np.ndarray
    theta_rad: np.ndarray
    sigma_r_rad: float
    estimated_sigma: bool
    rms_residual_rad: float
    theta_span_rad: float
    residuals_rad: np.ndarray = None  #: (N, 3) rotation residuals delta_k at the solution, camera frame

    def consistency(self, rot_cov: ArrayLike) -> dict:
        """Is the nacelle's rotation axis fixed within the noise? Chi-square of the residuals against
        ``rot_cov`` (N, 3, 3) or (3, 3) rad^2 (camera frame, the measurements' predicted rotation noise):
        {chi2, dof (= 2N - 3), chi2_dof, p_value}; chi2 None (not tested) when rot_cov is not positive
        definite (e.g. exact synthetic data). A fixed axis gives chi2_dof ~ 1; an axis that moves with the
        pose (a nacelle that tilts, a mount that flexes) leaves rotation residuals far above the noise."""
        from scipy.stats import chi2 as chi2_dist

        r = np.asarray(self.residuals_rad, float)
        N = len(r)
        S = np.broadcast_to(np.asarray(rot_cov, float), (N, 3, 3))
        dof = 2 * N - 3
        if dof <= 0 or not np.all(np.isfinite(S)) or np.any(np.linalg.eigvalsh(S) <= 0):
            return {"chi2": None, "dof": int(dof), "chi2_dof": None, "p_value": None}
        q = float(np.einsum("ki,ki->", r, np.linalg.solve(S, r[..., None])[..., 0]))
        return {"chi2": q, "dof": int(dof), "chi2_dof": q / dof, "p_value": float(chi2_dist.sf(q, dof))}

    @property
    def tilt_cam_std_rad(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov_tilt_cam))

    @property
    def tilt_target_std_rad(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov_tilt_target))

    def summary(self) -> str:
        tc, sc = np.rad2deg(self.tilt_cam_rad), np.rad2deg(self.tilt_cam_std_rad)
        tt, st = np.rad2deg(self.tilt_target_rad), np.rad2deg(self.tilt_target_std_rad)
        return (f"camera tilt (x, y) = ({tc[0]:+.4f} +- {sc[0]:.4f}, {tc[1]:+.4f} +- {sc[1]:.4f}) deg; "
                f"target tilt (x, y) = ({tt[0]:+.4f} +- {st[0]:.4f}, {tt[1]:+.4f} +- {st[1]:.4f}) deg; "
                f"theta span {np.rad2deg(self.theta_span_rad):.1f} deg, rotation residual RMS "
                f"{np.rad2deg(self.rms_residual_rad) * 3600:.1f} arcsec")


def _min_rotation(a, b) -> np.ndarray:
    """Smallest rotation (3, 3) taking unit vector a to unit vector b."""
    v = np.cross(a, b)
    s, c = np.linalg.norm(v), float(np.dot(a, b))
    if s < 1e-15:
        if c > 0:
            return np.eye(3)
        raise DataError("camera axis estimate is opposite to the nominal axis (check R_BC0 / R_ME0)")
    return so3_exp(v / s * np.arctan2(s, c))


def _tangent_basis(a) -> np.ndarray:
    """(3, 2) orthonormal basis of the plane orthogonal to unit vector a."""
    u = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    return np.column_stack([u, np.cross(a, u)])


def _common_axis(Q, ref) -> np.ndarray:
    """Least-squares common axis of rotations Q (K, 3, 3): argmin_|a|=1 sum |(Q_k - I) a|^2,
    sign chosen along ref."""
    M = Q - np.eye(3)
    w, V = np.linalg.eigh(np.einsum("kji,kjl->il", M, M))
    a = V[:, 0]
    return a if a @ ref >= 0 else -a


def _rotvec(R) -> np.ndarray:
    """Rotation vectors (..., 3) of rotation matrices (..., 3, 3) (log map)."""
    from scipy.spatial.transform import Rotation

    sh = R.shape[:-2]
    return Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(sh + (3,))


def _check_input(T_cam_target, rot_cov):
    T = np.asarray(T_cam_target, float)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise DataError(f"T_cam_target must have shape (N, 4, 4), got {T.shape}")
    if not np.all(np.isfinite(T)):
        raise DataError(f"T_cam_target {int(np.argwhere(~np.isfinite(T))[0][0])} contains a non-finite value")
    if len(T) < 2:
        raise DataError("the camera axis needs at least 2 poses that differ in theta")
    if rot_cov is not None:
        rot_cov = np.broadcast_to(np.asarray(rot_cov, float), (len(T), 3, 3))
        if np.any(np.linalg.eigvalsh(rot_cov) <= 0):
            raise DataError("rot_cov must be positive definite (rad^2)")
    return T[:, :3, :3], rot_cov


def estimate_camera_axis(T_cam_target: ArrayLike, rot_cov: ArrayLike | None = None, R_BC0: ArrayLike | None = None,
                         R_ME0: ArrayLike | None = None, min_theta_span_deg: float = 2.0,
                         max_iter: int = 20) -> CameraAxisEstimate:
    """Rotation axis of the nacelle in the camera and in the target frame from measured poses.

    T_cam_target: (N, 4, 4) measured target poses (only the rotations are used). rot_cov:
    (3, 3) or (N, 3, 3) covariance (rad^2) of the rotation error, camera frame (perturb_pose
    convention); None -> isotropic, its variance estimated from the residuals (needs N >= 3).
    R_BC0, R_ME0: nominal tilts of the robot (default Rx(pi), H4Robot's defaults): they fix the
    sign of the axes and the frame of the tilt angles. Raises DataError when the measured
    nacelle angles span less than min_theta_span_deg (the axis is then not determined).
    """
    R, rot_cov = _check_input(T_cam_target, rot_cov)
    N = len(R)
    R_BC0 = np.diag([1.0, -1.0, -1.0]) if R_BC0 is None else np.asarray(R_BC0, float)
    R_ME0 = np.diag([1.0, -1.0, -1.0]) if R_ME0 is None else np.asarray(R_ME0, float)
    c_nom, n_nom = R_BC0.T @ EZ, R_ME0 @ EZ
    c = _common_axis(R @ R[0].T, c_nom)
    n = _common_axis(np.swapaxes(R[0], -1, -2) @ R, n_nom)
    A = _min_rotation(c_nom, c) @ R_BC0.T
    B = (_min_rotation(n_nom, n) @ R_ME0).T
    phi = yaw_of(A.T @ R @ B.T)
    span = np.ptp(np.unwrap(phi))
    if span < np.deg2rad(min_theta_span_deg):
        raise DataError(f"the measured nacelle angles span {np.rad2deg(span):.2f} deg (< {min_theta_span_deg} deg): "
                        "the rotation axis is not determined; measure poses at different theta")
    W = np.eye(3)[None].repeat(N, 0) if rot_cov is None else np.linalg.cholesky(np.linalg.inv(rot_cov))
    W = np.swapaxes(W, -1, -2)  # W^T W = Sigma^-1
    for _ in range(max_iter):
        Gp, Prw, Gw, hw, rw, r, Uc, Un = _system(R, A, B, phi, W)
        dx = -np.linalg.lstsq(Gp.reshape(3 * N, 4), Prw.ravel(), rcond=None)[0]
        dphi = _back_substitute(Gw, hw, rw, dx)
        A = so3_exp(Uc @ dx[0:2]) @ A
        B = B @ so3_exp(Un @ dx[2:4])
        phi = phi + dphi
        if max(np.abs(dx).max(), np.abs(dphi).max()) < 1e-13:
            break
    Gp, Prw, Gw, hw, rw, r, Uc, Un = _system(R, A, B, phi, W)
    estimated = rot_cov is None
    dof = 3 * N - (4 + N - 1)
    s2 = 1.0
    if estimated:
        if dof <= 0:
            raise DataError("estimating the rotation noise from the residuals needs at least 3 poses")
        s2 = float(np.sum(rw * rw)) / dof
    # the common offset of phi is not a gauge here (A and B yaws are excluded from the basis), so J is full
    # rank; the marginal covariance of the 4 shared unknowns is the inverse of the Schur complement Gp^T Gp
    C = np.linalg.inv(np.einsum("kij,kil->jl", Gp, Gp)) * s2
    return replace(_finish(A, B, phi, Uc, Un, C, R_BC0, R_ME0, np.sqrt(s2) if estimated else float("nan"),
                           estimated, float(np.sqrt(np.mean(np.sum(r * r, 1))))), residuals_rad=r)


def axis_information_rows(T_cam_target: ArrayLike, rot_cov: ArrayLike, R_BC0: ArrayLike | None = None,
                          R_ME0: ArrayLike | None = None) -> np.ndarray:
    """(N, 3, 4) whitened rows, per pose, of the axis fit of :func:`estimate_camera_axis` on the 4 tilt angles
    (camera x/y, target x/y, rad; the estimate's ``tilt_cam_rad``, ``tilt_target_rad``) at exact rotations
    T_cam_target (N, 4, 4) (e.g. the nominal model's) with rotation noise rot_cov (3, 3) or (N, 3, 3) rad^2 (camera
    frame), each pose's nacelle angle eliminated: sum_k rows_k^T rows_k is the inverse of the tilts' covariance the
    estimate gives for those poses (first order), additive over poses (what a pose design adds to the axis prior)."""
    R, rot_cov = _check_input(T_cam_target, rot_cov)
    R_BC0 = np.diag([1.0, -1.0, -1.0]) if R_BC0 is None else np.asarray(R_BC0, float)
    R_ME0 = np.diag([1.0, -1.0, -1.0]) if R_ME0 is None else np.asarray(R_ME0, float)
    c_nom, n_nom = R_BC0.T @ EZ, R_ME0 @ EZ
    A = _min_rotation(c_nom, _common_axis(R @ R[0].T, c_nom)) @ R_BC0.T
    B = (_min_rotation(n_nom, _common_axis(np.swapaxes(R[0], -1, -2) @ R, n_nom)) @ R_ME0).T
    phi = yaw_of(A.T @ R @ B.T)
    W = np.swapaxes(np.linalg.cholesky(np.linalg.inv(rot_cov)), -1, -2)
    Gp, _, _, _, _, _, Uc, Un = _system(R, A, B, phi, W)
    c, n = A @ EZ, B.T @ EZ
    # tilt = J a for the tangent unknowns a (as in _finish): J = blockdiag(Tc Gc, Tn Gn)
    J = np.zeros((4, 4))
    J[0:2, 0:2] = _tilt(c_nom, c, -np.eye(3)[:, :2])[1] @ (-skew(c) @ Uc)
    J[2:4, 2:4] = _tilt(n_nom, n, np.eye(3)[:, :2])[1] @ (-skew(n) @ Un)
    return Gp @ np.linalg.inv(J)


def _system(R, A, B, phi, W):
    """Whitened Gauss-Newton system of the rotation model at (A, B, phi), by pose (O(N) time and memory).

    The full Jacobian (3N, 4 + N) has, for pose k, the block Gw_k (3, 4) on the 4 shared unknowns (the 2
    tilts of the camera axis, the 2 of the target axis) and the column hw_k (3,) on its own phi_k only.
    Eliminating phi_k (Schur complement) projects pose k's rows on the orthogonal complement of hw_k:
    P_k = I - hw_k hw_k^T / |hw_k|^2, Gp_k = P_k Gw_k, Prw_k = P_k rw_k; the reduced least-squares problem
    min |Gp dx + Prw| (3N rows, 4 unknowns) gives the same dx as the full one, and Gp^T Gp is the Schur
    complement (the inverse of the marginal covariance of the 4 shared unknowns).
    Returns Gp (N, 3, 4), Prw (N, 3), Gw (N, 3, 4), hw (N, 3), rw (N, 3) (whitened residuals),
    r (N, 3) (raw residuals delta_k, camera frame, rad) and the tangent bases Uc, Un (3, 2) of the axes.
    """
    Rm = A @ _rz(phi) @ B
    r = _rotvec(R @ np.swapaxes(Rm, -1, -2))  # (N, 3): delta at the solution
    Uc, Un = _tangent_basis(A @ EZ), _tangent_basis(B.T @ EZ)
    G = np.empty((len(R), 3, 4))
    G[:, :, 0:2] = -Uc  # A <- exp([Uc a]) A
    G[:, :, 2:4] = -Rm @ Un  # B <- B exp([Un b])
    Gw = W @ G
    hw = -W @ (A @ EZ)  # Rz(phi_k + dphi)
    rw = np.einsum("kij,kj->ki", W, r)
    u = hw / np.linalg.norm(hw, axis=1, keepdims=True)
    Gp = Gw - u[:, :, None] * np.einsum("ki,kij->kj", u, Gw)[:, None, :]
    Prw = rw - u * np.einsum("ki,ki->k", u, rw)[:, None]
    return Gp, Prw, Gw, hw, rw, r, Uc, Un


def _back_substitute(Gw, hw, rw, dx) -> np.ndarray:
    """Per-pose phi steps (N,) for the shared step dx (4,): argmin_dphi_k |Gw_k dx + hw_k dphi_k + rw_k|."""
    return -np.einsum("ki,ki->k", hw, Gw @ dx + rw) / np.einsum("ki,ki->k", hw, hw)


def _rz(phi):
    c, s = np.cos(phi), np.sin(phi)
    z, o = np.zeros_like(phi), np.ones_like(phi)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def _finish(A, B, phi, Uc, Un, C, R_BC0, R_ME0, sigma, estimated, rms):
    c, n = A @ EZ, B.T @ EZ
    # c moves by w x c for a rotation w = Uc a of A: dc/da = -skew(c) Uc; same for n with B^T
    Gc, Gn = -skew(c) @ Uc, -skew(n) @ Un
    cov_c, cov_n = Gc @ C[0:2, 0:2] @ Gc.T, Gn @ C[2:4, 2:4] @ Gn.T
    # tilt angles: rotation vector taking the nominal axis to the estimate, components on the
    # nominal frame's x, y axes (first order in the covariance)
    c_nom, n_nom = R_BC0.T @ EZ, R_ME0 @ EZ
    tc, Tc = _tilt(c_nom, c, -np.eye(3)[:, :2])
    tn, Tn = _tilt(n_nom, n, np.eye(3)[:, :2])
    cov_tc, cov_tn = Tc @ cov_c @ Tc.T, Tn @ cov_n @ Tn.T
    th = np.unwrap(phi) - phi[0]
    return CameraAxisEstimate(c, cov_c, n, cov_n, tc, cov_tc, tn, cov_tn, th,
                              float(sigma), estimated, rms, float(np.ptp(th)))


def _tilt(a_nom, a, axes):
    """Components on axes (3, 2) of the rotation vector a_nom -> a, and its derivative wrt a (2, 3)."""
    v = np.cross(a_nom, a)
    s, cth = np.linalg.norm(v), float(a_nom @ a)
    ang = np.arctan2(s, cth)
    rv = v * (ang / s) if s > 1e-15 else v
    # first order: rv ~ a_nom x a near a_nom (tilts are small)
    return axes.T @ rv, axes.T @ skew(a_nom)


def robot_with_camera_axis(robot: H4Robot, est: CameraAxisEstimate, target: bool = True) -> H4Robot:
    """Copy of robot whose fixed tilts carry the measured axes: R_BC0 <- R_BC0 M with M the
    smallest rotation taking est.z_B_cam to the robot's current axis R_BC0^T e_z (then
    R_BC0^T e_z = est.z_B_cam; the camera yaw stays in B_T_C.theta). With target=True also
    R_ME0 <- M' R_ME0 so that Rz(M_T_E.theta) R_ME0 e_z = est.n_target at the robot's nominal
    M_T_E.theta (the target tilt only enters the measured yaw, to second order)."""
    c_cur = robot.R_BC0.T @ EZ
    R_BC0 = robot.R_BC0 @ _min_rotation(est.z_B_cam, c_cur)
    out = replace(robot, R_BC0=R_BC0)
    if target:
        th = robot.params.values()["M_T_E.theta"]
        m = _rz(np.array([-th]))[0] @ est.n_target
        out = replace(out, R_ME0=_min_rotation(robot.R_ME0 @ EZ, m) @ robot.R_ME0)
    return out
