"""Study files: loading and validation (every cell's scene built once, so bad values fail before any
run), the sweep's cells, run seeds and run keys. The format is in the package docstring."""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..config import Section, confine, load_yaml
from ..errors import ConfigError
from ..rig.base import ModelVariants, NamedConfigurations, NamedTrials, PoseGrids

RUN_FORMAT = "study-run-1"
MODES = ("synthetic", "images")
OUTPUTS = ("parameters", "accuracy", "criteria", "condition")
AXES_ALL = ("n_poses", "sigma_mm", "sigma_deg", "method", "residual", "variant", "model", "trial", "pose_selection")
#: pose_selection values: random subset (default) or optimal design (identify.pose_selection criterion)
POSE_SELECTIONS = ("random", "D", "E")
AXES_IMAGES = ("noise_grey", "blur_px", "frames")
#: axes that only the synthetic mode reads (an image run measures its pose noise and uses all its poses)
AXES_SYNTHETIC = ("sigma_mm", "sigma_deg", "pose_selection")
ACCURACY_KEYS = ("position_rms_mm", "position_max_mm", "rotation_rms_deg")
CRITERIA_KEYS = ("V1_rad", "V2_rad", "V3_m")
#: figures a spec's ``target`` may bound (after calibration, validation poses): column ``after_<key>`` (not the
#: signed mean V1)
TARGET_KEYS = ACCURACY_KEYS + ("V2_rad", "V3_m")
#: main figures of the summary text and the plots: (column, label, factor for display)
MAIN_FIGURES = (
    ("after_position_rms_mm", "pos RMS mm", 1.0),
    ("after_rotation_rms_deg", "rot RMS deg", 1.0),
    ("after_V1_rad", "V1 mrad", 1e3),
    ("after_V2_rad", "V2 mrad", 1e3),
    ("after_V3_m", "V3 um", 1e6),
    ("cond", "cond", 1.0),
)


@dataclass(frozen=True)
class StudySpec:
    """A validated study file. sweep: ordered list of axis groups, each (names, values) with
    values a list of tuples (one value per name). settings: {axis: value} constants."""

    path: Path
    name: str
    scene_path: Path
    mode: str
    repetitions: int
    seed: int
    truth: str
    settings: dict
    sweep: tuple
    outputs: tuple
    parameters: tuple | None
    truth_variant: str | None = None
    #: accuracy targets {figure: threshold} (``TARGET_KEYS``; SI-suffixed units as named) for the budget table
    target: dict | None = None
    #: the wall time [h] the user accepts for this study (``max_hours``): a longer estimate stops it
    #: (study/budget.py check_study; default: budget.CONFIRM_HOURS, then --yes)
    max_hours: float | None = None
    hash: str = ""
    raw: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def axes(self) -> tuple[str, ...]:
        """Names of the swept axes, in file order."""
        return tuple(n for names, _ in self.sweep for n in names)

    def where(self, key: str) -> str:
        return f"{self.path}: {key}"


def _convert(spec_path, key, axis, value, mode):
    """One axis value, checked and converted (int, float or str)."""
    where = f"{spec_path}: {key}"
    if axis not in AXES_ALL + AXES_IMAGES:
        raise ConfigError(f"{where}: unknown sweep key {axis!r} (known: {', '.join(AXES_ALL + AXES_IMAGES)})")
    if axis in AXES_IMAGES and mode != "images":
        raise ConfigError(f"{where}: {axis!r} is an image setting: it needs mode: images (this study is {mode})")
    if axis in AXES_SYNTHETIC and mode != "synthetic":
        raise ConfigError(f"{where}: {axis!r} applies to mode: synthetic only (an image run measures its pose noise "
                          f"from the images); remove it or use mode: synthetic")
    try:
        if axis == "trial":
            if not isinstance(value, str) or not value:
                raise ValueError
            return value  # checked against the robot file's trials in _check_cells
        if axis in ("n_poses", "frames"):
            if isinstance(value, bool) or int(value) != value or int(value) <= 0:
                raise ValueError
            return int(value)
        if axis in ("sigma_mm", "sigma_deg", "noise_grey", "blur_px"):
            v = float(value)
            if isinstance(value, bool) or not math.isfinite(v) or v < 0:
                raise ValueError
            return v
    except (TypeError, ValueError):
        kind = ("a trial name" if axis == "trial" else "a positive integer" if axis in ("n_poses", "frames")
                else "a finite number >= 0")
        raise ConfigError(f"{where}: {axis} expects {kind}, got {value!r}") from None
    v = str(value)
    choices = {"method": ("lse", "ekf", "igm"), "residual": ("pose", "position", "joint"),
               "variant": tuple("ABCDEFGH"), "model": ("12", "31"), "pose_selection": POSE_SELECTIONS}[axis]
    if axis == "variant":
        v = v.upper()
    if axis == "pose_selection":
        v = v.upper() if v.upper() in ("D", "E") else v.lower() if v.lower() == "random" else v
    if v not in choices:
        raise ConfigError(f"{where}: unknown {axis} {value!r} (expected one of {', '.join(choices)})")
    return v


