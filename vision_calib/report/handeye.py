"""The hand-eye block of report.json (``process_handeye``; :mod:`.report` is the one builder, this is its
hand-eye part): the identified transforms and their inverses with their std, the residuals per pose, the
reprojection through the calibrated chain."""

from __future__ import annotations

import numpy as np

from .. import frames
from ..frames import so3_right_jacobian
from ..identify.handeye_problem import INVERSE_NAMES
from ..identify.problem import IdentificationProblem, IdentificationResult
from ..measure.reprojection import chain_reprojection


def _mount_error_map(T: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(6, 6) map from mount parameter deviations [dt, dr] to frames.pose_error(T, T') [m, rad]
    (rotation right-multiplied: dtheta = R Jr(r) dr)."""
    L = np.eye(6)
    L[3:, 3:] = T[:3, :3] @ so3_right_jacobian(r)
    return L


def _transform_dict(T: np.ndarray, cov: np.ndarray | None, unknown: np.ndarray | None = None) -> dict:
    """xyz/rpy/quat/matrix of T, and stds from cov (6, 6); components flagged in unknown (6,) -> None."""
    xyz, rpy = frames.xyz_rpy_from_T(T)
    _, q = frames.xyz_quat_from_T(T)
    d = {"xyz_m": xyz.tolist(), "rpy_deg": np.degrees(rpy).tolist(), "quat_xyzw": q.tolist(), "matrix": T.tolist()}
    if cov is not None:
        s = np.sqrt(np.clip(np.diag(cov), 0, None))
        s[3:] = np.degrees(s[3:])
        unknown = np.zeros(6, bool) if unknown is None else unknown
        vals = [None if u or not np.isfinite(v) else float(v) for v, u in zip(s, unknown)]
        d["std_xyz_m"] = vals[:3]
        d["std_rot_deg"] = vals[3:]  # small rotation about the parent frame's axes
    return d


def handeye_report(result: IdentificationResult, A, B, problem: IdentificationProblem, detections=None,
                   target=None, intrinsics=None) -> dict:
    """JSON-ready summary of a hand-eye identification.

    ``transforms``: for A, B and their inverses (named after the frames, e.g. ``T_cam_base`` and
    ``T_base_cam``): xyz [m], rpy [deg] (R = Rz(yaw) Ry(pitch) Rx(roll)), quaternion (x, y, z, w),
    4x4 matrix, and the standard deviations of the pose error in the frames.pose_error
    convention (translation [m] and small rotation [deg] about the axes of the transform's
    parent frame; None for a component that a fixed (non-identifiable) parameter enters).
    ``parameters``: the raw parameter table (:meth:`IdentificationResult.to_dict`). ``noise``: the
    observation noise model used. ``residuals``: per pose, translation norm [mm] and rotation
    angle [deg] (measured - model), plus their RMS and max. ``reprojection`` (when ``detections``
    {pose label: [Detection per frame]}, ``target`` and ``intrinsics`` are given): the target corners
    projected through the calibrated chain A G_k B of each pose vs the detected corners, RMS px overall,
    per pose and the worst poses (:func:`vision_calib.measure.reprojection.chain_reprojection`).
    """
    A = np.asarray(A, float)
    B = np.asarray(B, float)
    x = result.identified
    std = result.std
    # full (12, 12) covariance, zeros for fixed parameters
    C = np.zeros((12, 12))
    fi = np.flatnonzero(result.free)
    if result.covariance.shape == (fi.size, fi.size):
        C[np.ix_(fi, fi)] = result.covariance
    fixed = ~np.asarray(result.free, bool)
    nA, nB = problem.meta["A_name"], problem.meta["B_name"]
    transforms = {}
    for name, T, sl in ((nA, A, slice(0, 6)), (nB, B, slice(6, 12))):
        L = _mount_error_map(T, x[sl][3:])
        G = frames.inverse_error_map(T)
        cov = L @ C[sl, sl] @ L.T
        # a component is unknown when a fixed (non-identifiable) parameter enters it
        unk = (np.abs(L) @ fixed[sl]) > 0
        unk_inv = (np.abs(G) @ np.abs(L) @ fixed[sl]) > 0
        transforms[name] = _transform_dict(T, cov, unk)
        transforms[INVERSE_NAMES[name]] = _transform_dict(frames.inv_T(T), G @ cov @ G.T, unk_inv)
    r = np.asarray(result.residuals, float)
    t_mm = 1e3 * np.linalg.norm(r[:, :3], axis=1)
    rot_deg = np.degrees(np.linalg.norm(r[:, 3:], axis=1))
    labels = result.labels or tuple(range(r.shape[0]))
    reproj = None
    if detections is not None and target is not None and intrinsics is not None:
        keep = [problem.labels.index(lab) for lab in labels]
        reproj = chain_reprojection(A @ problem.meta["G"][keep] @ B, detections, labels, target, intrinsics)
    return {
        "model": "handeye",
        "mount": problem.meta["mount"],
        "A": nA,
        "B": nB,
        "converged": bool(result.converged),
        "n_poses": int(r.shape[0]),
        "noise": {k: problem.meta[k] for k in ("noise", "sigma_t_m", "sigma_rot_rad") if k in problem.meta},
        "transforms": transforms,
        "parameters": result.to_dict(),
        "stds": {n: (None if not np.isfinite(s) else float(s)) for n, s in zip(result.names, std)},
        "residuals": {
            "per_pose": [{"pose_id": lab if isinstance(lab, str) else int(lab) if isinstance(lab, (int, np.integer))
                          else str(lab), "translation_mm": float(a), "rotation_deg": float(b),
                          "components": rr.tolist()} for lab, a, b, rr in zip(labels, t_mm, rot_deg, r)],
            "rms_translation_mm": float(np.sqrt(np.mean(t_mm**2))),
            "rms_rotation_deg": float(np.sqrt(np.mean(rot_deg**2))),
            "max_translation_mm": float(t_mm.max()),
            "max_rotation_deg": float(rot_deg.max()),
        },
        "reprojection": reproj,
    }
