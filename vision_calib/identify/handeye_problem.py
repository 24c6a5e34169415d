"""Hand-eye identification when the flange poses are known (robot assumed calibrated).

Model. For robot pose k the camera measures ``M_k = T_cam_target,k`` and the robot gives
``T_base_flange,k``. Both mounts write as ``M_k = A . G_k . B`` with ``G_k`` known:

==============  =====================  ============================  =====================
mount            A (left unknown)       G_k (known)                   B (right unknown)
==============  =====================  ============================  =====================
"fixed"          ``T_cam_base``         ``T_base_flange,k``           ``T_flange_target``
"eye_in_hand"    ``T_cam_flange``       ``inv(T_base_flange,k)``      ``T_base_target``
==============  =====================  ============================  =====================

For the eye-in-hand mount the camera mounting the user thinks of is ``T_flange_cam = inv(A)``:
the problem identifies A (names ``T_cam_flange.*``) and :func:`vision_calib.report.handeye.handeye_report` gives
both A and its inverse, with the covariance carried through :func:`vision_calib.frames.inverse_error_map`.

Parameters (12, SI): ``<A>.tx, .ty, .tz, .rx, .ry, .rz`` then the same for B, with the mount
parametrisation of :mod:`vision_calib.kinematics.serial`: ``T = [R_nom . Exp(r), t]``, ``r`` a
rotation vector right-multiplied on the nominal rotation (nominal 0), ``t`` the translation
(nominal = nominal translation). The nominal transforms are the closed-form initial guess
(:func:`handeye_initial_guess`) unless given.

Residual (``residual_kind="pose"``, m = 6): ``r_k = frames.pose_error(A G_k B, M_k)`` =
[t_meas - t_model (m), rotvec(R_meas R_model^T) (rad)], camera frame, i.e. measured - model in
the error convention of :class:`vision_calib.measure.PoseMeasurement.cov`, so the PnP
covariances are the observation covariances as they are.

Jacobian (analytic). With the model pose perturbed as ``perturb_pose(M, delta)``:
``delta = [dtA, 0]`` for A's translation, ``[phi x (t_M - t_A), phi]`` with
``phi = R_A Jr(r_A) drA`` for A's rotation, ``[R_AG dtB, 0]`` for B's translation and
``[0, R_AG R_B Jr(r_B) drB]`` for B's rotation (``R_AG`` the rotation of A G_k, ``Jr`` the SO(3)
right Jacobian). The residual Jacobian is ``-delta`` for the translation rows and
``-Jr(e)^-1 delta_rot`` for the rotation rows (``e`` the rotation residual), exact at any point.

Robot pose error. The flange poses are what the robot reports: the true ones are
``perturb_pose(T_base_flange,k, d_k)`` with d_k [m, rad] (base-frame axes, about the flange origin) of
covariance ``robot_cov`` (6, 6). It moves the model pose by ``delta = L_k d_k`` with, for ``X G Y``
(X = A, Y = B, G = G_k) and a perturbation ``d_G`` of G, ``L = [[R_X, -R_X [R_G t_Y]x], [0, R_X]]``;
``d_G = d`` for "fixed" and ``inverse_error_map(T_base_flange,k) d`` for "eye_in_hand"
(:func:`flange_error_map` gives ``d r_k / d d_k``). Each pose's residual covariance is then
``obs_cov_k = camera_cov_k + D_k robot_cov D_k^T`` (D_k = d r_k / d d_k at the current x: the weights depend
on A and B, :func:`reweighted` recomputes them), the linearised Gauss-Helmert (errors-in-variables) model.

numpy only; OpenCV's closed forms are in :mod:`vision_calib.measure.handeye`.
"""

from __future__ import annotations

import dataclasses
from typing import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from .. import frames
from ..errors import ConfigError, DataError
from ..kinematics.params import DEFAULT_SCALE, ParameterSet
from ..frames import so3_exp, so3_right_jacobian
from ..kinematics.serial import MOUNT_SUFFIXES
from .problem import NOISE_ESTIMATED, IdentificationProblem, IdentificationResult