def _file_digest(paths) -> str:
    h = hashlib.sha256()
    for p in paths:
        h.update(str(Path(p).name).encode())
        h.update(Path(p).read_bytes())
    return h.hexdigest()


def _scene_files(scene_path: Path) -> list[Path]:
    """The scene file and the files it names (robot, target), for the spec hash."""
    out = [scene_path]
    try:
        data = load_yaml(scene_path)
    except ConfigError:
        return out
    for k in ("robot", "target"):
        v = data.get(k)
        if isinstance(v, str):
            p = Path(v) if Path(v).is_absolute() else scene_path.parent / v
            try:  # nothing outside the scene's folder (config.confine): load_scene names the key
                confine(p, scene_path.parent, str(scene_path))
            except ConfigError:
                continue
            if p.is_file():
                out.append(p)
    return out


def load_study(path) -> StudySpec:
    """Load and validate a study file; ConfigError naming the file and key on bad input
    (unknown sweep key / method / variant / parameter, non-positive repetitions, missing scene)."""
    path = Path(path)
    top = Section(load_yaml(path), path)
    known = {"name", "scene", "mode", "repetitions", "seed", "truth", "settings", "sweep", "outputs", "parameters",
             "description", "truth_variant", "target", "max_hours"}
    for k in top.keys():
        if k not in known:
            raise top.error(k, f"unknown key (known: {', '.join(sorted(known))})")
    name = top.get("name", str, path.stem)
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        raise top.error("name", f"use letters, digits, '_', '.', '-' only, got {name!r}")
    scene_path = top.path_value("scene")
    mode = top.get("mode", str, "synthetic", choices=MODES)
    reps = top.get("repetitions", int, 1)
    if isinstance(top.data.get("repetitions"), bool) or reps <= 0 or reps != top.data.get("repetitions", reps):
        raise top.error("repetitions", f"expected a positive integer, got {top.data.get('repetitions')!r}")
    seed = top.get("seed", int, 0)
    truth = top.get("truth", str, "scene", choices=("scene", "per_run"))
    if truth == "per_run" and mode == "images":
        raise top.error("truth", "per_run is not supported in mode images (use truth: scene)")
    settings = {}
    for k, v in top.get("settings", dict, {}).items():
        settings[str(k)] = _convert(path, f"settings.{k}", str(k), v, mode)
    sweep = []
    seen = set(settings)
    for key, values in top.get("sweep", dict, {}).items():
        names = tuple(s.strip() for s in str(key).split(","))
        for n in names:
            if n in seen:
                raise top.error(f"sweep.{key}", f"axis {n!r} is given twice (sweep/settings)")
            seen.add(n)
        if not isinstance(values, list) or not values:
            raise top.error(f"sweep.{key}", f"expected a non-empty list of values, got {values!r}")
        rows = []
        for j, v in enumerate(values):
            vv = v if len(names) > 1 else [v]
            if not isinstance(vv, list) or len(vv) != len(names):
                raise top.error(f"sweep.{key}[{j}]", f"expected a list of {len(names)} values ({', '.join(names)}), got {v!r}")
            rows.append(tuple(_convert(path, f"sweep.{key}[{j}]", n, x, mode) for n, x in zip(names, vv)))
        if len(set(rows)) != len(rows):
            raise top.error(f"sweep.{key}", f"repeated values in {values!r}")
        sweep.append((names, rows))
    outputs = top.get("outputs", list, list(OUTPUTS))
    for o in outputs:
        if o not in OUTPUTS:
            raise top.error("outputs", f"unknown output {o!r} (known: {', '.join(OUTPUTS)})")
    params = top.get("parameters", list, None)
    tv = top.get("truth_variant", str, None)
    if tv is not None:
        tv = _convert(path, "truth_variant", "variant", tv, mode)
        if mode != "synthetic":
            raise top.error("truth_variant", "only mode: synthetic supports another truth model")
    target = _target(top, outputs)
    max_hours = top.number("max_hours", float, None, min=0.0, min_open=True, unit="h") if "max_hours" in top else None
    spec = StudySpec(path=path, name=name, scene_path=scene_path, mode=mode, repetitions=reps, seed=seed,
                     truth=truth, settings=settings, sweep=tuple(sweep), outputs=tuple(outputs),
                     parameters=None if params is None else tuple(str(p) for p in params), truth_variant=tv,
                     target=target, max_hours=max_hours, raw=top.data)
    _check_cells(spec)
    key = {"format": RUN_FORMAT, "mode": mode, "seed": seed, "truth": truth, "truth_variant": tv, "settings": settings,
           "outputs": sorted(outputs), "parameters": spec.parameters, "files": _file_digest(_scene_files(scene_path))}
    return replace(spec, hash=hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16])


