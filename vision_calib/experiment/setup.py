"""Experimental setups: a robot + camera mount + target, with the maths every experiment needs.

Two kinds share one interface (:class:`Setup`):

- :class:`SerialSetup`: a serial arm (``kinematics.serial.SerialChain``). Eye-in-hand (camera on
  the flange, target on the table): the chain measures ``T_target_cam = T_target_base · FK(q) ·
  T_flange_cam``. Fixed camera (tripod, target on the flange/probe): ``T_cam_target =
  T_cam_base · FK(q) · T_flange_target``. Commanded poses are joint sets q (N, n) rad.
- :class:`H4Setup`: the H4 robot, camera on the base, target on the nacelle; commanded poses are
  nacelle poses X (N, 4) = (x, y, z [m], theta [rad]) mapped to joints by the TRUE inverse model.

Every setup turns poses into the camera's view ``T_cam_target`` (for rendering), builds the
identification problem from measurements, and evaluates a parameter vector on validation poses.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import frames as F
from ..camera import CameraIntrinsics
from ..errors import DataError
from ..identify.problem import IdentificationProblem
from ..kinematics.params import ParameterSet


@dataclass(frozen=True)
class Measurements:
    """What the camera (and the encoders) gave for N robot poses.

    poses: commanded poses (serial: q (N, n) rad; H4: X (N, 4)). joints: measured joint values
    (N, n_joints) rad. T_cam_target: (N, 4, 4) measured camera poses. cov: (N, 6, 6) covariance of
    each measured T_cam_target in the ``frames.pose_error`` convention (camera frame).
    labels: (N,) pose ids.
    """

    poses: np.ndarray
    joints: np.ndarray
    T_cam_target: np.ndarray
    cov: np.ndarray
    labels: tuple = ()

    def subset(self, idx) -> "Measurements":
        idx = np.asarray(idx, dtype=int)
        labels = tuple(self.labels[i] for i in idx) if self.labels else ()
        return Measurements(self.poses[idx], self.joints[idx], self.T_cam_target[idx], self.cov[idx], labels)


def pose_cov_from_sigmas(n: int, sigma_t_m: float, sigma_r_rad: float) -> np.ndarray:
    """(n, 6, 6) diagonal covariances [sigma_t² x3, sigma_r² x3]; tiny floor keeps them invertible."""
    st = max(float(sigma_t_m), 1e-6)  # floor 1 um / 1 urad: noise-free data keeps a well-conditioned weighting
    sr = max(float(sigma_r_rad), 1e-6)
    return np.broadcast_to(np.diag([st**2] * 3 + [sr**2] * 3), (n, 6, 6)).copy()


def accuracy_stats(err6: np.ndarray) -> dict:
    """Accuracy figures of pose errors (N, 6) [m, rad] -> {position_rms_mm, position_max_mm,
    rotation_rms_deg, rotation_max_deg} (RMS of the error vector norms)."""
    dp = np.linalg.norm(err6[:, :3], axis=1) * 1e3
    dr = np.degrees(np.linalg.norm(err6[:, 3:], axis=1))
    return {
        "position_rms_mm": float(np.sqrt(np.mean(dp**2))),
        "position_max_mm": float(dp.max()),
        "rotation_rms_deg": float(np.sqrt(np.mean(dr**2))),
        "rotation_max_deg": float(dr.max()),
        "n_poses": int(len(err6)),
    }


@dataclass(frozen=True)
class Setup:
    """Common interface; see the module docstring. ``params`` is the full parameter set
    (robot + mounts) with the scene's free mask."""

    name: str
    params: ParameterSet
    camera: CameraIntrinsics | None
    mount: str
    meta: dict = field(default_factory=dict, compare=False, repr=False)

    kind = "abstract"
    default_residual = "pose"
    default_method = "lse"

    # -- to implement
    def T_cam_target(self, poses, x) -> np.ndarray:  # (N, 4, 4)
        raise NotImplementedError

    def joints(self, poses, x) -> np.ndarray:  # measured joints of commanded poses under parameters x
        raise NotImplementedError

    def problem(self, meas: Measurements, residual: str | None = None, params: ParameterSet | None = None) -> IdentificationProblem:
        raise NotImplementedError

    def evaluate(self, x, x_true, poses_val) -> dict:
        raise NotImplementedError

    def sample_poses(self, rng: np.random.Generator, n: int) -> np.ndarray:
        raise NotImplementedError

    # -- shared
    def synthetic_measurements(self, poses, x_true, rng, sigma_t_m=0.0, sigma_r_rad=0.0, sigma_q_rad=0.0,
                               labels=None) -> Measurements:
        """Noise-free T_cam_target of the true robot ⊕ Gaussian noise (camera frame, per component)."""
        poses = np.asarray(poses, float)
        T = self.T_cam_target(poses, x_true)
        n = len(T)
        d = np.concatenate([rng.normal(scale=sigma_t_m, size=(n, 3)), rng.normal(scale=sigma_r_rad, size=(n, 3))], axis=1)
        q = self.joints(poses, x_true)
        if sigma_q_rad > 0:
            q = q + rng.normal(scale=sigma_q_rad, size=q.shape)
        labels = tuple(labels) if labels is not None else tuple(f"p{i:03d}" for i in range(n))
        return Measurements(poses, q, F.perturb_pose(T, d), pose_cov_from_sigmas(n, sigma_t_m, sigma_r_rad), labels)

    def visible(self, T_cam_target, target_outline_m, margin_px=10.0, max_tilt_deg=60.0) -> np.ndarray:
        """(N,) bool: the whole target outline (K, 3) [m, target frame] projects inside the image
        with ``margin_px``, in front of the camera, and the board normal is within max_tilt_deg of
        the viewing ray."""
        cam = self.camera
        T = np.asarray(T_cam_target, float)
        ok = np.ones(len(T), dtype=bool)
        for i, Ti in enumerate(T):
            p = F.transform_points(Ti, target_outline_m)
            if np.any(p[:, 2] <= 0.05):
                ok[i] = False
                continue
            uv = cam.project(p)
            inside = (uv[:, 0] >= margin_px) & (uv[:, 0] <= cam.width - 1 - margin_px) & (uv[:, 1] >= margin_px) & (
                uv[:, 1] <= cam.height - 1 - margin_px)
            centre = p.mean(axis=0)
            normal = Ti[:3, 2]
            cosang = abs(normal @ centre) / np.linalg.norm(centre)
            ok[i] = bool(inside.all() and cosang >= np.cos(np.radians(max_tilt_deg)))
        return ok