#: unknown transforms (A, B) named after the frames, per mount
MOUNT_NAMES = {"fixed": ("T_cam_base", "T_flange_target"), "eye_in_hand": ("T_cam_flange", "T_base_target")}
#: names of the inverse transforms reported beside A and B
INVERSE_NAMES = {"T_cam_base": "T_base_cam", "T_flange_target": "T_target_flange",
                 "T_cam_flange": "T_flange_cam", "T_base_target": "T_target_base"}
#: relative weights (not noise) when neither pose_cov nor sigmas are given (m, rad): the noise scale is then
#: estimated from the residuals (a-posteriori variance factor, ``problem.NOISE_ESTIMATED``)
RELATIVE_WEIGHT_T_M = 1e-3
RELATIVE_WEIGHT_ROT_RAD = np.radians(0.1)

_POSE_COMPONENTS = ("dx", "dy", "dz", "drx", "dry", "drz")


# ----------------------------------------------------------------------------- input checks
def check_mount(mount: str) -> str:
    """The mount name, checked ("fixed" | "eye_in_hand"), else ConfigError."""
    if mount not in MOUNT_NAMES:
        raise ConfigError(f"hand-eye mount must be 'fixed' or 'eye_in_hand', got {mount!r}")
    return mount


def check_poses(name: str, T: ArrayLike, N: int | None = None) -> np.ndarray:
    """(N, 4, 4) finite rigid transforms, else DataError naming the pose index."""
    T = np.asarray(T, dtype=float)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise DataError(f"{name} must have shape (N, 4, 4), got {T.shape}")
    if N is not None and T.shape[0] != N:
        raise DataError(f"{name} has {T.shape[0]} poses, expected {N} (one per flange pose)")
    bad = np.flatnonzero(~np.all(np.isfinite(T), axis=(1, 2)))
    if bad.size:
        raise DataError(f"{name}: pose {int(bad[0])} contains a non-finite value (NaN or inf)")
    R = T[:, :3, :3]
    err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2))
    bad = np.flatnonzero((err > 1e-6) | (np.linalg.det(R) < 0) | np.any(np.abs(T[:, 3] - [0, 0, 0, 1]) > 1e-9, axis=1))
    if bad.size:
        raise DataError(f"{name}: pose {int(bad[0])} is not a rigid transform (rotation not orthonormal "
                        f"or last row not [0, 0, 0, 1])")
    return T


def mount_G(T_base_flange: np.ndarray, mount: str) -> np.ndarray:
    """(N, 4, 4) the known G_k of ``M_k = A G_k B`` (module docstring): the flange poses, or their inverses."""
    return T_base_flange if mount == "fixed" else frames.inv_T(T_base_flange)


# ----------------------------------------------------------------------------- closed form
#: relative gap below which the two largest singular values of the rotation system count as equal (no unique
#: rotation: rotations about one axis only), and relative smallest singular value of the translation system
DEGENERATE_RTOL = 1e-10


def nearest_rotation(X: ArrayLike) -> np.ndarray:
    """(3, 3) rotation nearest to X (3, 3) in the Frobenius norm (SVD, determinant +1)."""
    U, _, Vt = np.linalg.svd(np.asarray(X, float))
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt


