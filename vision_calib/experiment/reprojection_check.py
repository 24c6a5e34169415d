"""The reprojection figures ``process`` reports, and their check against the noise model: the corners each pose's
measurement used (:func:`used_corners`), the report's point counts (:func:`label_points`, :func:`points_line`),
the robot pose error in pixels (:func:`robot_corner_variance`) and the check that points to ``--refine-intrinsics``
(:func:`reprojection_noise_check`, :data:`REPROJECTION_K`), read by the cause test (:mod:`.cause`)."""

from __future__ import annotations

import numpy as np


#: the chain's reprojection RMS above this many times what its noise model predicts, with intrinsics given (not
#: refined), is a warning pointing to --refine-intrinsics (see :func:`reprojection_noise_check`)
REPROJECTION_K = 4.0


def used_corners(dets: dict, pms, target) -> tuple[dict, dict]:
    """({pose id: [Detection]}, {pose id: (n used, n detected)}): each pose's detections with only the frames and
    corners its measurement used (``measure_pose``: frames the view rule rejected and corners it dropped left out),
    for the reprojection figures; counts over (frame, corner) pairs of target corners in valid detections."""
    from dataclasses import replace

    from ..measure.pnp import target_lookup

    lookup = target_lookup(target)
    by_id = {str(pm.pose_id): pm for pm in pms}
    out, counts = {}, {}
    for pid, ds in dets.items():
        pm = by_id.get(str(pid))
        frames = {int(f["frame_index"]): f for f in (pm.frames if pm is not None else ())}
        kept, n_used, n_all = [], 0, 0
        for d in ds or ():
            if not d.valid:
                continue
            on_target = np.array([int(i) in lookup for i in d.ids], bool)
            n_all += int(on_target.sum())
            f = frames.get(int(d.frame_index), {})
            if not f.get("valid", False):  # a frame the measurement rejected (view rule, too few corners)
                continue
            drop = {int(c["id"]) for c in f.get("dropped_corners", ())}
            m = on_target & np.array([int(i) not in drop for i in d.ids], bool)
            kept.append(replace(d, ids=d.ids[m], uv_px=d.uv_px[m], edges=None))  # (a subset: no edge refit)
            n_used += int(m.sum())
        out[pid], counts[str(pid)] = kept, (n_used, n_all)
    return out, counts


def label_points(block: dict | None, counts: dict) -> dict | None:
    """The reprojection block with the points each figure counts: per pose and overall ``n_detected`` (target
    corners detected in its frames), ``n_dropped`` (left out: corners the view rule dropped, frames it rejected)
    and ``points`` ("over N of M points" [+ "(K dropped by the view rule)"]); figures are over the used points."""
    if not block or block.get("rms_px") is None:
        return block

    def text(n, m):
        return f"over {n} of {m} points" + (f" ({m - n} dropped by the view rule: not counted)" if m > n else "")

    per = []
    for e in block["per_pose"]:
        n, m = counts.get(str(e["pose_id"]), (e["n_corners"], e["n_corners"]))
        per.append({**e, "n_detected": m, "n_dropped": m - n, "points": text(e["n_corners"], m)})
    m_all = sum(e["n_detected"] for e in per)
    worst = {str(e["pose_id"]): e for e in per}
    return {**block, "per_pose": per, "worst_poses": [worst[str(e["pose_id"])] for e in block["worst_poses"]],
            "n_detected": m_all, "n_dropped": m_all - block["n_corners"], "points": text(block["n_corners"], m_all)}


def points_line(block: dict | None) -> str:
    """'\nreprojection points: over N of M points ...; pose p: over n of m ...' (the poses with dropped points) or
    '' without a labelled block."""
    if not block or "points" not in block:
        return ""
    some = [e for e in block["per_pose"] if e.get("n_dropped")]
    return (f"\nreprojection points: the figures count the points the measurement used, {block['points']}"
            + "".join(f"; pose {e['pose_id']}: RMS {e['rms_px']:.3g} px {e['points']}" for e in some[:10]))


def robot_corner_variance(problem, x, T_model, dets_used: dict, target, camera) -> float:
    """Mean over the chain's corners of the 2-D variance [px^2] the robot's pose error in the hand-eye weights
    (``problem.meta["robot_cov"]``, (6, 6) m, rad) puts on a corner: the flange error mapped to T_cam_target
    (``flange_error_map``) then to pixels (``reprojection_jacobian``, pinhole). 0 without a robot term."""
    from ..identify.handeye_problem import flange_error_map
    from ..measure.pnp import reprojection_jacobian, target_lookup

    rc = problem.meta.get("robot_cov")
    if rc is None:
        return 0.0
    D = flange_error_map(problem, x)
    C = D @ np.asarray(rc, float) @ np.swapaxes(D, 1, 2)
    lookup = target_lookup(target)
    tot, n = 0.0, 0
    for k, lab in enumerate(problem.labels):
        for d in dets_used.get(lab, ()):
            ids = [int(i) for i in d.ids if int(i) in lookup]
            if not ids:
                continue
            J = reprojection_jacobian(T_model[k], np.array([lookup[i] for i in ids]), camera)
            tot += float(np.einsum("ij,jk,ik->", J, C[k], J))
            n += len(ids)
    return tot / n if n else 0.0


