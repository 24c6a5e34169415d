"""OpenCV's hand-eye closed forms: the candidates of the hand-eye fit, and a rigid-consistency check.

:func:`closed_forms` (:data:`CLOSED_FORM_METHODS`: ``cv2.calibrateHandEye``'s 5 methods and
``cv2.calibrateRobotWorldHandEye``'s 2) gives the starting candidates that ``experiment.handeye_step`` passes to
:func:`vision_calib.identify.handeye_fit.fit_handeye` (identify imports no cv2: its own default start is the
numpy :func:`vision_calib.identify.handeye_problem.handeye_initial_guess`).

:func:`hand_eye_consistency`: eye-to-hand (fixed camera, target on the flange): T_base_cam @ T_cam_target_i = T_base_flange_i @ T_flange_target.
Eye-in-hand (camera on the flange, fixed target): T_base_flange_i @ T_flange_cam @ T_cam_target_i = T_base_target.
Used to validate pose measurements on real data; identification proper lives in identify/.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from .. import frames
from ..errors import ConfigError, DataError
from ..identify.handeye_problem import check_mount, check_poses, mount_G

#: OpenCV's closed forms: cv2.calibrateHandEye (5) and cv2.calibrateRobotWorldHandEye (2)
CLOSED_FORM_METHODS = ("tsai", "park", "horaud", "andreff", "daniilidis", "shah", "li")
_ROBOT_WORLD = {"shah": cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH, "li": cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI}
_HAND_EYE = {"tsai": cv2.CALIB_HAND_EYE_TSAI, "park": cv2.CALIB_HAND_EYE_PARK, "horaud": cv2.CALIB_HAND_EYE_HORAUD,
             "andreff": cv2.CALIB_HAND_EYE_ANDREFF, "daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS}


def opencv_closed_form(T_base_flange, T_cam_target_meas, mount: str = "fixed",
                       method: str = "shah") -> tuple[np.ndarray, np.ndarray]:
    """Closed-form (A, B), each (4, 4), from N >= 3 pose pairs with one of OpenCV's methods.

    T_base_flange: (N, 4, 4) flange poses in the robot base [m]; T_cam_target_meas: (N, 4, 4)
    measured target poses in the camera. Returns (T_cam_base, T_flange_target) for "fixed",
    (T_cam_flange, T_base_target) for "eye_in_hand" (the model ``M_k = A G_k B`` of
    :mod:`vision_calib.identify.handeye_problem`).

    method "shah" | "li": ``cv2.calibrateRobotWorldHandEye`` on ``M_k = A G_k B``, which is
    OpenCV's ``cTw_k = cTg . gTb_k . inv(wTb)`` with world = our target side: R_world2cam = M_k,
    R_base2gripper = G_k, outputs R_gripper2cam = A and R_base2world = inv(B).
    method "tsai" | "park" | "horaud" | "andreff" | "daniilidis": ``cv2.calibrateHandEye`` (AX = XB)
    for the left/right unknown that it solves, then the other as the SE(3) mean over the poses.
    ConfigError for an unknown method; DataError when OpenCV fails or returns a non-finite result.
    """
    mount = check_mount(mount)
    F = check_poses("T_base_flange", T_base_flange)
    M = check_poses("T_cam_target_meas", T_cam_target_meas, F.shape[0])
    if F.shape[0] < 3:
        raise DataError(f"hand-eye calibration needs at least 3 poses, got {F.shape[0]}")
    G = mount_G(F, mount)
    return _closed_form(G, frames.inv_T(G), M, method)


def _closed_form(G, Ginv, M, method: str) -> tuple[np.ndarray, np.ndarray]:
    """:func:`opencv_closed_form` on checked poses: G (N, 4, 4) (``mount_G``), its inverses, M (N, 4, 4)."""
    try:
        if method in _ROBOT_WORLD:
            R_bw, t_bw, R_gc, t_gc = cv2.calibrateRobotWorldHandEye(
                list(M[:, :3, :3]), list(M[:, :3, 3]), list(G[:, :3, :3]), list(G[:, :3, 3]),
                method=_ROBOT_WORLD[method])
            A = frames.make_T(R_gc, np.ravel(t_gc))
            B = frames.inv_T(frames.make_T(R_bw, np.ravel(t_bw)))
        elif method in _HAND_EYE:
            # OpenCV finds X with H_k X M_k = const ("gripper2base" H_k, "target2cam" M_k); ours:
            # inv(G_k) inv(A) M_k = B, so H_k = inv(G_k), X = inv(A), const = B
            R_x, t_x = cv2.calibrateHandEye(list(Ginv[:, :3, :3]), list(Ginv[:, :3, 3]),
                                            list(M[:, :3, :3]), list(M[:, :3, 3]), method=_HAND_EYE[method])
            X = frames.make_T(R_x, np.ravel(t_x))  # H_k X M_k = inv(G_k) inv(A) M_k = B for every k
            A = frames.inv_T(X)
            B = frames.mean_pose(Ginv @ X @ M)
        else:
            raise ConfigError(f"opencv_closed_form: unknown method {method!r}; expected one of "
                              f"{sorted(_ROBOT_WORLD) + sorted(_HAND_EYE)}")
    except (cv2.error, ValueError) as exc:  # ValueError: a returned rotation that is no rotation (det <= 0)
        raise DataError(f"closed-form hand-eye calibration failed ({str(exc).splitlines()[0]}): the poses need "
                        f"rotations about at least two non-parallel axes, and the camera mount must be the right "
                        f"one (eye_in_hand or fixed); or give A0 and B0") from None
    A, B = np.asarray(A, float), np.asarray(B, float)
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
        raise DataError("closed-form hand-eye calibration returned a non-finite result (degenerate motions? "
                        "the poses need rotations about at least two non-parallel axes)")
    return A, B


#: the closed forms read at most this many pose pairs, evenly spaced over the recording: OpenCV's
#: ``calibrateHandEye`` pairs every motion with every other (time and memory grow as N^2: 800 pairs 30 s, 2,000 pairs
#: out of memory, measured); the fit that starts from them reads all the pairs
CLOSED_FORM_MAX_POSES = 200
#: at most this many threads run :func:`closed_forms_many`' OpenCV calls side by side (each releases the GIL; one set
#: of 7 methods on 2 cores: 1.4x at 16 poses, 1.6x at 40, 1.9x at 80, measured); 1: one after the other
CLOSED_FORM_THREADS = 8


def closed_forms(T_base_flange, T_cam_target, mount: str) -> dict:
    """{method: (A, B) (4, 4) each, or the error message (str) when OpenCV fails} for every
    :data:`CLOSED_FORM_METHODS` (the ``candidates`` of ``identify.handeye_fit.fit_handeye``), from at most
    :data:`CLOSED_FORM_MAX_POSES` of the pairs (evenly spaced; all of them up to that number)."""
    return closed_forms_many([(T_base_flange, T_cam_target)], mount)[0]


def closed_forms_many(pose_sets, mount: str) -> list:
    """:func:`closed_forms` of each (T_base_flange (N, 4, 4), T_cam_target (N, 4, 4)) of ``pose_sets`` (e.g. the
    training sets of held-out folds): every (set, method) call of OpenCV side by side in up to
    :data:`CLOSED_FORM_THREADS` threads (each releases the GIL; the answers do not depend on it)."""
    mount = check_mount(mount)
    out, tasks = [], []
    for T_base_flange, T_cam_target in pose_sets:
        F, M = np.asarray(T_base_flange, float), np.asarray(T_cam_target, float)
        if F.ndim == 3 and len(F) > CLOSED_FORM_MAX_POSES:
            pick = np.unique(np.linspace(0, len(F) - 1, CLOSED_FORM_MAX_POSES).round().astype(int))
            F, M = F[pick], M[pick[pick < len(M)]]
        try:
            F = check_poses("T_base_flange", F)
            M = check_poses("T_cam_target_meas", M, F.shape[0])
            if F.shape[0] < 3:
                raise DataError(f"hand-eye calibration needs at least 3 poses, got {F.shape[0]}")
        except DataError as exc:  # every method fails the same way: each says why
            out.append({m: str(exc) for m in CLOSED_FORM_METHODS})
            continue
        out.append({})
        G = mount_G(F, mount)
        Ginv = frames.inv_T(G)
        tasks += [(len(out) - 1, m, G, Ginv, M) for m in CLOSED_FORM_METHODS]  # the poses checked once, every method

    def one(task):
        try:
            return _closed_form(*task[2:], task[1])
        except DataError as exc:
            return str(exc)

    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    workers = min(len(tasks), cpus, CLOSED_FORM_THREADS)
    if workers < 2:
        found = [one(t) for t in tasks]
    else:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            found = list(pool.map(one, tasks))
    for (k, m, *_), v in zip(tasks, found):
        out[k][m] = v
    return out


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
