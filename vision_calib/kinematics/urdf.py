"""Serial robots read from URDF, calibrated through per-joint placement errors, written back to URDF.

Parsing
-------
The file is read with the standard library's XML parser (only its kinematic content: no mesh or
other file named in it is opened, so no path in it leads anywhere); our own checks then name the file, link and joint of every problem
we can detect on the chain: missing link, a link with two parents, a loop, a tip link not below the
base link, an unsupported joint type (floating, planar) or a mimic joint on the chain, a
non-finite origin/axis/limit, a zero axis, a revolute/prismatic joint without ``lower``/``upper``
limits (use ``continuous`` for an unlimited revolute joint). All are :class:`ConfigError`.

Model (parameter naming is stable: it is the contract)
-------------------------------------------------------
The chain goes from ``base_link`` to ``tip_link`` (the flange). Movable joints (revolute,
continuous, prismatic) are numbered i = 1..n in chain order. For each one, ``O_i`` (4, 4) is its
URDF origin with every *fixed* joint between the previous movable joint (or the base link) and it
folded in on the left (fixed joints carry no parameter); the fixed joints after the last movable
joint form the constant ``tail`` (4, 4) to the tip link (redundant with the right mount, so no
parameter either). Per movable joint, 7 parameters::

    j<i>.x, j<i>.y, j<i>.z  (m)      j<i>.rx, j<i>.ry, j<i>.rz  (rad)      q0_<i>  (rad, or m if prismatic)

    T_{i-1,i}(q_i) = O_i @ D_i @ M_i(q_i + q0_i)
    D_i = [Exp([j.rx, j.ry, j.rz]), (j.x, j.y, j.z)]   (= Trans(xyz) @ Rot(Exp(r)), both on O_i's axes)
    M_i(v) = Rot(axis_i, v) (revolute/continuous) or Trans(v * axis_i) (prismatic)

all nominal 0. ``Exp`` is the SO(3) exponential (rotation vector), non-singular about zero whatever
the nominal origin. The measured chain is, as for :class:`~vision_calib.kinematics.serial.SerialChain`::

    T_left_right(q) = T_left_base @ prod_i T_{i-1,i}(q_i) @ tail @ T_flange_right

with the two 6-parameter mounts ``<left>.tx .. .rz`` / ``<right>.tx .. .rz`` in the same
non-singular form (``[R_nom Exp(r), t]``). Vector order: left mount, then joint by joint
(``j<i>.x .. j<i>.rz, q0_<i>``), then right mount; all free by default.

Redundancy: the model is deliberately over-parameterised (7 per joint + 12). With full pose
measurements an all-revolute arm has 4 n + 6 identifiable parameters in total (Everett, Driels &
Mooring 1987: 4 per revolute joint, 2 per prismatic joint, + 6 for the base and tool frames), e.g.
30 for a 6R arm: run :func:`vision_calib.identify.analyze` (``selection="order"``) and identify
the base set. :meth:`URDFChain.redundant_pairs` is therefore empty (no pair is forbidden up front).

Export
------
:func:`export_urdf` rewrites the source URDF with only the movable joints' origins changed:
``origin_new = origin_file @ D_i @ M_i(q0_i)`` (the joint offset is folded into the origin as a
rotation about, or a translation along, the joint axis, so the joint reading and its limits keep
their meaning). Fixed joints, links, limits and geometry are written back unchanged (comments and
formatting are not kept). The mounts are not part of the URDF: get them with
``chain.nominal_transforms(x)``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import ConfigError, ParameterError
from ..frames import make_T, so3_exp, so3_right_jacobian, swing_twist, xyz_rotvec_from_T
from ..serialize import write_text_atomic
from .params import DEFAULT_SCALE, ParameterSet
from .serial import KNOWN_LEFT, KNOWN_RIGHT, MOUNT_SUFFIXES, JointChainChecks
from .urdf_file import MOVABLE, read_urdf, set_origin, urdf_xml_text

#: suffixes of the 6 placement parameters of a movable joint, in vector order
JOINT_SUFFIXES = ("x", "y", "z", "rx", "ry", "rz")


def _rot_axis(axis, v) -> np.ndarray:
    """Rotations (N, 3, 3) by angles v (N,) rad about the unit axis (3,)."""
    return so3_exp(np.asarray(v, float)[:, None] * axis[None, :])


# ----------------------------------------------------------------------------- the chain
@dataclass(frozen=True, eq=False)
class URDFChain(JointChainChecks):
    """Serial chain from a URDF between two mounting transforms (duck-types ``SerialChain``).

    name: robot name. params: all parameters (module docstring). left / right: mount names.
    origins: (n, 4, 4) folded nominal origins O_i (m). axes: (n, 3) unit joint axes in the joint
    frame. prismatic: (n,) bool. tail: (4, 4) fixed transform last joint frame -> tip link.
    joint_limits: (n, 2) [min, max] (rad or m; +-inf for continuous joints) or None.
    left_R_nominal / right_R_nominal: (3, 3) nominal mount rotations. meta: file, base_link,
    tip_link, joint_names (URDF names of the movable joints), raw_origins ((n, 4, 4) the file's own
    origins of the movable joints, used by :func:`export_urdf`), configurations, trials.
    """

    name: str
    params: ParameterSet
    origins: np.ndarray
    axes: np.ndarray
    prismatic: np.ndarray
    tail: np.ndarray = field(default_factory=lambda: np.eye(4))
    left: str = "T_world_base"
    right: str = "T_flange_tool"
    joint_limits: np.ndarray | None = None
    left_R_nominal: np.ndarray = field(default_factory=lambda: np.eye(3))
    right_R_nominal: np.ndarray = field(default_factory=lambda: np.eye(3))
    meta: dict = field(default_factory=dict, compare=False, repr=False)

    #: SerialChain attributes that have no meaning here (read by code written for MDH chains)
    hayati = ()
    pre_z = ()

    def __post_init__(self):
        O = np.array(self.origins, float)
        n = O.shape[0] if O.ndim == 3 else 0
        if n < 1 or O.shape != (n, 4, 4):
            raise ParameterError(f"URDFChain {self.name!r}: origins must be (n >= 1, 4, 4), got {O.shape}")
        ax = np.array(self.axes, float)
        pr = np.array(self.prismatic, bool).reshape(-1)
        if ax.shape != (n, 3) or pr.shape != (n,):
            raise ParameterError(f"URDFChain {self.name!r}: axes must be ({n}, 3) and prismatic ({n},)")
        if not np.allclose(np.linalg.norm(ax, axis=1), 1.0, atol=1e-12):
            raise ParameterError(f"URDFChain {self.name!r}: joint axes must be unit vectors")
        vals = {"origins": O, "axes": ax, "prismatic": pr, "tail": np.array(self.tail, float)}
        for attr in ("left_R_nominal", "right_R_nominal"):
            R = np.array(getattr(self, attr), dtype=float)
            if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
                raise ParameterError(f"URDFChain {self.name!r}: {attr} is not a rotation matrix")
            vals[attr] = R
        if self.joint_limits is not None:
            lim = np.array(self.joint_limits, float)
            if lim.shape != (n, 2) or np.any(lim[:, 0] > lim[:, 1]):
                raise ParameterError(f"URDFChain {self.name!r}: joint_limits must be ({n}, 2) with min <= max")
            vals["joint_limits"] = lim
        for k, v in vals.items():
            v.setflags(write=False)
            object.__setattr__(self, k, v)
        if self.left not in KNOWN_LEFT or self.right not in KNOWN_RIGHT:
            raise ParameterError(f"URDFChain {self.name!r}: mounts must be one of {KNOWN_LEFT} and one of "
                                 f"{KNOWN_RIGHT}, got {self.left!r}, {self.right!r}")
        expected = arm_parameter_names(n)
        mounts = [f"{m}.{s}" for m in (self.left, self.right) for s in MOUNT_SUFFIXES]
        if sorted(self.params.names) != sorted(expected + mounts):
            extra = sorted(set(self.params.names) - set(expected + mounts))
            missing = sorted(set(expected + mounts) - set(self.params.names))
            raise ParameterError(f"URDFChain {self.name!r}: parameter names do not match the model "
                                 f"(unexpected {extra}, missing {missing})")
        ix = self.params.index
        idx = {
            "joint": np.array([[ix(f"j{i}.{s}") for s in JOINT_SUFFIXES] for i in range(1, n + 1)], int),
            "q0": np.array([ix(f"q0_{i}") for i in range(1, n + 1)], int),
            "left": np.array([ix(f"{self.left}.{s}") for s in MOUNT_SUFFIXES], int),
            "right": np.array([ix(f"{self.right}.{s}") for s in MOUNT_SUFFIXES], int),
        }
        object.__setattr__(self, "_idx", idx)

    # ------------------------------------------------------------------ construction
    @classmethod
    def build(cls, name, origins, axes, prismatic, tail=None, left="T_world_base", right="T_flange_tool",
              T_left_base=None, T_flange_right=None, joint_limits=None, meta=None) -> "URDFChain":
        """Chain with nominal parameters (placements 0, offsets 0, mounts = T_left_base / T_flange_right
        (4, 4) m, identity if None), all free. origins (n, 4, 4), axes (n, 3), prismatic (n,) bool."""
        n = len(origins)
        pr = np.asarray(prismatic, bool)
        TL = np.eye(4) if T_left_base is None else np.asarray(T_left_base, float)
        TR = np.eye(4) if T_flange_right is None else np.asarray(T_flange_right, float)
        names = arm_parameter_names(n)
        kinds = []
        for i in range(n):
            kinds += ["length"] * 3 + ["angle"] * 3 + ["length" if pr[i] else "angle"]
        nominal = [0.0] * len(names)
        for m, T in ((left, TL), (right, TR)):
            names_m = [f"{m}.{s}" for s in MOUNT_SUFFIXES]
            vals = list(T[:3, 3]) + [0.0] * 3
            kinds_m = ["length"] * 3 + ["angle"] * 3
            if m == left:
                names, nominal, kinds = names_m + names, vals + nominal, kinds_m + kinds
            else:
                names, nominal, kinds = names + names_m, nominal + vals, kinds + kinds_m
        ps = ParameterSet.from_lists(names, nominal, kinds, None, [DEFAULT_SCALE[k] for k in kinds])
        return cls(name, ps, origins, axes, pr, np.eye(4) if tail is None else tail, left, right, joint_limits,
                   TL[:3, :3], TR[:3, :3], dict(meta or {}))

    def with_params(self, params: ParameterSet) -> "URDFChain":
        """Same model with another parameter set (same names, e.g. other free mask or nominal)."""
        if params.names != self.params.names:
            raise ParameterError("with_params: the parameter names must be those of the chain")
        return replace(self, params=params)

    def remounted(self, left: str, right: str, T_left_base=None, T_flange_right=None) -> "URDFChain":
        """Same arm (nominal values and free mask of its own parameters kept) with other mounts:
        names ``left``/``right`` and nominal (4, 4) transforms (m; identity if None), mounts all free."""
        new = URDFChain.build(self.name, self.origins, self.axes, self.prismatic, self.tail, left, right,
                              T_left_base, T_flange_right, self.joint_limits, self.meta)
        arm = arm_parameter_names(self.n_joints)
        old, ps = self.params, new.params
        nom, free = ps.nominal.copy(), ps.free.copy()
        src, dst = old.indices(arm), ps.indices(arm)
        nom[dst], free[dst] = old.nominal[src], old.free[src]
        return new.with_params(replace(ps, nominal=nom, free=free))

    # ------------------------------------------------------------------ info (SerialChain protocol)
    @property
    def n_joints(self) -> int:
        return int(self.origins.shape[0])

    def redundant_pairs(self) -> list[tuple[str, str, str]]:
        """Always empty: the redundancy is resolved by the identifiability analysis (module docstring)."""
        return []

    def nominal_transforms(self, x=None) -> tuple[np.ndarray, np.ndarray]:
        """(T_left_base (4, 4), T_flange_right (4, 4)) at x (nominal if None)."""
        x = self._x(x)
        return self._mount(x, "left", self.left_R_nominal), self._mount(x, "right", self.right_R_nominal)

    def joint_placements(self, x=None) -> tuple[np.ndarray, np.ndarray]:
        """(D (n, 4, 4) placement corrections, q0 (n,) joint offsets) at x (nominal if None)."""
        x = self._x(x)
        p = x[self._idx["joint"]]
        return make_T(so3_exp(p[:, 3:]), p[:, :3]), x[self._idx["q0"]].copy()

    def _mount(self, x, side, R_nom) -> np.ndarray:
        v = x[self._idx[side]]
        return make_T(R_nom @ so3_exp(v[3:]), v[:3])

    def joint_offset_form(self, x=None) -> tuple[np.ndarray, np.ndarray]:
        """(x_equiv (n_params,), offsets (n,)): the same kinematics as x (None = nominal) with each joint's motion
        about / along its own axis moved into its offset q0_i (``kinematics.protocols.JointOffsetForm``).
        Revolute: ``Exp(r_i) Rot(axis_i, q0_i) = Exp(r_i') Rot(axis_i, q0_i')``, r_i' the swing (no rotation about
        the axis, :func:`frames.swing_twist`), q0_i' the twist in (-pi, pi]. Prismatic: the part of the placement
        translation along the moved axis goes into q0_i (m). Exact to rounding; the rest of x unchanged."""
        x = self._x(x).copy()
        D, q0 = self.joint_placements(x)
        for i in range(self.n_joints):
            k, kq = self._idx["joint"][i], self._idx["q0"][i]
            R = D[i, :3, :3]
            if self.prismatic[i]:
                u = R @ self.axes[i]
                s = float(x[k[:3]] @ u)
                x[k[:3]] = x[k[:3]] - s * u
                x[kq] = q0[i] + s
            else:
                swing, twist = swing_twist(R @ _rot_axis(self.axes[i], q0[i : i + 1])[0], self.axes[i])
                x[k[3:]] = xyz_rotvec_from_T(make_T(swing))[3:]
                x[kq] = float(twist)
        return x, x[self._idx["q0"]].copy()

    # ------------------------------------------------------------------ forward model
    def _motion(self, i, v) -> np.ndarray:
        """M_i(v) (N, 4, 4) for joint values v (N,) (offset included)."""
        if self.prismatic[i]:
            return make_T(None, v[:, None] * self.axes[i][None, :])
        return make_T(_rot_axis(self.axes[i], v))

    def _walk(self, q, x):
        """(frames (N, n+2, 4, 4) in ``left``: [base, joint 1..n-1 child, tip link, right],
        placed (N, n, 4, 4): frame O_i D_i of each joint before its motion)."""
        N, n = q.shape[0], self.n_joints
        out = np.empty((N, n + 2, 4, 4))
        placed = np.empty((N, n, 4, 4))
        TL, TR = self.nominal_transforms(x)
        D, q0 = self.joint_placements(x)
        F = np.broadcast_to(TL, (N, 4, 4)).copy()
        out[:, 0] = F
        for i in range(n):
            placed[:, i] = F @ (self.origins[i] @ D[i])
            F = placed[:, i] @ self._motion(i, q[:, i] + q0[i])
            out[:, i + 1] = F
        out[:, n] = F @ self.tail
        out[:, n + 1] = out[:, n] @ TR
        return out, placed

    def forward(self, q, x=None) -> np.ndarray:
        """T_left_right (N, 4, 4) [m] for joint values q (N, n) and full parameter vector x (None = nominal)."""
        return self._walk(self.check_joints(q), self._x(x))[0][:, -1]

    def forward_all(self, q, x=None) -> np.ndarray:
        """All frames (N, n+2, 4, 4) in ``left``: 0 = robot base, i = child of movable joint i
        (i < n), n = tip link (flange), n+1 = ``right`` frame. For drawing the arm."""
        return self._walk(self.check_joints(q), self._x(x))[0]

    def flange(self, q, x=None) -> np.ndarray:
        """T_base_tip(q) (N, 4, 4): the arm alone, without the mounting transforms."""
        x = self._x(x)
        F = self.forward_all(q, x)
        return np.linalg.inv(self.nominal_transforms(x)[0]) @ F[:, self.n_joints]

    # ------------------------------------------------------------------ Jacobians
    def pose_jacobian(self, q, x=None) -> np.ndarray:
        """(N, 6, n_params) d pose_error(T(x), T(x + dx)) / d dx at q (N, n), x (n_params,).

        Rows [dt (m), dtheta (rad)] in frame ``left``; columns: every parameter in ``params.names``
        order. Rotation about unit axis w through p: ``[w x (p_end - p), w]``; translation along w:
        ``[w, 0]``; rotation-vector parameters use the SO(3) right Jacobian (exact at any x).
        """
        return self.pose_and_jacobian(q, x)[1]

    def pose_and_jacobian(self, q, x=None) -> tuple[np.ndarray, np.ndarray]:
        """(T_left_right (N, 4, 4) as :meth:`forward` gives it, :meth:`pose_jacobian` (N, 6, n_params)) from one
        walk of the chain."""
        q, x = self.check_joints(q), self._x(x)
        N, n = q.shape[0], self.n_joints
        frames, placed = self._walk(q, x)
        p_end = frames[:, -1, :3, 3]
        J = np.zeros((N, 6, len(self.params)))

        def rot_cols(ks, W, p):  # W (N, 3, 3) columns = spatial axes, p (N, 3) pivot
            J[:, :3, ks] = np.cross(np.swapaxes(W, 1, 2), (p_end - p)[:, None, :]).swapaxes(1, 2)
            J[:, 3:, ks] = W

        TL, TR = self.nominal_transforms(x)
        ixL, ixR = self._idx["left"], self._idx["right"]
        J[:, :3, ixL[:3]] = np.eye(3)
        rot_cols(ixL[3:], np.broadcast_to(TL[:3, :3] @ so3_right_jacobian(x[ixL[3:]]), (N, 3, 3)),
                 np.broadcast_to(TL[:3, 3], (N, 3)))
        D, _ = self.joint_placements(x)
        for i in range(n):
            A = frames[:, i] @ self.origins[i]  # joint frame before the correction
            k = self._idx["joint"][i]
            J[:, :3, k[:3]] = A[:, :3, :3]
            W = A[:, :3, :3] @ (D[i, :3, :3] @ so3_right_jacobian(x[k[3:]]))
            rot_cols(k[3:], W, placed[:, i, :3, 3])
            w = placed[:, i, :3, :3] @ self.axes[i]  # (N, 3) joint axis in left
            kq = self._idx["q0"][i]
            if self.prismatic[i]:
                J[:, :3, kq] = w
            else:
                J[:, :3, kq] = np.cross(w, p_end - placed[:, i, :3, 3])
                J[:, 3:, kq] = w
        Rf = frames[:, n, :3, :3]
        J[:, :3, ixR[:3]] = Rf
        rot_cols(ixR[3:], Rf @ (TR[:3, :3] @ so3_right_jacobian(x[ixR[3:]])), p_end)
        return frames[:, -1], J

    def position_jacobian(self, q, x=None) -> np.ndarray:
        """(N, 3, n_params): translation rows of :meth:`pose_jacobian` (m per unit parameter, in ``left``)."""
        return self.pose_jacobian(q, x)[:, :3, :]


def arm_parameter_names(n: int) -> list[str]:
    """The arm's own parameter names, in vector order: j1.x .. j1.rz, q0_1, j2.x, ..."""
    return [nm for i in range(1, n + 1) for nm in [f"j{i}.{s}" for s in JOINT_SUFFIXES] + [f"q0_{i}"]]