def handeye_initial_guess(T_base_flange: ArrayLike, T_cam_target_meas: ArrayLike,
                          mount: str = "fixed") -> tuple[np.ndarray, np.ndarray]:
    """Closed-form (A, B), each (4, 4), from N >= 3 pose pairs, numpy only: Shah's Kronecker-product solution of
    the robot-world / hand-eye problem ``M_k = A G_k B`` (M. Shah, J. Mechanisms Robotics 5, 031007, 2013).

    T_base_flange: (N, 4, 4) flange poses in the robot base [m]; T_cam_target_meas: (N, 4, 4) measured target
    poses in the camera. Returns (T_cam_base, T_flange_target) for "fixed", (T_cam_flange, T_base_target) for
    "eye_in_hand" (module docstring). The default start of :func:`handeye_problem`; OpenCV's 7 closed forms
    (the fit's candidates in the pipeline) are :func:`vision_calib.measure.handeye.closed_forms`.

    Rotations: ``sum_k tr(R_Mk^T R_A R_Gk R_B) = vec(R_A)^T K vec(R_B^T)`` with ``K = sum_k R_Gk (x) R_Mk``
    (9, 9, column-major vec); every term is orthogonal, so ``|K| <= N``, reached on exact data at
    ``vec(R_A), vec(R_B^T)``: the top singular pair of K, each projected on SO(3) (:func:`nearest_rotation`).
    Translations: ``t_Mk - R_A t_Gk = t_A + R_A R_Gk t_B``, linear least squares (3N, 6).
    DataError when the top singular value is not unique or the translations are not determined (rotations
    about one axis only).
    """
    mount = check_mount(mount)
    F = check_poses("T_base_flange", T_base_flange)
    M = check_poses("T_cam_target_meas", T_cam_target_meas, F.shape[0])
    N = F.shape[0]
    if N < 3:
        raise DataError(f"hand-eye calibration needs at least 3 poses, got {N}")
    G = mount_G(F, mount)
    RG, RM = G[:, :3, :3], M[:, :3, :3]
    K = np.einsum("kij,kab->iajb", RG, RM).reshape(9, 9)  # sum_k kron(RG_k, RM_k)
    U, s, Vt = np.linalg.svd(K)
    if s[0] - s[1] <= DEGENERATE_RTOL * s[0]:
        raise DataError("closed-form hand-eye calibration failed (the rotations do not determine the mounts): "
                        "the poses need rotations about at least two non-parallel axes; or give A0 and B0")
    XA, XBt = U[:, 0].reshape(3, 3, order="F"), Vt[0].reshape(3, 3, order="F")
    if np.linalg.det(XA) < 0:  # the pair's common sign
        XA, XBt = -XA, -XBt
    RA, RB = nearest_rotation(XA), nearest_rotation(XBt).T
    J = np.concatenate([np.broadcast_to(np.eye(3), (N, 3, 3)), RA @ RG], axis=2).reshape(3 * N, 6)
    b = (M[:, :3, 3] - np.einsum("ij,kj->ki", RA, G[:, :3, 3])).reshape(-1)
    t, _, _, sv = np.linalg.lstsq(J, b, rcond=None)
    if sv[-1] <= DEGENERATE_RTOL * sv[0]:
        raise DataError("closed-form hand-eye calibration failed (the translations are not determined): the poses "
                        "need rotations about at least two non-parallel axes; or give A0 and B0")
    return frames.make_T(RA, t[:3]), frames.make_T(RB, t[3:])


# ----------------------------------------------------------------------------- the problem
def _mount_params(name: str, T: np.ndarray):
    names = [f"{name}.{s}" for s in MOUNT_SUFFIXES]
    nominal = list(T[:3, 3]) + [0.0, 0.0, 0.0]
    kinds = ["length"] * 3 + ["angle"] * 3
    return names, nominal, kinds


