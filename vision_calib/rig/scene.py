"""Scene files (``scenes/*.yaml``): robot + camera + target + truth + poses + identification,
loaded ONCE into typed settings in SI units.

Schema (lengths/angles in the scene's ``units``, default m and deg; keys with a unit suffix are in
that unit). Unknown keys are errors (with the closest known key suggested)::

    name: h4_vision
    robot: robots/h4.yaml            # robot file, relative to the scene file; its kind (rig.registry)
                                     # decides which kind-specific keys below apply
    mount: base | eye_in_hand | fixed
    units: {length: m, angle: deg}
    camera: {width, height, fx, fy, cx, cy, dist}  or  {width, height, focal_mm, pixel_um, dist}
    target: ../targets/charuco_h4.yaml
    effects: {noise_grey: 2.0, blur_px: 0.6, ...}   # sensor effects (vision_calib.sensor.SensorEffects)
    render: {supersample: 2}         # anti-aliasing: render at s x resolution, box-average
    truth: {seed: 1, sigma_length_mm: 0.5, sigma_angle_deg: 0.05, deviations: {name: value}, trial: name}
    poses: {kind: random | configurations | file | <grid of the kind>, count: 81, configurations: name, ...}
                                     # file: {kind: file, path: poses.csv, units: {angle: deg}} (rig.pose_file)
    validation: {kind: random | configurations, count: 50, configurations: name}
    measurement: {frames: 10, averaging: corners|poses, sigma_mm: 0.2, sigma_deg: 0.03, sigma_q_deg: 0}
    identification: {method: ..., residual: ..., fix: [names], free: [names]}
    obstacles: [{kind: plane | box | cylinder | sphere, ...}]   # the cell, for the planner (rig.cell)
    planning: {clearance: 0.02, distance: [0.2, 1.5], max_incidence: 50, ...}  # the planner's settings (rig.cell)
    # kind-specific keys: serial: mounts, poses.center, poses.spread; h4: model, variant

``measurement.sigma_mm`` / ``sigma_deg`` are the pose noise of the *synthetic* (no image) mode; image
runs measure their noise.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ..camera import CameraIntrinsics
from ..config import Section, load_yaml, transform_from
from ..errors import ConfigError, ParameterError
from ..shipped import scenes_dir, shipped_path
from ..kinematics.params import ParameterSet
from .base import ArmFrames, NamedConfigurations, NamedTrials, PoseGrids, Setup, pose_grid_names
from .cell import Obstacle, PlanningSettings, read_obstacles, read_planning
from .registry import kind_of_robot_file

if TYPE_CHECKING:  # annotations only
    from ..sensor.settings import SensorEffects
    from ..targets.kinds.base import TargetSpec

SCENES_DIR = scenes_dir()  # the installed package's shipped scenes (package data)
TOP_KEYS = ("name", "robot", "mount", "units", "camera", "target", "effects", "render", "truth", "poses",
            "validation", "measurement", "identification", "obstacles", "planning")
#: scene effect names -> SensorEffects field names (short forms accepted in scenes and studies)
EFFECT_ALIASES = {"noise_grey": "read_noise_grey", "blur_px": "blur_sigma_px"}


@dataclass(frozen=True)
class TruthSettings:
    """How the true robot is drawn: seed, random deviation std per parameter kind [m, rad], explicit
    deviations {name: SI value}, or a robot-file ``trial`` (its deviation vector replaces the draw)."""

    seed: int = 0
    sigma_length_m: float = 0.5e-3
    sigma_angle_rad: float = float(np.radians(0.05))
    deviations: dict = field(default_factory=dict)
    trial: str | None = None
    #: errors of the true robot that the identified model does not have (kind-specific keys, ``Setup.truth_keys``,
    #: e.g. H4 ``model: "31"`` and ``tilt_deg``): the truth is then another setup (``Setup.truth_model``)
    unmodelled: dict = field(default_factory=dict)


@dataclass(frozen=True)
class PoseSettings:
    """A pose set: ``kind`` random | configurations | file | a pose grid of the robot kind; ``count`` poses
    (None: all of a grid / set / file); ``configurations``: the robot file's named joint set; ``path``: the joint
    file of kind ``file`` (:mod:`.pose_file`), read with ``angle_factor`` to rad (``units_from``: where that unit
    came from)."""

    kind: str = "random"
    count: int | None = None
    configurations: str | None = None
    path: Path | None = None
    angle_factor: float = 1.0
    units_from: str = ""


@dataclass(frozen=True)
class MeasurementSettings:
    """frames per pose, frame averaging mode, synthetic pose noise per component [m, rad] and joint
    reading noise [rad]."""

    frames: int = 10
    averaging: str = "corners"
    sigma_t_m: float = 0.2e-3
    sigma_r_rad: float = float(np.radians(0.03))
    sigma_q_rad: float = 0.0


@dataclass(frozen=True)
class IdentificationSettings:
    method: str
    residual: str


@dataclass(frozen=True)
class SceneContext:
    """What a robot kind's ``from_scene`` gets: the scene file's top Section, the common settings
    already read, and helpers for kind-specific keys."""

    top: Section
    name: str
    mount: str
    robot_path: Path
    camera: CameraIntrinsics | None
    target: TargetSpec | None
    Lf: float
    Af: float
    sigma_q_rad: float

    @property
    def ident(self) -> Section:
        return self.top.section("identification", default={})

    @property
    def fixed_names(self) -> list[str]:
        return [str(n) for n in self.ident.get("fix", list, [])]

    def apply_free(self, params: ParameterSet) -> ParameterSet:
        """params with the scene's ``identification.free`` (only these) then ``fix`` applied."""
        free = self.ident.get("free", list, None)
        try:
            if free is not None:
                params = params.only_free([str(n) for n in free])
            if self.fixed_names:
                params = params.fix(self.fixed_names)
        except ParameterError as exc:
            raise self.ident.error("free" if free is not None else "fix", str(exc)) from None
        return params

    def xyz_rpy(self, sec: Section, key: str) -> np.ndarray:
        """(4, 4) transform of ``sec[key] = {xyz: [..], rpy: [..]}`` or ``{xyz: [..], quat: [qx, qy, qz, qw]}``
        in the scene's units (:func:`vision_calib.config.transform_from`)."""
        return transform_from(sec.section(key), self.Lf, self.Af)