# ----------------------------------------------------------------------------- reading URDF
def _chain_joints(robot, path: Path, base_link: str, tip_link: str) -> list:
    """URDF joints (:class:`UrdfJoint`) from base_link to tip_link, in chain order."""
    links = set(robot.links)
    for what, nm in (("base_link", base_link), ("tip_link", tip_link)):
        if nm not in links:
            raise ConfigError(f"{path}: {what} {nm!r} is not a link of robot {robot.name!r} "
                              f"(links: {', '.join(sorted(links))})")
    parent_of = {j.child: j for j in robot.joints}  # one parent each: _read_urdf checked the tree
    out, link, seen = [], tip_link, {tip_link}
    while link != base_link:
        if link not in parent_of:
            raise ConfigError(f"{path}: tip_link {tip_link!r} is not below base_link {base_link!r} "
                              f"(walking up from the tip ends at root link {link!r})")
        j = parent_of[link]
        out.append(j)
        link = j.parent
        if link in seen:
            raise ConfigError(f"{path}: the joints {', '.join(repr(k.name) for k in out)} form a loop through link {link!r}")
        seen.add(link)
    return out[::-1]


def _joint_data(j, path: Path):
    """(origin (4, 4), unit axis (3,), (lower, upper)) of one chain joint, validated."""
    where = f"{path}: joint {j.name!r} ({j.parent} -> {j.child})"
    if j.type not in MOVABLE + ("fixed",):
        raise ConfigError(f"{where}: joint type {j.type!r} is not supported on a serial chain "
                          f"(expected one of {', '.join(MOVABLE + ('fixed',))})")
    if j.mimic is not None and j.type != "fixed":
        raise ConfigError(f"{where}: mimic joints are not supported on the calibrated chain")
    O = np.eye(4) if j.origin is None else np.asarray(j.origin, float)
    if not np.all(np.isfinite(O)):
        raise ConfigError(f"{where}: <origin> xyz/rpy has a non-finite value")
    if j.type == "fixed":
        return O, None, None
    axis = np.array([1.0, 0.0, 0.0]) if j.axis is None else np.asarray(j.axis, float)
    norm = np.linalg.norm(axis)
    if not np.all(np.isfinite(axis)) or norm < 1e-9:
        raise ConfigError(f"{where}: <axis xyz> must be a finite non-zero vector, got {axis}")
    lim = (-np.inf, np.inf)
    if j.type != "continuous":
        lo = None if j.limit is None else j.limit.lower
        hi = None if j.limit is None else j.limit.upper
        if lo is None or hi is None:
            raise ConfigError(f"{where}: a {j.type} joint needs <limit lower=... upper=...> "
                              "(use type 'continuous' for an unlimited revolute joint)")
        lim = (float(lo), float(hi))
        if not (np.all(np.isfinite(lim)) and lim[0] <= lim[1]):
            raise ConfigError(f"{where}: <limit> needs finite lower <= upper, got {lim}")
    return O, axis / norm, lim


