"""Serial arms in modified Denavit-Hartenberg form (+ Hayati beta), with analytic parameter Jacobians.

Model (Khalil-Kleinfinger / Craig modified DH, seed 003 eq. 3.2; all joints revolute)
-------------------------------------------------------------------------------------
Link transform of joint i (i = 1..n), joint value q_i (rad)::

    T_{i-1,i} = [Tz(l_i)] Rx(alpha_i) [Ry(beta_i)] Tx(a_i) Rz(theta_i + q_i) Tz(d_i)

* ``theta_i`` is the joint offset (zero reading), ``a_i``/``d_i`` lengths (m), angles in rad.
* **Hayati** joints (``SerialChain.hayati``, for (nearly) parallel consecutive axes z_{i-1} || z_i,
  e.g. RX-90 axes 2 and 3): ``Ry(beta_i)`` is inserted right after ``Rx(alpha_i)``, i.e. a rotation
  about the y axis of frame i-1 once turned by alpha_i, through the origin of frame i-1. Near
  alpha_i = beta_i = 0 the two small rotations (about x and about y) are independent, so beta is
  non-singular where the common normal of parallel axes is not defined. The price: with parallel
  axes, a translation along z_{i-1} before the joint (``d_{i-1}``) and along z_i after it (``d_i``)
  are the same motion, so ``d_i`` of a Hayati joint is the *dependent* parameter. It is **fixed by
  default** (kept at its nominal value, 0 for the RX-90) and :meth:`SerialChain.redundant_pairs`
  lists the pair so that :func:`vision_calib.identify.serial_problem.serial_problem` refuses to free
  both.
* ``l_i`` (optional, only for joints whose file gives ``l``): the thesis' extra fixed translation
  along z_{i-1} before joint i (seed 003 eq. 5.3, matrix L = Tz(l) A). It is exactly redundant with
  ``d_{i-1}`` (Tz(d_{i-1}) Tz(l_i) = Tz(d_{i-1} + l_i)), hence a parameter **fixed by default**.

Measured chain
--------------
``T_left_right(q) = T_left_base . T_base_flange(q) . T_flange_right`` where the two *mounting
transforms* are named by the scene: ``T_world_base``/``T_flange_tool`` (plain robot),
``T_target_base``/``T_flange_cam`` (eye-in-hand camera, pattern on the table: the chain gives
T_target_cam), ``T_cam_base``/``T_flange_target`` (tripod camera, pattern on the probe: T_cam_target).
``T_base_flange(q)`` is the product of the n link transforms (frame n = flange).

Each mount M (left or right) has 6 parameters about a nominal rotation ``R_nom`` (stored in the
chain, not a parameter)::

    M = [ R_nom . Exp([M.rx, M.ry, M.rz]) ,  (M.tx, M.ty, M.tz) ]

i.e. the small rotation vector is **right-multiplied** (expressed on the nominal mount frame's
own axes), nominal 0; the translation is the translation of M itself (in M's parent frame),
nominal = nominal translation. Non-singular near the nominal, whatever the nominal rotation.

Jacobians (analytic, screw-axis form)
-------------------------------------
``pose_jacobian(q, x)`` is d pose_error(T(x), T(x + dx)) / d dx with the :func:`frames.pose_error`
convention: rows [dt (3, m), dtheta (3, rad)], both expressed in frame ``left``. Column of a
rotation parameter about unit axis w through point p: ``[w x (p_end - p), w]``; of a translation
along w: ``[w, 0]``. The mount rotation parameters use the SO(3) right Jacobian of ``Exp`` so the
columns are exact at any x, not only at the nominal.

Everything is vectorised over N joint sets (numpy); Python loops only over joints.
This module imports numpy/scipy only; the robot file is read by :mod:`.serial_file`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import DataError, ParameterError
from ..frames import make_T, rot_x, rot_y, rot_z, skew, so3_exp, so3_right_jacobian  # noqa: F401 (re-exported)
from .params import DEFAULT_SCALE, ParameterSet

#: suffixes of the 6 mount parameters, in vector order
MOUNT_SUFFIXES = ("tx", "ty", "tz", "rx", "ry", "rz")

#: mount names a scene may use (left = parent of the robot base, right = child of the flange)
KNOWN_LEFT = ("T_world_base", "T_target_base", "T_cam_base")
KNOWN_RIGHT = ("T_flange_tool", "T_flange_cam", "T_flange_target")
#: poses per block of the forward walk (``SerialChain._walk``): a block's (B, 4, 4) temporaries stay in cache
WALK_BLOCK = 4096


# ----------------------------------------------------------------------------- the chain
class JointChainChecks:
    """What the serial chain classes (MDH :class:`SerialChain`, ``urdf.URDFChain``) share: mount names,
    named deviations and the checks of joint arrays and full parameter vectors. Needs ``name``,
    ``n_joints``, ``joint_limits``, ``params``, ``left``, ``right``."""

    @property
    def mount_names(self) -> tuple[str, str]:
        return (self.left, self.right)

    @property
    def measured_name(self) -> str:
        """Name of the transform the chain computes, e.g. ``T_target_cam`` for
        ``T_target_base`` . FK . ``T_flange_cam``."""
        a = self.left[2:].rsplit("_base", 1)[0] if self.left.endswith("_base") else self.left[2:]
        b = self.right[len("T_flange_"):] if self.right.startswith("T_flange_") else self.right[2:]
        return f"T_{a}_{b}"

    def deviated(self, deviation=None, base=None) -> np.ndarray:
        """Full vector (n_params,) = base (default nominal) + named deviations {name: SI value}."""
        x = (self.params.nominal if base is None else self._x(base)).copy()
        for k, v in (deviation or {}).items():
            x[self.params.index(k)] += float(v)
        return x

    def within_limits(self, q) -> np.ndarray:
        """(N,) bool: every joint inside joint_limits (all True when the chain has none)."""
        q = self.check_joints(q)
        if self.joint_limits is None:
            return np.ones(q.shape[0], dtype=bool)
        return np.all((q >= self.joint_limits[:, 0]) & (q <= self.joint_limits[:, 1]), axis=1)

    def check_limits(self, q, where: str = "", ids=None) -> None:
        """DataError naming ``where``, the pose id and the joint for a joint value outside joint_limits
        (the same check for the library path, :func:`~vision_calib.identify.serial_problem.serial_problem`,
        and the pipelines' input files); nothing when the chain has no limits."""
        check_joint_limits(self.check_joints(q), self.joint_limits, where or self.name, ids)

    def check_joints(self, q) -> np.ndarray:
        """Joint sets as a (N, n) float array (a single (n,) set becomes (1, n)); DataError naming
        the pose on a wrong shape or a non-finite value."""
        q = np.asarray(q, dtype=float)
        if q.ndim == 1:
            q = q[None, :]
        if q.ndim != 2 or q.shape[1] != self.n_joints:
            raise DataError(f"{self.name}: joint values must have shape (N, {self.n_joints}) rad, got {q.shape}")
        bad = ~np.isfinite(q)
        if bad.any():
            k, j = (int(v) for v in np.argwhere(bad)[0])
            raise DataError(f"{self.name}: joint values of pose {k} are not finite (joint {j + 1} = {q[k, j]})")
        return q

    def _x(self, x) -> np.ndarray:
        if x is None:
            return self.params.nominal
        x = np.asarray(x, dtype=float)
        if x.shape != (len(self.params),):
            raise ParameterError(
                f"{self.name}: parameter vector must have shape ({len(self.params)},) (full vector, "
                f"names {self.params.names[:3]}...), got {x.shape}")
        if not np.all(np.isfinite(x)):
            k = int(np.flatnonzero(~np.isfinite(x))[0])
            raise ParameterError(f"{self.name}: parameter {self.params.names[k]!r} is not finite")
        return x


@dataclass(frozen=True, eq=False)
class SerialChain(JointChainChecks):
    """An all-revolute serial arm (modified DH + Hayati) between two mounting transforms.

    name: robot/scene name. n_joints: n. params: every geometric parameter (names, nominal in
    m/rad, kinds, default free mask, scales). left / right: names of the mounting transforms
    (``T_world_base`` / ``T_flange_tool`` ...); their 6 parameters are ``<left>.tx`` ... ``<left>.rz``.
    hayati: 1-based joints with a beta parameter. pre_z: 1-based joints with an ``l`` parameter.
    joint_limits: (n, 2) rad [min, max] or None. left_R_nominal / right_R_nominal: (3, 3) nominal
    rotations of the mounts. meta: free-form data from the robot file (configurations, trials,
    source notes), not used by the maths.
    """

    name: str
    n_joints: int
    params: ParameterSet
    left: str = "T_world_base"
    right: str = "T_flange_tool"
    hayati: tuple[int, ...] = ()
    pre_z: tuple[int, ...] = ()
    joint_limits: np.ndarray | None = None
    left_R_nominal: np.ndarray = field(default_factory=lambda: np.eye(3))
    right_R_nominal: np.ndarray = field(default_factory=lambda: np.eye(3))
    meta: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self):
        n = int(self.n_joints)
        if n < 1:
            raise ParameterError(f"SerialChain {self.name!r}: n_joints must be >= 1, got {n}")
        object.__setattr__(self, "n_joints", n)
        for attr in ("hayati", "pre_z"):
            js = tuple(sorted(int(j) for j in getattr(self, attr)))
            bad = [j for j in js if not 1 <= j <= n]
            if bad:
                raise ParameterError(f"SerialChain {self.name!r}: {attr} joints {bad} outside 1..{n}")
            object.__setattr__(self, attr, js)
        for attr in ("left_R_nominal", "right_R_nominal"):
            R = np.array(getattr(self, attr), dtype=float)
            if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
                raise ParameterError(f"SerialChain {self.name!r}: {attr} is not a rotation matrix")
            R.setflags(write=False)
            object.__setattr__(self, attr, R)
        if self.joint_limits is not None:
            lim = np.array(self.joint_limits, dtype=float)
            if lim.shape != (n, 2) or np.any(lim[:, 0] > lim[:, 1]):
                raise ParameterError(f"SerialChain {self.name!r}: joint_limits must be (n, 2) with min <= max")
            lim.setflags(write=False)
            object.__setattr__(self, "joint_limits", lim)
        # index table, built once (names are the contract, the vector order is ours)
        ps = self.params
        idx = {}
        for i in range(1, n + 1):
            for p in ("alpha", "a", "theta", "d"):
                idx[f"{p}{i}"] = ps.index(f"{p}{i}")
            if i in self.hayati:
                idx[f"beta{i}"] = ps.index(f"beta{i}")
            if i in self.pre_z:
                idx[f"l{i}"] = ps.index(f"l{i}")
        for m in (self.left, self.right):
            for s in MOUNT_SUFFIXES:
                idx[f"{m}.{s}"] = ps.index(f"{m}.{s}")
        expected = len(idx)
        if len(ps) != expected:
            extra = sorted(set(ps.names) - set(idx))
            raise ParameterError(f"SerialChain {self.name!r}: parameters not used by the model: {extra}")
        object.__setattr__(self, "_idx", idx)

    # ------------------------------------------------------------------ construction
    @classmethod
    def build(
        cls,
        name: str,
        dh,
        hayati=(),
        pre_z: dict | None = None,
        left: str = "T_world_base",
        right: str = "T_flange_tool",
        T_left_base=None,
        T_flange_right=None,
        joint_limits=None,
        meta: dict | None = None,
    ) -> "SerialChain":
        """Chain from a nominal table. dh: (n, 4) rows [alpha (rad), a (m), theta (rad), d (m)];
        hayati: joints with beta (nominal 0, d of that joint fixed); pre_z: {joint: l (m)};
        T_left_base / T_flange_right: nominal (4, 4) mounts (identity if None)."""
        dh = np.asarray(dh, dtype=float)
        if dh.ndim != 2 or dh.shape[1] != 4:
            raise ParameterError(f"dh table must be (n, 4) [alpha, a, theta, d], got shape {dh.shape}")
        n = dh.shape[0]
        pre_z = dict(pre_z or {})
        hayati = tuple(sorted(int(j) for j in hayati))
        TL = np.eye(4) if T_left_base is None else np.asarray(T_left_base, float)
        TR = np.eye(4) if T_flange_right is None else np.asarray(T_flange_right, float)
        names, nom, kinds, free = [], [], [], []

        def add(nm, v, kind, fr=True):
            names.append(nm)
            nom.append(float(v))
            kinds.append(kind)
            free.append(bool(fr))

        def add_mount(m, T):
            for s, v in zip(MOUNT_SUFFIXES, list(T[:3, 3]) + [0.0, 0.0, 0.0]):
                add(f"{m}.{s}", v, "length" if s.startswith("t") else "angle")

        add_mount(left, TL)
        for i in range(1, n + 1):
            alpha, a, theta, d = dh[i - 1]
            if i in pre_z:
                add(f"l{i}", pre_z[i], "length", False)
            add(f"alpha{i}", alpha, "angle")
            if i in hayati:
                add(f"beta{i}", 0.0, "angle")
            add(f"a{i}", a, "length")
            add(f"theta{i}", theta, "angle")
            add(f"d{i}", d, "length", i not in hayati)
        add_mount(right, TR)
        ps = ParameterSet.from_lists(names, nom, kinds, free, [DEFAULT_SCALE[k] for k in kinds])
        return cls(
            name=name,
            n_joints=n,
            params=ps,
            left=left,
            right=right,
            hayati=hayati,
            pre_z=tuple(sorted(pre_z)),
            joint_limits=joint_limits,
            left_R_nominal=TL[:3, :3],
            right_R_nominal=TR[:3, :3],
            meta=dict(meta or {}),
        )

    def with_params(self, params: ParameterSet) -> "SerialChain":
        """Same model with another parameter set (same names, e.g. other free mask or nominal)."""
        if params.names != self.params.names:
            raise ParameterError("with_params: the parameter names must be those of the chain")
        return SerialChain(self.name, self.n_joints, params, self.left, self.right, self.hayati, self.pre_z,
                           self.joint_limits, self.left_R_nominal, self.right_R_nominal, self.meta)

    # ------------------------------------------------------------------ info
    def redundant_pairs(self) -> list[tuple[str, str, str]]:
        """Pairs of parameters that are exactly redundant at the nominal (never both free):
        (name_a, name_b, reason)."""
        out = []
        for i in self.hayati:
            if i >= 2:
                out.append((f"d{i}", f"d{i - 1}",
                            f"joint {i} has a Hayati beta (axes {i - 1} and {i} parallel): d{i} and d{i - 1} "
                            "are the same translation along the parallel axes"))
            out.append((f"d{i}", f"beta{i}",
                        f"joint {i} uses the Hayati parameter beta{i}; its d{i} is the dependent parameter"))
        for i in self.pre_z:
            prev = f"d{i - 1}" if i >= 2 else f"{self.left}.tz"
            out.append((f"l{i}", prev, f"l{i} (translation along z{i - 1} before joint {i}) equals a change of {prev}"))
        return out

    def nominal_transforms(self, x=None) -> tuple[np.ndarray, np.ndarray]:
        """(T_left_base (4, 4), T_flange_right (4, 4)) at x (nominal if None)."""
        x = self._x(x)
        return self._mount(x, self.left, self.left_R_nominal), self._mount(x, self.right, self.right_R_nominal)

    def joint_offset_form(self, x=None) -> tuple[np.ndarray, np.ndarray]:
        """(x (n_params,) unchanged, offsets (n,) = theta_1..theta_n rad): in modified DH theta_i is already the
        joint's only rotation about its axis, the model angle theta_i + q_i (``kinematics.protocols.JointOffsetForm``)."""
        x = self._x(x).copy()
        return x, np.array([x[self._idx[f"theta{i}"]] for i in range(1, self.n_joints + 1)])

    def _mount(self, x, m, R_nom) -> np.ndarray:
        i = self._idx
        t = [x[i[f"{m}.{s}"]] for s in ("tx", "ty", "tz")]
        r = np.array([x[i[f"{m}.{s}"]] for s in ("rx", "ry", "rz")])
        return make_T(R_nom @ so3_exp(r), t)

    # ------------------------------------------------------------------ forward model
    def _link_parts(self, x, i):
        """Constant prefix C_i = [Tz(l)] Rx(alpha) [Ry(beta)] Tx(a) (4, 4), theta_i, d_i."""
        ix = self._idx
        R = rot_x(x[ix[f"alpha{i}"]])
        if i in self.hayati:
            R = R @ rot_y(x[ix[f"beta{i}"]])
        C = np.zeros((4, 4))  # written out: [R, R e_x a (+ l e_z)]
        C[:3, :3], C[:3, 3], C[3, 3] = R, R[:, 0] * x[ix[f"a{i}"]], 1.0
        if i in self.pre_z:
            C[2, 3] += x[ix[f"l{i}"]]
        return C, x[ix[f"theta{i}"]], x[ix[f"d{i}"]]

    def _constant_parts(self, x):
        """(T_left_base, T_flange_right, [_link_parts(x, i) for each joint]) at x: the walk's pose-independent
        matrices, kept for the last x (a solver asks for the residual and the Jacobian at the same x; the pair is
        read and replaced as one tuple, so concurrent callers at other x only recompute)."""
        key = x.tobytes()
        kept = self.__dict__.get("_parts_cache")
        if kept is not None and kept[0] == key:
            return kept[1]
        TL, TR = self.nominal_transforms(x)
        val = (TL, TR, [self._link_parts(x, i) for i in range(1, self.n_joints + 1)])
        object.__setattr__(self, "_parts_cache", (key, val))
        return val

    def _walk(self, q, x, keep: bool = True):
        """Frames (n+2, N, 4, 4) in `left`, joint-major: [base, link 1..n (n = flange), right]; keep=False: only
        the last (``right``) is stored, (1, N, 4, 4). Per joint one BLAS product with the constant prefix and the
        Rz(theta + q) Tz(d) columns written out (no per-pose 4x4 products), over blocks of :data:`WALK_BLOCK`
        poses (a block's temporaries stay in cache)."""
        N = q.shape[0]
        out = np.empty((self.n_joints + 2 if keep else 1, N, 4, 4))
        TL, TR, parts = self._constant_parts(x)
        for a in range(0, max(N, 1), WALK_BLOCK):
            b = min(a + WALK_BLOCK, N)
            self._walk_block(q[a:b], TL, TR, parts, out[:, a:b], keep)
        return out

    def _walk_block(self, q, TL, TR, parts, out, keep: bool) -> None:
        """:meth:`_walk` of one block of poses q (B, n) into out ((n+2 or 1), B, 4, 4)."""
        B = q.shape[0]
        F = np.broadcast_to(TL, (B, 4, 4))
        if keep:
            out[0] = F
        FC = np.empty((B, 4, 4))
        for i, (C, theta, d) in enumerate(parts, start=1):
            np.matmul(F.reshape(-1, 4), C, out=FC.reshape(-1, 4))
            # (F C) Rz(theta + q) Tz(d): columns x, y rotated about z, origin moved by d along z
            ang = theta + q[:, i - 1]
            c, sn = np.cos(ang)[:, None], np.sin(ang)[:, None]
            F = out[i] if keep else np.empty((B, 4, 4))
            F[:, :, 0] = FC[:, :, 0] * c + FC[:, :, 1] * sn
            F[:, :, 1] = FC[:, :, 1] * c - FC[:, :, 0] * sn
            F[:, :, 2] = FC[:, :, 2]
            F[:, :, 3] = FC[:, :, 2] * d + FC[:, :, 3]
        np.matmul(F.reshape(-1, 4), TR, out=out[-1].reshape(-1, 4))

    def forward(self, q, x=None) -> np.ndarray:
        """T_left_right (N, 4, 4) [m] for joint sets q (N, n) rad and full parameter vector x (n_params,)
        (None = nominal)."""
        q = self.check_joints(q)
        x = self._x(x)
        return self._walk(q, x, keep=False)[-1]

    def forward_all(self, q, x=None) -> np.ndarray:
        """All frames (N, n+2, 4, 4) expressed in frame ``left``: index 0 = robot base (T_left_base),
        i = link i (i = 1..n; n = flange), n+1 = ``right`` frame (T_left_right). For drawing the arm."""
        q = self.check_joints(q)
        x = self._x(x)
        return np.moveaxis(self._walk(q, x), 0, 1)

    def flange(self, q, x=None) -> np.ndarray:
        """T_base_flange(q) (N, 4, 4): the arm alone, without the mounting transforms."""
        F = self.forward_all(q, x)
        TL, _ = self.nominal_transforms(x)
        Li = np.linalg.inv(TL)
        return Li @ F[:, self.n_joints]

    # ------------------------------------------------------------------ Jacobians
    def pose_jacobian(self, q, x=None) -> np.ndarray:
        """(N, 6, n_params) d pose_error(T(x), T(x + dx)) / d dx at q (N, n) rad, x (n_params,).

        Rows: [dt (m), dtheta (rad)] expressed in frame ``left`` (frames.pose_error convention);
        columns: every parameter of ``params`` (free or not), in ``params.names`` order.
        """
        return self.pose_and_jacobian(q, x)[1]

    def walk_frames(self, q, x=None) -> np.ndarray:
        """Frames (n+2, N, 4, 4) of one walk of the chain in ``left``, joint-major: [base, link 1..n (n = flange),
        right]; frames[-1] is :meth:`forward`. :meth:`pose_and_jacobian` takes them (``frames=``) instead of
        walking again (``kinematics.protocols.WalkFrames``)."""
        return self._walk(self.check_joints(q), self._x(x))

    def _jacobian_layout(self) -> dict:
        """The columns of :meth:`pose_and_jacobian` by role (index arrays into ``params.names``): left_t, left_r,
        right_t, right_r (3,) each, alpha, a, theta, d (n_joints,) in joint order; idx: the name -> index map."""
        lay = self.__dict__.get("_jac_layout")
        if lay is None:
            ix, js = self._idx, range(1, self.n_joints + 1)
            lay = {"idx": ix, **{f"{side}_{k}": np.array([ix[f"{m}.{k}{c}"] for c in "xyz"])
                                 for side, m in (("left", self.left), ("right", self.right)) for k in "tr"},
                   **{nm: np.array([ix[f"{nm}{i}"] for i in js]) for nm in ("alpha", "a", "theta", "d")}}
            object.__setattr__(self, "_jac_layout", lay)
        return lay

    def pose_and_jacobian(self, q, x=None, frames=None) -> tuple[np.ndarray, np.ndarray]:
        """(T_left_right (N, 4, 4) as :meth:`forward` gives it, :meth:`pose_jacobian` (N, 6, n_params)) from one
        walk of the chain (``frames``: :meth:`walk_frames` at the same q, x, when the caller has them)."""
        q = self.check_joints(q)
        x = self._x(x)
        N = q.shape[0]
        n_par = len(self.params)
        if frames is None:
            frames = self._walk(q, x)  # (n+2, N, 4, 4)
        elif np.shape(frames) != (self.n_joints + 2, N, 4, 4):
            raise ParameterError(f"frames have shape {np.shape(frames)}, expected {(self.n_joints + 2, N, 4, 4)} "
                                 "(walk_frames of the same joint values)")
        p_end_t = np.ascontiguousarray(frames[-1, :, :3, 3].T)  # (3, N)
        lay = self._jacobian_layout()
        nj = self.n_joints
        Jt = np.zeros((n_par, 6, N))  # (columns, rows, poses), filled a group of columns at a time; returned transposed
        rot_k, arms = [], []  # rotation columns [w x (p_end - p), w]: w written now, p_end - p kept for the end

        # ---- left mount: T_left_base = [R_nom Exp(r), t], parent frame = left (identity)
        TL, TR, _ = self._constant_parts(x)
        Jt[lay["left_t"], (0, 1, 2)] = 1.0  # along axis a of left
        WL = TL[:3, :3] @ so3_right_jacobian(x[lay["left_r"]])  # columns = axes in left
        Jt[lay["left_r"], 3:] = WL.T[:, :, None]
        rot_k.append(lay["left_r"])
        arms.append(np.broadcast_to(p_end_t - TL[:3, 3][:, None], (3, 3, N)))

        # ---- joints, all at once: frame i-1's axes and origin (k, 3, N) for joint i = k + 1
        Fp = frames[:nj]
        ax = Fp[:, :, :3, 0].transpose(0, 2, 1)  # x axis of frame i-1: Rx(alpha) keeps it
        o = Fp[:, :, :3, 3].transpose(0, 2, 1)
        az = frames[1:nj + 1, :, :3, 2].transpose(0, 2, 1)  # z axis of frame i (Rz(theta + q) and Tz(d) keep it)
        if self.pre_z or self.hayati:
            o, ax, az = o.copy(), ax.copy(), az.copy()
        for i in self.pre_z:
            zp = Fp[i - 1, :, :3, 2].T
            Jt[lay["idx"][f"l{i}"], :3] = zp
            o[i - 1] = o[i - 1] + zp * x[lay["idx"][f"l{i}"]]
        Jt[lay["alpha"], 3:] = ax
        rot_k.append(lay["alpha"])
        arms.append(p_end_t - o)
        for i in self.hayati:  # Rx(alpha) Ry(beta): the y axis after Rx(alpha) turns beta; x and z axes move
            R = Fp[i - 1, :, :3, :3] @ rot_x(x[lay["idx"][f"alpha{i}"]])
            rot_k.append(np.array([lay["idx"][f"beta{i}"]]))
            Jt[rot_k[-1][0], 3:] = R[:, :, 1].T
            arms.append((p_end_t - o[i - 1])[None])
            R = R @ rot_y(x[lay["idx"][f"beta{i}"]])
            ax[i - 1], az[i - 1] = R[:, :, 0].T, R[:, :, 2].T
        Jt[lay["a"], :3] = ax
        Jt[lay["theta"], 3:] = az
        rot_k.append(lay["theta"])
        arms.append(p_end_t - (o + ax * x[lay["a"]][:, None, None]))  # (the moment arm from after Tx(a))
        Jt[lay["d"], :3] = az

        # ---- right mount: T_flange_right = [R_nom Exp(r), t] in the flange frame F
        F = frames[nj]
        Rf, of = F[:, :3, :3], F[:, :3, 3]
        Jt[lay["right_t"], :3] = Rf.transpose(2, 1, 0)
        WR = Rf @ (TR[:3, :3] @ so3_right_jacobian(x[lay["right_r"]]))  # (N, 3, 3)
        Jt[lay["right_r"], 3:] = WR.transpose(2, 1, 0)
        rot_k.append(lay["right_r"])
        p_right = of + np.einsum("nij,j->ni", Rf, TR[:3, 3])
        arms.append(np.broadcast_to(p_end_t - p_right.T, (3, 3, N)))
        # the cross products of every rotation column at once, written out on contiguous (columns, N) rows
        K = np.concatenate(rot_k)
        w, v = Jt[K, 3:], np.concatenate(arms)  # (r, 3, N)
        Jt[K, 0] = w[:, 1] * v[:, 2] - w[:, 2] * v[:, 1]
        Jt[K, 1] = w[:, 2] * v[:, 0] - w[:, 0] * v[:, 2]
        Jt[K, 2] = w[:, 0] * v[:, 1] - w[:, 1] * v[:, 0]
        return frames[-1], Jt.transpose(2, 1, 0)  # J a view: the caller's first selection copies it

    def position_jacobian(self, q, x=None) -> np.ndarray:
        """(N, 3, n_params): translation rows of :meth:`pose_jacobian` (m per unit parameter, in ``left``)."""
        return self.pose_jacobian(q, x)[:, :3, :]


def check_joint_limits(q, limits, where: str, ids=None) -> None:
    """DataError ``"{where}: pose {id} joint q{j} = ... deg is outside the robot's limits [...] deg (wrong
    angle unit?)"`` for the first joint value of q (N, n) rad outside limits (n, 2) (None: no check)."""
    if limits is None:
        return
    q = np.asarray(q, float)
    bad = np.argwhere((q < limits[:, 0]) | (q > limits[:, 1]))
    if bad.size:
        k, j = (int(v) for v in bad[0])
        pid = list(ids)[k] if ids is not None else k
        raise DataError(
            f"{where}: pose {pid!r} joint q{j + 1} = {np.degrees(q[k, j]):.4g} deg is outside the robot's "
            f"limits [{np.degrees(limits[j, 0]):.4g}, {np.degrees(limits[j, 1]):.4g}] deg (wrong angle unit?)")