def transforms_from_x(problem: IdentificationProblem, x: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) (4, 4) for the full parameter vector x (12,) of a :func:`handeye_problem`."""
    x = np.asarray(x, dtype=float).reshape(-1)
    RA0, RB0 = problem.meta["R_A_nominal"], problem.meta["R_B_nominal"]
    return (frames.make_T(RA0 @ so3_exp(x[3:6]), x[0:3]), frames.make_T(RB0 @ so3_exp(x[9:12]), x[6:9]))


def _obs_cov(N, pose_cov, sigma_t_m, sigma_rot_rad) -> tuple[np.ndarray, dict]:
    """(N, 6, 6) observation covariances: pose_cov (N, 6, 6) or (6, 6), plus diag(sigmas^2) when given."""
    meta = {}
    if pose_cov is None and sigma_t_m is None and sigma_rot_rad is None:
        sigma_t_m, sigma_rot_rad = RELATIVE_WEIGHT_T_M, RELATIVE_WEIGHT_ROT_RAD
        meta["noise"] = NOISE_ESTIMATED
    cov = np.zeros((N, 6, 6))
    if pose_cov is not None:
        pc = np.asarray(pose_cov, dtype=float)
        if pc.shape == (6, 6):
            pc = np.broadcast_to(pc, (N, 6, 6))
        if pc.shape != (N, 6, 6):
            raise DataError(f"pose_cov must have shape ({N}, 6, 6) or (6, 6), got {pc.shape}")
        bad = np.flatnonzero(~np.all(np.isfinite(pc), axis=(1, 2)))
        if bad.size:
            raise DataError(f"pose_cov of pose {int(bad[0])} is not finite (invalid measurement?)")
        cov = cov + 0.5 * (pc + np.swapaxes(pc, 1, 2))
        meta.setdefault("noise", "pose_cov")
    for name, s, sl in (("sigma_t_m", sigma_t_m, slice(0, 3)), ("sigma_rot_rad", sigma_rot_rad, slice(3, 6))):
        if s is None:
            continue
        if not (np.isfinite(s) and s >= 0):
            raise DataError(f"{name} must be a finite number >= 0, got {s}")
        cov[:, sl, sl] += float(s) ** 2 * np.eye(3)
        meta[name] = float(s)
    eig = np.linalg.eigvalsh(cov)[:, 0]
    bad = np.flatnonzero(eig <= 0)
    if bad.size:
        raise DataError(f"observation covariance of pose {int(bad[0])} is not positive definite "
                        f"(give pose_cov or sigma_t_m > 0 and sigma_rot_rad > 0)")
    return cov, meta


def robot_pose_cov(sigma_t_m: float, sigma_rot_rad: float) -> np.ndarray:
    """(6, 6) covariance [m, rad] of a flange pose error with independent std sigma_t_m per translation
    axis and sigma_rot_rad per rotation axis (isotropic: the same in any frame)."""
    for name, s in (("translation std", sigma_t_m), ("rotation std", sigma_rot_rad)):
        if not (np.isfinite(s) and s >= 0):
            raise DataError(f"robot pose error: {name} must be a finite number >= 0, got {s}")
    return np.diag([float(sigma_t_m) ** 2] * 3 + [float(sigma_rot_rad) ** 2] * 3)


def robot_weighted_cov(camera_cov: ArrayLike, D: np.ndarray, robot_cov: ArrayLike) -> np.ndarray:
    """(..., N, 6, 6) each measured pose's covariance with the robot's pose error: camera_cov (..., N, 6, 6) + D
    robot_cov D^T, D (..., N, 6, 6) the flange error maps (:func:`flange_error_map`), robot_cov (..., 6, 6) [m, rad]
    (e.g. :func:`robot_pose_cov`; broadcast over the poses)."""
    return np.asarray(camera_cov, float) + D @ np.asarray(robot_cov, float) @ np.swapaxes(D, -1, -2)


def robot_blocks(D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(V_t, V_r) (..., N, 6, 6): the residual covariance per unit variance of the flange's translation and rotation
    error per axis, D_t D_t^T and D_r D_r^T of the flange error maps D (..., N, 6, 6) (the REML blocks)."""
    return D[..., :3] @ np.swapaxes(D[..., :3], -1, -2), D[..., 3:] @ np.swapaxes(D[..., 3:], -1, -2)


