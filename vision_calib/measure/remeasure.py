"""Re-measuring a pose under other intrinsics, light: the derivative of a measurement with respect to the camera
(``experiment.camera_step.remeasure``: the shared error of intrinsics calibrated from the same images).

:func:`remeasurable` keeps, once per pose, what :func:`~vision_calib.measure.pose.measure_pose` with
``selection=`` would read again for each camera: the raw pixels of the corners the measurement used (its frames and
corner selection), their target points and the measured pose. :func:`remeasure_pose` then undistorts them with the
camera given (one call for all the frames), averages them per corner as ``measure_pose`` does, and refines the pose
from the measured one (``pnp.refine_pnp_planar``: the same minimum as IPPE + refinement). Where anything is
unusual (a non-finite undistortion, a failed refinement, a reprojection RMS over the limit) it returns None and the
caller runs ``measure_pose``, whose verdict and message stand.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .. import frames
from ..camera import CameraIntrinsics
from ..targets import TargetSpec
from .detect import Detection
from .pnp import pinhole, project_pinhole, refine_pnp_many, refine_pnp_planar, target_lookup, undistort_px
from .pose import MeasureConfig, PoseMeasurement, selected_corners


@dataclass(frozen=True)
class Remeasurable:
    """One valid pose measurement kept for :func:`remeasure_pose`: uv_raw (M, 2) px, the detected (distorted) pixels
    of the corners it used, its used frames stacked in order; frame (M,) int, each pixel's frame (0..F-1 over the
    used frames); corner (M,) int, its corner (index into p_target); p_target (C, 3) m; mode ("corners": one PnP on
    the per-corner means, "poses": one per frame, then their mean pose); T_start (4, 4) the measured pose, or
    (F, 4, 4) the frames' poses (mode "poses"); max_rms_px (the measurement's limit)."""

    uv_raw: np.ndarray
    frame: np.ndarray
    corner: np.ndarray
    p_target: np.ndarray
    mode: str
    T_start: np.ndarray
    max_rms_px: float


def remeasurable(detections: Sequence[Detection], target: TargetSpec, pm: PoseMeasurement,
                 config: MeasureConfig = MeasureConfig()) -> Remeasurable | None:
    """What :func:`remeasure_pose` needs of the measurement ``pm`` of these detections (its frames and corner
    selection, ``pm.frames``); None when pm is not valid or its frames cannot be matched to the detections."""
    if not pm.valid:
        return None
    lookup = target_lookup(target)
    sel = {int(f["frame_index"]): f for f in pm.frames}
    uv, ids, fidx, starts = [], [], [], []
    for d in detections:
        prev = sel.get(int(d.frame_index))
        if not d.valid or prev is None or not prev.get("valid"):
            continue
        keep = selected_corners(d, lookup, {int(c["id"]) for c in prev.get("dropped_corners", ())})
        if keep.sum() < config.min_corners:
            return None
        uv.append(np.asarray(d.uv_px, float)[keep])
        ids.append(d.ids[keep].astype(int))
        fidx.append(np.full(int(keep.sum()), len(starts)))
        starts.append(prev.get("frame_T_cam_target"))
    if not uv or (config.mode != "corners" and any(s is None for s in starts)):
        return None
    all_ids, corner = np.unique(np.concatenate(ids), return_inverse=True)
    T0 = np.asarray(pm.T_cam_target, float) if config.mode == "corners" else np.array(starts, float)
    return Remeasurable(np.concatenate(uv), np.concatenate(fidx), corner.reshape(-1),
                        np.array([lookup[int(i)] for i in all_ids]), config.mode, T0, float(config.max_rms_px))


def _corner_means(rm: Remeasurable, uv: np.ndarray) -> np.ndarray:
    """(C, 2) px: the mean of each corner's undistorted pixels uv (M, 2) over the frames, summed in frame order as
    ``measure_pose`` sums them."""
    n = rm.p_target.shape[0]
    sums, cnt = np.zeros((n, 2)), np.zeros(n)
    np.add.at(sums, rm.corner, uv)
    np.add.at(cnt, rm.corner, 1)
    return sums / cnt[:, None]


def remeasure_pose(rm: Remeasurable, intrinsics: CameraIntrinsics) -> np.ndarray | None:
    """T_cam_target (4, 4) of the pose ``rm`` re-measured with ``intrinsics`` (module docstring); None where the
    caller must run ``measure_pose`` (a non-finite undistortion, a failed refinement, RMS over the limit)."""
    uv = undistort_px(rm.uv_raw, intrinsics)
    if not np.all(np.isfinite(uv)):
        return None
    try:
        if rm.mode == "corners":
            T, _ = refine_pnp_planar(rm.p_target, _corner_means(rm, uv), intrinsics, rm.T_start)
        else:
            Ts = [refine_pnp_planar(rm.p_target[rm.corner[rm.frame == f]], uv[rm.frame == f], intrinsics, T0)[0]
                  for f, T0 in enumerate(rm.T_start)]
            T = frames.mean_pose(np.array(Ts))
    except Exception:  # cv2.error, ValueError: the full measurement says why
        return None
    r = uv - project_pinhole(T, rm.p_target, intrinsics)[rm.corner]
    rms = float(np.sqrt(np.mean(np.sum(r**2, axis=1))))
    return T if rms <= rm.max_rms_px else None


def remeasure_many(rms: Sequence[Remeasurable], intrinsics: CameraIntrinsics) -> list[np.ndarray | None]:
    """[T_cam_target (4, 4) or None] of :func:`remeasure_pose` for each of ``rms``, the poses of mode "corners" at
    once: their pixels undistorted in one call, their per-corner means, and one batched Gauss-Newton refinement
    from the measured poses (``pnp.refine_pnp_many``: the same minimum); a pose it does not settle, and the poses of
    mode "poses", by :func:`remeasure_pose`. None as there (the caller runs ``measure_pose``)."""
    out: list = [None] * len(rms)
    batch = [k for k, rm in enumerate(rms) if rm.mode == "corners"]
    for k in sorted(set(range(len(rms))) - set(batch)):
        out[k] = remeasure_pose(rms[k], intrinsics)
    if not batch:
        return out
    uv_all = undistort_px(np.concatenate([rms[k].uv_raw for k in batch]), intrinsics)
    cut = np.cumsum([0] + [len(rms[k].uv_raw) for k in batch])
    C = max(rms[k].p_target.shape[0] for k in batch)
    P, M, Wt = np.zeros((len(batch), C, 3)), np.zeros((len(batch), C, 2)), np.zeros((len(batch), C))
    P[..., 2] = 1.0  # padding: a point in front of the camera, weight 0
    ok = np.ones(len(batch), bool)
    for j, k in enumerate(batch):
        rm, uv = rms[k], uv_all[cut[j]:cut[j + 1]]
        if not np.all(np.isfinite(uv)):
            ok[j] = False
            continue
        n = rm.p_target.shape[0]
        P[j, :n], M[j, :n], Wt[j, :n] = rm.p_target, _corner_means(rm, uv), 1.0
    T, settled = refine_pnp_many(P, M, Wt, intrinsics, np.array([rms[k].T_start for k in batch]))
    proj = pinhole(P @ np.swapaxes(T[:, :3, :3], 1, 2) + T[:, None, :3, 3], intrinsics)  # each pixel at its pose's T
    owner = np.repeat(np.arange(len(batch)), np.diff(cut))
    r2 = np.sum((uv_all - proj[owner, np.concatenate([rms[k].corner for k in batch])]) ** 2, axis=1)
    rms_px = np.sqrt(np.bincount(owner, r2, len(batch)) / np.diff(cut))
    for j, k in enumerate(batch):
        if ok[j]:
            out[k] = remeasure_pose(rms[k], intrinsics) if not settled[j] else (
                T[j] if rms_px[j] <= rms[k].max_rms_px else None)
    return out


__all__ = ["Remeasurable", "remeasurable", "remeasure_pose", "remeasure_many"]
