"""Serial arms (``kinematics.serial.SerialChain``, modified DH + Hayati, or any chain with the same
interface) with a camera on the flange or on a tripod.

Eye-in-hand (camera on the flange, target on the table): the chain measures ``T_target_cam =
T_target_base · FK(q) · T_flange_cam``. Fixed camera (tripod, target on the flange/probe):
``T_cam_target = T_cam_base · FK(q) · T_flange_target``. A robot file whose mounts are
``T_world_base`` / ``T_flange_tool`` is a fixed measuring device in the world frame measuring the
tool frame (the thesis' chapter 3-4 setup). Commanded poses are joint sets q (N, n) rad.

Scene keys of this kind: ``mounts`` (nominal camera/target mounting, overrides the robot file's) and
``poses.center`` / ``poses.spread`` (random joint sets, in the scene's angle unit).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import ClassVar, Sequence

import numpy as np
from numpy.typing import ArrayLike

from .. import frames as F
from ..config import Section
from ..errors import DataError
from ..identify.problem import IdentificationProblem
from ..kinematics.params import ParameterSet
from ..kinematics.protocols import ChainModel, PrismaticJoints, Remountable
from .base import Evaluation, Measurements, Setup

#: mount names of each camera mount: (left, right) of the chain
MOUNTS = {"eye_in_hand": ("T_target_base", "T_flange_cam"), "fixed": ("T_cam_base", "T_flange_target")}
#: scene ``mounts`` keys: (left key, right key) with the left one giving T_base_<x> (inverted on load)
MOUNT_KEYS = {"eye_in_hand": ("target_in_base", "camera_in_flange"), "fixed": ("camera_in_base", "target_in_flange")}


def remount_chain(chain: ChainModel, left: str, right: str, T_left_base: ArrayLike,
                  T_flange_right: ArrayLike) -> ChainModel:
    """Same arm, other mounting transforms (nominal (4, 4) each), keeping the arm's own parameter
    values and free flags. ``chain``: a :class:`~vision_calib.kinematics.protocols.Remountable` chain (any
    chain kind) or a SerialChain."""
    if isinstance(chain, Remountable):
        return chain.remounted(left, right, T_left_base, T_flange_right)
    from ..kinematics.serial import SerialChain

    v = chain.params.values()
    n = chain.n_joints
    dh = np.array([[v[f"alpha{i}"], v[f"a{i}"], v[f"theta{i}"], v[f"d{i}"]] for i in range(1, n + 1)])
    pre_z = {i: v[f"l{i}"] for i in chain.pre_z}
    new = SerialChain.build(chain.name, dh, hayati=chain.hayati, pre_z=pre_z, left=left, right=right,
                            T_left_base=T_left_base, T_flange_right=T_flange_right,
                            joint_limits=chain.joint_limits, meta=chain.meta)
    arm = [nm for nm in chain.params.names if "." not in nm]  # the arm's own parameters (not the mounts')
    ps = new.params.with_nominal({nm: v[nm] for nm in arm})
    free = ps.free.copy()
    for nm in arm:
        free[ps.index(nm)] = chain.params.free[chain.params.index(nm)]
    return new.with_params(replace(ps, free=free))


#: |q| [rad] above which a revolute joint without finite limits is refused (degrees read as radians)
MAX_FREE_REVOLUTE_RAD = 2 * np.pi + 0.1


@dataclass(frozen=True)
class SerialSetup(Setup):
    """Serial arm + camera. ``chain``: chain whose left/right mounts are (T_target_base,
    T_flange_cam) for eye_in_hand or (T_cam_base, T_flange_target) for fixed. ``q_center`` (n,) rad
    and ``q_spread`` (n,) rad: random poses are drawn uniformly in q_center ± q_spread (within joint
    limits) and kept when the target (``target_outline`` (4, 3) m, target frame) is visible."""

    chain: ChainModel | None = None
    q_center: np.ndarray | None = None
    q_spread: np.ndarray | None = None
    target_outline: np.ndarray | None = None

    kind: ClassVar[str] = "serial"
    residuals: ClassVar[tuple[str, ...]] = ("pose", "position")
    methods: ClassVar[tuple[str, ...]] = ("lse", "ekf")
    mounts: ClassVar[tuple[str, ...]] = ("eye_in_hand", "fixed")
    scene_keys: ClassVar[tuple[str, ...]] = ("mounts",)
    pose_keys: ClassVar[tuple[str, ...]] = ("center", "spread")
    reach_check: ClassVar[str] = "joint limits"

    # ------------------------------------------------------------------ protocol
    @property
    def n_joints(self) -> int:
        return self.chain.n_joints

    def T_cam_target(self, poses: ArrayLike, x: ArrayLike) -> np.ndarray:
        T = self.chain.forward(poses, x)
        return F.inv_T(T) if self.mount == "eye_in_hand" else T

    def joints(self, poses: ArrayLike, x: ArrayLike) -> np.ndarray:
        return np.asarray(poses, float).copy()

    def reachable(self, poses: ArrayLike, x: ArrayLike | None = None) -> np.ndarray:
        """(N,) bool: every joint of the joint sets (N, n) rad within the robot's joint limits."""
        return self.chain.within_limits(poses)

    def end_point(self, poses: ArrayLike, x: ArrayLike | None = None) -> np.ndarray:
        """(N, 3) [m] flange position in the robot base frame."""
        return self.chain.flange(poses, x)[:, :3, 3]

    # ------------------------------------------------------------------ rig.base.ArmFrames (planning)
    @property
    def robot_name(self) -> str:
        return str(self.chain.name)

    @property
    def robot_file(self) -> str:
        return str(self.meta.get("robot_path", ""))

    def link_frames(self, poses: ArrayLike, x: ArrayLike | None = None) -> np.ndarray:
        """(N, n + 2, 4, 4) [m] in the robot base frame: base, frames after joints 1..n-1, flange, right mount."""
        frames = self.chain.forward_all(poses, x)
        T_left_base = self.chain.nominal_transforms(x)[0]
        return F.inv_T(T_left_base) @ frames

    def link_names(self) -> tuple[str, ...]:
        """Names of the :meth:`link_frames`: base, link1..link<n-1>, flange, the right mount (e.g. T_flange_cam)."""
        n = self.n_joints
        return ("base",) + tuple(f"link{i}" for i in range(1, n)) + ("flange", self.chain.right)

    def chain_measurements(self, meas: Measurements) -> tuple[np.ndarray, np.ndarray]:
        """Measured chain poses T_left_right (N, 4, 4) and their covariances (N, 6, 6)."""
        if self.mount == "eye_in_hand":
            G = F.inverse_error_map(meas.T_cam_target)
            return F.inv_T(meas.T_cam_target), G @ meas.cov @ np.swapaxes(G, -1, -2)
        return meas.T_cam_target, meas.cov

    def problem(self, meas: Measurements, residual: str | None = None,
                params: ParameterSet | None = None) -> IdentificationProblem:
        from ..identify.serial_problem import serial_problem

        residual = self.check_residual(residual)
        T, cov = self.chain_measurements(meas)
        if residual == "position":
            cov = cov[:, :3, :3]
        chain = self.chain.with_params(params or self.params)
        return serial_problem(chain, meas.joints, T, residual=residual, obs_cov=cov, labels=meas.labels)

    def evaluate(self, x: ArrayLike, x_true: ArrayLike, validation: ArrayLike, measurements: Measurements | None = None,
                 truth: Setup | None = None) -> Evaluation:
        """Errors of the predicted chain pose (end frame in the left frame) vs truth on validation joints."""
        truth = truth or self
        T_true = truth.chain.forward(validation, x_true)
        return Evaluation(T_true[:, :3, 3], F.pose_error(T_true, self.chain.forward(validation, x)))

    def sample_poses(self, rng: np.random.Generator, n: int, check_view: bool = True,
                     max_tries: int = 200) -> np.ndarray:
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

    def generic_poses(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Joint sets uniform within the joint limits (+-180 deg where the robot has none)."""
        lim = self.chain.joint_limits
        lo, hi = (np.full(self.n_joints, -np.pi), np.full(self.n_joints, np.pi)) if lim is None else \
            (np.maximum(lim[:, 0], -np.pi), np.minimum(lim[:, 1], np.pi))
        return lo + rng.uniform(size=(n, self.n_joints)) * (hi - lo)

    def model_dict(self) -> dict:
        ch = self.chain
        return {"mounts": {"left": ch.left, "right": ch.right, "left_R_nominal": ch.left_R_nominal.tolist(),
                           "right_R_nominal": ch.right_R_nominal.tolist()}}

    def with_params(self, params: ParameterSet) -> "SerialSetup":
        return replace(self, params=params, chain=self.chain.with_params(params))

    def configurations(self) -> dict:
        return self.chain.meta.get("configurations", {})

    def trials(self) -> dict:
        return self.chain.meta.get("trials", {})

    def check_joints(self, q: ArrayLike, where: str, ids: Sequence | None = None) -> None:
        """:meth:`Setup.check_joints`, and DataError for a value outside the robot's joint limits, or, for a
        revolute joint without finite limits, beyond +-(2 pi + 0.1) rad (both: likely an angle unit error)."""
        super().check_joints(q, where, ids)
        q = np.asarray(q, float)
        ids = list(ids) if ids is not None else list(range(len(q)))
        # revolute joints without finite limits: |q| > 2 pi + margin is degrees read as radians
        prismatic = self.chain.prismatic if isinstance(self.chain, PrismaticJoints) else np.zeros(q.shape[1], bool)
        revolute = ~np.asarray(prismatic, bool)
        lim = self.chain.joint_limits
        free = revolute & (np.ones(q.shape[1], bool) if lim is None else ~np.all(np.isfinite(lim), axis=1))
        big = np.argwhere((np.abs(q) > MAX_FREE_REVOLUTE_RAD) & free)
        if big.size:
            k, j = (int(v) for v in big[0])
            raise DataError(f"{where}: pose {ids[k]!r} joint q{j + 1} = {q[k, j]:.4g} rad is more than a turn "
                            f"(|q| > 2 pi + {MAX_FREE_REVOLUTE_RAD - 2 * np.pi:.2g}) for a revolute joint: degrees "
                            "declared as radians? (set units.angle: deg)")
        from ..kinematics.serial import check_joint_limits

        check_joint_limits(q, lim, where, ids)

    def fixed_note(self, name: str) -> str:
        for a, b, why in self.chain.redundant_pairs():
            if name in (a, b):
                return f"fixed: redundant with {b if name == a else a} ({why})"
        return super().fixed_note(name)

    # ------------------------------------------------------------------ registry hooks
    @staticmethod
    def claims(robot_path: Path, doc: dict | None) -> bool:
        """A YAML robot file without ``kind`` (or ``kind: serial``) is a serial MDH robot."""
        return doc is not None and doc.get("kind", "serial") == "serial"

    @classmethod
    def from_scene(cls, ctx) -> "SerialSetup":
        """The setup of a scene (``rig.scene.SceneContext``): robot file, mounts, pose sampling."""
        chain = cls._mounted(cls.load_chain(ctx), ctx)
        params = ctx.apply_free(chain.params)
        ps = ctx.top.section("poses", default={})
        n = chain.n_joints
        center = ps.floats("center", n, np.zeros(n)) * ctx.Af
        spread = ps.floats("spread", n, np.full(n, 20.0)) * ctx.Af
        outline = None if ctx.target is None else ctx.target.measured_outline_m()
        return cls(name=ctx.name, params=params, camera=ctx.camera, mount=ctx.mount,
                   meta={"robot_path": str(ctx.robot_path)}, chain=chain.with_params(params),
                   q_center=center, q_spread=spread, target_outline=outline)

    @classmethod
    def load_chain(cls, ctx):
        """The robot file's chain (MDH robot YAML)."""
        from ..kinematics.serial_file import load_serial_robot

        return load_serial_robot(ctx.robot_path)

    @staticmethod
    def _mounted(chain, ctx):
        """The chain with the scene's ``mounts`` (or the robot file's, checked against the camera mount)."""
        ms = ctx.top.section("mounts", default={})
        ms.check_known(MOUNT_KEYS[ctx.mount])
        lk, rk = MOUNT_KEYS[ctx.mount]
        if lk in ms or rk in ms:
            T_base_left = ctx.xyz_rpy(ms, lk)
            return remount_chain(chain, *MOUNTS[ctx.mount], F.inv_T(T_base_left), ctx.xyz_rpy(ms, rk))
        ok = [MOUNTS[ctx.mount]] + ([("T_world_base", "T_flange_tool")] if ctx.mount == "fixed" else [])
        if chain.mount_names not in ok:
            raise ms.error(lk, f"a {ctx.mount} camera needs mounts {lk} and {rk} (the robot file has {chain.mount_names})")
        return chain

    @classmethod
    def load_model(cls, doc: Section, robot_path: Path) -> ChainModel:
        """The robot of a calibrated-model file (``io.model_export``), nominal values still to set."""
        from ..kinematics.serial_file import load_serial_robot

        return cls._model_mounts(load_serial_robot(robot_path), doc)

    @staticmethod
    def _model_mounts(chain, doc):
        m = doc.section("mounts")
        chain = remount_chain(chain, m.get("left", str), m.get("right", str), np.eye(4), np.eye(4))
        return replace(chain, left_R_nominal=np.asarray(m.get("left_R_nominal", list), float),
                       right_R_nominal=np.asarray(m.get("right_R_nominal", list), float))