def handeye_problem(T_base_flange: ArrayLike, T_cam_target_meas: ArrayLike, mount: str = "fixed",
                    A0: ArrayLike | None = None, B0: ArrayLike | None = None, pose_cov: ArrayLike | None = None,
                    sigma_t_m: float | None = None, sigma_rot_rad: float | None = None,
                    labels: Sequence[str] | None = None, robot_cov: ArrayLike | None = None) -> IdentificationProblem:
    """Hand-eye identification problem (residual_kind "pose", m = 6, 12 parameters).

    T_base_flange: (N, 4, 4) known flange poses in the robot base [m] (the problem builds
    ``G_k`` from them: itself for "fixed", its inverse for "eye_in_hand").
    T_cam_target_meas: (N, 4, 4) measured target poses in the camera [m].
    mount: "fixed" (A = T_cam_base, B = T_flange_target) | "eye_in_hand" (A = T_cam_flange,
    B = T_base_target). A0, B0: (4, 4) nominal transforms (starting point); None -> closed form
    (:func:`handeye_initial_guess`, both must be None or both given).
    pose_cov: (N, 6, 6) or (6, 6) covariance of the measured pose error [dt (m), drot (rad)],
    camera frame (``PoseMeasurement.cov``). sigma_t_m / sigma_rot_rad: isotropic noise added to
    pose_cov (robot repeatability, model error); with neither pose_cov nor sigmas no noise is invented:
    relative weights 1 mm : 0.1 deg and the noise scale estimated from the residuals (``meta["noise"]`` =
    "estimated from residuals, not given"; the solvers scale the covariance by chi2/dof).
    labels: (N,) pose identifiers. robot_cov: (6, 6) covariance [m, rad] of the flange pose error
    (:func:`robot_pose_cov`; module docstring), propagated into obs_cov at (A0, B0) (:func:`reweighted` at
    another x). ``meta`` holds mount, the A/B names, G (N, 4, 4), the nominal rotations used by
    :func:`transforms_from_x`, camera_cov (N, 6, 6) (obs_cov without the robot part) and robot_cov.
    Longer than 80 lines: input checks, initial guess, covariance and the two closures share one scope.
    """
    mount = check_mount(mount)
    F = check_poses("T_base_flange", T_base_flange)
    N = F.shape[0]
    M = check_poses("T_cam_target_meas", T_cam_target_meas, N)
    if N < 3:
        raise DataError(f"hand-eye identification needs at least 3 poses (12 parameters, 6 equations each, "
                        f"and two rotation axes), got {N}")
    if (A0 is None) != (B0 is None):
        raise ConfigError("handeye_problem: give both A0 and B0, or neither (closed-form start)")
    if A0 is None:
        A0, B0 = handeye_initial_guess(F, M, mount)
    A0 = check_poses("A0", np.asarray(A0, float)[None])[0]
    B0 = check_poses("B0", np.asarray(B0, float)[None])[0]
    labels = tuple(range(N)) if labels is None else tuple(labels)
    if len(labels) != N:
        raise DataError(f"{len(labels)} labels for {N} poses")
    cov, noise_meta = _obs_cov(N, pose_cov, sigma_t_m, sigma_rot_rad)
    if robot_cov is not None:
        robot_cov = np.asarray(robot_cov, dtype=float)
        if robot_cov.shape != (6, 6) or not np.all(np.isfinite(robot_cov)) or np.linalg.eigvalsh(
                0.5 * (robot_cov + robot_cov.T))[0] < 0:
            raise DataError(f"robot_cov must be a finite positive semi-definite (6, 6) matrix, got shape "
                            f"{robot_cov.shape}")

    nA, nB = MOUNT_NAMES[mount]
    na, va, ka = _mount_params(nA, A0)
    nb, vb, kb = _mount_params(nB, B0)
    kinds = ka + kb
    params = ParameterSet.from_lists(na + nb, va + vb, kinds, None, [DEFAULT_SCALE[k] for k in kinds])
    G = mount_G(F, mount)
    RA0, RB0 = A0[:3, :3].copy(), B0[:3, :3].copy()

    def sel(idx):
        return np.arange(N) if idx is None else np.asarray(idx, dtype=int)

    def residual(x, idx=None):
        idx = sel(idx)
        return _model(RA0, RB0, G[idx][None], M[idx][None], None, mount, x, False, False)[0][0]

    def jacobian(x, idx=None):
        idx = sel(idx)
        return _model(RA0, RB0, G[idx][None], M[idx][None], None, mount, x, True, False)[1][0]

    problem = IdentificationProblem(
        params=params, residual=residual, jacobian=jacobian, obs_cov=cov, residual_kind="pose", labels=labels,
        component_names=_POSE_COMPONENTS,
        meta={"model": "handeye", "mount": mount, "A_name": nA, "B_name": nB, "G": G, "T_base_flange": F,
              "T_cam_target_meas": M, "R_A_nominal": RA0, "R_B_nominal": RB0, "A0": A0, "B0": B0,
              "camera_cov": cov, "robot_cov": robot_cov, **noise_meta},
    )
    return problem if robot_cov is None else reweighted(problem, params.nominal)


def flange_error_map(problem: IdentificationProblem, x: ArrayLike) -> np.ndarray:
    """(N, 6, 6) d r_k / d d_k at x (12,): the residual's response to the flange pose error d_k [m, rad]
    (``perturb_pose`` on T_base_flange,k; module docstring), for all N poses of the problem."""
    return model_many(problem, np.asarray(x, float)[None], jacobian=False)[2][0]


