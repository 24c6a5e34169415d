"""Scene files (``scenes/*.yaml``): robot + camera + target + truth + poses + identification.

Schema (lengths/angles in the scene's ``units``, default m and deg; keys with a unit suffix are
in that unit)::

    name: h4_vision
    robot: robots/h4.yaml            # robot file, relative to the scene file
    mount: base | eye_in_hand | fixed   # fixed: also a robot file with T_world_base/T_flange_tool mounts
                                     # (a fixed device in the world frame measuring the tool frame)
    units: {length: m, angle: deg}
    model: "12"                      # H4 only: "12" | "31"
    variant: D                       # H4 only: A..H (paper table 2), optional
    mounts:                          # serial only (nominal camera/target mounting)
      target_in_base: {xyz: [..], rpy: [..]}   # eye_in_hand: T_base_target
      camera_in_flange: {xyz: [..], rpy: [..]} # eye_in_hand: T_flange_cam
      camera_in_base: {...}                    # fixed: T_base_cam
      target_in_flange: {...}                  # fixed: T_flange_target
    camera: {width, height, fx, fy, cx, cy, dist}  or  {width, height, focal_mm, pixel_um, dist}
    target: ../targets/charuco_h4.yaml
    effects: {noise_grey: 2.0, blur_px: 0.6, ...}   # sensor effects (see vision_calib.sensor)
    render: {supersample: 3}         # anti-aliasing: render at s x resolution, box-average
    truth: {seed: 1, sigma_length_mm: 0.5, sigma_angle_deg: 0.05, deviations: {name: value}, trial: name,
            perturb: base|free}
    poses: {kind: grid81 | random | configurations, count: 81, center: [..], spread: [..], configurations: name}
    validation: {kind: random | configurations, count: 50, seed_offset: 1000}
    measurement: {frames: 10, averaging: corners|poses, sigma_mm: 0.2, sigma_deg: 0.03, sigma_q_deg: 0}
    identification: {method: lse|ekf|igm, residual: pose|position|joint, fix: [names], free: [names]}
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import frames as F
from ..camera import CameraIntrinsics
from ..config import ANGLE_UNITS, LENGTH_UNITS, Section, load_yaml
from ..errors import ConfigError, ParameterError
from .setup import H4Setup, SerialSetup, Setup

SCENES_DIR = Path(__file__).resolve().parents[2] / "scenes"


@dataclass(frozen=True)
class Scene:
    """A loaded scene. ``setup``: the robot/camera model with the scene's free mask.
    The other fields are validated plain settings in SI units."""

    path: Path
    name: str
    setup: Setup
    target_path: Path | None
    effects: dict
    truth: dict
    poses: dict
    validation: dict
    measurement: dict
    identification: dict
    render: dict = field(default_factory=lambda: {"supersample": 2})
    raw: dict = field(repr=False, default_factory=dict)

    @property
    def kind(self) -> str:
        return self.setup.kind


def _xyz_rpy(sec: Section, key: str, Lf: float, Af: float) -> np.ndarray:
    s = sec.section(key)
    vals = {}
    for k in ("xyz", "rpy"):
        v = s.get(k, list, [0.0, 0.0, 0.0])
        try:
            arr = np.asarray(v, float)
        except (TypeError, ValueError):
            raise s.error(k, f"expected 3 numbers, got {v!r}") from None
        if arr.shape != (3,) or not np.all(np.isfinite(arr)):
            raise s.error(k, f"expected 3 finite numbers, got {v!r}")
        vals[k] = arr
    return F.T_from_xyz_rpy(vals["xyz"] * Lf, vals["rpy"] * Af)


def _camera(sec: Section) -> CameraIntrinsics:
    if "focal_mm" in sec:
        cam = CameraIntrinsics.from_focal_mm(sec.get("width", int), sec.get("height", int), sec.positive("focal_mm"),
                                             sec.positive("pixel_um"))
        d = sec.floats("dist", 5, np.zeros(5))
        return CameraIntrinsics(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, tuple(float(v) for v in d))
    return CameraIntrinsics.from_dict(sec.data, where=sec.where())


def _remount(chain, left, right, T_left_base, T_flange_right):
    """Same arm, other mounting transforms (nominal), keeping the arm's free mask."""
    from ..kinematics.serial import SerialChain

    v = chain.params.values()
    n = chain.n_joints
    dh = np.array([[v[f"alpha{i}"], v[f"a{i}"], v[f"theta{i}"], v[f"d{i}"]] for i in range(1, n + 1)])
    pre_z = {i: v[f"l{i}"] for i in chain.pre_z}
    new = SerialChain.build(chain.name, dh, hayati=chain.hayati, pre_z=pre_z, left=left, right=right,
                            T_left_base=T_left_base, T_flange_right=T_flange_right,
                            joint_limits=chain.joint_limits, meta=chain.meta)
    # carry beta nominal values and free flags of the arm's own parameters
    arm = [nm for nm in chain.params.names if "." not in nm]
    ps = new.params.with_nominal({nm: v[nm] for nm in arm})
    free = ps.free.copy()
    for nm in arm:
        free[ps.index(nm)] = chain.params.free[chain.params.index(nm)]
    from dataclasses import replace

    return new.with_params(replace(ps, free=free))


