"""Pose measurement over the N frames of one robot pose: undistort, PnP, average, covariance.

Two averaging modes (``MeasureConfig.mode``):
- ``"corners"`` (default): average each corner's undistorted position over the frames where it
  was detected, then one PnP; covariance sigma^2 (J^T W J)^-1 with W = frames per corner.
- ``"poses"``: PnP per frame, then the SE(3) mean (``frames.mean_pose``); covariance
  sigma^2 (sum_f J_f^T J_f)^-1.
sigma_px is the pooled per-coordinate scatter of the corners across frames when >= 2 frames
are valid, else the reprojection residual std (2K - 6 degrees of freedom). The covariance adds to
that random part the systematic corner error that does not average over frames
(:func:`vision_calib.measure.covariance.pose_covariance`, whose docstring gives the model).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .. import frames
from ..camera import CameraIntrinsics
from ..errors import ConfigError
from ..serialize import jsonable
from ..targets import TargetSpec
from .covariance import corner_estimator, pose_covariance
from .batch import detect_batch
from .detect import DetectConfig, Detection
from .pnp import (project_pinhole, solve_pnp_planar,
                  target_lookup, undistort_px)
from .view_checks import check_view, hull_area


@dataclass(frozen=True)
class MeasureConfig:
    """mode: "corners" | "poses". min_corners: PnP needs at least this many corners (per frame
    for "poses", averaged for "corners"). max_rms_px: reject when the final reprojection RMS (over
    all frames' corners, px) exceeds it. pnp_method: "ippe" | "sqpnp". lens_field_std: (4,) stds of
    a smooth per-pose corner error field (a lens-model residual) in the covariance (None:
    ``covariance.LENS_FIELD_STD``, zeros: none measured in simulation). phase_share: share of the systematic
    corner variance locked to the pixel phase (0, the default: independent corner errors; None: the target
    kind's ``TargetKind.phase_locked_share``, 0.92 for ChArUco's cornerSubPix corners; the module docstring of
    measure/covariance.py says where it helps and where it fails).
    min_view_corners, min_area_fraction, corner_noise_px: the per-view rule of
    :mod:`vision_calib.measure.view_checks` (>= 6 corners, or all of a smaller target; corner hull >= 10 %
    of the board's; homography consistency within multiples of the corner noise)."""

    mode: str = "corners"
    min_corners: int = 4
    max_rms_px: float = 1.5
    pnp_method: str = "ippe"
    lens_field_std: tuple | None = None
    phase_share: float | None = 0.0
    min_view_corners: int = 6
    min_area_fraction: float = 0.1
    corner_noise_px: float = 0.3

    def __post_init__(self):
        if self.mode not in ("corners", "poses"):
            raise ConfigError(f"MeasureConfig.mode must be 'corners' or 'poses', got {self.mode!r}")
        if self.pnp_method not in ("ippe", "sqpnp"):
            raise ConfigError(f"MeasureConfig.pnp_method must be 'ippe' or 'sqpnp', got {self.pnp_method!r}")
        if self.min_corners < 4:
            raise ConfigError(f"MeasureConfig.min_corners must be >= 4 (planar PnP), got {self.min_corners}")
        if not 0 <= self.min_area_fraction <= 1:
            raise ConfigError(f"MeasureConfig.min_area_fraction must be in [0, 1], got {self.min_area_fraction}")
        if not self.corner_noise_px > 0:
            raise ConfigError(f"MeasureConfig.corner_noise_px must be > 0, got {self.corner_noise_px}")
        if self.phase_share is not None and not 0 <= self.phase_share <= 1:
            raise ConfigError(f"MeasureConfig.phase_share must be in [0, 1] or None, got {self.phase_share}")
        if not self.max_rms_px > 0:
            raise ConfigError(f"MeasureConfig.max_rms_px must be > 0, got {self.max_rms_px}")


@dataclass(frozen=True, eq=False)
class PoseMeasurement:
    """Measured pose of the target in the camera for one robot pose.

    T_cam_target: (4, 4) (NaN when invalid). cov: (6, 6) covariance of the pose error
    [dt (m), dtheta (rad)] of T_cam_target (frames.pose_error convention; NaN when invalid).
    n_frames_used: frames with a valid detection that entered the average. n_corners: distinct
    corner ids used. reprojection_rms_px: RMS of the 2-D reprojection residual of the final pose
    over all used frames' corners. sigma_px: corner noise std used for cov. frames: per-frame
    diagnostics (dicts: frame_index, valid, reason, n_corners, rms_px, and the view rule's
    area_fraction, homography_rms_px, dropped_corners [{id, residual_px}])."""

    pose_id: int | str
    valid: bool
    reason: str
    T_cam_target: np.ndarray
    cov: np.ndarray
    n_frames_used: int
    n_corners: int
    reprojection_rms_px: float
    sigma_px: float = float("nan")
    mode: str = "corners"
    frames: tuple = field(default_factory=tuple)

    @property
    def std(self) -> np.ndarray:
        """(6,) standard deviations [m, m, m, rad, rad, rad]."""
        return np.sqrt(np.diag(self.cov))

    def to_dict(self) -> dict:
        return {
            "pose_id": self.pose_id if isinstance(self.pose_id, str) else int(self.pose_id),
            "valid": bool(self.valid),
            "reason": self.reason,
            "mode": self.mode,
            "T_cam_target": np.asarray(self.T_cam_target, dtype=float).tolist(),
            "cov": np.asarray(self.cov, dtype=float).tolist(),
            "n_frames_used": int(self.n_frames_used),
            "n_corners": int(self.n_corners),
            "reprojection_rms_px": float(self.reprojection_rms_px),
            "sigma_px": float(self.sigma_px),
            "frames": jsonable(list(self.frames)),
        }


def _invalid(pose_id, reason, mode, frames_diag, n_used=0, n_corners=0, rms=float("nan")) -> PoseMeasurement:
    nan4 = np.full((4, 4), np.nan)
    return PoseMeasurement(pose_id, False, reason, nan4, np.full((6, 6), np.nan), n_used, n_corners, rms,
                           float("nan"), mode, tuple(frames_diag))


def _rms(res: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(res**2, axis=1)))) if len(res) else float("nan")


