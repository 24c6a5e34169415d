"""Rigid-consistency check of measured target poses against robot flange poses (cv2.calibrateHandEye).

Eye-to-hand (fixed camera, target on the flange): T_base_cam @ T_cam_target_i = T_base_flange_i @ T_flange_target.
Eye-in-hand (camera on the flange, fixed target): T_base_flange_i @ T_flange_cam @ T_cam_target_i = T_base_target.
Used to validate pose measurements on real data; identification proper lives in identify/.
"""

from __future__ import annotations

import cv2
import numpy as np

from .. import frames
from ..errors import DataError


def hand_eye_consistency(T_base_flange: np.ndarray, T_cam_target: np.ndarray, setup: str = "eye_to_hand",
                         method: int = cv2.CALIB_HAND_EYE_TSAI) -> dict:
    """Solve the hand-eye relation and return the per-pose residuals.

    T_base_flange: (N, 4, 4) robot flange poses; T_cam_target: (N, 4, 4) measured target poses, N >= 3.
    Returns dict: "T_base_cam" and "T_flange_target" (eye_to_hand) or "T_flange_cam" and
    "T_base_target" (eye_in_hand), each (4, 4); "residuals" (N, 6) pose_error [m, rad] between the two
    sides of the loop (in the base frame); "rms_t_m", "rms_rot_rad" (RMS of the norms)."""
    A = np.asarray(T_base_flange, dtype=float)
    B = np.asarray(T_cam_target, dtype=float)
    if A.ndim != 3 or A.shape != B.shape or A.shape[0] < 3:
        raise DataError(f"hand_eye_consistency needs >= 3 matching (N, 4, 4) poses, got {A.shape} and {B.shape}")
    if setup == "eye_to_hand":
        G = frames.inv_T(A)  # "gripper2base" input of OpenCV = T_flange_base for eye-to-hand
    elif setup == "eye_in_hand":
        G = A
    else:
        raise DataError(f"setup must be 'eye_to_hand' or 'eye_in_hand', got {setup!r}")
    R, t = cv2.calibrateHandEye(list(G[:, :3, :3]), list(G[:, :3, 3]), list(B[:, :3, :3]), list(B[:, :3, 3]),
                                method=method)
    X = frames.make_T(R, t.ravel())
    if setup == "eye_to_hand":
        Ys = frames.inv_T(A) @ X @ B  # T_flange_target per pose
        Y = frames.mean_pose(Ys)
        lhs, rhs = X @ B, A @ Y
        out = {"T_base_cam": X, "T_flange_target": Y}
    else:
        Ys = A @ X @ B  # T_base_target per pose
        Y = frames.mean_pose(Ys)
        lhs, rhs = Ys, np.broadcast_to(Y, Ys.shape)
        out = {"T_flange_cam": X, "T_base_target": Y}
    res = frames.pose_error(rhs, lhs)
    out["residuals"] = res
    out["rms_t_m"] = float(np.sqrt(np.mean(np.sum(res[:, :3] ** 2, axis=1))))
    out["rms_rot_rad"] = float(np.sqrt(np.mean(np.sum(res[:, 3:] ** 2, axis=1))))
    return out
