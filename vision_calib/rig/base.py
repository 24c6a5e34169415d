"""The Setup protocol: what every robot kind provides to the pipelines, and the types it exchanges.

A setup = a robot + the camera mount + the target mount, with ONE parameter set (robot + mounting
parameters, by name) and the scene's free mask. Commanded poses are kind-specific arrays (serial:
joint sets q (N, n) rad; H4: nacelle poses X (N, 4) = x, y, z [m], theta [rad]). Every kind turns
commanded poses into the camera's view ``T_cam_target`` (for rendering), builds the identification
problem from :class:`Measurements`, and evaluates a parameter vector on validation poses into one
:class:`Evaluation`. Kinds are registered in :mod:`vision_calib.rig.registry` (the one place to touch
when adding a robot kind). Kind-specific capabilities are optional interfaces (``Protocol`` classes checked
with ``isinstance`` where they are used): :class:`ChainMeasured`, :class:`ModelVariants`,
:class:`NamedConfigurations`, :class:`NamedTrials`, :class:`PoseGrids`, :class:`TiltsFromAxis`, :class:`ArmFrames`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import ClassVar, Protocol, Sequence, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from .. import frames as F
from ..camera import CameraIntrinsics
from ..errors import ConfigError, DataError
from ..identify.handeye_problem import nearest_rotation
from ..identify.problem import IdentificationProblem
from ..kinematics.params import ParameterSet

#: a mounting transform's name (``T_a_b``, ``A_T_B``) before the dot of a parameter name
_MOUNT_NAME = re.compile(r"(^|_)T_")


@dataclass(frozen=True)
class Measurements:
    """What the camera (and the encoders) gave for N robot poses.

    poses: commanded poses (serial: q (N, n) rad; H4: X (N, 4)). joints: measured joint values
    (N, n_joints) rad. T_cam_target: (N, 4, 4) measured camera poses. cov: (N, 6, 6) covariance of
    each measured T_cam_target in the ``frames.pose_error`` convention (camera frame).
    labels: (N,) pose ids. cov_scale: [k_lo, k_hi], the range of the factor by which the true covariance
    may differ from ``cov`` (the covariance model's own accuracy, read by the adequacy test:
    ``identify.model_adequacy``): (1, 1) for synthetic or user-given covariances,
    ``identify.adequacy.IMAGE_COV_SCALE`` for poses measured from images.
    """

    poses: np.ndarray
    joints: np.ndarray
    T_cam_target: np.ndarray
    cov: np.ndarray
    labels: tuple = ()
    cov_scale: tuple = (1.0, 1.0)

    def subset(self, idx: ArrayLike) -> "Measurements":
        idx = np.asarray(idx, dtype=int)
        labels = tuple(self.labels[i] for i in idx) if self.labels else ()
        return Measurements(self.poses[idx], self.joints[idx], self.T_cam_target[idx], self.cov[idx], labels,
                            self.cov_scale)

    def select(self, labels: Sequence[str]) -> "Measurements":
        """The poses with these ``labels`` (e.g. a problem's kept poses), in that order; self when either side
        carries no labels. KeyError naming the label when one is not here."""
        if not labels or not self.labels:
            return self
        pos = {lab: k for k, lab in enumerate(self.labels)}
        return self.subset([pos[lab] for lab in labels])

    @classmethod
    def from_pose_measurements(cls, poses: ArrayLike, joints: ArrayLike,
                               pms: Sequence) -> tuple["Measurements", list[int]]:
        """Measurements of the valid ``measure.PoseMeasurement`` of ``pms`` (one per commanded pose of
        ``poses`` (N, .) and ``joints`` (N, n_joints) rad), and the indices of those poses."""
        ok = [i for i, pm in enumerate(pms) if pm.valid]
        T = np.array([pms[i].T_cam_target for i in ok]).reshape(-1, 4, 4)
        cov = np.array([pms[i].cov for i in ok]).reshape(-1, 6, 6)
        labels = tuple(str(pms[i].pose_id) for i in ok)
        from ..identify.adequacy import IMAGE_COV_SCALE

        return cls(np.asarray(poses)[ok], np.asarray(joints)[ok], T, cov, labels, IMAGE_COV_SCALE), ok


def pose_cov_from_sigmas(n: int, sigma_t_m: float, sigma_r_rad: float) -> np.ndarray:
    """(n, 6, 6) diagonal covariances [sigma_t² x3, sigma_r² x3]; tiny floor keeps them invertible."""
    st = max(float(sigma_t_m), 1e-6)  # floor 1 um / 1 urad: noise-free data keeps a well-conditioned weighting
    sr = max(float(sigma_r_rad), 1e-6)
    return np.broadcast_to(np.diag([st**2] * 3 + [sr**2] * 3), (n, 6, 6)).copy()


def pose_noise(rng: np.random.Generator, cov: ArrayLike) -> np.ndarray:
    """(N, 6) pose errors d_k ~ N(0, cov[k]) for covariances cov (N, 6, 6) in the ``frames.pose_error``
    convention (translation m, rotation vector rad, camera frame; apply with ``frames.perturb_pose``).
    d_k = S_k z_k, z_k ~ N(0, I), S_k = V diag(sqrt(lam)) V^T the symmetric square root of cov[k] (eigen-decomposition;
    a semi-definite covariance is fine, negative rounding eigenvalues count as 0): unlike V sqrt(lam) alone, it does
    not depend on the eigenvectors' signs or on their basis within a repeated eigenvalue, so covariances equal to
    rounding give draws equal to rounding. DataError when a covariance is not finite."""
    cov = np.asarray(cov, float)
    if not np.all(np.isfinite(cov)):
        bad = np.flatnonzero(~np.all(np.isfinite(cov), axis=(1, 2)))
        raise DataError(f"pose covariance not finite for poses {bad.tolist()[:5]}: no noise can be drawn from it")
    lam, V = np.linalg.eigh(0.5 * (cov + np.swapaxes(cov, 1, 2)))
    S = (V * np.sqrt(np.clip(lam, 0.0, None))[:, None, :]) @ np.swapaxes(V, 1, 2)
    z = rng.normal(size=(len(cov), 6))
    return np.einsum("kij,kj->ki", S, z)


#: the kind-independent fields of ``Evaluation.to_dict()`` (the rest are the kind's criteria)
ACCURACY_FIELDS = ("position_rms_mm", "position_max_mm", "rotation_rms_deg", "rotation_max_deg", "n_poses",
                   "position_rms_registered_mm")


@dataclass(frozen=True)
class Evaluation:
    """Accuracy of a parameter vector on validation poses (true robot vs model).

    positions_m: (N, 3) true positions of the evaluated frame (serial: chain end in the left mount's
    frame; H4: nacelle point in the base frame). errors: (N, 6) pose errors [m, rad] (model - truth).
    criteria: kind-specific figures (H4: V1_rad, V2_rad, V3_m of the paper, §6.1)."""

    positions_m: np.ndarray
    errors: np.ndarray
    criteria: dict = field(default_factory=dict)

    @property
    def position_errors_mm(self) -> np.ndarray:
        """(N,) norm of the position error [mm]."""
        return np.linalg.norm(self.errors[:, :3], axis=1) * 1e3

    @property
    def position_rms_registered_mm(self) -> float:
        """Position RMS [mm] left after the best rigid transform of the model's positions onto the true ones
        (Kabsch, over the N poses): the error a registration of the robot's frame cannot remove. It differs from
        ``position_rms_mm`` when the model places its base frame elsewhere than the truth's convention does
        (e.g. an H4 model 12 identified on a model-31 robot, whose base frame is fixed by its first motor). NaN
        with fewer than 3 poses."""
        P_true = np.asarray(self.positions_m, float)
        if len(P_true) < 3:
            return float("nan")
        P = P_true + self.errors[:, :3]
        pc, qc = P.mean(axis=0), P_true.mean(axis=0)
        R = nearest_rotation((P_true - qc).T @ (P - pc))  # Kabsch: the rotation taking P - pc onto P_true - qc
        aligned = (P - pc) @ R.T + qc
        return float(np.sqrt(np.mean(np.sum((aligned - P_true) ** 2, axis=1)))) * 1e3

    def __getitem__(self, key: str) -> float:
        """One figure of :meth:`to_dict`, e.g. ``evaluation["position_rms_mm"]``."""
        return self.to_dict()[key]

    def to_dict(self) -> dict:
        """{position_rms_mm, position_max_mm, rotation_rms_deg, rotation_max_deg, n_poses,
        position_rms_registered_mm, *criteria}."""
        dp = self.position_errors_mm
        dr = np.degrees(np.linalg.norm(self.errors[:, 3:], axis=1))
        return {
            "position_rms_mm": float(np.sqrt(np.mean(dp**2))),
            "position_max_mm": float(dp.max()),
            "rotation_rms_deg": float(np.sqrt(np.mean(dr**2))),
            "rotation_max_deg": float(dr.max()),
            "n_poses": int(len(self.errors)),
            "position_rms_registered_mm": self.position_rms_registered_mm,
            **{k: float(v) for k, v in self.criteria.items()},
        }


@runtime_checkable
class ChainMeasured(Protocol):
    """Optional capability of a setup: a robot commanded by joint sets whose camera measures one transform of its
    chain (serial, URDF); measured-pose files (``io.measured_poses``) need it.
    ``chain_measurements(meas) -> Measurements``: the measurements in the chain's direction."""

    def chain_measurements(self, meas: Measurements) -> Measurements: ...


@runtime_checkable
class ModelVariants(Protocol):
    """Optional capability of a setup: model variants rebuilt from the robot file (H4: paper table 2, model
    "12" | "31"); study cells (``variant``, ``model``) and unmodelled truths ask for them.
    ``with_variant(variant, model) -> Setup``; ConfigError when the pair is impossible."""

    def with_variant(self, variant: str | None = None, model: str | None = None) -> "Setup": ...


@runtime_checkable
class NamedConfigurations(Protocol):
    """Optional capability of a setup: named joint sets of the robot file (scene ``poses.kind: configurations``).
    ``configurations() -> {name: {"q": (N, n_joints) rad, ...}}``."""

    def configurations(self) -> dict: ...


@runtime_checkable
class NamedTrials(Protocol):
    """Optional capability of a setup: named deviation vectors of the robot file (scene ``truth.trial``, study
    ``trial`` axis). ``trials() -> {name: {"deviation": {param: value (SI)}, "configurations": name (optional),
    "reported": {...} (optional)}}``."""

    def trials(self) -> dict: ...


@runtime_checkable
class PoseGrids(Protocol):
    """Optional capability of a setup: named grids of commanded poses (scene ``poses.kind``), e.g. the H4 81-pose
    grid. ``pose_grids``: their names; ``pose_grid(name) -> (N, .)`` commanded poses (ConfigError for another
    name)."""

    pose_grids: tuple[str, ...]

    def pose_grid(self, name: str) -> np.ndarray: ...


def pose_grid_names(setup: "Setup") -> tuple[str, ...]:
    """The names of the setup's pose grids (:class:`PoseGrids`), () without the capability."""
    return tuple(setup.pose_grids) if isinstance(setup, PoseGrids) else ()


@runtime_checkable
class TiltsFromAxis(Protocol):
    """Optional capability of a setup: camera and target mounts with small tilts that the rotation axis of the
    moving part measures before identification (H4, paper §4.1); ``experiment.prepare.prepare_setup`` runs that
    step and decides what to do with the estimate. The kind only describes what it needs:

    - ``tilt_mode``: "identify" (the axis estimate as a prior of identified tilt parameters), "axis" (tilts fixed
      at the estimate) or "off" (nominal tilts kept);
    - ``tilt_names``: the names of the 4 tilt parameters (camera x/y, target x/y) [rad];
    - ``tilt_reference() -> (R_BC0, R_ME0)`` (3, 3) each: the nominal mount rotations the tilts are relative to
      (what ``identify.camera_axis.estimate_camera_axis`` measures against);
    - ``with_tilts(tilts_rad (4,), prior_std_rad (4,) | None) -> Setup``: the setup with the tilt parameters at
      ``tilts_rad``, free with that prior std, or fixed (None)."""

    tilt_mode: str
    tilt_names: tuple[str, ...]

    def tilt_reference(self) -> tuple[np.ndarray, np.ndarray]: ...

    def with_tilts(self, tilts_rad: ArrayLike, prior_std_rad: ArrayLike | None = None) -> "Setup": ...


@runtime_checkable
class ArmFrames(Protocol):
    """Optional capability of a setup: a serial arm whose links the planner checks for collisions
    (``vision_calib.planning``). ``link_frames(poses, x=None) -> (N, n_joints + 2, 4, 4)`` [m] in the robot base
    frame: the base, the frame after each movable joint 1..n-1 (origin on its axis), the tip link (flange) and the
    right mount (camera or target on the flange), at parameters x (default nominal); ``link_names() -> tuple`` of
    the n_joints + 2 names of those frames (URDF link names for a URDF robot); ``robot_name``: the robot file's
    robot name; ``robot_file``: its path."""

    robot_name: str
    robot_file: str

    def link_frames(self, poses: ArrayLike, x: ArrayLike | None = None) -> np.ndarray: ...

    def link_names(self) -> tuple[str, ...]: ...


@dataclass(frozen=True)
class Setup:
    """Common interface of every robot kind (see the module docstring). ``params`` is the full
    parameter set (robot + mounts) with the scene's free mask; ``mount`` says where the camera is
    (``eye_in_hand`` | ``fixed`` | ``base``); ``meta``: kind-specific facts for reports."""

    name: str
    params: ParameterSet
    camera: CameraIntrinsics | None
    mount: str
    meta: dict = field(default_factory=dict, compare=False, repr=False)

    kind: ClassVar[str] = "abstract"
    #: residual kinds the kind's problem builder accepts; the first is the default
    residuals: ClassVar[tuple[str, ...]] = ()
    #: identification methods; the first is the default
    methods: ClassVar[tuple[str, ...]] = ("lse", "ekf")
    #: {method: the method that checks it}: two methods minimising different residuals of the same data
    #: (``experiment.steps.identify_measurements`` runs both and compares them, ``identify.method_check``;
    #: needs :meth:`noise_response`). Empty: methods of one residual, no check.
    cross_methods: ClassVar[dict] = {}
    #: top-level scene keys of this kind (besides ``rig.scene.TOP_KEYS``) and ``poses`` keys of its random poses
    scene_keys: ClassVar[tuple[str, ...]] = ()
    pose_keys: ClassVar[tuple[str, ...]] = ()
    #: scene ``truth`` keys describing errors the model does not share (see :meth:`truth_model`)
    truth_keys: ClassVar[tuple[str, ...]] = ()
    #: criteria of :meth:`evaluate` computed from validation measurements (H4: V1_rad, V2_rad); none: the
    #: pipelines need not measure the validation poses
    measured_criteria: ClassVar[tuple[str, ...]] = ()
    #: what :meth:`reachable` checks, in words (the planner's notes)
    reach_check: ClassVar[str] = "nothing"

    # ------------------------------------------------------------------ to implement
    @property
    def n_joints(self) -> int:
        raise NotImplementedError

    def T_cam_target(self, poses: ArrayLike, x: ArrayLike) -> np.ndarray:
        """(N, 4, 4) camera pose of the target for commanded poses under parameters x (n,)."""
        raise NotImplementedError

    def joints(self, poses: ArrayLike, x: ArrayLike) -> np.ndarray:
        """(N, n_joints) rad: the joint readings of commanded poses under parameters x."""
        raise NotImplementedError

    def problem(self, meas: Measurements, residual: str | None = None,
                params: ParameterSet | None = None) -> IdentificationProblem:
        """Identification problem of measurements (free mask of ``params``, default the setup's)."""
        raise NotImplementedError

    def evaluate(self, x: ArrayLike, x_true: ArrayLike, validation: ArrayLike, measurements: Measurements | None = None,
                 truth: "Setup | None" = None) -> Evaluation:
        """Accuracy of parameters x (n,) on validation poses against the true robot (``truth`` setup with
        parameters x_true; default this setup). measurements: validation measurements, for criteria
        that need them (H4 V1/V2)."""
        raise NotImplementedError

    def sample_poses(self, rng: np.random.Generator, n: int, check_view: bool = True) -> np.ndarray:
        """n random commanded poses (with check_view: only poses where the target is in view)."""
        raise NotImplementedError

    def model_dict(self) -> dict:
        """Kind-specific part of the calibrated-model file (what :func:`registry.load_model` needs to
        rebuild the robot besides the parameter values)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ optional, with defaults
    def truth_model(self, spec: dict, rng: np.random.Generator, where: str = "truth") -> "Setup":
        """The setup of a true robot with errors this model does not share (``spec``: the scene's
        ``truth`` entries of :attr:`truth_keys`); its parameters are drawn by the caller. Default: none."""
        if spec:
            raise ConfigError(f"{where}: {', '.join(spec)}: this {self.kind} setup has no unmodelled truth options")
        return self

    def predict_from_joints(self, joints: ArrayLike, x: ArrayLike) -> np.ndarray:
        """(N, 4, 4) T_cam_target the model with parameters x predicts from joint readings (N, n_joints)
        rad. Default: commanded poses are joint sets (serial kinds)."""
        return self.T_cam_target(joints, x)

    def generic_poses(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n varied commanded poses for the structural identifiability of the kind (no view check)."""
        return self.sample_poses(rng, n, check_view=False)

    def commanded_from_joints(self, joints: ArrayLike, x: ArrayLike | None = None) -> np.ndarray:
        """Commanded poses (N, .) that joint values (N, n_joints) rad command under parameters x (default nominal):
        the inverse of :meth:`joints`. Default: commanded poses are joint sets (serial kinds)."""
        return np.array(joints, float)

    def reachable(self, poses: ArrayLike, x: ArrayLike | None = None) -> np.ndarray:
        """(N,) bool: the robot can take each commanded pose under parameters x (default nominal). Default: all
        (kinds add joint limits, closure of the inverse model...)."""
        return np.ones(len(np.asarray(poses)), dtype=bool)

    def end_point(self, poses: ArrayLike, x: ArrayLike | None = None) -> np.ndarray:
        """(N, 3) [m] position of the robot's end (serial: the flange; H4: the nacelle point) in the robot base
        frame, at parameters x (default nominal): what a workspace box of the planner bounds."""
        raise NotImplementedError(f"{self.kind} setups give no end point")

    def export_model_files(self, out_dir: str | Path, x: ArrayLike) -> dict:
        """Write kind-specific calibrated-model files (e.g. a URDF) into out_dir for parameters x (n,);
        returns {file kind: file name}. Default: none (``calibrated_model.yaml`` is written for every kind)."""
        return {}

    def check_joints(self, q: ArrayLike, where: str, ids: Sequence | None = None) -> None:
        """DataError naming ``where``, the pose id and the joint when joint readings q (N, n) rad have the
        wrong width or a non-finite value (kinds add their own range checks)."""
        q = np.asarray(q, float)
        if q.ndim != 2 or q.shape[1] != self.n_joints:
            raise DataError(f"{where}: {q.shape[-1] if q.ndim else 0} joint columns, the robot has "
                            f"{self.n_joints}")
        bad = np.argwhere(~np.isfinite(q))
        if bad.size:
            k, j = (int(v) for v in bad[0])
            pid = list(ids)[k] if ids is not None else k
            raise DataError(f"{where}: pose {pid!r} joint q{j + 1} is not finite ({q[k, j]})")

    def joint_names(self) -> tuple[str, ...]:
        """Names of the joints in the order of the joint columns (what a ROS ``JointState`` calls them):
        ``q1..qn`` by default; kinds whose robot file names its joints (URDF) give those names."""
        return tuple(f"q{j + 1}" for j in range(self.n_joints))

    def is_mount_parameter(self, name: str) -> bool:
        """Whether parameter ``name`` belongs to a mounting transform (camera, target, base frame: what a robot
        that is exactly nominal still needs calibrated), by the naming convention of DESIGN.md: a transform's
        name before the dot (``T_flange_cam.tx``, ``B_T_C.theta``, ``M_T_E.tilt_x``); kinds with other names
        override it."""
        return bool(_MOUNT_NAME.search(name.split(".", 1)[0])) if "." in name else False

    def fixed_note(self, name: str) -> str:
        """Why parameter ``name`` is fixed (for tables)."""
        return "fixed (not free in the scene)"

    def with_params(self, params: ParameterSet) -> "Setup":
        """Same setup, other parameter set (free mask / nominal values)."""
        return replace(self, params=params)

    def with_camera(self, camera: CameraIntrinsics) -> "Setup":
        return replace(self, camera=camera)

    # ------------------------------------------------------------------ shared
    def synthetic_measurements(self, poses: ArrayLike, x_true: ArrayLike, rng: np.random.Generator,
                               sigma_t_m: float = 0.0, sigma_r_rad: float = 0.0, sigma_q_rad: float = 0.0,
                               labels: Sequence[str] | None = None, pose_cov: ArrayLike | None = None) -> Measurements:
        """Noise-free T_cam_target of the true robot ⊕ Gaussian noise (camera frame): independent per
        component (sigma_t_m, sigma_r_rad), or, with ``pose_cov`` (N, 6, 6), drawn from each pose's own
        covariance (``pose_noise``; the measurements then carry that covariance)."""
        poses = np.asarray(poses, float)
        T = self.T_cam_target(poses, x_true)
        n = len(T)
        if pose_cov is None:
            d = np.concatenate([rng.normal(scale=sigma_t_m, size=(n, 3)), rng.normal(scale=sigma_r_rad, size=(n, 3))],
                               axis=1)
            cov = pose_cov_from_sigmas(n, sigma_t_m, sigma_r_rad)
        else:
            cov = np.array(pose_cov, float)
            if cov.shape != (n, 6, 6):
                raise DataError(f"{self.name}: pose_cov has shape {cov.shape}, expected ({n}, 6, 6) for {n} poses")
            d = pose_noise(rng, cov)
        q = self.joints(poses, x_true)
        if sigma_q_rad > 0:
            q = q + rng.normal(scale=sigma_q_rad, size=q.shape)
        labels = tuple(labels) if labels is not None else tuple(f"p{i:03d}" for i in range(n))
        return Measurements(poses, q, F.perturb_pose(T, d), cov, labels)

    def visible(self, T_cam_target: np.ndarray, target_outline_m: ArrayLike, margin_px: float = 10.0,
                max_tilt_deg: float = 60.0) -> np.ndarray:
        """(N,) bool: the whole target outline (K, 3) [m, target frame] projects inside the image
        with ``margin_px``, in front of the camera, and the board normal is within max_tilt_deg of
        the viewing ray."""
        cam = self.camera
        T = np.asarray(T_cam_target, float).reshape(-1, 4, 4)
        P = np.asarray(target_outline_m, float)
        p = P @ np.swapaxes(T[:, :3, :3], 1, 2) + T[:, None, :3, 3]  # (N, K, 3), all poses at once
        front = np.all(p[:, :, 2] > 0.05, axis=1)
        ok = np.zeros(len(T), dtype=bool)
        if not front.any():
            return ok
        q = p[front]
        uv = cam.project(q.reshape(-1, 3)).reshape(q.shape[0], -1, 2)
        inside = np.all((uv[..., 0] >= margin_px) & (uv[..., 0] <= cam.width - 1 - margin_px)
                        & (uv[..., 1] >= margin_px) & (uv[..., 1] <= cam.height - 1 - margin_px), axis=1)
        centre = q.mean(axis=1)
        cosang = np.abs(np.einsum("ni,ni->n", T[front, :3, 2], centre)) / np.linalg.norm(centre, axis=1)
        ok[front] = inside & (cosang >= np.cos(np.radians(max_tilt_deg)))
        return ok

    def residual_for(self, method: str, residual: str | None = None) -> str:
        """The residual kind ``method`` minimises (default: ``residual``, checked by :meth:`check_residual`;
        kinds whose methods differ by their residual, e.g. H4, override it)."""
        return self.check_residual(residual)

    def noise_response(self, meas: Measurements, residual: str, params: ParameterSet, x: ArrayLike) -> tuple:
        """(B (N, m, K), cov_e (N, K, K)): first-order response d r / d e at parameters x (n,) of the
        ``residual`` of :meth:`problem` (``params``) to the raw measurement errors e of each pose, and their
        covariance; what ``identify.method_check`` needs for :attr:`cross_methods`."""
        raise NotImplementedError(f"{self.kind} setups give no noise response")

    def check_residual(self, residual: str | None) -> str:
        """The residual kind to use (default: the kind's first); DataError if the kind has no such residual."""
        residual = residual or self.residuals[0]
        if residual not in self.residuals:
            raise DataError(f"{self.kind} setups use {' or '.join(repr(r) for r in self.residuals)} residuals, "
                            f"not {residual!r}")
        return residual