def reprojection_noise_check(block: dict | None, pms, intr: dict, robot_px2: float = 0.0, robot: dict | None = None):
    """(record, warning or None): the chain's reprojection RMS against what its noise model predicts per corner,
    sqrt(2 sigma_c^2 + robot_px2): sigma_c the corner noise the measurement assumes (pooled ``sigma_px`` of the kept
    poses, per coordinate), robot_px2 the robot pose error of the hand-eye weights in px^2 (2-D). Measured on a
    simulated RX-90 recording (12 poses, 2 frames), RMS / prediction: right intrinsics 2.1 (the per-corner
    systematic error the frame scatter does not show), fx 2 % off 7.5, no distortion 26; hand-eye with a 0.2 mm /
    0.02 deg robot error in the weights 0.75-1.0. With intrinsics given (not calibrated from these images) a warning
    names the figures and points to --refine-intrinsics when the ratio exceeds :data:`REPROJECTION_K`, or when a
    robot error *estimated* by the hand-eye fit is what explains an RMS above that many times the corner noise alone
    (``ratio_corner_noise``): such an estimate takes up whatever the chain misses, wrong intrinsics included (the
    real ViSP set: 5.73 px, 11 x its corner noise, ascribed to a 1.29 mm / 0.197 deg robot error); the poses cannot
    tell the two apart, so that case is a ``note`` in the record (printed with the reprojection line) giving the
    estimate for the user to judge, not a verdict warning. robot: the hand-eye ``robot_pose_std`` block."""
    from .camera_step import SOURCE_CALIBRATED

    if not block or block.get("rms_px") is None:
        return None, None
    sig = np.array([pm.sigma_px for pm in pms if pm.valid and np.isfinite(pm.sigma_px) and pm.sigma_px > 0])
    if not sig.size:
        return None, None
    rms, sigma_c = float(block["rms_px"]), float(np.sqrt(np.mean(sig**2)))
    expected = float(np.sqrt(2 * sigma_c**2 + robot_px2))
    ratio, ratio_c = rms / expected, rms / float(np.sqrt(2) * sigma_c)
    given = intr.get("source") != SOURCE_CALIBRATED
    estimated = bool(robot) and robot.get("source") == "estimated"
    rec = {"rms_px": rms, "expected_px": expected, "corner_noise_px": sigma_c, "robot_px": float(np.sqrt(robot_px2)),
           "ratio": ratio, "ratio_corner_noise": ratio_c, "limit": REPROJECTION_K, "intrinsics_given": given}
    k = REPROJECTION_K
    if not given or not (ratio > k or (estimated and ratio_c > k)):
        return rec, None
    head = f"reprojection RMS {rms:.3g} px {block.get('points', '')}".rstrip()
    if ratio > k:
        why = (f"{head} is {ratio:.1f} x what the noise model predicts ({expected:.3g} px: corner noise {sigma_c:.3g} px "
               "per coordinate, measured" + (f", and the robot's pose error in the weights, {np.sqrt(robot_px2):.3g} px"
                                             if robot_px2 > 0 else "") + f"; above {k:g} x)")
    else:
        why = (f"{head} is {ratio_c:.1f} x the corner noise ({np.sqrt(2) * sigma_c:.3g} px from {sigma_c:.3g} px per "
               f"coordinate, measured; above {k:g} x): the fit ascribes it to the robot's pose error, estimated from "
               f"these data at {robot['translation_mm']:.3g} mm, {robot['rotation_deg']:.3g} deg per axis "
               f"({np.sqrt(robot_px2):.3g} px); if the robot is more accurate than that, the intrinsics are the likely "
               "cause")
    text = (f"{why}: the intrinsics were given ({intr.get('source')}), not refined; calibrate them from these "
            "images (process --refine-intrinsics: >= 4 views of >= 8 corners) or from a calibration set "
            "(calibrate-camera, then process --camera FILE)")
    if ratio <= k:
        # the data explain the RMS with the estimated robot error: these poses cannot tell a robot error from
        # wrong intrinsics, so this is a printed note, not a warning (it fires on clean simulated 0.2 mm robots)
        return {**rec, "note": text}, None
    return rec, text


__all__ = ["REPROJECTION_K", "used_corners", "label_points", "points_line", "robot_corner_variance",
           "reprojection_noise_check"]