@dataclass(frozen=True)
class SerialSetup(Setup):
    """Serial arm + camera. ``chain``: SerialChain whose left/right mounts are
    (T_target_base, T_flange_cam) for eye_in_hand or (T_cam_base, T_flange_target) for fixed.
    ``q_center`` (n,) rad and ``q_spread`` (n,) rad: random poses are drawn uniformly in
    q_center ± q_spread (within joint limits) and kept when the target is visible."""

    chain: object = None
    q_center: np.ndarray | None = None
    q_spread: np.ndarray | None = None
    target_outline: np.ndarray | None = None

    kind = "serial"
    default_residual = "pose"
    default_method = "lse"

    def _chain_T(self, q, x):
        return self.chain.forward(q, x)

    def T_cam_target(self, poses, x) -> np.ndarray:
        T = self._chain_T(poses, x)
        return F.inv_T(T) if self.mount == "eye_in_hand" else T

    def joints(self, poses, x) -> np.ndarray:
        return np.asarray(poses, float).copy()

    def chain_measurements(self, meas: Measurements):
        """Measured chain poses T_left_right (N, 4, 4) and their covariances (N, 6, 6)."""
        if self.mount == "eye_in_hand":
            G = F.inverse_error_map(meas.T_cam_target)
            return F.inv_T(meas.T_cam_target), G @ meas.cov @ np.swapaxes(G, -1, -2)
        return meas.T_cam_target, meas.cov

    def problem(self, meas, residual=None, params=None) -> IdentificationProblem:
        from ..identify.serial_problem import serial_problem

        residual = residual or self.default_residual
        if residual not in ("pose", "position"):
            raise DataError(f"serial setups use 'pose' or 'position' residuals, not {residual!r}")
        T, cov = self.chain_measurements(meas)
        if residual == "position":
            cov = cov[:, :3, :3]
        chain = self.chain.with_params(params or self.params)
        return serial_problem(chain, meas.joints, T, residual=residual, obs_cov=cov, labels=meas.labels)

    def evaluate(self, x, x_true, poses_val) -> dict:
        """Errors of the predicted chain pose (end frame in the left frame) vs truth on validation joints."""
        err = F.pose_error(self._chain_T(poses_val, x_true), self._chain_T(poses_val, x))
        return accuracy_stats(err)

    def sample_poses(self, rng, n, max_tries=200, check_view=True) -> np.ndarray:
        """n joint sets uniform in q_center ± q_spread within the joint limits; with check_view, only
        those where the whole target is in view (identification poses must see it)."""
        c = np.asarray(self.q_center, float)
        s = np.asarray(self.q_spread, float)
        out = []
        for _ in range(max_tries):
            q = c + rng.uniform(-1, 1, size=(max(4 * n, 64), c.size)) * s
            q = q[self.chain.within_limits(q)]
            if check_view and self.camera is not None and self.target_outline is not None:
                q = q[self.visible(self.T_cam_target(q, self.params.nominal), self.target_outline)]
            out.extend(q)
            if len(out) >= n:
                return np.array(out[:n])
        raise DataError(
            f"{self.name}: could not draw {n} joint sets with the target in view around q_center ± q_spread "
            f"(found {len(out)}); widen poses.spread_deg or check the mounts")