@dataclass(frozen=True)
class Scene:
    """A loaded scene: the setup (robot/camera model with the scene's free mask) and typed settings in
    SI units. ``effects``: sensor.SensorEffects. ``raw``: the file's mapping (for hashing only)."""

    path: Path
    name: str
    setup: Setup
    target_path: Path | None
    effects: SensorEffects
    truth: TruthSettings
    poses: PoseSettings
    validation: PoseSettings
    measurement: MeasurementSettings
    identification: IdentificationSettings
    supersample: int = 2
    raw: dict = field(repr=False, default_factory=dict)
    #: the cell's static obstacles (robot base frame) and the planner's settings (:mod:`.cell`)
    obstacles: tuple[Obstacle, ...] = ()
    planning: PlanningSettings = field(default_factory=PlanningSettings)

    @property
    def kind(self) -> str:
        return self.setup.kind

    def with_setup(self, setup: Setup) -> "Scene":
        """Same scene, other setup; truth deviations of names the new setup lacks are dropped."""
        devs = {k: v for k, v in self.truth.deviations.items() if k in setup.params.names}
        return replace(self, setup=setup, truth=replace(self.truth, deviations=devs))


def _camera(sec: Section | None) -> CameraIntrinsics | None:
    if sec is None:
        return None
    if "focal_mm" in sec:
        sec.check_known(("width", "height", "focal_mm", "pixel_um", "dist"))
        cam = CameraIntrinsics.from_focal_mm(sec.get("width", int), sec.get("height", int), sec.positive("focal_mm"),
                                             sec.positive("pixel_um"))
        d = sec.floats("dist", 5, np.zeros(5))
        return CameraIntrinsics(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, tuple(float(v) for v in d))
    sec.check_known(("width", "height", "fx", "fy", "cx", "cy", "dist"))
    return CameraIntrinsics.from_dict(sec.data, where=sec.where())


def _effects(sec: Section):
    from ..sensor.settings import SensorEffects

    d = {EFFECT_ALIASES.get(k, k): v for k, v in sec.data.items()}
    return SensorEffects.from_dict(d, where=sec.where())


def _pose_settings(sec: Section, kinds, extra_keys=(), Lf: float = 1.0, Af: float = 1.0) -> PoseSettings:
    kind = sec.get("kind", str, "random", choices=kinds)
    if kind == "file":
        from .pose_file import pose_file_units

        sec.check_known(("kind", "count", "path", "units") + tuple(extra_keys))  # kind keys: the random region
        path = sec.path_value("path")
        if not path.is_file():
            raise sec.error("path", f"not a file: {path} (a poses.csv: pose_id,q1..qn)")
        _, af, where = pose_file_units(path, Lf, Af, sec.section("units") if "units" in sec else None)
        return PoseSettings(kind=kind, count=sec.positive("count", int, None), path=path, angle_factor=af,
                            units_from=where)
    sec.check_known(("kind", "count", "configurations") + tuple(extra_keys))
    return PoseSettings(kind=kind, count=sec.positive("count", int, None),
                        configurations=sec.get("configurations", str, None))