def _apply_free(params, sec: Section):
    free = sec.get("free", list, None)
    fix = sec.get("fix", list, [])
    try:
        if free is not None:
            params = params.only_free([str(n) for n in free])
        if fix:
            params = params.fix([str(n) for n in fix])
    except ParameterError as exc:
        raise sec.error("free" if free is not None else "fix", str(exc)) from None
    return params


def load_scene(path) -> Scene:
    """Load and validate a scene file; ConfigError naming the file and key on bad input."""
    path = Path(path)
    if not path.exists() and not path.is_absolute() and (SCENES_DIR / path).exists():
        path = SCENES_DIR / path
    top = Section(load_yaml(path), path)
    name = top.get("name", str, path.stem)
    Lf, Af = top.units(default_length="m", default_angle="deg")
    mount = top.get("mount", str, choices=("base", "eye_in_hand", "fixed"))
    robot_path = top.path_value("robot")
    camera = _camera(top.section("camera"))
    target_path = top.path_value("target", None)
    effects = dict(top.get("effects", dict, {}))
    rs = top.section("render", default={})
    render = {"supersample": rs.positive("supersample", int, 2)}
    meas = top.section("measurement", default={})
    measurement = {
        "frames": meas.positive("frames", int, 10),
        "averaging": meas.get("averaging", str, "corners", choices=("corners", "poses")),
        "sigma_t_m": meas.nonnegative("sigma_mm", float, 0.2) * 1e-3,
        "sigma_r_rad": np.radians(meas.nonnegative("sigma_deg", float, 0.03)),
        "sigma_q_rad": np.radians(meas.nonnegative("sigma_q_deg", float, 0.0)),
    }
    ident = top.section("identification", default={})

    if mount == "base":
        from ..kinematics.h4 import load_h4_robot

        model = str(top.get("model", str, "12"))
        if model not in ("12", "31"):
            raise top.error("model", f"expected '12' or '31', got {model!r}")
        robot = load_h4_robot(robot_path, model=model)
        variant = top.get("variant", str, None)
        if variant is not None:
            try:
                robot = robot.variant(variant)
            except ParameterError as exc:
                raise top.error("variant", str(exc)) from None
        params = _apply_free(robot.params, ident)
        setup = H4Setup(name=name, params=params, camera=camera, mount=mount,
                        meta={"sigma_q_rad": measurement["sigma_q_rad"], "model": model, "variant": variant,
                              "robot_path": str(robot_path)},
                        robot=robot)
        default_method, default_residual = "igm", "joint"
    else:
        from ..kinematics.serial import load_serial_robot

        chain = load_serial_robot(robot_path)
        ms = top.section("mounts", default={})
        if mount == "eye_in_hand":
            if "target_in_base" in ms or "camera_in_flange" in ms:
                T_base_target = _xyz_rpy(ms, "target_in_base", Lf, Af)
                T_flange_cam = _xyz_rpy(ms, "camera_in_flange", Lf, Af)
                chain = _remount(chain, "T_target_base", "T_flange_cam", F.inv_T(T_base_target), T_flange_cam)
            elif chain.mount_names != ("T_target_base", "T_flange_cam"):
                raise ms.error("target_in_base", f"eye_in_hand needs mounts target_in_base and camera_in_flange "
                               f"(the robot file has {chain.mount_names})")
        else:
            if "camera_in_base" in ms or "target_in_flange" in ms:
                T_base_cam = _xyz_rpy(ms, "camera_in_base", Lf, Af)
                T_flange_target = _xyz_rpy(ms, "target_in_flange", Lf, Af)
                chain = _remount(chain, "T_cam_base", "T_flange_target", F.inv_T(T_base_cam), T_flange_target)
            elif chain.mount_names not in (("T_cam_base", "T_flange_target"), ("T_world_base", "T_flange_tool")):
                raise ms.error("camera_in_base", f"fixed camera needs mounts camera_in_base and target_in_flange "
                               f"(the robot file has {chain.mount_names})")
            # (T_world_base, T_flange_tool): a fixed measuring device (tracker, camera) whose frame is the
            # world frame, measuring the tool frame -- the thesis' chapter 3-4 setup
        params = _apply_free(chain.params, ident)
        ps = top.section("poses", default={})
        n = chain.n_joints
        center = ps.floats("center", n, np.zeros(n)) * Af
        spread = ps.floats("spread", n, np.full(n, 20.0)) * Af
        if center.shape != (n,) or spread.shape != (n,):
            raise ps.error("center", f"center and spread need {n} joint values each")
        outline = None
        if target_path is not None:
            from ..targets import load_target

            tspec = load_target(target_path)
            ids, pts = tspec.corner_points()
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            outline = np.array([[lo[0], lo[1], 0], [hi[0], lo[1], 0], [hi[0], hi[1], 0], [lo[0], hi[1], 0]], float)
        setup = SerialSetup(name=name, params=params, camera=camera, mount=mount, meta={"robot_path": str(robot_path)},
                            chain=chain.with_params(params), q_center=center, q_spread=spread, target_outline=outline)
        default_method, default_residual = "lse", "pose"

    identification = {
        "method": ident.get("method", str, default_method, choices=("lse", "ekf", "igm")),
        "residual": ident.get("residual", str, default_residual, choices=("pose", "position", "joint")),
    }
    if setup.kind == "h4" and identification["method"] == "lse":
        identification["method"] = "igm"
    tr = top.section("truth", default={})
    truth = {
        "seed": tr.nonnegative("seed", int, 0),
        "sigma_length_m": tr.get("sigma_length_mm", float, 0.5) * 1e-3,
        "sigma_angle_rad": np.radians(tr.get("sigma_angle_deg", float, 0.05)),
        "perturb": tr.get("perturb", str, "base", choices=("base", "free")),
        "deviations": {},
        "trial": tr.get("trial", str, None),
    }
    for k, v in tr.get("deviations", dict, {}).items():
        try:
            i = setup.params.index(str(k))
        except ParameterError as exc:
            raise tr.error(f"deviations.{k}", str(exc)) from None
        f = Lf if setup.params.kinds[i] == "length" else Af
        truth["deviations"][str(k)] = tr.section("deviations").get(k, float) * f
    ps = top.section("poses", default={})
    poses = {"kind": ps.get("kind", str, "random", choices=("random", "grid81", "configurations")),
             "count": ps.positive("count", int, None), "configurations": ps.get("configurations", str, None)}
    vs = top.section("validation", default={})
    validation = {"kind": vs.get("kind", str, "random", choices=("random", "configurations")),
                  "count": vs.positive("count", int, 50), "configurations": vs.get("configurations", str, None)}
    assert Lf in LENGTH_UNITS.values() and Af in ANGLE_UNITS.values()
    return Scene(path, name, setup, target_path, effects, truth, poses, validation, measurement, identification,
                 render, top.data)


