"""The calibrated robot a controller uses: forward kinematics with its uncertainty, inverse kinematics on the
calibrated model, and compensation of joint commands meant for the nominal model.

Frames and units: ``T_base_tool`` (4, 4) [m] is the tool in the robot's base frame, tool = flange + ``tcp``
(x, y, z [m] in the flange frame, default 0). A pose covariance (6, 6) is in the ``frames.pose_error``
convention: [translation (m), rotation vector (rad)], both in the base frame (the parent frame of the pose).
Joint values q are (n,) or (N, n) [rad; m for a prismatic joint] as the controller reads them. The base frame is
the calibrated model's: where the identification could not see a part of the base (e.g. the rotation about joint
1's axis of an eye-in-hand calibration: folded into the target mount), the nominal convention defines it.

The nominal model (:attr:`CalibratedRobot.nominal`) is the robot file's geometry with the calibrated mounts.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from .. import frames as F
from ..errors import DataError, ParameterError
from ..io.controller_export import find_result
from ..io.model_export import CalibratedModel, joint_offsets, read_calibrated_model
from ..kinematics.protocols import JointOffsetForm, PrismaticJoints
from .kinematics import kinematics_for

#: parameter step [m or rad] of the finite-difference parameter Jacobian
FD_PARAM_STEP = 1e-6


def model_path(path) -> Path:
    """The calibrated_model.yaml of a result folder (or ``path`` itself, such a file): ``io.controller_export.
    find_result``; DataError naming the folder when it holds none (a failed fit writes no model) or only a hand-eye
    result (no robot kinematics: export its mounts with ``vision-calib export RESULT --format ros_tf``)."""
    p = find_result(path)
    if p.suffix.lower() == ".json":
        raise DataError(f"{p}: a hand-eye result has no robot kinematics to deploy (it identified the camera and target "
                        "mounts only: `vision-calib export RESULT --format ros_tf` writes them)")
    return p


def _check_q(q: ArrayLike, n: int, what: str = "joint values") -> tuple[np.ndarray, bool]:
    """(q (N, n) float, single) from (n,) or (N, n); DataError naming the row and joint of a bad value."""
    q = np.asarray(q, float)
    single = q.ndim == 1
    q = q[None] if single else q
    if q.ndim != 2 or q.shape[1] != n:
        raise DataError(f"{what}: expected shape ({n},) or (N, {n}), got {np.shape(q)}")
    bad = np.argwhere(~np.isfinite(q))
    if bad.size:
        k, j = (int(v) for v in bad[0])
        raise DataError(f"{what}: row {k} joint q{j + 1} is not finite ({q[k, j]})")
    return q, single


def _check_T(T: ArrayLike, what: str = "poses") -> tuple[np.ndarray, bool]:
    """(T (N, 4, 4), single) from (4, 4) or (N, 4, 4); DataError naming the row of a non-finite or non-rigid pose."""
    T = np.asarray(T, float)
    single = T.ndim == 2
    T = T[None] if single else T
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise DataError(f"{what}: expected shape (4, 4) or (N, 4, 4), got {np.shape(T)}")
    R = T[:, :3, :3]
    bad = ~np.all(np.isfinite(T), axis=(1, 2)) | (np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2)) > 1e-6)
    bad |= np.linalg.det(R) < 0
    if bad.any():
        raise DataError(f"{what}: row {int(np.argmax(bad))} is not a finite rigid transform")
    return T, single


@dataclass(frozen=True, eq=False)
class CalibratedRobot:
    """A calibrated model ready for a controller (module docstring). Build it with :meth:`load`.

    model: the file's content (``io.model_export.CalibratedModel``). x / x_nominal (n,): calibrated and nominal
    parameter vectors (SI, ``model.names`` order; they differ only in the robot's own parameters, not the mounts).
    covariance (n, n): of x (zero for a nominal model). tcp (3,) [m, flange frame]. notes: what was assumed."""

    model: CalibratedModel
    kin: object
    x: np.ndarray
    x_nominal: np.ndarray
    covariance: np.ndarray
    tcp: np.ndarray
    notes: tuple = ()
    is_nominal: bool = False

    # ------------------------------------------------------------------ construction
    @classmethod
    def load(cls, path, tcp: ArrayLike | None = None) -> "CalibratedRobot":
        """From a result folder or its calibrated_model.yaml; tcp: x, y, z [m] of the tool in the flange frame."""
        return cls.from_model(read_calibrated_model(model_path(path)), tcp)

    @classmethod
    def from_model(cls, model: CalibratedModel, tcp: ArrayLike | None = None) -> "CalibratedRobot":
        tcp = np.zeros(3) if tcp is None else np.asarray(tcp, float).reshape(-1)
        if tcp.shape != (3,) or not np.all(np.isfinite(tcp)):
            raise ParameterError(f"tcp: expected 3 finite numbers x, y, z [m, flange frame], got {tcp.tolist()}")
        kin = kinematics_for(model.robot, tcp)
        names = model.names
        nom = dict(zip(model.nominal_robot.params.names, model.nominal_robot.params.nominal))
        x_nom = np.array([nom[n] if n in kin.arm_names else v for n, v in zip(names, model.x)])
        notes = tuple(model.notes)
        if not np.any(model.covariance):
            notes += ("the model has no covariance: forward() gives zero covariance",)
        return cls(model, kin, model.x.copy(), x_nom, model.covariance, tcp, notes)

    @property
    def nominal(self) -> "CalibratedRobot":
        """The nominal model (robot file geometry, calibrated mounts, same tcp), zero covariance."""
        if self.is_nominal:
            return self
        return replace(self, x=self.x_nominal, covariance=np.zeros_like(self.covariance), is_nominal=True,
                       notes=("nominal model: the robot file's geometry with the calibrated mounts",))

    @property
    def names(self) -> tuple:
        return self.model.names

    @property
    def n_joints(self) -> int:
        return self.kin.n_joints

    @property
    def prismatic(self) -> np.ndarray:
        """(n,) bool: joints whose value is a length (m); all False for an all-revolute robot."""
        robot = self.model.robot
        return np.asarray(robot.prismatic, bool) if isinstance(robot, PrismaticJoints) else np.zeros(self.n_joints, bool)

    @property
    def observed_name(self) -> str:
        """Name of the transform the calibration measured (e.g. ``T_target_cam``), see :meth:`observed`."""
        return self.kin.observed_name

    # ------------------------------------------------------------------ kinematics
    def _propagate(self, fun, jac, q, fd: bool) -> tuple[np.ndarray, np.ndarray]:
        T = fun(q, self.x)
        C = self.covariance
        if not np.any(C):
            return T, np.zeros((len(T), 6, 6))
        J = self._fd_jacobian(fun, q) if fd or jac is None else jac(q, self.x)
        return T, np.einsum("kin,nm,kjm->kij", J, C, J)

    def _fd_jacobian(self, fun, q) -> np.ndarray:
        """(N, 6, n) central-difference parameter Jacobian in the pose_error convention (columns of parameters with
        a non-zero variance only; the others stay 0)."""
        J = np.zeros((len(q), 6, len(self.x)))
        for k in np.flatnonzero(np.diag(self.covariance) > 0):
            dx = np.zeros(len(self.x))
            dx[k] = FD_PARAM_STEP
            J[:, :, k] = F.pose_error(fun(q, self.x - dx), fun(q, self.x + dx)) / (2 * FD_PARAM_STEP)
        return J

    def forward(self, q: ArrayLike, fd: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(T_base_tool (4, 4) or (N, 4, 4) [m], covariance (6, 6) or (N, 6, 6) [m, rad: translation, then rotation
        vector, base frame]) at joint values q (n,) or (N, n). The covariance propagates the parameter covariance
        through the analytic parameter Jacobian (fd, or a kinematics without one: central finite differences)."""
        q, single = _check_q(q, self.n_joints)
        T, C = self._propagate(self.kin.tool, self.kin.tool_jacobian, q, fd)
        return (T[0], C[0]) if single else (T, C)

    def observed(self, q: ArrayLike, fd: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(T, covariance) of the transform the calibration measured (:attr:`observed_name`: serial
        ``T_<left>_<right>`` in the left mount's frame, e.g. T_target_cam; H4 T_cam_target in the camera frame) at
        joint values q, mounts included; covariance as in :meth:`forward`, in that transform's parent frame."""
        q, single = _check_q(q, self.n_joints)
        T, C = self._propagate(self.kin.observed, self.kin.observed_jacobian, q, fd)
        return (T[0], C[0]) if single else (T, C)

    def inverse(self, T_base_tool: ArrayLike, q_start: ArrayLike | None = None, labels=None) -> np.ndarray:
        """Joint values (n,) or (N, n) that put the tool at T_base_tool (4, 4) or (N, 4, 4) [m] on this model:
        a serial chain by damped Newton (Levenberg-Marquardt, joint limits kept) from q_start, else from the
        nominal model's solution (itself from the stored starts nearest the goal; those starts directly where the
        nominal model has no solution); the H4 by its closed-form inverse geometric model.
        ``deploy.kinematics.PoseNotReachedError`` (CLI exit 3) names the pose (``labels``: names of the rows) when it
        is unreachable or the iteration does not converge."""
        T, single = _check_T(T_base_tool)
        start = None
        if q_start is not None:
            start, _ = _check_q(q_start, self.n_joints, "q_start")
            start = np.broadcast_to(start, (len(T), self.n_joints))
        q = self.kin.inverse(T, self.x, start, labels, "nominal" if self.is_nominal else "calibrated",
                             x_seed=None if self.is_nominal else self.x_nominal)
        return q[0] if single else q

    def compensate(self, q: ArrayLike, labels=None) -> np.ndarray:
        """The joint values (n,) or (N, n) that put the tool, on the calibrated model, where the NOMINAL model puts
        it for q: what to send instead of q to a controller that computed q with the nominal model."""
        q, single = _check_q(q, self.n_joints)
        T = self.kin.tool(q, self.x_nominal)
        qc = self.kin.inverse(T, self.x, q, labels, "calibrated")
        return qc[0] if single else qc

    # ------------------------------------------------------------------ joint offsets
    def joint_offsets(self) -> dict:
        """{"q<i>": {parameter, offset, unit}}: the joint offsets a controller can take
        (``io.model_export.OFFSET_CONVENTION``: model joint value = reading + offset); from the file, else computed
        ({} for a robot without ``kinematics.protocols.JointOffsetForm``)."""
        if self.model.joint_offsets:
            return dict(self.model.joint_offsets)
        robot = self.model.robot
        if not isinstance(robot, JointOffsetForm):
            return {}
        return joint_offsets(robot, self.x, self.x_nominal, self.prismatic)

    def offset_form(self) -> np.ndarray:
        """(n,) the calibrated parameters in the equivalent joint-offset form (same predictions; each joint's
        rotation about its own axis carried by its offset parameter); x itself for a robot without it."""
        robot = self.model.robot
        return robot.joint_offset_form(self.x)[0] if isinstance(robot, JointOffsetForm) else self.x.copy()


__all__ = ["CalibratedRobot", "model_path"]