def _measurement(sec: Section) -> MeasurementSettings:
    sec.check_known(("frames", "averaging", "sigma_mm", "sigma_deg", "sigma_q_deg"))
    return MeasurementSettings(
        frames=sec.positive("frames", int, 10),
        averaging=sec.get("averaging", str, "corners", choices=("corners", "poses")),
        sigma_t_m=sec.nonnegative("sigma_mm", float, 0.2) * 1e-3,
        sigma_r_rad=float(np.radians(sec.nonnegative("sigma_deg", float, 0.03))),
        sigma_q_rad=float(np.radians(sec.nonnegative("sigma_q_deg", float, 0.0))),
    )


def _truth(sec: Section, setup: Setup, Lf: float, Af: float) -> TruthSettings:
    sec.check_known(("seed", "sigma_length_mm", "sigma_angle_deg", "deviations", "trial") + tuple(setup.truth_keys))
    unmodelled = {k: sec.data[k] for k in setup.truth_keys if sec.data.get(k) is not None}
    if unmodelled:
        setup.truth_model(unmodelled, np.random.default_rng(0), where=sec.where())  # validate now
    devs = {}
    dsec = sec.section("deviations", default={})
    for k in dsec.keys():
        try:
            i = setup.params.index(str(k))
        except ParameterError as exc:
            raise dsec.error(str(k), str(exc)) from None
        devs[str(k)] = dsec.get(k, float) * (Lf if setup.params.kinds[i] == "length" else Af)
    trial = sec.get("trial", str, None)
    trials = setup.trials() if isinstance(setup, NamedTrials) else {}
    if trial is not None and trial not in trials:
        raise sec.error("trial", f"unknown trial {trial!r} (robot file has {sorted(trials) or 'no trials'})")
    return TruthSettings(seed=sec.nonnegative("seed", int, 0),
                         sigma_length_m=sec.nonnegative("sigma_length_mm", float, 0.5) * 1e-3,
                         sigma_angle_rad=float(np.radians(sec.nonnegative("sigma_angle_deg", float, 0.05))),
                         deviations=devs, trial=trial, unmodelled=unmodelled)


def load_scene(path: str | Path) -> Scene:
    """Load and validate a scene file; ConfigError naming the file and key on bad input."""
    path = shipped_path(path)  # a shipped scene by its name (``h4_vision.yaml``, ``scenes/h4_vision.yaml``)
    return scene_from_section(Section(load_yaml(path), path))


def scene_from_section(top: Section) -> Scene:
    """The scene of a mapping (a scene file's top, or a scene written inside another file, e.g. a measured-pose
    file's ``scene:``; paths relative to ``top.file``, errors naming its keys); ``Scene.path`` is ``top.file``."""
    path = top.file
    robot_path = top.path_value("robot")
    kind = kind_of_robot_file(robot_path, where=top.where("robot"))
    top.check_known(TOP_KEYS + tuple(kind.scene_keys))
    name = top.get("name", str, path.stem if not top.path else Path(robot_path).stem)
    Lf, Af = top.units(default_length="m", default_angle="deg")
    mount = top.get("mount", str, choices=kind.mounts)
    camera = _camera(top.section("camera") if "camera" in top else None)
    target_path = top.path_value("target", None)
    target = None
    if target_path is not None:
        from ..targets import load_target

        target = load_target(target_path)
    measurement = _measurement(top.section("measurement", default={}))
    rs = top.section("render", default={}).check_known(("supersample",))
    ctx = SceneContext(top, name, mount, robot_path, camera, target, Lf, Af, measurement.sigma_q_rad)
    setup = kind.from_scene(ctx)
    ident = top.section("identification", default={}).check_known(("method", "residual", "fix", "free"))
    method = ident.get("method", str, kind.methods[0], choices=kind.methods)
    residual = ident.get("residual", str, kind.residuals[0], choices=kind.residuals)
    if setup.residual_for(method, residual) != residual:  # a kind whose methods decide the residual (H4)
        if ident.data.get("residual") is not None:
            raise ident.error("residual", f"method {method!r} minimises {setup.residual_for(method, residual)!r} "
                                          f"residuals, not {residual!r} (leave residual out)")
        residual = setup.residual_for(method, residual)
    pose_kinds = ("random", "configurations", "file") + pose_grid_names(setup)
    arm = isinstance(setup, ArmFrames)
    return Scene(
        path=path, name=name, setup=setup, target_path=target_path,
        effects=_effects(top.section("effects", default={})),
        truth=_truth(top.section("truth", default={}), setup, Lf, Af),
        poses=_pose_settings(top.section("poses", default={}), pose_kinds, kind.pose_keys, Lf, Af),
        validation=_pose_settings(top.section("validation", default={}), ("random", "configurations")),
        measurement=measurement, identification=IdentificationSettings(method, residual),
        supersample=rs.positive("supersample", int, 2), raw=top.data,
        obstacles=read_obstacles(top, Lf, Af, arm, setup.kind),
        planning=read_planning(top, Lf, Af, setup.n_joints if arm else None, setup.kind),
    )