def _target(top: Section, outputs) -> dict | None:
    """The ``target`` mapping {figure: threshold > 0}: figures of TARGET_KEYS whose output (accuracy / criteria)
    the study records. Not part of the spec hash: it only selects rows of the budget table."""
    raw = top.get("target", dict, None)
    if raw is None:
        return None
    if not raw:
        raise top.error("target", f"expected at least one of {', '.join(TARGET_KEYS)}")
    out = {}
    for k, v in raw.items():
        if k not in TARGET_KEYS:
            raise top.error(f"target.{k}", f"unknown figure (known: {', '.join(TARGET_KEYS)})")
        need = "accuracy" if k in ACCURACY_KEYS else "criteria"
        if need not in outputs:
            raise top.error(f"target.{k}", f"needs the {need!r} output")
        try:
            x = float(v)
            if isinstance(v, bool) or not math.isfinite(x) or x <= 0:
                raise ValueError
        except (TypeError, ValueError):
            raise top.error(f"target.{k}", f"expected a finite number > 0, got {v!r}") from None
        out[str(k)] = x
    return out


# ----------------------------------------------------------------------------- scenes
def scene_with(scene, variant: str | None = None, model: str | None = None):
    """The scene with its robot replaced by a model variant (``rig.base.ModelVariants``: for H4,
    ``variant`` A..H of paper table 2 and/or ``model`` "12"|"31"); truth deviations of names the new
    model lacks are dropped. ConfigError if the kind has no variants or the pair is impossible."""
    if variant is None and model is None:
        return scene
    if not isinstance(scene.setup, ModelVariants):
        raise ConfigError(f"{scene.path}: {scene.setup.name}: variant/model choices need a robot kind that has them "
                          f"(this one is {scene.setup.kind})")
    try:
        return scene.with_setup(scene.setup.with_variant(variant, model))
    except ConfigError as exc:
        raise ConfigError(f"{scene.path}: {exc}") from None


def scene_with_trial(scene, trial: str | None):
    """The scene with its truth replaced by the robot file's trial ``trial`` (its deviation vector);
    when the scene's poses are ``kind: configurations``, they become the trial's own configuration
    set (the thesis' experiment = a deviation vector on its configurations). ConfigError naming the
    scene if the robot has no such trial."""
    if trial is None:
        return scene
    trials = scene.setup.trials() if isinstance(scene.setup, NamedTrials) else {}
    if trial not in trials:
        raise ConfigError(f"{scene.path}: unknown trial {trial!r} (robot file has {sorted(trials) or 'no trials'})")
    poses = scene.poses
    conf = trials[trial].get("configurations")
    if poses.kind == "configurations" and conf:
        if not isinstance(scene.setup, NamedConfigurations) or conf not in scene.setup.configurations():
            raise ConfigError(f"{scene.path}: trial {trial!r} names configurations {conf!r} that the robot file lacks")
        poses = replace(poses, configurations=conf)
    return replace(scene, truth=replace(scene.truth, trial=trial), poses=poses)


def cell_scene(spec: StudySpec, cell: dict, base):
    """The scene of a cell (errors name the spec's axis)."""
    s = {**spec.settings, **cell}
    scene = base
    if s.get("variant") is not None or s.get("model") is not None:
        try:
            scene = scene_with(scene, s.get("variant"), s.get("model"))
        except ConfigError as exc:
            key = "variant" if s.get("variant") is not None else "model"
            raise ConfigError(f"{_axis_where(spec, key)}: {exc}") from None
    try:
        return scene_with_trial(scene, s.get("trial"))
    except ConfigError as exc:
        raise ConfigError(f"{_axis_where(spec, 'trial')}: {exc}") from None


