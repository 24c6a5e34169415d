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


def reprojection_line(block: dict) -> str:
    """One summary line of a :func:`chain_reprojection` block."""
    if not block or block.get("rms_px") is None:
        return "reprojection: no corner detections"
    w = ", ".join(f"{e['pose_id']} ({e['rms_px']:.2f} px)" for e in block["worst_poses"][:3])
    return (f"reprojection: RMS {block['rms_px']:.3f} px over {block['n_corners']} corners of {block['n_poses']} "
            f"poses; worst: {w}")