def scene_poses(scene: Scene, rng: np.random.Generator, n: int | None = None, which: str = "poses") -> np.ndarray:
    """Commanded poses of a scene: identification poses (``which="poses"``) or validation poses."""
    spec = scene.poses if which == "poses" else scene.validation
    setup = scene.setup
    if n is not None and int(n) < 1:
        raise ConfigError(f"{scene.path}: asked for {n} {which}: need at least 1")
    n = n or spec.count
    if isinstance(setup, PoseGrids) and spec.kind in setup.pose_grids:
        X = setup.pose_grid(spec.kind)
        if n is not None and n > len(X):
            raise ConfigError(f"{scene.path}: {which}: {n} poses asked, the grid has {len(X)}")
        if n is not None and n < len(X):
            X = X[np.sort(rng.choice(len(X), size=n, replace=False))]
        return X
    if spec.kind == "configurations":
        confs = setup.configurations() if isinstance(setup, NamedConfigurations) else {}
        if spec.configurations not in confs:
            raise ConfigError(f"{scene.path}: {which}.configurations: unknown set {spec.configurations!r} "
                              f"(robot file has {sorted(confs)})")
        q = confs[spec.configurations]["q"]
        if n is not None and n > len(q):
            raise ConfigError(f"{scene.path}: {which}: {n} poses asked, configuration set "
                              f"{spec.configurations!r} has {len(q)}")
        return q if n is None else q[:n]
    if spec.kind == "file":
        return file_poses(scene, n, which)
    # validation poses are evaluated through the kinematics only: they need not see the target
    return setup.sample_poses(rng, n or 30, check_view=(which == "poses"))


def file_poses(scene: Scene, n: int | None = None, which: str = "poses") -> np.ndarray:
    """Commanded poses of the scene's pose file (``poses: {kind: file}``): its joint sets, checked against the
    robot (joint count, limits), mapped to commanded poses by the nominal model (``Setup.commanded_from_joints``:
    the same joints for a serial arm, the forward model for the H4); the first n when n is given."""
    from .pose_file import read_joint_file

    spec = scene.poses
    setup = scene.setup
    ids, q = read_joint_file(spec.path, setup.n_joints, spec.angle_factor)
    setup.check_joints(q, f"{spec.path} (angles read with {spec.units_from})", ids)
    if n is not None and n > len(q):
        raise ConfigError(f"{scene.path}: {which}: {n} poses asked, the pose file {spec.path} has {len(q)}")
    q = q if n is None else q[:n]
    return setup.commanded_from_joints(q)


def true_parameters(scene: Scene, rng: np.random.Generator, base_free: ArrayLike | None = None) -> np.ndarray:
    """Truth x_true (n,) = nominal + deviations. Seeded random deviations (sigma by kind) on the
    parameters that are free and identifiable (``base_free`` mask; default the scene's free mask),
    unless the scene names a robot-file trial (its deviation vector replaces the random draw);
    the scene's explicit ``truth.deviations`` are applied last."""
    ps = scene.setup.params
    x = ps.nominal.copy()
    mask = ps.free if base_free is None else np.asarray(base_free, bool)
    sig = np.where(np.array(ps.kinds) == "length", scene.truth.sigma_length_m, scene.truth.sigma_angle_rad)
    x[mask] += rng.normal(size=int(mask.sum())) * sig[mask]
    devs = dict(scene.truth.deviations)
    if scene.truth.trial:
        devs.update(scene.setup.trials()[scene.truth.trial].get("deviation", {}))  # checked NamedTrials on load
        x = ps.nominal.copy()  # a given deviation vector replaces the random draw
    for k, v in devs.items():
        x[ps.index(k)] = ps.nominal[ps.index(k)] + v
    return x