def selected_corners(d: Detection, lookup: dict, drop: set | None = None) -> np.ndarray:
    """(n,) bool: the corners of detection d that are target corners (``lookup``: pnp.target_lookup) and not in
    ``drop`` (ids the view rule dropped in an earlier measurement; None: none)."""
    return np.array([int(i) in lookup and (drop is None or int(i) not in drop) for i in d.ids], dtype=bool)


def measure_pose(detections: Sequence[Detection], target: TargetSpec, intrinsics: CameraIntrinsics, pose_id=0,
                 config: MeasureConfig = MeasureConfig(), covariance: bool = True,
                 selection: Sequence[dict] | None = None) -> PoseMeasurement:
    """Average the frames of one pose into a PoseMeasurement (``target.kind`` picks the kind's corner-error
    terms, measure/covariance.py); never raises on bad frames
    (invalid frames are skipped and recorded; an unusable pose gives valid=False + reason). ConfigError for a
    target whose poses are ambiguous (a 180-degree-symmetric board, ``allow_symmetric``). covariance: False for a
    re-measurement that reads the pose only (``cov`` NaN (6, 6); pose, validity and diagnostics the same).
    selection: the per-frame diagnostics of a measurement of the same detections (``PoseMeasurement.frames``):
    each frame's validity and corner selection (the view rule's dropped corners) are kept and the view rule is
    not run again: a re-measurement under other intrinsics (a derivative) with the same data association.
    Longer than 80 lines: one pass over the frames' detections (validity, averaging, PnP, residuals, covariance, diagnostics) sharing the per-corner arrays."""
    target.check_pose_measurable()  # ConfigError: a 180-degree-symmetric board gives ambiguous poses
    lookup = target_lookup(target)
    need = max(config.min_corners, min(config.min_view_corners, len(lookup)))  # per-view rule: view_checks
    board_area = hull_area(np.array([p[:2] for p in lookup.values()]))
    fdiag = []
    obs = []  # (frame_index, ids, uv_undist)
    sel = None if selection is None else {int(f["frame_index"]): f for f in selection}
    for d in detections:
        fd = {"frame_index": int(d.frame_index), "valid": bool(d.valid), "reason": d.reason,
              "n_corners": int(d.n_corners)}
        fdiag.append(fd)
        if not d.valid:
            continue
        drop = None  # the view rule's choice of the earlier measurement (selection), else run here
        if sel is not None:
            prev = sel.get(int(d.frame_index)) or {"valid": False, "reason": "not in the earlier measurement"}
            if not prev.get("valid"):
                fd.update(valid=False, reason=prev.get("reason") or "invalid in the earlier measurement")
                continue
            fd.update({k: prev[k] for k in ("area_fraction", "homography_rms_px", "dropped_corners") if k in prev})
            drop = {int(c["id"]) for c in prev.get("dropped_corners", ())}
        keep = selected_corners(d, lookup, drop)
        if keep.sum() < config.min_corners:
            fd.update(valid=False, reason=f"too few corners: {int(keep.sum())} < {config.min_corners}")
            continue
        uv_u = undistort_px(d.uv_px[keep], intrinsics)
        if not np.all(np.isfinite(uv_u)):
            fd.update(valid=False, reason="undistortion produced non-finite coordinates")
            continue
        ids_k = d.ids[keep].astype(int)
        kv = np.ones(len(ids_k), bool)
        if drop is None:
            kv, why, vdiag = check_view(ids_k, np.array([lookup[int(i)] for i in ids_k]), uv_u, need,
                                        config.min_area_fraction, board_area, config.corner_noise_px)
            fd.update(vdiag)
            if why:
                fd.update(valid=False, reason=why)
                continue
        obs.append((len(fdiag) - 1, ids_k[kv], uv_u[kv]))
    if not obs:
        reasons = sorted({f["reason"] for f in fdiag if f["reason"]})
        return _invalid(pose_id, "no valid frame" + (f" ({'; '.join(reasons)})" if reasons else " (no frames)"),
                        config.mode, fdiag)

    # per-id statistics (undistorted px)
    all_ids = np.unique(np.concatenate([o[1] for o in obs]))
    pos = {int(i): k for k, i in enumerate(all_ids)}
    sums = np.zeros((len(all_ids), 2))
    cnt = np.zeros(len(all_ids))
    for _, ids, uv in obs:
        idx = [pos[int(i)] for i in ids]
        np.add.at(sums, idx, uv)
        np.add.at(cnt, idx, 1)
    mean_uv = sums / cnt[:, None]
    ss = 0.0
    for _, ids, uv in obs:
        idx = [pos[int(i)] for i in ids]
        ss += float(np.sum((uv - mean_uv[idx]) ** 2))
    dof_scatter = 2 * float(np.sum(cnt - 1))
    sigma_scatter = float(np.sqrt(ss / dof_scatter)) if dof_scatter > 0 else float("nan")
    p_all = np.array([lookup[int(i)] for i in all_ids])

    try:
        if config.mode == "corners":
            if len(all_ids) < config.min_corners:
                return _invalid(pose_id, f"too few corners: {len(all_ids)} < {config.min_corners}", config.mode,
                                fdiag, len(obs), len(all_ids))
            T, res_mean = solve_pnp_planar(p_all, mean_uv, intrinsics, config.pnp_method)
        else:
            Ts, kept = [], []
            for fi, ids, uv in obs:
                try:
                    Tf, rf = solve_pnp_planar(np.array([lookup[int(i)] for i in ids]), uv, intrinsics,
                                              config.pnp_method)
                except Exception as exc:  # one bad frame is skipped, not fatal
                    fdiag[fi].update(valid=False, reason=f"PnP failed: {str(exc).splitlines()[0]}")
                    continue
                fdiag[fi]["frame_pnp_rms_px"] = _rms(rf)
                fdiag[fi]["frame_T_cam_target"] = Tf.tolist()
                Ts.append(Tf)
                kept.append((fi, ids, uv))
            if not Ts:
                raise ValueError("no frame gave a PnP solution")
            obs = kept
            T = frames.mean_pose(np.array(Ts))
    except Exception as exc:  # cv2.error, ValueError, LinAlgError: a rejection, not a crash
        return _invalid(pose_id, f"PnP failed: {str(exc).splitlines()[0]}", config.mode, fdiag, len(obs), len(all_ids))

    # final-pose residuals over every used frame
    proj = project_pinhole(T, p_all, intrinsics)
    all_res = []
    cnt = np.zeros(len(all_ids))  # observations per corner in the frames actually used
    for fi, ids, uv in obs:
        idx = [pos[int(i)] for i in ids]
        np.add.at(cnt, idx, 1)
        r = uv - proj[idx]
        fdiag[fi]["rms_px"] = _rms(r)
        all_res.append(r)
    all_res = np.concatenate(all_res)
    rms = _rms(all_res)
    n_res = 2 * len(all_res)
    if len(obs) >= 2 and np.isfinite(sigma_scatter):
        sigma = sigma_scatter
    else:
        sigma = float(np.sqrt(np.sum(all_res**2) / max(n_res - 6, 1)))
    used = cnt > 0  # random (frame scatter / n) + systematic per-corner (phase-locked) + lens field: covariance.py
    cov = np.full((6, 6), np.nan) if not covariance else pose_covariance(
        T, p_all[used], mean_uv[used], cnt[used], sigma if len(obs) >= 2 else float("nan"), intrinsics,
        config.lens_field_std, target.kind, all_ids[used], corner_estimator(detections), config.phase_share).cov
    if not rms <= config.max_rms_px:
        return PoseMeasurement(pose_id, False, f"reprojection RMS {rms:.3f} px > {config.max_rms_px} px",
                               np.full((4, 4), np.nan), np.full((6, 6), np.nan), len(obs), len(all_ids), rms,
                               sigma, config.mode, tuple(fdiag))
    for fd in fdiag:
        fd.setdefault("rms_px", float("nan"))
    return PoseMeasurement(pose_id, True, "", T, cov, len(obs), len(all_ids), rms, sigma, config.mode, tuple(fdiag))


def measure_images(images, target: TargetSpec, intrinsics: CameraIntrinsics, pose_id=0,
                   detect_config: DetectConfig = DetectConfig(),
                   config: MeasureConfig = MeasureConfig()) -> tuple[PoseMeasurement, list[Detection]]:
    """Detect + measure one pose from its frames ((N, H, W) uint8 array or paths)."""
    dets = detect_batch(images, target, intrinsics, detect_config)
    return measure_pose(dets, target, intrinsics, pose_id, config), dets