def scene_poses(scene: Scene, rng: np.random.Generator, n: int | None = None, which: str = "poses") -> np.ndarray:
    """Commanded poses of a scene: identification poses (``which="poses"``) or validation poses."""
    spec = scene.poses if which == "poses" else scene.validation
    setup = scene.setup
    kind = spec["kind"]
    if n is not None and int(n) < 1:
        raise ConfigError(f"{scene.path}: asked for {n} {which}: need at least 1")
    n = n or spec.get("count")
    if kind == "grid81":
        if setup.kind != "h4":
            raise ConfigError(f"{scene.path}: {which}.kind: grid81 is the H4 pose grid (this scene is serial)")
        X = setup.robot.pose_grid()
        if n is not None and n > len(X):
            raise ConfigError(f"{scene.path}: {which}: {n} poses asked, the grid has {len(X)}")
        if n is not None and n < len(X):
            X = X[np.sort(rng.choice(len(X), size=n, replace=False))]
        return X
    if kind == "configurations":
        conf = spec.get("configurations")
        confs = setup.chain.meta.get("configurations", {}) if setup.kind == "serial" else {}
        if conf not in confs:
            raise ConfigError(f"{scene.path}: {which}.configurations: unknown set {conf!r} (robot file has {sorted(confs)})")
        q = confs[conf]["q"]
        if n is not None and n > len(q):
            raise ConfigError(f"{scene.path}: {which}: {n} poses asked, configuration set {conf!r} has {len(q)}")
        return q if n is None else q[:n]
    # validation poses are evaluated through the kinematics only: they need not see the target
    return setup.sample_poses(rng, n or 30, check_view=(which == "poses"))


def true_parameters(scene: Scene, rng: np.random.Generator, base_free=None) -> np.ndarray:
    """Truth x_true (n,) = nominal + deviations. Seeded random deviations (sigma by kind) on the
    parameters that are free and identifiable (``base_free`` mask; default the scene's free mask),
    unless the scene names a robot-file trial (its deviation vector replaces the random draw);
    the scene's explicit ``truth.deviations`` are applied last."""
    ps = scene.setup.params
    x = ps.nominal.copy()
    mask = ps.free if base_free is None else np.asarray(base_free, bool)
    sig = np.where(np.array(ps.kinds) == "length", scene.truth["sigma_length_m"], scene.truth["sigma_angle_rad"])
    x[mask] += rng.normal(size=int(mask.sum())) * sig[mask]
    devs = dict(scene.truth["deviations"])
    trial = scene.truth.get("trial")
    if trial:
        trials = scene.setup.chain.meta.get("trials", {}) if scene.kind == "serial" else {}
        if trial not in trials:
            raise ConfigError(f"{scene.path}: truth.trial: unknown trial {trial!r} (robot file has {sorted(trials)})")
        devs.update(trials[trial].get("deviation", {}))
        x = ps.nominal.copy()  # a given deviation vector replaces the random draw
    for k, v in devs.items():
        x[ps.index(k)] = ps.nominal[ps.index(k)] + v
    return x
