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
"""

from __future__ import annotations

import numpy as np

from ..errors import DataError
from ..frames import perturb_pose
from ..kinematics.h4 import H4Robot
from .problem import NOISE_ESTIMATED, IdentificationProblem

#: relative joint weight (rad) when neither sigma_q_rad nor pose_cov is given: the noise scale is then
#: estimated from the residuals (``problem.NOISE_ESTIMATED``)
RELATIVE_WEIGHT_Q_RAD = 1e-4


def _check(name, a, shape_tail):
    a = np.asarray(a, float)
    if a.ndim != 1 + len(shape_tail) or a.shape[1:] != shape_tail:
        raise DataError(f"{name} must have shape (N, {', '.join(map(str, shape_tail))}), got {a.shape}")
    bad = ~np.isfinite(a)
    if bad.any():
        raise DataError(f"{name}: pose {int(np.argwhere(bad)[0][0])} contains a non-finite value (NaN or inf)")
    return a


def h4_igm_problem(
    robot: H4Robot,
    q_meas,
    T_cam_target_meas,
    sigma_q_rad: float | None = None,
    pose_cov=None,
    labels=None,
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
    q_meas = _check("q_meas", q_meas, (4,))
    T = _check("T_cam_target_meas", T_cam_target_meas, (4, 4))
    N = len(q_meas)
    if len(T) != N:
        raise DataError(f"q_meas has {N} poses but T_cam_target_meas has {len(T)}")
    if N == 0:
        raise DataError("H4 IGM problem needs at least one pose")
    if sigma_q_rad is None:
        estimated = pose_cov is None
        sigma_q_rad = 0.0 if pose_cov is not None else RELATIVE_WEIGHT_Q_RAD
    else:
        estimated = False
    if not np.isfinite(sigma_q_rad) or sigma_q_rad < 0:
        raise DataError(f"sigma_q_rad must be a finite number >= 0, got {sigma_q_rad}")
    x0 = robot.params.nominal
    cov = np.broadcast_to(float(sigma_q_rad) ** 2 * np.eye(4), (N, 4, 4)).copy()
    if pose_cov is not None:
        S = np.asarray(pose_cov, float)
        if S.shape == (6, 6):
            S = np.broadcast_to(S, (N, 6, 6))
        S = _check("pose_cov", S, (6, 6))
        if len(S) != N:
            raise DataError(f"pose_cov has {len(S)} poses, expected {N}")
        _, G = robot.igm_from_camera_jacobian(T, x0, with_meas=True)
        cov += G @ S @ np.swapaxes(G, -1, -2)
    eig = np.linalg.eigvalsh(cov)
    if np.any(eig <= 0):
        k = int(np.argwhere(eig.min(axis=1) <= 0)[0][0])
        raise DataError(f"H4 observation covariance of pose {k} is not positive definite (give sigma_q_rad > 0)")
    # fail early, naming the pose, if the starting model cannot reach a measured pose
    robot.igm_from_camera(T, x0)

    def residual(x, idx=None):
        sel = slice(None) if idx is None else np.asarray(idx, int)
        return q_meas[sel] - robot.igm_from_camera(T[sel], x)

    def jacobian(x, idx=None):
        sel = slice(None) if idx is None else np.asarray(idx, int)
        return -robot.igm_from_camera_jacobian(T[sel], x)

    return IdentificationProblem(
        params=robot.params,
        residual=residual,
        jacobian=jacobian,
        obs_cov=cov,
        residual_kind="joint",
        labels=tuple(labels) if labels is not None else tuple(range(N)),
        component_names=("q1", "q2", "q3", "q4"),
        meta={"robot": "h4", "model": robot.model, "sigma_q_rad": float(sigma_q_rad),
              **({"noise": NOISE_ESTIMATED} if estimated else {})},
    )


def synthetic_h4_measurements(robot: H4Robot, X, x_true, rng, sigma_q_rad=0.0, sigma_t_m=0.0, sigma_r_rad=0.0):
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