def _model(RA0, RB0, G, M, F, mount: str, X, jacobian: bool = True, flange_map: bool = True):
    """The hand-eye model at each row of X (K, 12) (rotations relative to RA0, RB0 (3, 3)) for the poses G, M, F
    (K or 1, N, 4, 4): (r (K, N, 6), J (K, N, 6, 12) or None, D (K, N, 6, 6) or None): the residual
    ``pose_error(A G B, M)``, its Jacobian in the 12 parameters and its response to the flange pose error (F: the
    flange poses, read for eye_in_hand)."""
    X = np.asarray(X, float).reshape(-1, 12)
    RA = RA0 @ so3_exp(X[:, 3:6])  # (K, 3, 3)
    RB = RB0 @ so3_exp(X[:, 9:12])
    A, B = frames.make_T(RA, X[:, 0:3]), frames.make_T(RB, X[:, 6:9])
    AG = A[:, None] @ G  # (K, N, 4, 4)
    Tm = AG @ B[:, None]
    r = frames.pose_error(Tm, M)
    if not (jacobian or flange_map):
        return r, None, None
    Jri = frames.so3_right_jacobian_inv(r[..., 3:])  # (K, N, 3, 3)
    K, N = r.shape[:2]
    J = Dfl = None
    if jacobian:
        D = np.zeros((K, N, 6, 12))  # delta (model pose error) per parameter
        D[..., 0:3, 0:3] = np.eye(3)
        WA = RA @ so3_right_jacobian(X[:, 3:6])  # (K, 3, 3): axes phi per unit rA, camera frame
        D[..., 0:3, 3:6] = -frames.skew(Tm[..., :3, 3] - A[:, None, :3, 3]) @ WA[:, None]  # phi x arm
        D[..., 3:6, 3:6] = WA[:, None]
        D[..., 0:3, 6:9] = AG[..., :3, :3]
        D[..., 3:6, 9:12] = AG[..., :3, :3] @ (RB @ so3_right_jacobian(X[:, 9:12]))[:, None]
        J = -D
        J[..., 3:, :] = -(Jri @ D[..., 3:, :])
    if flange_map:
        L = np.zeros((K, N, 6, 6))
        L[..., :3, :3] = RA[:, None]
        L[..., 3:, 3:] = RA[:, None]
        L[..., :3, 3:] = -(RA[:, None] @ frames.skew((G[..., :3, :3] @ B[:, None, :3, 3, None])[..., 0]))
        if mount == "eye_in_hand":
            L = L @ frames.inverse_error_map(F)
        Dfl = -L
        Dfl[..., 3:, :] = -(Jri @ L[..., 3:, :])
    return r, J, Dfl


def model_many(problem: IdentificationProblem, X: ArrayLike, flange_map: bool = True, poses=None,
               jacobian: bool = True):
    """The hand-eye problem's residual, Jacobian and flange error map at each row of X (K, 12), for all its N
    poses: (r (K, N, 6), J (K, N, 6, 12) or None without ``jacobian``, D (K, N, 6, 6) or None without
    ``flange_map``): the problem's own model (its closures and :func:`flange_error_map` read the same).
    poses: (K,) one pose per row instead (the arrays then have N = 1)."""
    m = problem.meta
    G, M, F = m["G"], m["T_cam_target_meas"], m["T_base_flange"]
    if poses is not None:
        p = np.asarray(poses, int)
        G, M, F = G[p][:, None], M[p][:, None], F[p][:, None]  # (K, 1, 4, 4): pose p_j for row j
    else:
        G, M, F = G[None], M[None], F[None]
    return _model(m["R_A_nominal"], m["R_B_nominal"], G, M, F, m["mount"], X, jacobian, flange_map)


def reweighted(problem: IdentificationProblem, x: ArrayLike,
               robot_cov: ArrayLike | None = None) -> IdentificationProblem:
    """The problem with obs_cov = camera_cov + D_k robot_cov D_k^T at x (12,) (:func:`flange_error_map`);
    robot_cov (6, 6) replaces the problem's own (None: keep it; a problem without one is returned as is)."""
    rc = problem.meta.get("robot_cov") if robot_cov is None else np.asarray(robot_cov, float)
    if rc is None:
        return problem
    D = flange_error_map(problem, x)
    cov = robot_weighted_cov(problem.meta["camera_cov"], D, rc)
    return dataclasses.replace(problem, obs_cov=0.5 * (cov + np.swapaxes(cov, 1, 2)),
                               meta={**problem.meta, "robot_cov": rc})


