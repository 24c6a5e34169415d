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
  orientation and foreshortening of the edges around the corner), so it is modelled with one variance
  sigma_s^2 per pose, independent between corners (the share locked to the pixel phase, below, is
  optional).

Estimation of sigma_s, per pose: the PnP fit on the frame-averaged corners leaves the residual
r = (I - H)(b + e), H = J (J^T J)^-1 J^T the hat matrix of the 6 pose parameters (J: reprojection
Jacobian, 2K x 6). For independent errors of covariance D = diag(sigma_f^2 / n_k + sigma_s^2),
E[r^T r] = sum_i D_ii (1 - H_ii), where sum_i (1 - H_ii) = 2K - 6. Hence

    sigma_s^2 = (r^T r - sum_i (sigma_f^2 / n_i)(1 - H_ii)) / (2K - 6),   clipped at 0.

The part of b that a rigid pose can explain (J delta) is invisible in r; for independent b_k it is
accounted for by propagation: the pose error of the (unweighted) PnP is delta = (J^T J)^-1 J^T (b + e),

    Cov(delta) = (J^T J)^-1 J^T D J (J^T J)^-1      [m, rad; frames.pose_error convention].

Pixel-phase-locked corner error (ChArUco corners, cv2.cornerSubPix; ``TargetKind.phase_locked_share``). The
systematic error of a corner is nearly a periodic function of its sub-pixel position in the detector's
(distorted) pixels: on noise-free renders of the UR5e and RX-90 scenes (1500 poses each) the errors of two
corners of a pose correlate +0.91 when their separation is within 0.1 px of an integer in u and v, and -0.81
near a half-pixel one. A pose whose corners fall on similar phases (square size near a whole number of pixels
along an axis) shares its corner error between corners, which moves the pose and never shows in r: the
independent model made such poses optimistic (mean chi2/6 of the noise-free pose error 1.10, 99 % quantile 3.89
over the UR5e poses; chi2_6 / 6: 1, 2.80). With the board's sub-pixel position random, first harmonics:

    Cov(b_u,k, b_u,l) = Cov(b_v,k, b_v,l) = sigma_s^2 [rho (cos 2 pi du + cos 2 pi dv) / 2 + (1 - rho) [k = l]]

(du, dv: the corners' separation in px), i.e. 8 random amplitudes (cos and sin of 2 pi u and of 2 pi v for
each coordinate, :func:`phase_directions`) entering as columns sigma_s S0, and sigma_s^2 estimated with
E[r^T r] = sum_i (sigma_f^2 / n_i)(1 - H_ii) + sigma_s^2 (||(I - H) S0||_F^2 + (1 - rho)(2K - 6)).
rho (``TargetKind.phase_locked_share``, ``benchmarks/bench_measure.py --phase-terms``): fitting a cos 2 pi du +
b cos 2 pi dv to the pairs per 3-degree band of the board's edge angle to the pixel axes gives a + b = 0.88-0.97
(3000 random views, blur 0.6 px; 0.82-0.96 at 0.3 px, 0.83-0.94 at 1.2 px, 900 views each). The split between
the two terms depends on the edge angle and the blur (a = 0.97 at 0-3 deg and 0.29-0.31 at 9-21 deg with blur
0.6 px, 0.01-0.13 at 6-15 deg with 1.2 px), hence the even split. Same poses: mean chi2/6 1.03, 99 % quantile
2.38 (UR5e), 1.00, 2.27 (RX-90; independent: 1.03, 3.57); a split per edge angle measured at the scenes' blur
does little better (1.00 / 0.97), one measured at another blur (1.2 px) worse (1.08 / 1.04). NOT the default
(``phase_share`` 0):
on the H4 demo's views (board exactly fronto-parallel, rolls -18 / 2 / 22 deg, squares of ~33.0 px at 0.755 m,
so rows and columns share their phases) the model is optimistic, mean chi2/6 0.84 -> 1.78 (99 % quantile
6.1 -> 17; 1215 poses), and a direction per pose for each harmonic (the data show rank-one terms at a signed
angle) still gives 1.26 with the best direction: the coherent lattice also aliases what the first harmonics
leave. Opt in with ``MeasureConfig(phase_share=None)`` (the kind's measured share).

A *correlated* corner error (the same shift or scale on all corners, e.g. a depth bias) does not
show in r: a rigid pose absorbs it. Measured against the renderer's truth (:func:`corner_error_split`,
``benchmarks/bench_zscores.py --corner-bias``): with the distortion applied on the supersampled render
(``sensor.ideal_render_grid``) the mean radial corner error over 27 H4 poses is 0.0043 px or less in every
image-radius band and the pose z RMS with the independent model alone is 0.71-1.13 per component (H4 and
RX-90 scenes, 40 poses x 2 seeds). (Distorting the coarse, pixel-integrated render instead left a smooth
radial corner error of up to 0.024 px, common to all poses, that this module once modelled as a per-pose
"lens field"; it was a simulation artefact and is fixed at its source.) An optional smooth per-pose error
field over the board (a real camera's residual of its calibrated lens model) can still be modelled: scale
strain (e = eps_u x_u, eps_v x_v) and keystone (e = x (kappa . x)) as random amplitudes in px at the
pattern's edge (x = corner offset from the pattern's centroid / the largest such offset), stds
``MeasureConfig.lens_field_std`` (default :data:`LENS_FIELD_STD` = 0: none measured in simulation),
propagated like the rest:

    D = diag(sigma_f^2 / n_k + sigma_s^2) + S S^T,   S = d u / d(field terms) x their stds  (2K x 4),

