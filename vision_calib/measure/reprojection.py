"""Reprojection error in pixels of a calibrated chain: the target corners projected through the model's
T_cam_target of each pose (robot chain, hand-eye A G_k B, ...) with the camera intrinsics (distortion
included) and compared with the corners detected in that pose's images. The figure users compare first."""

from __future__ import annotations

import numpy as np

from .. import frames
from .pnp import target_lookup


def chain_reprojection(T_cam_target_model, detections_by_label: dict, labels, target, intrinsics,
                       n_worst: int = 5) -> dict:
    """Reprojection RMS of a calibrated chain (JSON-ready).

    T_cam_target_model: (N, 4, 4) model poses [m] of the N poses ``labels`` (N,); detections_by_label:
    {label: [Detection, ...]} (the frames of each pose, distorted px; missing or invalid detections are
    skipped). Returns {rms_px: over every corner of every frame (2-D distance), n_corners, n_poses,
    per_pose: [{pose_id, rms_px, max_px, n_corners}], worst_poses: the n_worst per_pose entries with
    the largest rms_px}."""
    lookup = target_lookup(target)
    per_pose, all_sq = [], []
    for T, lab in zip(np.asarray(T_cam_target_model, float), labels):
        sq = []
        for d in detections_by_label.get(lab, ()) or ():
            if not d.valid or len(d.ids) == 0:
                continue
            keep = np.array([int(i) in lookup for i in d.ids], dtype=bool)
            if not keep.any():
                continue
            p = np.array([lookup[int(i)] for i in d.ids[keep]])
            pc = frames.transform_points(T, p)
            if np.any(pc[:, 2] <= 0):
                sq.append(np.full(int(keep.sum()), np.inf))  # behind the camera: the model is wrong there
                continue
            sq.append(np.sum((intrinsics.project(pc) - d.uv_px[keep]) ** 2, axis=1))
        if not sq:
            continue
        sq = np.concatenate(sq)
        all_sq.append(sq)
        per_pose.append({"pose_id": lab if isinstance(lab, str) else int(lab) if isinstance(lab, (int, np.integer))
                         else str(lab), "rms_px": float(np.sqrt(np.mean(sq))), "max_px": float(np.sqrt(sq.max())),
                         "n_corners": int(sq.size)})
    allc = np.concatenate(all_sq) if all_sq else np.zeros(0)
    worst = sorted(per_pose, key=lambda e: -e["rms_px"])[:max(0, int(n_worst))]
    return {"rms_px": float(np.sqrt(np.mean(allc))) if allc.size else None, "n_corners": int(allc.size),
            "n_poses": len(per_pose), "per_pose": per_pose, "worst_poses": worst}


#: the ``intrinsics`` label of a reprojection block computed with the intrinsics the fit ended at
FITTED = ("fitted: calibrated from the recording, moved by the fit's shared-error (nuisance) coefficients, "
          "the intrinsics the identified chain is consistent with")
CALIBRATED = "calibrated from the recording, before the fit (without its shared-error coefficients)"


def with_calibrated_figure(fitted_block: dict, calibrated_block: dict) -> dict:
    """The reprojection block of the fitted intrinsics (``FITTED``), with the overall figure of the same chain
    through the intrinsics calibrated before the fit beside it (``with_calibrated_intrinsics``: {rms_px,
    n_corners, intrinsics}). Both figures matter: the chain was fitted to poses consistent with the fitted
    intrinsics, so the calibrated ones show the intrinsics' error, not the robot's."""
    return {**fitted_block, "intrinsics": FITTED,
            "with_calibrated_intrinsics": {"rms_px": calibrated_block.get("rms_px"),
                                           "n_corners": calibrated_block.get("n_corners"), "intrinsics": CALIBRATED}}


def reprojection_with(T_cam_target_model, detections_by_label: dict, labels, target, intrinsics, fitted=None) -> dict:
    """:func:`chain_reprojection` with the intrinsics the fit used: ``fitted`` (CameraIntrinsics, when the
    intrinsics were calibrated from the recording and their error entered the fit) with the figure of
    ``intrinsics`` beside it (:func:`with_calibrated_figure`), else ``intrinsics``."""
    if fitted is None:
        return chain_reprojection(T_cam_target_model, detections_by_label, labels, target, intrinsics)
    return with_calibrated_figure(chain_reprojection(T_cam_target_model, detections_by_label, labels, target, fitted),
                                  chain_reprojection(T_cam_target_model, detections_by_label, labels, target,
                                                     intrinsics, n_worst=0))


def reprojection_line(block: dict) -> str:
    """One summary line of a :func:`chain_reprojection` block (both figures when it has the calibrated one)."""
    if not block or block.get("rms_px") is None:
        return "reprojection: no corner detections"
    w = ", ".join(f"{e['pose_id']} ({e['rms_px']:.2f} px)" for e in block["worst_poses"][:3])
    cal = block.get("with_calibrated_intrinsics")
    how = ""
    if cal is not None:
        other = "n/a" if cal.get("rms_px") is None else f"{cal['rms_px']:.3f} px"
        how = (f" with the intrinsics the fit ended at (calibrated + fitted shared error; {other} with the "
               "intrinsics calibrated before the fit)")
    note = (block.get("noise_check") or {}).get("note")
    return (f"reprojection: RMS {block['rms_px']:.3f} px{how} over {block['n_corners']} corners of "
            f"{block['n_poses']} poses; worst: {w}" + (f"\n  note: {note}" if note else ""))