def x_from_transforms(problem: IdentificationProblem, A: ArrayLike, B: ArrayLike) -> np.ndarray:
    """(12,) parameter vector of the transforms A, B (4, 4) (inverse of :func:`transforms_from_x`); stacks A, B
    (..., 4, 4) give (..., 12)."""
    A, B = np.asarray(A, float), np.asarray(B, float)
    RA0, RB0 = problem.meta["R_A_nominal"], problem.meta["R_B_nominal"]
    rA = frames.rotvec_from_matrix(RA0.T @ A[..., :3, :3])
    rB = frames.rotvec_from_matrix(RB0.T @ B[..., :3, :3])
    return np.concatenate([A[..., :3, 3], rA, B[..., :3, 3], rB], axis=-1)


def solve_handeye(T_base_flange: ArrayLike, T_cam_target_meas: ArrayLike, mount: str = "fixed",
                  pose_cov: ArrayLike | None = None, sigma_t_m: float | None = None, sigma_rot_rad: float | None = None,
                  labels: Sequence[str] | None = None, A0: ArrayLike | None = None, B0: ArrayLike | None = None,
                  robot_cov: ArrayLike | None = None,
                  **lse_kwargs) -> tuple[IdentificationResult, np.ndarray, np.ndarray, IdentificationProblem]:
    """Closed-form start + weighted least squares. Returns (result, A (4, 4), B (4, 4), problem).

    One fit with the weights at the start (A0, B0) (see :func:`vision_calib.identify.handeye_fit.fit_handeye`
    for the weights iterated to the solution, the closed-form start chosen by cost and the robot's variance
    estimated). Arguments as :func:`handeye_problem`; ``lse_kwargs`` go to :func:`~vision_calib.identify.lse.solve_lse`
    (e.g. ``scale_cov_by_residual=True`` when the measurement covariances are not trusted).
    """
    from .lse import solve_lse

    problem = handeye_problem(T_base_flange, T_cam_target_meas, mount, A0, B0, pose_cov, sigma_t_m,
                              sigma_rot_rad, labels, robot_cov)
    result = solve_lse(problem, **lse_kwargs)
    A, B = transforms_from_x(problem, result.identified)
    return result, A, B, problem


def stack_measurements(measurements: Iterable,
                       pool_sigma: bool = False) -> tuple[np.ndarray, np.ndarray, tuple, np.ndarray]:
    """Arrays from PoseMeasurement-like objects (``T_cam_target``, ``cov``, ``valid``, ``pose_id``,
    ``sigma_px``): (T (N, 4, 4), cov (N, 6, 6), labels (N,) tuple, valid (N,) bool).

    Filter with ``valid`` (together with the flange poses) before :func:`handeye_problem`.
    pool_sigma: rescale each covariance (``sigma_px^2 (J^T J)^-1``) to the RMS of ``sigma_px`` over
    the valid poses. Use it when each pose has one image and few corners (e.g. one AprilTag: the
    per-pose sigma_px is then estimated from 2 degrees of freedom and varies by a factor ~10 by chance).
    """
    ms = list(measurements)
    if not ms:
        raise DataError("stack_measurements: no measurement given")
    T = np.array([np.asarray(m.T_cam_target, float) for m in ms]).reshape(-1, 4, 4)
    cov = np.array([np.asarray(m.cov, float) for m in ms]).reshape(-1, 6, 6)
    valid = np.array([bool(m.valid) for m in ms], dtype=bool)
    if pool_sigma and valid.any():
        sig = np.array([float(getattr(m, "sigma_px", np.nan)) for m in ms])
        ok = valid & np.isfinite(sig) & (sig > 0)
        if ok.any():
            pooled = float(np.sqrt(np.mean(sig[ok] ** 2)))
            cov[ok] *= ((pooled / sig[ok]) ** 2)[:, None, None]
    return T, cov, tuple(m.pose_id for m in ms), valid
