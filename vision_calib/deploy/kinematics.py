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
  :class:`PoseNotReachedError` naming the pose (label) when it is not reached; ``inverse_rows`` (same arguments)
  -> (q (N, n), why (N,) str): every goal on its own, q NaN and why naming the pose where it is not reached.
"""

from __future__ import annotations

import numpy as np

from .. import frames as F
from ..errors import ConfigError, UnreachablePoseError
from ..kinematics.h4 import EXTERNAL_NAMES, TILT_NAMES, H4Robot
from ..kinematics.h4_camera import nacelle_T, yaw_of
from ..kinematics.protocols import ChainModel
from ..kinematics.serial import SerialChain
from ..kinematics.urdf import URDFChain
from ..rig.serial import remount_chain
from .solve import AMPLIFIED_DEG_PER_MM, LEVER_M, amplification_deg_per_mm, joint_jacobian, levenberg_marquardt

#: candidate starts (after the centre of the joint ranges) of a chain's inverse without a start, and how many of
#: them (those whose tool pose is nearest the goal: |dt| + SEED_LENGTH_M |drot|) are tried
N_SEEDS = 1023
N_TRIES = 8
SEED_LENGTH_M = 0.3
#: goals per block of the goal-to-seed distance table (SEED_BLOCK x (1 + N_SEEDS) floats)
SEED_BLOCK = 4096
#: largest tilt [rad] of an H4 goal pose (the nacelle only turns about z_B)
H4_TILT_TOL_RAD = 1e-6


class PoseNotReachedError(UnreachablePoseError):
    """The calibrated (or nominal) model does not reach a goal pose: the message names the pose (row / label), the
    goal and why (residual, the joint at its limit, the chain that cannot close). CLI exit code 3."""

    exit_code = 3


def _nearest(T: np.ndarray, Ts: np.ndarray) -> np.ndarray:
    """(N, N_TRIES) indices of the poses Ts (S, 4, 4) nearest each goal T (N, 4, 4), nearest first: |dt| +
    SEED_LENGTH_M |drot|, by blocks of SEED_BLOCK goals (an (SEED_BLOCK, S) distance table, no (N, S, 3, 3)
    temporaries)."""
    out = np.empty((len(T), N_TRIES), dtype=np.intp)
    Rs, b = Ts[:, :3, :3].reshape(len(Ts), 9), Ts[:, :3, 3]
    bb = (b * b).sum(1)[None]
    for k in range(0, len(T), SEED_BLOCK):
        Tk = T[k:k + SEED_BLOCK]
        a = Tk[:, :3, 3]
        dist = np.sqrt(np.clip((a * a).sum(1)[:, None] + bb - 2.0 * a @ b.T, 0.0, None))
        cos = 0.5 * (Tk[:, :3, :3].reshape(len(Tk), 9) @ Rs.T - 1.0)  # trace(R_a R_b^T) = sum of the products
        dist += SEED_LENGTH_M * np.arccos(np.clip(cos, -1.0, 1.0))
        order = np.argpartition(dist, N_TRIES, axis=1)[:, :N_TRIES]
        out[k:k + SEED_BLOCK] = np.take_along_axis(order, np.argsort(np.take_along_axis(dist, order, axis=1), axis=1),
                                                   axis=1)
    return out


def _labels(labels, N) -> list:
    return list(labels) if labels is not None else [f"#{k}" for k in range(N)]


class BatchedArm:
    """A serial arm (modified-DH ``SerialChain`` or ``URDFChain``, remounted: base = identity, right mount = tcp) at
    one parameter vector, as the constants its forward kinematics needs, built once::

        T_base_tool(q) = K_1 M_1(q_1) K_2 M_2(q_2) ... K_n M_n(q_n) B

    K_i (n, 4, 4) = F_{i-1}(0)^-1 F_i(0) (F_i: the child frame of joint i, F_0 the base), B (4, 4) = F_n^-1 T_tool
    (tail and tcp), M_i a rotation about (revolute) or translation along (prismatic) the unit axis u_i (n, 3) of
    joint i in its child frame: exact, as a motion about / along the joint's own axis commutes with the joint's
    offset (MDH: Rz(theta + q) Tz(d) = Rz(theta) Tz(d) Rz(q)). :meth:`forward` runs it on N joint sets at once (a
    batched matrix product per joint) and gives the geometric joint Jacobian from the same frames."""

    def __init__(self, arm):
        n = arm.n_joints
        fr = arm.forward_all(np.zeros((1, n)))[0]  # (n + 2, 4, 4): base, joint frames, right (tcp) frame
        if isinstance(arm, URDFChain):
            axes, prism, tail = np.asarray(arm.axes, float), np.asarray(arm.prismatic, bool), arm.tail
        else:  # SerialChain: every joint turns about its frame's z axis
            axes, prism, tail = np.tile([0.0, 0.0, 1.0], (n, 1)), np.zeros(n, bool), np.eye(4)
        child = fr[1:n + 1].copy()
        child[-1] = child[-1] @ F.inv_T(tail)  # URDF: the tip link is joint n's child . tail
        prev = np.concatenate([fr[:1], child[:-1]])
        self.K = F.inv_T(prev) @ child
        self.B = F.inv_T(child[-1]) @ fr[-1]
        self.axes, self.prismatic = axes, prism
        # K_i M_i(v) = K_i + a(v) K_i P_i + b(v) K_i Q_i (revolute: a = sin v, b = 1 - cos v, P = [u]x, Q = [u]x^2;
        # prismatic: a = v, b = 0, P = translation along u); and K_i [u_i, 0] (the axis, which M_i keeps): constant
        # (4, 4) matrices applied to the N frames by plain (3N, 4) matrix products
        P, Q = np.zeros((n, 4, 4)), np.zeros((n, 4, 4))
        S = F.skew(axes)
        P[~prism, :3, :3], Q[~prism, :3, :3] = S[~prism], (S @ S)[~prism]
        P[prism, :3, 3] = axes[prism]
        u = np.zeros((n, 4, 1))
        u[:, :3, 0] = axes
        self.KP, self.KQ, self.Ku = self.K @ P, self.K @ Q, (self.K @ u)[..., 0]
        # an axis sign e_k (every MDH joint, most URDF ones): the motion turns two columns of the frame or moves its
        # origin along column k, and the joint's axis in the base frame is sign x column k (M_i keeps u_i)
        unit = (np.abs(axes) == 1.0).sum(1) == 1
        self.axis_column = [(int(np.argmax(np.abs(v))), float(v[np.argmax(np.abs(v))])) if ok else None
                            for v, ok in zip(axes, unit)]

    def forward(self, q: np.ndarray, jacobian: bool = False):
        """T_base_tool (N, 4, 4) [m] at joint sets q (N, n) [rad, m]; with ``jacobian`` also (N, 6, n) the geometric
        joint Jacobian (``ChainKinematics.joint_jacobian``)."""
        q = np.asarray(q, float)
        N, n = q.shape
        a = np.repeat(np.where(self.prismatic, q, np.sin(q)).T, 3, axis=1)  # (n, 3N): one per row of each frame
        c = np.repeat(np.cos(q).T, 3, axis=1)
        G = np.zeros((N, 3, 4))  # the top 3 rows of each frame, as (3N, 4) below
        G[:, 0, 0] = G[:, 1, 1] = G[:, 2, 2] = 1.0
        G = G.reshape(3 * N, 4)
        W, O = np.empty((N, 3, n)), np.empty((N, 3, n))
        for i in range(n):
            if self.axis_column[i] is None:  # any axis: G K (I + a P + b Q)
                W[:, :, i] = (G @ self.Ku[i]).reshape(N, 3)
                H1 = G @ self.KP[i]
                H1 *= a[i, :, None]
                H2 = G @ self.KQ[i]
                H2 *= (1.0 - c[i])[:, None]
                G = G @ self.K[i]
                G += H1
                G += H2
            else:  # axis sign e_k: the motion only mixes two columns of G K (or adds to its translation)
                G = G @ self.K[i]
                k, sign = self.axis_column[i]
                if self.prismatic[i]:
                    G[:, 3] += (sign * a[i]) * G[:, k]
                else:  # R Rot(e_k, v): columns (k+1, k+2) turned by v
                    ci, cj = (k + 1) % 3, (k + 2) % 3
                    s_, c_ = sign * a[i], c[i]
                    gi = G[:, ci].copy()
                    G[:, ci] = c_ * gi + s_ * G[:, cj]
                    G[:, cj] = c_ * G[:, cj] - s_ * gi
                W[:, :, i] = sign * G[:, k].reshape(N, 3)
            O[:, :, i] = G[:, 3].reshape(N, 3)
        G = G.reshape(N, 3, 4)
        T = np.zeros((N, 4, 4))
        T[:, :3] = (G.reshape(3 * N, 4) @ self.B).reshape(N, 3, 4)
        T[:, 3, 3] = 1.0
        if not jacobian:
            return T
        L = T[:, :3, 3, None] - O  # (N, 3, n) lever of each joint
        J = np.zeros((N, 6, n))
        J[:, 0] = W[:, 1] * L[:, 2] - W[:, 2] * L[:, 1]
        J[:, 1] = W[:, 2] * L[:, 0] - W[:, 0] * L[:, 2]
        J[:, 2] = W[:, 0] * L[:, 1] - W[:, 1] * L[:, 0]
        J[:, 3:] = W
        pr = self.prismatic
        J[:, :3, pr] = W[:, :, pr]
        J[:, 3:, pr] = 0.0
        return T, J


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

    def arm_at(self, x: np.ndarray):
        """The arm alone at x: the chain remounted on identity (base) and the tcp (``T_flange_tool``)."""
        return self._arms(x)[0]

    def _arms(self, x: np.ndarray) -> tuple:
        """(the arm alone at x (:meth:`arm_at`), its :class:`BatchedArm` or None for a chain of another kind), built
        once per x."""
        key = np.asarray(x, float).tobytes()
        arms = self._arm_cache.get(key)
        if arms is None:
            valued = self.robot.with_params(self.robot.params.with_nominal(np.asarray(x, float)))
            arm = remount_chain(valued, "T_world_base", "T_flange_tool", np.eye(4), self.T_tcp)
            arms = (arm, BatchedArm(arm) if isinstance(arm, (SerialChain, URDFChain)) else None)
            if len(self._arm_cache) > 8:
                self._arm_cache.clear()
            self._arm_cache[key] = arms
        return arms

    def tool(self, q, x) -> np.ndarray:
        arm, batched = self._arms(x)
        return arm.forward(q) if batched is None else batched.forward(arm.check_joints(q))

    def tool_jacobian(self, q, x) -> np.ndarray:
        arm = self.arm_at(x)
        Ja = arm.pose_jacobian(q)
        J = np.zeros(Ja.shape[:2] + (len(x),))
        names = self.robot.params.names
        J[:, :, [names.index(n) for n in self.arm_names]] = Ja[:, :, arm.params.indices(self.arm_names)]
        return J

    def joint_jacobian(self, q, x) -> np.ndarray:
        """(N, 6, n_joints) d pose_error(T, tool(q + dq)) / dq at q (N, n) [per rad or m], base frame: geometric
        (a revolute joint about unit axis w through o: [w x (p_tool - o), w]; a prismatic one: [w, 0],
        :class:`BatchedArm`) for modified-DH and URDF arms, central differences for another chain. Exact for the
        translation rows; the rotation rows are the angular velocity (= the rotation-vector derivative at a zero
        pose error)."""
        return self.tool_and_jacobian(q, x)[1]

    def tool_and_jacobian(self, q, x) -> tuple[np.ndarray, np.ndarray]:
        """(:meth:`tool`, :meth:`joint_jacobian`) at q (N, n) from the same frames."""
        arm, batched = self._arms(x)
        q = arm.check_joints(q)
        if batched is None:
            T = arm.forward(q)
            return T, joint_jacobian(arm.forward, q, T)
        return batched.forward(q, jacobian=True)

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
        arm, batched = self._arms(x)
        lim = self.joint_limits
        # the angular-velocity rows: the exact gradient of |r|^2 (J_log^T r = r for a rotation vector r)
        if batched is not None:
            f, kw = batched.forward, {"fj": lambda q: batched.forward(q, jacobian=True)}
        else:
            f, kw = arm.forward, {"jac": lambda q: self.joint_jacobian(q, x)}
        if q_start is not None:
            return levenberg_marquardt(f, T, np.broadcast_to(np.asarray(q_start, float), (N, self.n_joints)), lim,
                                       **kw)
        seeds = self.seeds()
        order = _nearest(T, f(seeds))
        q, r, ok = np.zeros((N, self.n_joints)), np.full((N, 6), np.inf), np.zeros(N, bool)
        for t in range(N_TRIES):
            todo = np.flatnonzero(~ok)
            if not todo.size:
                break
            qs, rs, oks = levenberg_marquardt(f, T[todo], seeds[order[todo, t]], lim, **kw)
            better = oks | (np.linalg.norm(rs, axis=1) < np.linalg.norm(r[todo], axis=1))
            q[todo[better]], r[todo[better]], ok[todo[better]] = qs[better], rs[better], oks[better]
        return q, r, ok

    def inverse_rows(self, T, x, q_start=None, labels=None, what: str = "calibrated",
                     x_seed=None, branch_only: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(q (N, n), why (N,) str) of the goals T (N, 4, 4) on the model of x: from q_start (N, n) (the nearest
        branch), the goals not reached from there as without it (``branch_only``: left not reached, no search from
        other starts, which may land on another branch of the arm); without q_start from the solution of the model
        of x_seed (the nominal) where it has one, and from several starts elsewhere. A goal not reached: q NaN, why
        names the pose (``labels``), the residual and a joint held at its limit ("" for a goal reached)."""
        T = np.asarray(T, float)
        if q_start is not None:  # the branch asked for: Newton from q_start; the goals it misses as without one
            q, r, ok = self._solve(T, x, q_start)
            if branch_only:
                why = self._not_reached(T, x, q, r, ok, labels, what, False)
                q[~ok] = np.nan
                return q, why
            why = np.full(len(T), "", dtype=object)
            miss = np.flatnonzero(~ok)
            if miss.size:
                lab = _labels(labels, len(T))
                q[miss], why[miss] = self.inverse_rows(T[miss], x, None, [lab[k] for k in miss], what, x_seed)
            return q, why
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
        why = self._not_reached(T, x, q, r, ok, labels, what, multi)
        q[~ok] = np.nan
        return q, why

    def inverse(self, T, x, q_start=None, labels=None, what: str = "calibrated", x_seed=None) -> np.ndarray:
        """Joint values (N, n) of :meth:`inverse_rows`; PoseNotReachedError naming the first goal not reached."""
        q, why = self.inverse_rows(T, x, q_start, labels, what, x_seed)
        raise_not_reached(why)
        return q

    def _not_reached(self, T, x, q, r, ok, labels, what, multi) -> np.ndarray:
        """(N,) why each goal is not reached ("" where it is): residual, a joint held at its limit, the amplification
        (``deploy.solve.amplification_deg_per_mm``) where the iteration ended when above AMPLIFIED_DEG_PER_MM."""
        lab = _labels(labels, len(T))
        why = np.full(len(T), "", dtype=object)
        lim = self._limits()
        start = "from the start given or the nominal solution" + (f" or {N_TRIES} other starts" if multi else "")
        bad = np.flatnonzero(~ok)
        if bad.size:  # the conditioning where the iteration ended: near a singularity it converges slowly or stalls
            J = self.joint_jacobian(q[bad], x) * np.array([1.0, 1.0, 1.0, LEVER_M, LEVER_M, LEVER_M])[:, None]
            amp = amplification_deg_per_mm(np.linalg.svd(J, compute_uv=False)[:, -1])
            at_limit = np.isclose(q[bad], lim[:, 0], atol=1e-9) | np.isclose(q[bad], lim[:, 1], atol=1e-9)  # (B, n)
        for i, k in enumerate(bad):
            at = np.flatnonzero(at_limit[i])
            held = f"; joint q{at[0] + 1} at its limit [{lim[at[0], 0]:.4g}, {lim[at[0], 1]:.4g}]" if at.size else ""
            if amp[i] > AMPLIFIED_DEG_PER_MM:
                held += f"; near a singularity there ({amp[i]:.3g} deg of joint motion per mm)"
            why[k] = (f"pose {lab[k]} (x={T[k, 0, 3]:.4f}, y={T[k, 1, 3]:.4f}, z={T[k, 2, 3]:.4f} m) is not reached "
                      f"by the {what} model {start}: residual {np.linalg.norm(r[k, :3]) * 1e3:.3g} mm, "
                      f"{np.linalg.norm(r[k, 3:]) * 1e3:.3g} mrad{held}")
        return why


