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
from .export import find_result
from ..io.model_export import CalibratedModel, joint_offsets, read_calibrated_model
from ..kinematics.protocols import JointOffsetForm, PrismaticJoints
from .kinematics import PoseNotReachedError, kinematics_for, raise_not_reached
from .solve import AMPLIFIED_DEG_PER_MM, amplification_deg_per_mm, damped_correction, levenberg_marquardt

#: parameter step [m or rad] of the finite-difference parameter Jacobian
FD_PARAM_STEP = 1e-6
#: the accuracy compensate brings the tool within: this many predicted standard deviations of the tool pose (sqrt of
#: the trace of the translation / rotation block of :meth:`CalibratedRobot.forward`'s covariance), at least the floors
ACCURACY_SIGMAS = 1.0
ACCURACY_FLOOR_T_M = 1e-6
ACCURACY_FLOOR_R_RAD = 1e-6
#: the share of the predicted accuracy a damped correction may leave (the rest of the error budget is the model's
#: own: leaving r adds in quadrature, sqrt(1 + 0.5^2) = 1.12 x the predicted error at most)
DAMPED_SHARE = 0.5
#: largest joint correction [deg] compensate gives a joint set: more is another arm configuration, not a correction
#: (the row is named, not corrected)
MAX_CORRECTION_DEG = 10.0
#: ... and of a prismatic joint [mm] (more is not a calibration correction)
MAX_CORRECTION_MM = 10.0
#: rows per chunk of compensate (bounded memory: a few MB per chunk)
CHUNK_ROWS = 4096
#: poses per chunk of inverse (tens of MB per chunk; larger than CHUNK_ROWS: the Newton iterations of the few poses
#: converging last cost per iteration, not per pose)
INVERSE_CHUNK_ROWS = 32768
#: statuses of a compensated row (:class:`Compensation`)
STATUSES = ("corrected", "near_singularity", "outside_limits", "not_corrected")


