"""H4 identification by the inverse-geometric-model method (seed 000 §2.1, eq. 2-4).

For each robot pose k the measured joint values q~_k (4,) and the measured camera pose
T_cam_target_k give the residual

    r_k(x) = q~_k - IGM(X(T_cam_target_k, x_ext), x_geo)          (N, 4) rad

where X(., x_ext) = (translation, yaw) of T_base_cam @ T_cam_target @ T_target_nacelle
(:meth:`H4Robot.nacelle_pose_from_camera`): geometric and external parameters are identified
together. Noise model of observation k (its covariance ``obs_cov[k]``, (4, 4) rad^2):

    cov(r_k) = sigma_q^2 I + G_k Sigma_k G_k^T,  G_k = d IGM / d delta  (4, 6)

with Sigma_k (6, 6) the covariance of the measured-pose error delta = [dt (m), drot (rad)]
(:func:`vision_calib.frames.perturb_pose` convention, camera frame) and G_k evaluated at the
problem's nominal parameters (first order; the noise enters through the pose, so the weighting
of LSE and the predicted covariance account for it).

The pose-residual problem (:func:`h4_pose_problem`, residual_kind "pose") runs the model the other way:
the measured joints give the nacelle pose through the forward model, X = FGM(q~_k, x) (Newton on the
IGM), and the residual compares the measured camera pose with the one the model predicts,

    r_k(x) = frames.pose_error(camera_measurement(FGM(q~_k, x), x), T_cam_target_k)   (N, 6) [m, rad]

Only (x, y, z, theta) of the nacelle are driven by X; the two other rotation components are measured
too and depend on the mounts (tilts). dX/dx at fixed q~ comes from the implicit function theorem,
dX/dx = -(dIGM/dX)^-1 dIGM/dx. Both problems share one noise model: per pose the raw errors
e_k = [delta_k (6), dq_k (4)] with covariance blockdiag(Sigma_k, sigma_q^2 I) (:func:`h4_raw_noise_cov`)
enter the residual through B_k = d r_k / d e_k (:func:`h4_noise_response`), obs_cov[k] = B_k cov(e_k) B_k^T;
this is what lets ``identify.method_check`` compare the two estimates from the same data.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..errors import DataError
from ..frames import perturb_pose, pose_error, so3_right_jacobian_inv
from ..kinematics.h4 import H4Robot
from .problem import NOISE_ESTIMATED, IdentificationProblem

#: relative joint weight (rad) when neither sigma_q_rad nor pose_cov is given: the noise scale is then
#: estimated from the residuals (``problem.NOISE_ESTIMATED``)
RELATIVE_WEIGHT_Q_RAD = 1e-4
#: relative pose weights (m, rad) of the pose-residual problem when no pose_cov is given (noise estimated)
RELATIVE_WEIGHT_T_M = 1e-3
RELATIVE_WEIGHT_R_RAD = 1e-3
POSE_COMPONENTS = ("dt_x", "dt_y", "dt_z", "dtheta_x", "dtheta_y", "dtheta_z")


def _check(name, a, shape_tail):
    a = np.asarray(a, float)
    if a.ndim != 1 + len(shape_tail) or a.shape[1:] != shape_tail:
        raise DataError(f"{name} must have shape (N, {', '.join(map(str, shape_tail))}), got {a.shape}")
    bad = ~np.isfinite(a)
    if bad.any():
        raise DataError(f"{name}: pose {int(np.argwhere(bad)[0][0])} contains a non-finite value (NaN or inf)")
    return a


def h4_raw_noise_cov(pose_cov: ArrayLike, sigma_q_rad: float) -> np.ndarray:
    """(N, 10, 10) covariance of the raw errors e = [delta (6): measured-pose error, dq (4): joint-reading
    error (rad)] of each pose: blockdiag(pose_cov[k], sigma_q^2 I4). pose_cov: (N, 6, 6)."""
    S = np.asarray(pose_cov, float)
    out = np.zeros((len(S), 10, 10))
    out[:, :6, :6] = S
    out[:, 6:, 6:] = float(sigma_q_rad) ** 2 * np.eye(4)
    return out


def h4_noise_response(robot: H4Robot, q_meas: ArrayLike, T_cam_target_meas: ArrayLike, x: ArrayLike,
                      residual_kind: str) -> np.ndarray:
    """B (N, m, 10) = d r / d e at parameters x (n,): how the raw errors e = [delta (6), dq (4)] (see
    :func:`h4_raw_noise_cov`) enter the residual of ``residual_kind`` "joint" (m = 4: [-dq/d delta, I4])
    or "pose" (m = 6: [I6, -d delta/dX (dIGM/dX)^-1]); first order."""
    T = np.asarray(T_cam_target_meas, float)
    if residual_kind == "joint":
        _, G = robot.igm_from_camera_jacobian(T, x, with_meas=True)
        return np.concatenate([-G, np.broadcast_to(np.eye(4), (len(T), 4, 4))], axis=2)
    if residual_kind != "pose":
        raise DataError(f"H4 residual kind must be 'joint' or 'pose', got {residual_kind!r}")
    X = _forward_pose(robot, np.asarray(q_meas, float), T, x)
    JX, _ = robot.camera_measurement_jacobian(X, x)
    dXdq = np.linalg.inv(robot.igm_jacobian_pose(X, x))
    return np.concatenate([np.broadcast_to(np.eye(6), (len(T), 6, 6)), -JX @ dXdq], axis=2)


def _inputs(q_meas, T_cam_target_meas, pose_cov):
    """Checked (q (N, 4), T (N, 4, 4), pose_cov (N, 6, 6) or None)."""
    q_meas = _check("q_meas", q_meas, (4,))
    T = _check("T_cam_target_meas", T_cam_target_meas, (4, 4))
    N = len(q_meas)
    if len(T) != N:
        raise DataError(f"q_meas has {N} poses but T_cam_target_meas has {len(T)}")
    if N == 0:
        raise DataError("H4 identification problem needs at least one pose")
    S = None
    if pose_cov is not None:
        S = np.asarray(pose_cov, float)
        if S.shape == (6, 6):
            S = np.broadcast_to(S, (N, 6, 6))
        S = _check("pose_cov", S, (6, 6))
        if len(S) != N:
            raise DataError(f"pose_cov has {len(S)} poses, expected {N}")
    return q_meas, T, S


def _check_cov(cov, what):
    eig = np.linalg.eigvalsh(cov)
    if np.any(eig <= 0):
        k = int(np.argwhere(eig.min(axis=1) <= 0)[0][0])
        raise DataError(f"H4 observation covariance of pose {k} is not positive definite ({what})")


def _problem(robot, residual, jacobian, cov, kind, labels, names, sigma_q_rad, estimated):
    return IdentificationProblem(
        params=robot.params, residual=residual, jacobian=jacobian, obs_cov=cov, residual_kind=kind,
        labels=tuple(labels) if labels is not None else tuple(range(len(cov))), component_names=names,
        meta={"robot": "h4", "model": robot.model, "sigma_q_rad": float(sigma_q_rad),
              **({"noise": NOISE_ESTIMATED} if estimated else {})})


def h4_igm_problem(
    robot: H4Robot,
    q_meas: ArrayLike,
    T_cam_target_meas: ArrayLike,
    sigma_q_rad: float | None = None,
    pose_cov: ArrayLike | None = None,
    labels: Sequence[str] | None = None,
) -> IdentificationProblem:
    """Build the IGM identification problem (residual_kind "joint", m = 4).

    robot: model and parameter set (nominal = starting point, free mask = what is identified).
    q_meas: (N, 4) measured joint values, rad. T_cam_target_meas: (N, 4, 4) measured target
    poses in the camera frame. sigma_q_rad: joint noise std (rad); None -> 0 when pose_cov is
    given, else no noise is invented: equal joint weights and the noise scale estimated from the
    residuals (``meta["noise"]`` = "estimated from residuals, not given"; solvers scale the covariance).
    pose_cov: (N, 6, 6) or (6, 6) covariance of the measured
    pose error [dt (m), drot (rad)], camera frame. labels: (N,) pose identifiers.
    Raises DataError on bad shapes, NaN, or a pose the nominal model cannot reach.
    """
    q_meas, T, S = _inputs(q_meas, T_cam_target_meas, pose_cov)
    N = len(q_meas)
    estimated = sigma_q_rad is None and pose_cov is None
    if sigma_q_rad is None:
        sigma_q_rad = 0.0 if pose_cov is not None else RELATIVE_WEIGHT_Q_RAD
    if not np.isfinite(sigma_q_rad) or sigma_q_rad < 0:
        raise DataError(f"sigma_q_rad must be a finite number >= 0, got {sigma_q_rad}")
    x0 = robot.params.nominal
    S = np.zeros((N, 6, 6)) if S is None else S
    B = h4_noise_response(robot, q_meas, T, x0, "joint")  # fails early, naming the pose, if x0 cannot reach one
    cov = B @ h4_raw_noise_cov(S, sigma_q_rad) @ np.swapaxes(B, -1, -2)
    _check_cov(cov, "give sigma_q_rad > 0")

    def residual(x, idx=None):
        sel = slice(None) if idx is None else np.asarray(idx, int)
        return q_meas[sel] - robot.igm_from_camera(T[sel], x)

    def jacobian(x, idx=None):
        sel = slice(None) if idx is None else np.asarray(idx, int)
        return -robot.igm_from_camera_jacobian(T[sel], x)

    return _problem(robot, residual, jacobian, cov, "joint", labels, ("q1", "q2", "q3", "q4"), sigma_q_rad,
                    estimated)


def _forward_pose(robot: H4Robot, q, T, x) -> np.ndarray:
    """X (N, 4) = FGM(q (N, 4), x), Newton started at the nacelle pose the measured T (N, 4, 4) gives."""
    return robot.fgm(q, x, X0=robot.nacelle_pose_from_camera(T, x)[0])


def h4_pose_problem(
    robot: H4Robot,
    q_meas: ArrayLike,
    T_cam_target_meas: ArrayLike,
    sigma_q_rad: float | None = None,
    pose_cov: ArrayLike | None = None,
    labels: Sequence[str] | None = None,
) -> IdentificationProblem:
    """Build the pose-residual problem (residual_kind "pose", m = 6; module doc): the measured camera pose
    against the one the forward model predicts from the measured joints.

    Arguments as :func:`h4_igm_problem`. obs_cov[k] = pose_cov[k] + sigma_q^2 (d delta/dq)(d delta/dq)^T
    (the joint noise through the FGM, at the nominal). No pose_cov: relative pose weights
    (RELATIVE_WEIGHT_T_M, RELATIVE_WEIGHT_R_RAD) and the noise scale estimated from the residuals when
    sigma_q_rad is None too; sigma_q_rad alone (an exact camera) leaves two rotation components without
    noise: DataError. Raises DataError on bad shapes, NaN, or joints the nominal forward model cannot solve.
    """
    q_meas, T, S = _inputs(q_meas, T_cam_target_meas, pose_cov)
    N = len(q_meas)
    estimated = sigma_q_rad is None and pose_cov is None
    if S is None:
        w = np.diag([RELATIVE_WEIGHT_T_M**2] * 3 + [RELATIVE_WEIGHT_R_RAD**2] * 3)
        S = np.broadcast_to(w if estimated else np.zeros((6, 6)), (N, 6, 6))
    sigma_q_rad = 0.0 if sigma_q_rad is None else sigma_q_rad
    if not np.isfinite(sigma_q_rad) or sigma_q_rad < 0:
        raise DataError(f"sigma_q_rad must be a finite number >= 0, got {sigma_q_rad}")
    B = h4_noise_response(robot, q_meas, T, robot.params.nominal, "pose")
    cov = B @ h4_raw_noise_cov(S, sigma_q_rad) @ np.swapaxes(B, -1, -2)
    _check_cov(cov, "the pose residual needs pose_cov")

    def residual(x, idx=None):
        sel = slice(None) if idx is None else np.asarray(idx, int)
        X = _forward_pose(robot, q_meas[sel], T[sel], x)
        return pose_error(robot.camera_measurement(X, x), T[sel])

    def jacobian(x, idx=None):
        sel = slice(None) if idx is None else np.asarray(idx, int)
        X = _forward_pose(robot, q_meas[sel], T[sel], x)
        JX, Jx = robot.camera_measurement_jacobian(X, x)
        dXdx = -np.linalg.solve(robot.igm_jacobian_pose(X, x), robot.igm_jacobian_params(X, x))
        J = -(JX @ dXdx + Jx)
        rho = pose_error(robot.camera_measurement(X, x), T[sel])[:, 3:]
        J[:, 3:] = so3_right_jacobian_inv(rho) @ J[:, 3:]
        return J

    return _problem(robot, residual, jacobian, cov, "pose", labels, POSE_COMPONENTS, sigma_q_rad, estimated)


def synthetic_h4_measurements(robot: H4Robot, X: ArrayLike, x_true: ArrayLike, rng: np.random.Generator,
                              sigma_q_rad: float = 0.0, sigma_t_m: float = 0.0,
                              sigma_r_rad: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Simulated measurements of commanded poses X (N, 4) on the robot with true parameters
    x_true (n,): q = IGM(X, x_true) + N(0, sigma_q^2) (N, 4) rad and T_cam_target (N, 4, 4) =
    true camera measurement perturbed by delta = [N(0, sigma_t^2 I3) m, N(0, sigma_r^2 I3) rad]
    (:func:`perturb_pose`). rng: numpy Generator."""
    X = np.atleast_2d(np.asarray(X, float))
    q = robot.igm(X, x_true)
    T = robot.camera_measurement(X, x_true)
    N = len(X)
    q = q + sigma_q_rad * rng.standard_normal((N, 4))
    delta = np.concatenate([sigma_t_m * rng.standard_normal((N, 3)), sigma_r_rad * rng.standard_normal((N, 3))], 1)
    return q, perturb_pose(T, delta)