def raise_not_reached(why: np.ndarray, offset: int = 0) -> None:
    """PoseNotReachedError (pose_index: offset + the row) with the first message of why (N,) str that is not "",
    and how many rows are not reached; nothing when every row is reached."""
    bad = np.flatnonzero(np.asarray(why) != "")
    if bad.size:
        more = "" if bad.size == 1 else f" ({bad.size} poses not reached)"
        raise PoseNotReachedError(str(why[bad[0]]) + more, pose_index=offset + int(bad[0]))


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

    def inverse_rows(self, T, x, q_start=None, labels=None, what: str = "calibrated",
                     x_seed=None, branch_only: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(q (N, 4), why (N,) str) by the closed-form inverse geometric model (q_start, x_seed, branch_only: unused,
        it has one solution); a tilted or unreachable goal: q NaN, why names it ("" for a goal reached)."""
        T = np.asarray(T, float) @ F.inv_T(self.T_tcp)
        lab = _labels(labels, len(T))
        q, why = np.full((len(T), self.n_joints), np.nan), np.full(len(T), "", dtype=object)
        yaw = yaw_of(T[:, :3, :3])
        X = np.column_stack([T[:, :3, 3], yaw])
        tilt = np.linalg.norm(F.pose_error(nacelle_T(X), T)[:, 3:], axis=1)
        for k in np.flatnonzero(tilt > H4_TILT_TOL_RAD):
            why[k] = (f"pose {lab[k]}: the H4 nacelle only turns about z_B, the pose is tilted by "
                      f"{np.degrees(tilt[k]):.3g} deg (tolerance {H4_TILT_TOL_RAD:g} rad)")
        todo = np.flatnonzero(tilt <= H4_TILT_TOL_RAD)
        while todo.size:  # the IGM names the first unreachable pose: name it, solve the others
            try:
                q[todo] = self.robot.igm(X[todo], x)
                break
            except UnreachablePoseError as exc:
                k = exc.pose_index if exc.pose_index is not None else 0
                why[todo[k]] = f"pose {lab[todo[k]]}: not reached by the {what} model: {exc}"
                todo = np.delete(todo, k)
        return q, why

    def inverse(self, T, x, q_start=None, labels=None, what: str = "calibrated", x_seed=None) -> np.ndarray:
        """Joint values (N, 4) of :meth:`inverse_rows`; PoseNotReachedError naming the first goal not reached."""
        q, why = self.inverse_rows(T, x, q_start, labels, what, x_seed)
        raise_not_reached(why)
        return q


#: kinematics class per robot type (``isinstance``), first match: the one place to add a robot kind here
KINDS: tuple = ((H4Robot, H4Kinematics), (ChainModel, ChainKinematics))


def kinematics_for(robot, tcp) -> ChainKinematics | H4Kinematics:
    """The deploy kinematics of a robot object (:data:`KINDS`); ConfigError naming its type when none fits."""
    for typ, cls in KINDS:
        if isinstance(robot, typ):
            return cls(robot, tcp)
    raise ConfigError(f"no forward / inverse kinematics for deployment of a {type(robot).__name__} robot "
                      "(vision_calib.deploy.kinematics.KINDS knows serial chains and the H4)")


__all__ = ["BatchedArm", "ChainKinematics", "H4Kinematics", "KINDS", "PoseNotReachedError", "kinematics_for",
           "raise_not_reached"]