def model_path(path) -> Path:
    """The calibrated_model.yaml of a result folder (or ``path`` itself, such a file): ``deploy.export.
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


def _limit_text(v: float, lo: float, hi: float, prismatic: bool) -> str:
    if prismatic:
        return f"{v:.6g} m outside its limits [{lo:.6g}, {hi:.6g}] m"
    return (f"{v:.6g} rad ({np.degrees(v):.6g} deg) outside its limits [{lo:.6g}, {hi:.6g}] rad "
            f"([{np.degrees(lo):.6g}, {np.degrees(hi):.6g}] deg)")


@dataclass(frozen=True)
class Compensation:
    """Per joint set of :meth:`CalibratedRobot.compensate_rows` (N rows, n joints): q (N, n) the commands meant for
    the nominal model; q_corrected (N, n) (NaN where not corrected); status (N,) one of :data:`STATUSES`; why (N,)
    str ("" for a corrected row); remaining_t_m / remaining_r_rad (N,): the tool error left on the calibrated model
    (NaN where not corrected); tolerance_t_m / tolerance_r_rad (N,): the predicted accuracy it is brought within;
    amplification (N,) [deg per mm] (``deploy.solve.amplification_deg_per_mm``, NaN for a closed-form robot)."""

    q: np.ndarray
    q_corrected: np.ndarray
    status: np.ndarray
    why: np.ndarray
    remaining_t_m: np.ndarray
    remaining_r_rad: np.ndarray
    tolerance_t_m: np.ndarray
    tolerance_r_rad: np.ndarray
    amplification: np.ndarray

    @property
    def corrected(self) -> np.ndarray:
        """(N,) bool: the rows with a correction (status corrected or near_singularity)."""
        return np.isin(self.status, STATUSES[:2])

    @staticmethod
    def concatenate(parts: list) -> "Compensation":
        return Compensation(*(np.concatenate([getattr(p, f) for p in parts]) for f in Compensation.__dataclass_fields__))


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

    def inverse_rows(self, T_base_tool: ArrayLike, q_start: ArrayLike | None = None, labels=None,
                     progress=None) -> tuple[np.ndarray, np.ndarray]:
        """(q (N, n), why (N,) str): joint values that put the tool at each pose of T_base_tool (N, 4, 4) [m] on this
        model, each pose on its own: a serial chain by damped Newton (Levenberg-Marquardt, joint limits kept,
        ``deploy.kinematics.BatchedArm``) from q_start ((n,): one start for all, or (N, n): one per pose; the branch
        nearest it), else from the nominal model's solution (itself from the stored starts nearest the goal; those
        starts directly where the nominal model has no solution); the H4 by its closed-form inverse geometric model.
        A pose not reached (unreachable, or the iteration stalls off it): q NaN, why names it (``labels``: names of
        the rows) with the residual left; "" for a pose reached. In chunks of :data:`INVERSE_CHUNK_ROWS` poses
        (``progress(rows_done, rows_total)`` after each)."""
        T, _ = _check_T(T_base_tool)
        start = None
        if q_start is not None:
            start, _ = _check_q(q_start, self.n_joints, "q_start")
            if len(start) not in (1, len(T)):
                raise DataError(f"q_start: {len(start)} joint sets for {len(T)} poses (give one, or one per pose)")
            start = np.broadcast_to(start, (len(T), self.n_joints))
        lab = list(labels) if labels is not None else [f"#{k}" for k in range(len(T))]
        q, why = np.empty((len(T), self.n_joints)), np.empty(len(T), dtype=object)
        for a in range(0, len(T), INVERSE_CHUNK_ROWS):
            b = min(a + INVERSE_CHUNK_ROWS, len(T))
            q[a:b], why[a:b] = self.kin.inverse_rows(T[a:b], self.x, None if start is None else start[a:b], lab[a:b],
                                                     "nominal" if self.is_nominal else "calibrated",
                                                     x_seed=None if self.is_nominal else self.x_nominal)
            if progress is not None:
                progress(b - a, len(T))
        return q, why.astype(str)

    def inverse(self, T_base_tool: ArrayLike, q_start: ArrayLike | None = None, labels=None,
                progress=None) -> np.ndarray:
        """Joint values (n,) or (N, n) that put the tool at T_base_tool (4, 4) or (N, 4, 4) [m] on this model
        (:meth:`inverse_rows`); ``deploy.kinematics.PoseNotReachedError`` (CLI exit 3) names the first pose not
        reached (``labels``: names of the rows) and how many are not."""
        q, why = self.inverse_rows(T_base_tool, q_start, labels, progress)
        raise_not_reached(why)
        return q[0] if np.ndim(T_base_tool) == 2 else q

    def compensate(self, q: ArrayLike, labels=None) -> np.ndarray:
        """The joint values (n,) or (N, n) that put the tool, on the calibrated model, within its predicted accuracy
        of where the NOMINAL model puts it for q: what to send instead of q to a controller that computed q with the
        nominal model (:meth:`compensate_rows`). PoseNotReachedError naming the first row (``labels``) that cannot
        be corrected or is outside the joint limits."""
        q, single = _check_q(q, self.n_joints)
        c = self.compensate_rows(q)
        bad = np.flatnonzero(~c.corrected)
        if bad.size:
            k = int(bad[0])
            lab = list(labels) if labels is not None else [f"#{i}" for i in range(len(q))]
            raise PoseNotReachedError(f"joint set {lab[k]}: {c.why[k]}" + (f" ({bad.size} rows not corrected)"
                                                                            if bad.size > 1 else ""), pose_index=k)
        return c.q_corrected[0] if single else c.q_corrected

    def accuracy(self, q: np.ndarray) -> np.ndarray:
        """(N, 2) [m, rad]: the predicted accuracy at joint sets q (N, n): :data:`ACCURACY_SIGMAS` x the RMS
        translation / rotation error the covariance predicts, the smaller of the tool pose's (base frame) and the
        measured transform's (:meth:`observed`: what the calibration saw; the base frame's own uncertainty, common
        to all poses, is in the first only), at least the floors."""
        var = np.zeros((len(q), 6))
        if np.any(self.covariance):
            tol = []
            for jac in (self.kin.tool_jacobian, self.kin.observed_jacobian):
                J = jac(q, self.x)
                v = np.einsum("kin,kin->ki", J @ self.covariance, J)
                tol.append(np.column_stack([v[:, :3].sum(1), v[:, 3:].sum(1)]))
            var = np.minimum(*tol)
        else:
            var = var[:, :2]
        return np.maximum(ACCURACY_SIGMAS * np.sqrt(np.clip(var, 0, None)), [ACCURACY_FLOOR_T_M, ACCURACY_FLOOR_R_RAD])

    def compensate_rows(self, q: ArrayLike, progress=None) -> Compensation:
        """Compensate each joint set of q (N, n) (meant for the nominal model) on its own (:class:`Compensation`):
        the smallest joint correction that puts the calibrated model's tool within its predicted accuracy
        (:meth:`accuracy`) of the nominal model's tool: exact along the well-conditioned joint directions, damped
        along those that need more than :data:`AMPLIFIED_DEG_PER_MM` (``deploy.solve.damped_correction``; flagged
        ``near_singularity``); a row the damped Gauss-Newton leaves outside the accuracy gets the exact solution
        (Levenberg-Marquardt) when that reaches it. Joint sets outside the joint limits, and rows whose correction
        would need a joint past its limit or does not converge, are named in ``why``, never raised. Vectorised
        over chunks of :data:`CHUNK_ROWS` rows; ``progress(rows_done, rows_total)`` is called after each."""
        q, _ = _check_q(q, self.n_joints)
        parts = []
        for a in range(0, len(q), CHUNK_ROWS):
            parts.append(self._compensate_chunk(q[a:a + CHUNK_ROWS]))
            if progress is not None:
                progress(len(parts[-1].q), len(q))
        return Compensation.concatenate(parts)

    def _outside_limits(self, q: np.ndarray) -> np.ndarray:
        """(N,) str: why each joint set is outside the joint limits ("" inside)."""
        why = np.full(len(q), "", dtype=object)
        lim = self.kin.joint_limits
        if lim is None:
            return why
        lim = np.asarray(lim, float)
        out = (q < lim[:, 0]) | (q > lim[:, 1])
        for k, j in zip(*np.nonzero(out)):
            if not why[k]:
                why[k] = f"joint q{j + 1} = " + _limit_text(q[k, j], *lim[j], bool(self.prismatic[j]))
        return why

    def _compensate_chunk(self, q: np.ndarray) -> Compensation:
        N = len(q)
        kin = self.kin
        T_goal = kin.tool(q, self.x_nominal)
        tol = self.accuracy(q)
        why = self._outside_limits(q)
        status = np.where(why != "", "outside_limits", "corrected").astype(object)
        qc, amp = np.full(q.shape, np.nan), np.full(N, np.nan)
        idx = np.flatnonzero(why == "")
        if kin.closed_form:
            qc[idx], err = kin.inverse_rows(T_goal[idx], self.x)
            for i, e in zip(idx, err):
                if e:
                    status[i], why[i] = "not_corrected", f"not corrected: {e}"
        elif idx.size:
            lim = kin.joint_limits

            def f(qq):
                return kin.tool(qq, self.x)

            def jac(qq):
                return kin.joint_jacobian(qq, self.x)

            s_near = np.degrees(1.0) / (1e3 * AMPLIFIED_DEG_PER_MM)
            qd, r, s_min = damped_correction(f, jac, T_goal[idx], q[idx], tol[idx], s_near, lim, target=DAMPED_SHARE)
            amp[idx] = amplification_deg_per_mm(s_min)
            within = self._within(r, tol[idx], qd - q[idx])
            qc[idx[within]] = qd[within]
            redo = idx[~within]
            if redo.size:  # the damped iteration missed (a joint limit, a strong non-linearity): the exact solution
                qe, re, _ = levenberg_marquardt(f, T_goal[redo], q[redo], lim, jac=jac)
                ok = self._within(re, tol[redo], qe - q[redo])
                qc[redo[ok]] = qe[ok]
                for i, qi, ri in zip(redo[~ok], qe[~ok], re[~ok]):
                    status[i], why[i] = "not_corrected", self._not_corrected_why(q[i], qi, ri, tol[i], amp[i])
            status[(status == "corrected") & (amp > AMPLIFIED_DEG_PER_MM)] = "near_singularity"
        done = np.flatnonzero(np.isin(status, STATUSES[:2]))
        rem = np.full((N, 6), np.nan)
        rem[done] = F.pose_error(T_goal[done], kin.tool(qc[done], self.x))
        qc[~np.isin(status, STATUSES[:2])] = np.nan
        return Compensation(q, qc, status.astype(str), why.astype(str), np.linalg.norm(rem[:, :3], axis=1),
                            np.linalg.norm(rem[:, 3:], axis=1), tol[:, 0], tol[:, 1], amp)

    def max_correction(self) -> np.ndarray:
        """(n,) the largest correction compensate gives each joint [rad: :data:`MAX_CORRECTION_DEG`; m for a
        prismatic joint: :data:`MAX_CORRECTION_MM`]."""
        return np.where(self.prismatic, MAX_CORRECTION_MM * 1e-3, np.radians(MAX_CORRECTION_DEG))

    def _within(self, r: np.ndarray, tol: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """(N,) bool: residual r (N, 6) within tol (N, 2) by a correction dq (N, n) within :meth:`max_correction`."""
        return ((np.linalg.norm(r[:, :3], axis=1) <= tol[:, 0]) & (np.linalg.norm(r[:, 3:], axis=1) <= tol[:, 1])
                & np.all(np.abs(dq) <= self.max_correction(), axis=1))

    def _not_corrected_why(self, q0: np.ndarray, q: np.ndarray, r: np.ndarray, tol: np.ndarray, amp: float) -> str:
        """Why the exact solution q (n,) from q0 with residual r (6,) is refused."""
        lim = self.kin.joint_limits
        near = f" (near a singularity: {amp:.3g} deg per mm)" if amp > AMPLIFIED_DEG_PER_MM else ""
        j = int(np.argmax(np.abs(q - q0) / self.max_correction()))
        if np.linalg.norm(r[:3]) <= tol[0] and np.linalg.norm(r[3:]) <= tol[1]:
            if self.prismatic[j]:
                need = f"{(q[j] - q0[j]) * 1e3:+.3g} mm on q{j + 1}, more than {MAX_CORRECTION_MM:g} mm (prismatic)"
            else:
                need = (f"{np.degrees(q[j] - q0[j]):+.3g} deg on q{j + 1}, more than {MAX_CORRECTION_DEG:g} deg "
                        "(another arm configuration)")
            return f"not corrected: the exact correction needs {need}{near}"
        at = [] if lim is None else [j for j in range(self.n_joints) if np.isclose(q[j], lim[j, 0], atol=1e-9)
                                     or np.isclose(q[j], lim[j, 1], atol=1e-9)]
        return (f"not corrected: the calibrated model's tool stays {np.linalg.norm(r[:3]) * 1e3:.3g} mm, "
                f"{np.linalg.norm(r[3:]) * 1e3:.3g} mrad from the nominal one (predicted accuracy {tol[0] * 1e3:.3g} mm, "
                f"{tol[1] * 1e3:.3g} mrad){near}" + (f"; joint q{at[0] + 1} at its limit" if at else ""))

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