and their expected share of r^T r, tr((I - H) S S^T), is removed before sigma_s is estimated.

AprilTag grids have detector errors common to the corners of a pose, which never show in r. Measured
on 30 rendered bench poses (noise-free, distortion on the supersampled render; least-squares fit per pose
of a common shift, a tag growth -- each tag looks larger by delta px at each corner, along the direction
from the tag's centre, which biases the depth -- and the smooth field terms above, compared with the leak
of the independent part into the same fit):
- the default seeded detection (straight-edge fits of each tag's border, :mod:`.tag_edges`): growth mean
  +0.002-0.003 px, RMS 0.0063-0.0067 px (leak 0.001-0.0015); shift and field terms at the leak;
- OpenCV's AprilTag refinement (``DetectConfig(batch="per_frame")``): shift mean (-0.037, -0.050) px,
  RMS (0.045, 0.055) px (leak 0.02; ``apriltag_offset_px`` = -0.5 has corrected its +0.46 to +0.49 px
  convention offset); strain and keystone 0.045-0.087 px (leak 0.036-0.074; on a second pose set
  0.033-0.053, leak 0.032-0.064); growth at the leak.
``TargetKind.bias_columns`` adds them as columns of S, per kind and corner estimator (measured with
``benchmarks/bench_measure.py --detector-terms``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import CameraIntrinsics
from ..frames import transform_points
from ..targets.kinds import KINDS
from ..targets.kinds.image_model import field_directions
from .pnp import project_pinhole, reprojection_jacobian


#: default stds [px at the pattern's edge] of a smooth per-pose corner error field: scale strain (u, v) and
#: keystone (u, v); zero: none left in simulation once the distortion is applied on the supersampled render
#: (module docstring); a real camera's lens-model residual can be given with MeasureConfig.lens_field_std
LENS_FIELD_STD = (0.0, 0.0, 0.0, 0.0)
def phase_directions(uv_dist_px: np.ndarray, share: float) -> np.ndarray:
    """(2K, 8) columns S0 of the pixel-phase-locked corner error per unit sigma_s (module docstring): b = sigma_s
    (S0 xi + sqrt(1 - share) eta), xi (8,), eta (2K,) independent N(0, 1). uv_dist_px (K, 2): the corners in the
    detector's (distorted) pixels. Columns: sqrt(share / 2) (cos 2 pi u, sin 2 pi u, cos 2 pi v, sin 2 pi v) on the
    u rows, then the same on the v rows, so that Cov(b_u,k, b_u,l) = Cov(b_v,k, b_v,l) =
    sigma_s^2 share (cos 2 pi du + cos 2 pi dv) / 2."""
    ph = 2 * np.pi * np.asarray(uv_dist_px, float)
    F = np.sqrt(share / 2) * np.column_stack([np.cos(ph[:, 0]), np.sin(ph[:, 0]), np.cos(ph[:, 1]), np.sin(ph[:, 1])])
    S0 = np.zeros((2 * len(F), 8))
    S0[0::2, :4] = F
    S0[1::2, 4:] = F
    return S0


def corner_estimator(detections) -> str:
    """"edges" when every valid detection's corners come from the seeded batch's per-frame estimator
    (diagnostics "batch": "seeded" / "full"), else "opencv" (OpenCV's own refinement, per-frame detection)."""
    ok = [d for d in detections if d.valid]
    return "edges" if ok and all(d.diagnostics.get("batch") in ("seeded", "full") for d in ok) else "opencv"


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


def pose_covariance(T_cam_target: np.ndarray, p_target: np.ndarray, mean_uv_px: np.ndarray, n_obs: np.ndarray,
                    sigma_frame_px: float, intr: CameraIntrinsics,
                    field_std=None, target_kind: str | None = None, ids=None,
                    estimator: str = "edges", phase_share: float | None = 0.0) -> PoseCovariance:
    """Covariance of the pose measured from frame-averaged corners (see the module docstring).

    T_cam_target: (4, 4) the measured pose; p_target: (K, 3) m corner points; mean_uv_px: (K, 2)
    frame-averaged undistorted corners (px); n_obs: (K,) frames per corner; sigma_frame_px: pooled
    frame-to-frame corner std (px, per coordinate; NaN with a single frame: then the random and
    systematic parts cannot be told apart and the whole residual variance is used as one sigma);
    field_std: (4,) stds of the smooth error field terms (None: :data:`LENS_FIELD_STD`); target_kind, ids
    (K,) corner ids: add the kind's detector-bias terms (``TargetKind.bias_columns``) of the corner estimator
    ("edges" | "opencv", :func:`corner_estimator`); phase_share: share of the systematic variance locked to the
    pixel phase (:func:`phase_directions`; 0: independent corners, the default; None: the kind's
    ``TargetKind.phase_locked_share``, 0 for kinds without one; used with >= 2 frames)."""
    p_target = np.asarray(p_target, dtype=float)
    n_obs = np.asarray(n_obs, dtype=float)
    J = reprojection_jacobian(T_cam_target, p_target, intr)
    r = (np.asarray(mean_uv_px, dtype=float) - project_pinhole(T_cam_target, p_target, intr)).ravel()
    dof = max(J.shape[0] - 6, 1)
    ss = float(r @ r)
    Jp = np.linalg.pinv(J.T @ J)
    h = np.einsum("ij,jk,ik->i", J, Jp, J)  # leverages H_ii
    if field_std is None:
        field_std = LENS_FIELD_STD
    uv = project_pinhole(T_cam_target, p_target, intr)
    S = field_directions(uv) * np.asarray(field_std, float)
    kind = KINDS.get(target_kind)
    if kind is not None and ids is not None:
        cols = kind.bias_columns(np.asarray(ids, dtype=int), uv, estimator)
        if cols is not None:
            S = np.column_stack([S, cols])
    S_perp = S - J @ (Jp @ (J.T @ S))
    ss_field = float(np.sum(S_perp**2))  # expected share of the strain in r^T r
    # systematic part per unit sigma_s^2: independent (nugget) + phase-locked columns S0 (module docstring)
    if phase_share is None:
        phase_share = KINDS[target_kind].phase_locked_share if target_kind in KINDS else 0.0
    if not 0.0 <= phase_share <= 1.0:
        raise ValueError(f"pose_covariance: phase_share must be in [0, 1], got {phase_share}")
    nug, S0 = np.ones(J.shape[0]), np.zeros((J.shape[0], 0))
    if phase_share > 0 and np.isfinite(sigma_frame_px):
        S0 = phase_directions(intr.project(transform_points(T_cam_target, p_target)), phase_share)
        nug = nug * (1.0 - phase_share)
    unit = float(np.sum(nug * (1.0 - h)) + np.sum((S0 - J @ (Jp @ (J.T @ S0))) ** 2))  # E[r^T r] per sigma_s^2
    if np.isfinite(sigma_frame_px):
        d_rand = np.repeat(sigma_frame_px**2 / n_obs, 2)
        sys2 = max((ss - ss_field - float(np.sum(d_rand * (1.0 - h)))) / unit, 0.0)
    else:  # one frame: the residual carries both parts
        d_rand = np.full(J.shape[0], max(ss - ss_field, 0.0) / dof)
        sys2 = 0.0
    cov_random = _sandwich(J, d_rand)
    cov = _sandwich(J, d_rand + sys2 * nug, np.column_stack([S, np.sqrt(sys2) * S0]))
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


def corner_info(target, T_cam_target, p_target, intr: CameraIntrinsics, effects, detect_config=None) -> np.ndarray:
    """(K, 2, 2) image-model Fisher information of the target's corners p_target (K, 3) seen from
    T_cam_target: the target kind's image model (``TargetKind.corner_info``, :mod:`vision_calib.targets.kinds.image_model`)."""
    from .detect import DetectConfig
    from .pnp import corner_edge_normals

    cfg = detect_config or DetectConfig()
    normals, scale = corner_edge_normals(T_cam_target, p_target, intr)
    return target.kind_impl.corner_info(target, normals, scale, effects, cfg.subpix_win)


def image_bound_pose_cov(target, intr: CameraIntrinsics, T_cam_target: np.ndarray, effects, n_frames: int = 1,
                         detect_config=None) -> np.ndarray:
    """Cramér–Rao bound (6, 6) [m, rad] of T_cam_target from the image model (sensor noise and blur, target
    contrast, detector window; not from measured frames) for the corners inside the image, n_frames
    independent frames."""
    from .pnp import pose_bound_from_corner_info

    _, p = target.corner_points()
    p = np.asarray(p, dtype=float)
    uv = project_pinhole(T_cam_target, p, intr)
    z = (p @ T_cam_target[:3, :3].T + T_cam_target[:3, 3])[:, 2]
    inside = (z > 0) & (uv[:, 0] >= -0.5) & (uv[:, 0] <= intr.width - 0.5) & (uv[:, 1] >= -0.5) \
        & (uv[:, 1] <= intr.height - 0.5)
    p = p[inside]
    F = corner_info(target, T_cam_target, p, intr, effects, detect_config)
    return pose_bound_from_corner_info(reprojection_jacobian(T_cam_target, p, intr), F, n_frames)