def load_urdf_robot(path: str | os.PathLike, base_link: str, tip_link: str, left: str = "T_world_base",
                    right: str = "T_flange_tool", T_left_base=None, T_flange_right=None,
                    name: str | None = None) -> URDFChain:
    """Serial chain of the URDF file ``path`` from ``base_link`` to ``tip_link`` (the flange).

    left / right: mount names (``T_world_base``/``T_flange_tool``, ``T_target_base``/``T_flange_cam``
    eye-in-hand, ``T_cam_base``/``T_flange_target`` fixed camera); T_left_base / T_flange_right:
    their nominal (4, 4) transforms in m (identity if None). name: default the URDF robot name.
    Model and parameter names: module docstring. Errors: :class:`ConfigError` naming the file,
    link and joint.
    """
    path = Path(path)
    robot = read_urdf(path)
    joints = _chain_joints(robot, path, base_link, tip_link)
    pending = np.eye(4)
    origins, raw, axes, prism, limits, names = [], [], [], [], [], []
    for j in joints:
        O, axis, lim = _joint_data(j, path)
        if axis is None:
            pending = pending @ O
            continue
        origins.append(pending @ O)
        raw.append(O)
        pending = np.eye(4)
        axes.append(axis)
        prism.append(j.type == "prismatic")
        limits.append(lim)
        names.append(j.name)
    if not origins:
        raise ConfigError(f"{path}: no movable joint between base_link {base_link!r} and tip_link {tip_link!r}")
    meta = {"file": str(path), "robot": robot.name, "base_link": base_link, "tip_link": tip_link,
            "joint_names": tuple(names), "raw_origins": np.array(raw), "source": f"URDF {path.name}",
            "description": "", "notes": "", "configurations": {}, "trials": {}}
    return URDFChain.build(name or robot.name, np.array(origins), np.array(axes), np.array(prism), pending, left, right,
                           T_left_base, T_flange_right, np.array(limits), meta)


