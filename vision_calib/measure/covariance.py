"""Pose covariance of one measured pose: a random part that averages over frames and a systematic
part that does not.

Model (per corner k, undistorted pixels, after averaging its n_k frames):

    u_k_mean = u_k(T_true) + b_k + e_k,   Cov(e_k) = sigma_f^2 / n_k I2,   Cov(b_k) = sigma_s^2 I2

- e_k, the *random* part: photon/read noise moving the detected corner from frame to frame.
  sigma_f is the pooled frame-to-frame scatter of the corners (per coordinate, px); averaging n_k
  frames divides its variance by n_k.
- b_k, the *systematic* part: the error of the detector (and of the rendering/resampling for
  simulated images) on *this* view of the corner: the same in every frame of the pose, so it does
  not average out. It changes from corner to corner with the local geometry (sub-pixel phase,
  orientation and foreshortening of the edges around the corner), so it is modelled as independent
  between corners with one variance sigma_s^2 per pose.

Estimation of sigma_s, per pose: the PnP fit on the frame-averaged corners leaves the residual
r = (I - H)(b + e), H = J (J^T J)^-1 J^T the hat matrix of the 6 pose parameters (J: reprojection
Jacobian, 2K x 6). For independent errors of covariance D = diag(sigma_f^2 / n_k + sigma_s^2),
E[r^T r] = sum_i D_ii (1 - H_ii), where sum_i (1 - H_ii) = 2K - 6. Hence

    sigma_s^2 = (r^T r - sum_i (sigma_f^2 / n_i)(1 - H_ii)) / (2K - 6),   clipped at 0.

The part of b that a rigid pose can explain (J delta) is invisible in r; for independent b_k it is
accounted for by propagation: the pose error of the (unweighted) PnP is delta = (J^T J)^-1 J^T (b + e),

    Cov(delta) = (J^T J)^-1 J^T D J (J^T J)^-1      [m, rad; frames.pose_error convention].

A *correlated* corner error (the same shift or scale on all corners, e.g. a depth bias) does not
show in r: a rigid pose absorbs it. Measured against the renderer's truth (:func:`corner_error_split`,
:func:`strain_fit`; ``benchmarks/bench_measure.py --skip speed,sweep``): without lens distortion the
part of the true corner error that moves the pose is the share independent errors predict
(|J delta| / |r| = 0.27 vs 0.28 expected, H4 scene); with distortion it is larger (0.42), and the
excess is a smooth per-pose error field over the board, found by fitting one to the true corner
errors (``strain_fit``: 6 low-order terms per pose, minus what the independent part leaks into
such a fit): a *scale strain* e = f diag(eps_u, eps_v) x, std about 1e-4 per axis (H4: 0.7e-4 / 1.7e-4;
RX-90 A5 board: 0.7e-4 / 0.9e-4), and a *keystone* term e = f x (kappa . x), std up to 1e-3 (RX-90:
0.9e-3 / 1.0e-3; H4: 0.4e-3 / 0); x = normalised image coordinates of the corner from the pattern's
centroid, f the focal length in px. Without distortion all of these are within the leak. Their origin is
the lens model chain: the image is resampled through the distortion map and the corners are undistorted
with the model, and the residual of that correction varies smoothly over the board (a real camera has
the same kind of term from the residual of its calibrated lens model). They are modelled as random with
stds :data:`LENS_FIELD_STD` (cameras with distortion; 0 without) and propagated like the rest:

    D = diag(sigma_f^2 / n_k + sigma_s^2) + S S^T,   S = d u / d(field terms) x their stds  (2K x 4),

and their expected share of r^T r, tr((I - H) S S^T), is removed before sigma_s is estimated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import CameraIntrinsics
from .pnp import project_pinhole, reprojection_jacobian


#: stds of the smooth per-pose corner error field left by the lens-distortion chain: scale strain
#: (eps_u, eps_v; dimensionless) and keystone (kappa_u, kappa_v; per unit normalised image coordinate),
#: measured on rendered H4 and RX-90 poses (see the module docstring)
LENS_FIELD_STD = (1.2e-4, 1.2e-4, 0.6e-3, 0.6e-3)


@dataclass(frozen=True)
class PoseCovariance:
    """cov: (6, 6) total [m, rad]; cov_random: (6, 6) its frame-noise part; sigma_frame_px: per-frame
    corner scatter used (px, per coordinate); sigma_sys_px: systematic per-corner std estimated from
    the averaged-corner fit (px, per coordinate); dof: 2K - 6 of that fit; residual_rms_px: RMS
    (per coordinate) of the averaged-corner residual."""

    cov: np.ndarray
    cov_random: np.ndarray
    sigma_frame_px: float
    sigma_sys_px: float
    dof: int
    residual_rms_px: float


def _sandwich(J: np.ndarray, d: np.ndarray, S: np.ndarray | None = None) -> np.ndarray:
    """(J^T J)^-1 J^T (diag(d) + S S^T) J (J^T J)^-1 for J (2K, 6), d (2K,), S (2K, m) or None."""
    A = np.linalg.pinv(J.T @ J)
    M = J.T @ (J * d[:, None])
    if S is not None:
        JS = J.T @ S
        M = M + JS @ JS.T
    return A @ M @ A


def field_directions(uv_px: np.ndarray, intr: CameraIntrinsics) -> np.ndarray:
    """(2K, 4) d(uv)/d(eps_u, eps_v, kappa_u, kappa_v) of the smooth corner error field (module
    docstring) at the corners uv_px (K, 2), rows (u0, v0, u1, v1, ...)."""
    x = (uv_px - uv_px.mean(axis=0)) / np.array([intr.fx, intr.fy])
    f = np.array([intr.fx, intr.fy])
    A = np.zeros((2 * len(x), 4))
    A[0::2, 0] = f[0] * x[:, 0]
    A[1::2, 1] = f[1] * x[:, 1]
    for j in range(2):  # keystone: e = f x (kappa . x)
        A[0::2, 2 + j] = f[0] * x[:, 0] * x[:, j]
        A[1::2, 2 + j] = f[1] * x[:, 1] * x[:, j]
    return A


def pose_covariance(T_cam_target: np.ndarray, p_target: np.ndarray, mean_uv_px: np.ndarray, n_obs: np.ndarray,
                    sigma_frame_px: float, intr: CameraIntrinsics,
                    field_std=None) -> PoseCovariance:
    """Covariance of the pose measured from frame-averaged corners (see the module docstring).

    T_cam_target: (4, 4) the measured pose; p_target: (K, 3) m corner points; mean_uv_px: (K, 2)
    frame-averaged undistorted corners (px); n_obs: (K,) frames per corner; sigma_frame_px: pooled
    frame-to-frame corner std (px, per coordinate; NaN with a single frame: then the random and
    systematic parts cannot be told apart and the whole residual variance is used as one sigma);
    field_std: (4,) stds of the smooth error field terms (None: :data:`LENS_FIELD_STD` if the camera
    has distortion, else zeros)."""
    p_target = np.asarray(p_target, dtype=float)
    n_obs = np.asarray(n_obs, dtype=float)
    J = reprojection_jacobian(T_cam_target, p_target, intr)
    r = (np.asarray(mean_uv_px, dtype=float) - project_pinhole(T_cam_target, p_target, intr)).ravel()
    dof = max(J.shape[0] - 6, 1)
    ss = float(r @ r)
    Jp = np.linalg.pinv(J.T @ J)
    h = np.einsum("ij,jk,ik->i", J, Jp, J)  # leverages H_ii
    if field_std is None:
        field_std = LENS_FIELD_STD if any(intr.dist) else (0.0,) * 4
    S = field_directions(project_pinhole(T_cam_target, p_target, intr), intr) * np.asarray(field_std, float)
    S_perp = S - J @ (Jp @ (J.T @ S))
    ss_field = float(np.sum(S_perp**2))  # expected share of the strain in r^T r
    if np.isfinite(sigma_frame_px):
        d_rand = np.repeat(sigma_frame_px**2 / n_obs, 2)
        sys2 = max((ss - ss_field - float(np.sum(d_rand * (1.0 - h)))) / dof, 0.0)
    else:  # one frame: the residual carries both parts
        d_rand = np.full(J.shape[0], max(ss - ss_field, 0.0) / dof)
        sys2 = 0.0
    cov_random = _sandwich(J, d_rand)
    cov = _sandwich(J, d_rand + sys2, S)
    return PoseCovariance(cov, cov_random, float(sigma_frame_px), float(np.sqrt(sys2)), int(dof),
                          float(np.sqrt(ss / len(r))))


def corner_error_split(T_true: np.ndarray, p_target: np.ndarray, mean_uv_px: np.ndarray,
                       intr: CameraIntrinsics) -> dict:
    """Split the true corner error e = mean_uv - u(T_true) (needs the truth: rendered data only) into
    the part a rigid pose explains (J delta, the correlated part that moves the pose) and the rest
    (what the PnP residual sees). Returns {"delta": (6,) pose error of that LS fit, "explained_rms_px",
    "orthogonal_rms_px" (per coordinate), "n": 2K}; for independent corner errors of equal variance
    E[|J delta|^2] / E[|r|^2] = 6 / (2K - 6)."""
    J = reprojection_jacobian(T_true, p_target, intr)
    e = (np.asarray(mean_uv_px, dtype=float) - project_pinhole(T_true, p_target, intr)).ravel()
    delta, *_ = np.linalg.lstsq(J, e, rcond=None)
    ex = J @ delta
    return {"delta": delta, "explained_rms_px": float(np.sqrt(np.mean(ex**2))),
            "orthogonal_rms_px": float(np.sqrt(np.mean((e - ex) ** 2))), "n": int(len(e))}
