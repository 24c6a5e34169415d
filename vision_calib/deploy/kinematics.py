"""What :class:`~vision_calib.deploy.robot.CalibratedRobot` asks of a robot model, one class per kinematics kind,
chosen in ONE place (:data:`KINDS`, by the robot object's type): serial chains
(``kinematics.protocols.ChainModel``: modified DH, URDF) and the H4 parallel robot (``kinematics.h4.H4Robot``).

Every method takes a full parameter vector x (n,) SI (calibrated or nominal values) and batches of N joint sets
q (N, n_joints) [rad, m for prismatic joints]:

- ``tool(q, x)`` -> T_base_tool (N, 4, 4) [m]: the robot alone (no mount), tool = flange + ``tcp`` (3,) [m, flange
  frame];
- ``tool_jacobian(q, x)`` -> (N, 6, n): d frames.pose_error(T_base_tool(x), T_base_tool(x + dx)) / dx, rows
  [dt (m), drot (rad)] in the base frame (analytic);
- ``observed(q, x)`` / ``observed_jacobian(q, x)``: the same for the transform the calibration measured (serial:
  ``chain.forward``, e.g. T_target_cam, in the left mount's frame; H4: T_cam_target, camera frame);
- ``inverse(T_base_tool (N, 4, 4), x, q_start (N, n) | None, labels, what, x_seed)`` -> q (N, n): on the model of x;
  a chain by damped Newton (``deploy.solve``) from q_start, else from the solution of the model of x_seed (the
  nominal), else from the stored starts nearest each goal; the H4 by its closed-form inverse geometric model;
  :class:`PoseNotReachedError` naming the pose (label) when it is not reached.
"""

from __future__ import annotations

import numpy as np

from .. import frames as F
from ..errors import ConfigError, UnreachablePoseError
from ..kinematics.h4 import EXTERNAL_NAMES, TILT_NAMES, H4Robot, nacelle_T, yaw_of
from ..kinematics.protocols import ChainModel
from ..kinematics.serial import SerialChain
from ..kinematics.urdf import URDFChain
from ..rig.serial import remount_chain
from .solve import joint_jacobian, levenberg_marquardt

#: candidate starts (after the centre of the joint ranges) of a chain's inverse without a start, and how many of
#: them (those whose tool pose is nearest the goal: |dt| + SEED_LENGTH_M |drot|) are tried
N_SEEDS = 1023
N_TRIES = 8
SEED_LENGTH_M = 0.3
#: largest tilt [rad] of an H4 goal pose (the nacelle only turns about z_B)
H4_TILT_TOL_RAD = 1e-6


class PoseNotReachedError(UnreachablePoseError):
    """The calibrated (or nominal) model does not reach a goal pose: the message names the pose (row / label), the
    goal and why (residual, the joint at its limit, the chain that cannot close). CLI exit code 3."""

    exit_code = 3


def _labels(labels, N) -> list:
    return list(labels) if labels is not None else [f"#{k}" for k in range(N)]