# ----------------------------------------------------------------------------- writing URDF
def calibrated_origins(chain: URDFChain, x) -> np.ndarray:
    """(n, 4, 4) new URDF origins of the movable joints at x: ``origin_file @ D_i @ M_i(q0_i)``."""
    raw = chain.meta.get("raw_origins")
    if raw is None:
        raise ParameterError(f"{chain.name}: the chain was not loaded from a URDF file (no raw_origins in meta)")
    D, q0 = chain.joint_placements(x)
    out = np.empty_like(D)
    for i in range(chain.n_joints):
        out[i] = raw[i] @ D[i] @ chain._motion(i, q0[i : i + 1])[0]
    return out


def export_urdf(chain: URDFChain, x, path: str | os.PathLike, source: str | os.PathLike | None = None) -> Path:
    """Write the robot calibrated at x (full vector) as URDF to ``path``: the ``source`` URDF (default
    the file the chain was loaded from) with only the movable joints' origins changed (module
    docstring). Returns the written path. The mounts are not written (``chain.nominal_transforms(x)``)."""
    src = Path(source or chain.meta.get("file", ""))
    if not str(src) or not src.is_file():
        raise ConfigError(f"export_urdf: source URDF {str(src)!r} not found")
    urdf = read_urdf(src)
    new = calibrated_origins(chain, chain._x(x))
    jmap = {el.get("name"): el for el in urdf.tree.getroot().findall("joint")}
    for nm, O in zip(chain.meta["joint_names"], new):
        if nm not in jmap:
            raise ConfigError(f"{src}: joint {nm!r} of chain {chain.name!r} is not in this file")
        set_origin(jmap[nm], O)
    return write_text_atomic(Path(path), urdf_xml_text(urdf.tree))