@dataclass(frozen=True)
class H4Setup(Setup):
    """H4 robot (``robot``: kinematics.h4.H4Robot), camera on the base, target on the nacelle.
    Poses are nacelle poses X (N, 4); joints come from the TRUE inverse model."""

    robot: object = None
    line_tests: tuple = ()

    kind = "h4"
    default_residual = "joint"
    default_method = "igm"

    def T_cam_target(self, poses, x) -> np.ndarray:
        return self.robot.camera_measurement(poses, x)

    def joints(self, poses, x) -> np.ndarray:
        return self.robot.igm(poses, x)

    def problem(self, meas, residual=None, params=None) -> IdentificationProblem:
        from ..identify.h4_problem import h4_igm_problem

        residual = residual or self.default_residual
        if residual != "joint":
            raise DataError(f"the H4 inverse-model method uses 'joint' residuals, not {residual!r}")
        robot = self.robot_with(params or self.params)
        sigma_q = self.meta.get("sigma_q_rad", 0.0)
        return h4_igm_problem(robot, meas.joints, meas.T_cam_target, sigma_q_rad=sigma_q or None,
                              pose_cov=meas.cov, labels=meas.labels)

    def robot_with(self, params: ParameterSet):
        from dataclasses import replace

        return replace(self.robot, params=params)

    def evaluate(self, x, x_true, poses_val, meas_val: Measurements | None = None) -> dict:
        """Nacelle pose error of the forward model (Newton on the IGM) with parameters x, from the
        joints the true robot needs for poses_val (N, 4); plus the paper's V1, V2 (joint residuals on
        validation measurements, rad) and V3 (straightness of reconstructed straight lines, m)."""
        X = np.asarray(poses_val, float)
        q = self.robot.igm(X, x_true)
        Xh = self.robot.fgm(q, x, X0=X)
        err = np.zeros((len(X), 6))
        err[:, :3] = Xh[:, :3] - X[:, :3]
        err[:, 5] = np.angle(np.exp(1j * (Xh[:, 3] - X[:, 3])))
        out = accuracy_stats(err)
        if meas_val is not None:
            r = meas_val.joints - self.robot.igm_from_camera(meas_val.T_cam_target, x)
            r = np.angle(np.exp(1j * r))
            out["V1_rad"] = float(np.mean(r))
            out["V2_rad"] = float(np.sqrt(np.mean(r**2)))
        out["V3_m"] = float(np.mean([self.straightness(line, x, x_true) for line in self.lines()]))
        return out

    def lines(self) -> list[np.ndarray]:
        """Two straight-line motions through the workspace (paper §6.1, configurations 1 and 2):
        X (50, 4) each, along a diagonal of the box at theta = 0 and theta = 10 deg."""
        c, s = self.robot.center, self.robot.size
        t = np.linspace(-0.45, 0.45, 50)[:, None]
        d1 = np.array([s[0], s[1], 0.0])
        d2 = np.array([s[0], -s[1], s[2]])
        L1 = np.column_stack([c + t * d1, np.zeros(len(t))])
        L2 = np.column_stack([c + t * d2, np.full(len(t), np.radians(10.0))])
        return [L1, L2]

    def straightness(self, line_X, x, x_true) -> float:
        """RMS distance [m] of the forward-model positions (parameters x) of the joints that move the
        TRUE robot along a straight line, to their least-squares line."""
        q = self.robot.igm(line_X, x_true)
        P = self.robot.fgm(q, x, X0=line_X)[:, :3]
        P = P - P.mean(axis=0)
        _, _, Vt = np.linalg.svd(P, full_matrices=False)
        resid = P - np.outer(P @ Vt[0], Vt[0])
        return float(np.sqrt(np.mean(np.sum(resid**2, axis=1))))

    def sample_poses(self, rng, n, check_view=True) -> np.ndarray:
        from ..kinematics.h4 import random_workspace_poses

        return random_workspace_poses(n, rng, center=self.robot.center, size=self.robot.size)