class ChainKinematics:
    """A serial chain (``ChainModel``: SerialChain, URDFChain) between its two mounts; tool = flange + tcp."""

    closed_form = False

    def __init__(self, robot: ChainModel, tcp: np.ndarray):
        self.robot = robot
        self.T_tcp = F.make_T(None, np.asarray(tcp, float))
        mounts = (f"{robot.left}.", f"{robot.right}.")
        self.arm_names = tuple(n for n in robot.params.names if not n.startswith(mounts))
        self.observed_name = robot.measured_name
        self._arm_cache: dict = {}

    @property
    def n_joints(self) -> int:
        return self.robot.n_joints

    @property
    def joint_limits(self) -> np.ndarray | None:
        return self.robot.joint_limits

    def _arm(self, x: np.ndarray):
        """The arm alone at x: the chain remounted on identity (base) and the tcp (``T_flange_tool``)."""
        key = np.asarray(x, float).tobytes()
        arm = self._arm_cache.get(key)
        if arm is None:
            valued = self.robot.with_params(self.robot.params.with_nominal(np.asarray(x, float)))
            arm = remount_chain(valued, "T_world_base", "T_flange_tool", np.eye(4), self.T_tcp)
            if len(self._arm_cache) > 8:
                self._arm_cache.clear()
            self._arm_cache[key] = arm
        return arm

    def tool(self, q, x) -> np.ndarray:
        return self._arm(x).forward(q)

    def tool_jacobian(self, q, x) -> np.ndarray:
        arm = self._arm(x)
        Ja = arm.pose_jacobian(q)
        J = np.zeros(Ja.shape[:2] + (len(x),))
        names = self.robot.params.names
        J[:, :, [names.index(n) for n in self.arm_names]] = Ja[:, :, arm.params.indices(self.arm_names)]
        return J

    def joint_jacobian(self, q, x) -> np.ndarray:
        """(N, 6, n_joints) d pose_error(T, tool(q + dq)) / dq at q (N, n) [per rad or m], base frame: geometric
        (a revolute joint about unit axis w through o: [w x (p_tool - o), w]; a prismatic one: [w, 0]) for modified-DH
        and URDF arms, central differences for another chain. Exact for the translation rows; the rotation rows are
        the angular velocity (= the rotation-vector derivative at a zero pose error)."""
        arm = self._arm(x)
        q = np.asarray(q, float)
        if isinstance(arm, SerialChain):
            fr = arm.forward_all(q)
            joint_frames, axes, prism = fr[:, 1:-1], np.array([0.0, 0.0, 1.0]), np.zeros(self.n_joints, bool)
        elif isinstance(arm, URDFChain):
            fr = arm.forward_all(q)
            joint_frames = fr[:, 1:-1].copy()  # child frame of each joint after its motion: same axis, same origin
            joint_frames[:, -1] = joint_frames[:, -1] @ F.inv_T(arm.tail)  # the tip link is the last one . tail
            axes, prism = np.asarray(arm.axes, float), np.asarray(arm.prismatic, bool)
        else:
            return joint_jacobian(arm.forward, q, np.broadcast_to(arm.forward(q), (len(q), 4, 4)))
        R = joint_frames[..., :3, :3]
        w = R @ axes[..., None] if axes.ndim == 2 else R[..., 2:3]
        w = w[..., 0]  # (N, n, 3)
        lever = fr[:, -1, None, :3, 3] - joint_frames[..., :3, 3]
        J = np.empty((len(q), 6, self.n_joints))
        J[:, :3] = np.swapaxes(np.where(prism[:, None], w, np.cross(w, lever)), 1, 2)
        J[:, 3:] = np.swapaxes(np.where(prism[:, None], 0.0, w), 1, 2)
        return J

    def observed(self, q, x) -> np.ndarray:
        return self.robot.forward(q, x)

    def observed_jacobian(self, q, x) -> np.ndarray:
        return self.robot.pose_jacobian(q, x)

    def _limits(self) -> np.ndarray:
        lim = self.joint_limits
        return np.tile([-np.inf, np.inf], (self.n_joints, 1)) if lim is None else np.asarray(lim, float)

    def seeds(self) -> np.ndarray:
        """(1 + N_SEEDS, n) candidate starts of an inverse without q_start: the centre of the joint ranges (within
        +-pi), then random joint sets in them (fixed seed: the same answer every run)."""
        lim = self._limits()
        lo, hi = np.maximum(lim[:, 0], -np.pi), np.minimum(lim[:, 1], np.pi)
        rng = np.random.default_rng(0)
        return np.vstack([0.5 * (lo + hi), lo + rng.uniform(size=(N_SEEDS, lo.size)) * (hi - lo)])

    def _solve(self, T, x, q_start=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q (N, n), residual (N, 6), reached (N,)) on the model of x, from q_start (N, n), else from the N_TRIES
        seeds whose tool pose is nearest each goal (nearest first)."""
        N = len(T)
        f = self._arm(x).forward
        lim = self.joint_limits

        def jac(q):  # the angular-velocity rows: the exact gradient of |r|^2 (J_log^T r = r for a rotation vector r)
            return self.joint_jacobian(q, x)

        if q_start is not None:
            return levenberg_marquardt(f, T, np.broadcast_to(np.asarray(q_start, float), (N, self.n_joints)), lim,
                                       jac=jac)
        seeds = self.seeds()
        Ts = f(seeds)
        # |dt| + SEED_LENGTH_M |drot| of every goal to every seed, (N, n_seeds) without (N, n_seeds, 3, 3) temporaries
        cos = 0.5 * (np.einsum("kij,sij->ks", T[:, :3, :3], Ts[:, :3, :3]) - 1.0)
        a, b = T[:, :3, 3], Ts[:, :3, 3]
        dist = np.sqrt(np.clip((a * a).sum(1)[:, None] + (b * b).sum(1)[None] - 2.0 * a @ b.T, 0.0, None))
        dist += SEED_LENGTH_M * np.arccos(np.clip(cos, -1.0, 1.0))
        order = np.argpartition(dist, N_TRIES, axis=1)[:, :N_TRIES]
        order = np.take_along_axis(order, np.argsort(np.take_along_axis(dist, order, axis=1), axis=1), axis=1)
        q, r, ok = np.zeros((N, self.n_joints)), np.full((N, 6), np.inf), np.zeros(N, bool)
        for t in range(N_TRIES):
            todo = np.flatnonzero(~ok)
            if not todo.size:
                break
            qs, rs, oks = levenberg_marquardt(f, T[todo], seeds[order[todo, t]], lim, jac=jac)
            better = oks | (np.linalg.norm(rs, axis=1) < np.linalg.norm(r[todo], axis=1))
            q[todo[better]], r[todo[better]], ok[todo[better]] = qs[better], rs[better], oks[better]
        return q, r, ok

    def inverse(self, T, x, q_start=None, labels=None, what: str = "calibrated", x_seed=None) -> np.ndarray:
        """Joint values (N, n) of the goals T (N, 4, 4) on the model of x: from q_start (N, n) (the nearest branch),
        the goals not reached from there as without it; without q_start from the solution of the model of x_seed
        (the nominal) where it has one, and from several starts elsewhere."""
        T = np.asarray(T, float)
        if q_start is not None:  # the branch asked for: Newton from q_start; the goals it misses as without one
            q, r, ok = self._solve(T, x, q_start)
            miss = np.flatnonzero(~ok)
            if miss.size:
                q[miss] = self.inverse(T[miss], x, None, [_labels(labels, len(T))[k] for k in miss], what, x_seed)
            return q
        if x_seed is not None:
            q_start, _, seeded = self._solve(T, x_seed)
            q, r, ok = self._solve(T, x, q_start)
            redo = np.flatnonzero(~ok)  # no nominal solution, or none of the calibrated model near it
            if redo.size:
                q[redo], r[redo], ok[redo] = self._solve(T[redo], x)
            multi = bool(redo.size)
        else:
            q, r, ok = self._solve(T, x, q_start)
            multi = q_start is None
        if not ok.all():
            self._not_reached(T, q, r, ok, labels, what, multi)
        return q

    def _not_reached(self, T, q, r, ok, labels, what, multi) -> None:
        lab = _labels(labels, len(T))
        bad = np.flatnonzero(~ok)
        k = int(bad[0])
        lim = self._limits()
        at = [j for j in range(self.n_joints) if np.isclose(q[k, j], lim[j, 0], atol=1e-9) or
              np.isclose(q[k, j], lim[j, 1], atol=1e-9)]
        why = (f"; joint q{at[0] + 1} at its limit [{lim[at[0], 0]:.4g}, {lim[at[0], 1]:.4g}]" if at else "")
        start = "from the start given or the nominal solution" + (f" or {N_TRIES} other starts" if multi else "")
        more = f" ({bad.size} poses not reached: {', '.join(map(str, [lab[i] for i in bad[:5]]))}"
        more += ", ...)" if bad.size > 5 else ")"
        raise PoseNotReachedError(
            f"pose {lab[k]} (x={T[k, 0, 3]:.4f}, y={T[k, 1, 3]:.4f}, z={T[k, 2, 3]:.4f} m) is not reached by the "
            f"{what} model {start}: residual {np.linalg.norm(r[k, :3]) * 1e3:.3g} mm, "
            f"{np.linalg.norm(r[k, 3:]) * 1e3:.3g} mrad{why}" + (more if bad.size > 1 else ""),
            pose_index=k)


class H4Kinematics:
    """The H4 (``kinematics.h4.H4Robot``): T_base_tool = T_base_nacelle(X) . tcp, X from the joints by Newton on
    the IGM (``H4Robot.fgm``), joints from a pose by the closed-form IGM."""

    closed_form = True
    observed_name = "T_cam_target"
    joint_limits = None
    n_joints = 4

    def __init__(self, robot: H4Robot, tcp: np.ndarray):
        self.robot = robot
        self.tcp = np.asarray(tcp, float)
        self.T_tcp = F.make_T(None, self.tcp)
        self.arm_names = tuple(n for n in robot.params.names if n not in EXTERNAL_NAMES + TILT_NAMES)

    def _X(self, q, x) -> np.ndarray:
        return self.robot.fgm(q, x)

    def tool(self, q, x) -> np.ndarray:
        return nacelle_T(self._X(q, x)) @ self.T_tcp

    def _dX_dx(self, X, x) -> np.ndarray:
        """(N, 4, n) dX / dx at fixed joints: -(dq/dX)^-1 dq/dx (implicit function of the IGM)."""
        return -np.linalg.solve(self.robot.igm_jacobian_pose(X, x), self.robot.igm_jacobian_params(X, x))

    def tool_jacobian(self, q, x) -> np.ndarray:
        X = self._X(q, x)
        dX = self._dX_dx(X, x)
        lever = np.cross([0.0, 0.0, 1.0], F.rot_z(X[:, 3]) @ self.tcp)  # d p_tool / d theta
        J = np.zeros((len(X), 6, len(x)))
        J[:, :3] = dX[:, :3] + lever[:, :, None] * dX[:, 3][:, None, :]
        J[:, 5] = dX[:, 3]
        return J

    def observed(self, q, x) -> np.ndarray:
        return self.robot.camera_measurement(self._X(q, x), x)

    def observed_jacobian(self, q, x) -> np.ndarray:
        X = self._X(q, x)
        JX, Jx = self.robot.camera_measurement_jacobian(X, x)
        return JX @ self._dX_dx(X, x) + Jx

    def inverse(self, T, x, q_start=None, labels=None, what: str = "calibrated", x_seed=None) -> np.ndarray:
        T = np.asarray(T, float) @ F.inv_T(self.T_tcp)
        lab = _labels(labels, len(T))
        yaw = yaw_of(T[:, :3, :3])
        tilt = np.linalg.norm(F.pose_error(nacelle_T(np.column_stack([T[:, :3, 3], yaw])), T)[:, 3:], axis=1)
        if np.any(tilt > H4_TILT_TOL_RAD):
            k = int(np.argmax(tilt > H4_TILT_TOL_RAD))
            raise PoseNotReachedError(f"pose {lab[k]}: the H4 nacelle only turns about z_B, the pose is tilted by "
                                      f"{np.degrees(tilt[k]):.3g} deg (tolerance {H4_TILT_TOL_RAD:g} rad)", pose_index=k)
        X = np.column_stack([T[:, :3, 3], yaw])
        try:
            return self.robot.igm(X, x)
        except UnreachablePoseError as exc:
            k = exc.pose_index if exc.pose_index is not None else 0
            raise PoseNotReachedError(f"pose {lab[k]}: not reached by the {what} model: {exc}", pose_index=k) from None


#: kinematics class per robot type (``isinstance``), first match: the one place to add a robot kind here
KINDS: tuple = ((H4Robot, H4Kinematics), (ChainModel, ChainKinematics))


def kinematics_for(robot, tcp) -> ChainKinematics | H4Kinematics:
    """The deploy kinematics of a robot object (:data:`KINDS`); ConfigError naming its type when none fits."""
    for typ, cls in KINDS:
        if isinstance(robot, typ):
            return cls(robot, tcp)
    raise ConfigError(f"no forward / inverse kinematics for deployment of a {type(robot).__name__} robot "
                      "(vision_calib.deploy.kinematics.KINDS knows serial chains and the H4)")


__all__ = ["ChainKinematics", "H4Kinematics", "KINDS", "PoseNotReachedError", "kinematics_for"]