def _check_cells(spec: StudySpec) -> None:
    """Build the scene of every cell once (cheap) so bad values fail before any run."""
    from ..rig import load_scene

    base = load_scene(spec.scene_path)
    if spec.truth_variant is not None:
        try:
            scene_with(base, variant=spec.truth_variant)
        except ConfigError as exc:
            raise ConfigError(f"{spec.path}: truth_variant: {exc}") from None
    names = set()
    for cell in study_cells(spec):
        sc = cell_scene(spec, cell, base)
        setup = sc.setup
        names.update(setup.params.names)
        s = {**spec.settings, **cell}
        res = s.get("residual")
        if res is not None and res not in setup.residuals:
            raise ConfigError(f"{_axis_where(spec, 'residual')}: residual {res!r} does not apply to the "
                              f"{sc.kind} scene {base.path.name} (use {' or '.join(setup.residuals)})")
        method = s.get("method") or sc.identification.method
        if res is not None and method in setup.methods and setup.residual_for(method, res) != res:
            raise ConfigError(f"{_axis_where(spec, 'residual')}: residual {res!r} does not apply to method "
                              f"{method!r} on the {sc.kind} scene {base.path.name} (it minimises "
                              f"{setup.residual_for(method, res)!r} residuals: leave residual out)")
        if s.get("method") is not None and s["method"] not in setup.methods:
            raise ConfigError(f"{_axis_where(spec, 'method')}: method {s['method']!r} does not apply to the "
                              f"{sc.kind} scene {base.path.name} (use {' or '.join(setup.methods)})")
        n = s.get("n_poses")
        if (n is not None and isinstance(setup, PoseGrids) and base.poses.kind in setup.pose_grids
                and n > len(setup.pose_grid(base.poses.kind))):
            raise ConfigError(f"{_axis_where(spec, 'n_poses')}: {n} poses asked, the scene's grid has "
                              f"{len(setup.pose_grid(base.poses.kind))}")
        m = {"joint": 4, "pose": 6, "position": 3}[setup.residual_for(method, res or sc.identification.residual)
                                                   if method in setup.methods else res or sc.identification.residual]
        n_free = setup.params.n_free
        if n is not None and n * m < n_free:
            raise ConfigError(f"{_axis_where(spec, 'n_poses')}: {n} poses give {n * m} equations "
                              f"({m} per pose) for {n_free} free parameters in cell {cell}: use at least "
                              f"{-(-n_free // m)} poses")
    for p in spec.parameters or ():
        if p not in names:
            import difflib

            close = difflib.get_close_matches(p, sorted(names), n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise ConfigError(f"{spec.path}: parameters: unknown parameter {p!r}{hint}")


def _axis_where(spec: StudySpec, axis: str) -> str:
    if axis in spec.settings:
        return spec.where(f"settings.{axis}")
    for names, _ in spec.sweep:
        if axis in names:
            return spec.where(f"sweep.{','.join(names)}")
    return str(spec.path)


def study_cells(spec: StudySpec) -> list[dict]:
    """Sweep points in order (cartesian product of the axis groups): [{axis: value}]."""
    groups = [[dict(zip(names, row)) for row in rows] for names, rows in spec.sweep]
    out = []
    for combo in itertools.product(*groups):
        d = {}
        for g in combo:
            d.update(g)
        out.append(d)
    return out


def run_seed(spec_seed: int, repetition: int) -> int:
    """Seed of repetition r: SeedSequence([spec_seed, r]) -> uint32 (same for every cell)."""
    return int(np.random.SeedSequence([int(spec_seed), int(repetition)]).generate_state(1)[0])


def row_value(row: dict, c: str) -> float:
    """Column ``c`` of a results row as a float (NaN when empty or missing)."""
    v = row.get(c)
    if v is None or v == "":
        return float("nan")
    return float(v)


def format_value(v) -> str:
    """A swept value as it appears in run keys, tables and plot labels (floats in %g)."""
    return f"{v:g}" if isinstance(v, float) else str(v)


def cell_key(cell: dict, repetition: int) -> str:
    """File-name-safe key of one run, e.g. ``n_poses=6,rep=0003``."""
    parts = [f"{k}={format_value(v)}" for k, v in cell.items()] + [f"rep={repetition:04d}"]
    return re.sub(r"[^A-Za-z0-9_.=,+-]", "_", ",".join(parts))


