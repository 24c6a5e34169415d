"""Studies: a parameter sweep x Monte Carlo repetitions of one scene, run locally (processes) or
on a Dask cluster, resumable, written as a tidy table + summary + plots (``vision-calib study``).

Spec file (YAML; paths relative to the spec file)::

    name: h4_pose_count              # default: the file's stem
    scene: ../h4_vision.yaml         # required
    mode: synthetic                  # synthetic (pose measurements + Gaussian noise, run_synthetic)
                                     # | images (render + measure, experiment.simulate.run_simulation)
    repetitions: 100                 # Monte Carlo runs per sweep point (> 0)
    seed: 0                          # study seed (int)
    description: free text           # optional, ignored
    truth: scene                     # scene: one true robot (the scene's truth.seed) for every run
                                     # | per_run: a new random truth per repetition (seeded by the run seed)
    truth_variant: H                 # optional, H4 + synthetic: measurements come from this variant's
                                     # robot (e.g. model 31 with deviations on all its free parameters)
                                     # while each cell identifies its own variant/model (model error);
                                     # accuracy and V1..V3 are evaluated across models, err: columns
                                     # only for parameter names both models share
    settings: {n_poses: 71}          # optional constants applied to every run (same keys as sweep)
    sweep:                           # cartesian product of the axes (may be empty: one cell)
      n_poses: [6, 15, 71]
      "sigma_mm,sigma_deg": [[0.05, 0.0075], [0.1, 0.015]]   # linked axes: varied together
    outputs: [parameters, accuracy, criteria, condition]      # default: all four
    parameters: [h4.L, h4.l]         # optional: parameters recorded in the table (default: all)

Sweep/settings keys: ``n_poses`` (int > 0: subset drawn at random from the scene's poses),
``sigma_mm``, ``sigma_deg`` (pose noise per component, >= 0), ``method`` (lse|ekf|igm; igm = H4
only), ``residual`` (pose|position for serial scenes, joint for H4), ``variant`` (H4 paper table 2,
A..H: the scene's robot is replaced by ``robot.variant(letter)`` of the model-12 robot, E..H
are model 31, the free mask follows), ``model`` ("12"|"31", H4), ``trial`` (serial scenes whose
robot file has ``trials``, e.g. the thesis' chapter 3-4 experiments: the truth is the trial's
deviation vector, and when the scene's poses are ``kind: configurations`` they become the trial's
own configuration set), ``pose_selection`` (mode synthetic: ``random`` = the default, a random
subset of ``n_poses`` drawn per repetition; ``D`` | ``E`` = the ``n_poses`` poses of the scene's
pose pool -- the whole grid81 / configuration set, or for ``kind: random`` the scene's ``count``
poses drawn with repetition 0's pose stream -- that maximise log det (D-optimal, Borm-Menq O1) or
the smallest singular value (E, O3) of the scaled whitened identification Jacobian of the
identifiable parameters, ``identify.pose_selection.select_poses``; computed at the nominal
geometry with exact measurements weighted by the cell's noise sigmas, so it never sees the truth
or the noise draws: the subset is the same in every repetition, the noise still varies), and for
mode images only
``noise_grey``, ``blur_px`` (sensor effects) and ``frames`` (frames per pose).

Reproducibility. A run = (cell, repetition) is a pure function of the spec, the cell's values and
the run seed ``seed = SeedSequence([spec.seed, repetition]).generate_state(1)[0]`` (uint32). The
run seed does not depend on the sweep values: every cell of repetition r uses the same pose/noise
streams (``synthetic.rngs``), i.e. common random numbers -- the noise draws of a repetition are
shared across sweep values, and with ``n_poses`` the subsets come from the same generator state
(not nested, since ``rng.choice`` of another size draws differently). Results do not depend on the
number of workers or on the executor (local processes or Dask).

Outputs (in ``out_dir``):

- ``runs/<cell-key>.json``: one file per finished run (written atomically as it completes), with
  the spec hash; on start, runs whose file exists with the same hash are reused, not recomputed.
  The hash covers the scene/robot/target files and every spec entry except ``name``, ``sweep``
  and ``repetitions`` (which only select which runs exist: adding repetitions or sweep values
  reuses what was computed). It does not cover the package's code: delete ``runs/`` after a
  code change that alters the numbers.
- ``results.csv`` / ``results.parquet``: tidy table, one row per run: ``study``, the sweep axes,
  ``repetition``, ``seed``, ``error`` (message of a run that failed with a VisionCalibError, else
  empty), ``converged``, ``iterations``, ``seconds`` (identification time), ``n_free``; with
  ``accuracy``: ``before_``/``after_`` ``position_rms_mm``, ``position_max_mm``,
  ``rotation_rms_deg`` (validation poses; before = nominal, after = identified parameters); with
  ``criteria`` (H4): ``before_``/``after_`` ``V1_rad``, ``V2_rad``, ``V3_m``; with
  ``condition``: ``cond`` (condition number of the scaled, whitened identification Jacobian of the
  identifiable parameters at the nominal over the run's poses, ``identify.analyze``); with
  ``parameters``: wide columns ``err:<name>`` (identified - true, SI: m or rad) and
  ``std:<name>`` (predicted std, SI) for every parameter (NaN where fixed / not in the model).
- ``parameters.csv`` (mode synthetic, ``truth: scene``, with ``parameters``): one row per (cell,
  parameter) for the free parameters and those with a true deviation: ``true_deviation``
  (x_true - nominal, SI), ``identifiable`` (yes/no: in the cell's base set), ``noise_free``
  (deviation identified from exact measurements on the poses of repetition 0: what the
  identifiable parameters converge to when the truth has non-identifiable parts, e.g. d2 absorbs
  d3), ``identified_mean``, ``mc_std`` (Monte Carlo std), ``predicted_std`` (mean), ``mc_rms_error``
  (RMS of identified - true), ``note`` (coupling of a non-identifiable parameter, or why it is
  fixed) and ``thesis_reported`` (the robot file's ``reported`` estimate of a ``trial`` truth).
  The summary text prints it when the sweep has ``trial`` or the study has at most 2 cells.
- ``summary.csv``: long table, one row per (cell, metric): the axes, ``metric``, ``n`` (finite
  values), ``mean``, ``std`` (ddof 1), ``rms``, ``p05``, ``p50``, ``p95``. For ``err:`` metrics
  with ``truth: scene`` the std is the Monte Carlo std of the identified parameter.
- plots (PNG): ``<metric>_vs_<axis>.png`` (median and 5-95 % band of the main figures vs each
  swept axis) and ``param_std_vs_<axis>.png`` (Monte Carlo std of each identified parameter).

Workers must see the same files (scene, robot, target) at the same paths: a shared filesystem or
the same checkout on every Dask worker. Only the calling process writes files.
"""

from __future__ import annotations

import csv
import functools
import hashlib
import io
import itertools
import json
import math
import os
import re
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..config import Section, load_yaml
from ..errors import ConfigError, ParameterError, VisionCalibError
from ..io.atomic import write_bytes_atomic, write_json_atomic, write_text_atomic

RUN_FORMAT = "study-run-1"
MODES = ("synthetic", "images")
OUTPUTS = ("parameters", "accuracy", "criteria", "condition")
AXES_ALL = ("n_poses", "sigma_mm", "sigma_deg", "method", "residual", "variant", "model", "trial", "pose_selection")
#: pose_selection values: random subset (default) or optimal design (identify.pose_selection criterion)
POSE_SELECTIONS = ("random", "D", "E")
AXES_IMAGES = ("noise_grey", "blur_px", "frames")
ACCURACY_KEYS = ("position_rms_mm", "position_max_mm", "rotation_rms_deg")
CRITERIA_KEYS = ("V1_rad", "V2_rad", "V3_m")
#: main figures of the summary text and the plots: (column, label, factor for display)
MAIN_FIGURES = (
    ("after_position_rms_mm", "pos RMS mm", 1.0),
    ("after_rotation_rms_deg", "rot RMS deg", 1.0),
    ("after_V1_rad", "V1 mrad", 1e3),
    ("after_V2_rad", "V2 mrad", 1e3),
    ("after_V3_m", "V3 um", 1e6),
    ("cond", "cond", 1.0),
)


# ----------------------------------------------------------------------------- spec
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
            if p.is_file():
                out.append(p)
    return out


def load_study(path) -> StudySpec:
    """Load and validate a study file; ConfigError naming the file and key on bad input
    (unknown sweep key / method / variant / parameter, non-positive repetitions, missing scene)."""
    path = Path(path)
    top = Section(load_yaml(path), path)
    known = {"name", "scene", "mode", "repetitions", "seed", "truth", "settings", "sweep", "outputs", "parameters",
             "description", "truth_variant"}
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
    spec = StudySpec(path=path, name=name, scene_path=scene_path, mode=mode, repetitions=reps, seed=seed,
                     truth=truth, settings=settings, sweep=tuple(sweep), outputs=tuple(outputs),
                     parameters=None if params is None else tuple(str(p) for p in params), truth_variant=tv,
                     raw=top.data)
    _check_cells(spec)
    key = {"format": RUN_FORMAT, "mode": mode, "seed": seed, "truth": truth, "truth_variant": tv, "settings": settings,
           "outputs": sorted(outputs), "parameters": spec.parameters, "files": _file_digest(_scene_files(scene_path))}
    return replace(spec, hash=hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16])


def _check_cells(spec: StudySpec) -> None:
    """Build the scene of every cell once (cheap) so bad values fail before any run."""
    from .scene import load_scene

    base = load_scene(spec.scene_path)
    if spec.truth_variant is not None:
        try:
            scene_with(base, variant=spec.truth_variant)
        except ConfigError as exc:
            raise ConfigError(f"{spec.path}: truth_variant: {exc}") from None
    names = set()
    for cell in study_cells(spec):
        sc = _cell_scene(spec, cell, base)
        names.update(sc.setup.params.names)
        s = {**spec.settings, **cell}
        res = s.get("residual")
        if res is not None:
            ok = ("joint",) if sc.kind == "h4" else ("pose", "position")
            if res not in ok:
                raise ConfigError(f"{_axis_where(spec, 'residual')}: residual {res!r} does not apply to the "
                                  f"{sc.kind} scene {base.path.name} (use {' or '.join(ok)})")
        if s.get("pose_selection", "random") != "random" and spec.mode != "synthetic":
            raise ConfigError(f"{_axis_where(spec, 'pose_selection')}: pose_selection {s['pose_selection']!r} "
                              f"needs mode: synthetic (this study is {spec.mode}; use random)")
        if s.get("method") == "igm" and sc.kind != "h4":
            raise ConfigError(f"{_axis_where(spec, 'method')}: method 'igm' is the H4 inverse-model method "
                              f"(scene {base.path.name} is {sc.kind}; use lse or ekf)")
        n = s.get("n_poses")
        if n is not None and base.poses["kind"] == "grid81" and n > 81:
            raise ConfigError(f"{_axis_where(spec, 'n_poses')}: {n} poses asked, the scene's grid has 81")
        m = {"joint": 4, "pose": 6, "position": 3}[res or sc.identification["residual"]]
        n_free = sc.setup.params.n_free
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


def _fmt(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def cell_key(cell: dict, repetition: int) -> str:
    """File-name-safe key of one run, e.g. ``n_poses=6,rep=0003``."""
    parts = [f"{k}={_fmt(v)}" for k, v in cell.items()] + [f"rep={repetition:04d}"]
    return re.sub(r"[^A-Za-z0-9_.=,+-]", "_", ",".join(parts))


# ----------------------------------------------------------------------------- scenes
def scene_with(scene, variant: str | None = None, model: str | None = None):
    """The scene with its H4 robot replaced: ``variant`` A..H (paper table 2, built from the
    model-12 robot: E..H are model 31) and/or ``model`` "12"|"31"; the free mask follows the
    variant (or the model's default: D for 12, H for 31), then the scene's
    ``identification.fix`` names that exist in the new model are fixed. ConfigError if the
    scene is not H4 or the variant/model pair is impossible."""
    from .scene import H4Setup

    if variant is None and model is None:
        return scene
    if scene.kind != "h4":
        raise ConfigError(f"{scene.path}: variant/model sweeps need an H4 scene (this one is {scene.kind})")
    from ..kinematics.h4 import load_h4_robot

    robot_file = Path(scene.raw["robot"])
    robot_file = robot_file if robot_file.is_absolute() else scene.path.parent / robot_file
    model = model or (("31" if variant in tuple("EFGH") else "12") if variant else scene.setup.meta.get("model", "12"))
    robot = load_h4_robot(robot_file, model=model)
    if variant is not None:
        if model == "31" and variant in tuple("ABCD"):
            raise ConfigError(f"{scene.path}: H4 variant {variant} is built on model 12, not model 31")
        try:
            robot = robot.variant(variant)
        except ParameterError as exc:
            raise ConfigError(f"{scene.path}: variant: {exc}") from None
    fix = [str(n) for n in (scene.raw.get("identification") or {}).get("fix", []) or [] if str(n) in robot.names]
    params = robot.params.fix(fix) if fix else robot.params
    robot = replace(robot, params=params)
    meta = {**scene.setup.meta, "model": model, "variant": variant}
    setup = H4Setup(name=scene.setup.name, params=params, camera=scene.setup.camera, mount=scene.setup.mount,
                    meta=meta, robot=robot, line_tests=scene.setup.line_tests)
    truth = dict(scene.truth)
    truth["deviations"] = {k: v for k, v in truth["deviations"].items() if k in params.names}
    return replace(scene, setup=setup, truth=truth)


def scene_with_trial(scene, trial: str | None):
    """The serial scene with its truth replaced by the robot file's trial ``trial`` (its deviation
    vector); when the scene's poses are ``kind: configurations``, they become the trial's own
    configuration set (the thesis' experiment = a deviation vector on its configurations).
    ConfigError naming the scene if the scene is not serial or the trial is unknown."""
    if trial is None:
        return scene
    trials = scene.setup.chain.meta.get("trials", {}) if scene.kind == "serial" else {}
    if trial not in trials:
        raise ConfigError(f"{scene.path}: unknown trial {trial!r} (robot file has {sorted(trials) or 'no trials'})")
    poses = scene.poses
    conf = trials[trial].get("configurations")
    if poses["kind"] == "configurations" and conf:
        if conf not in scene.setup.chain.meta.get("configurations", {}):
            raise ConfigError(f"{scene.path}: trial {trial!r} names configurations {conf!r} that the robot file lacks")
        poses = {**poses, "configurations": conf}
    return replace(scene, truth={**scene.truth, "trial": trial}, poses=poses)


def _cell_scene(spec: StudySpec, cell: dict, base):
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


@functools.lru_cache(maxsize=4)
def _load_scene_cached(path: str, spec_hash: str):
    from .scene import load_scene

    return load_scene(path)


@functools.lru_cache(maxsize=32)
def _scene_for(scene_path: str, variant, model, spec_hash: str = "", trial=None):
    """Scene of a cell in a worker (cached per process and spec hash, which covers the scene's
    files; values were validated by load_study)."""
    return scene_with_trial(scene_with(_load_scene_cached(scene_path, spec_hash), variant, model), trial)


@functools.lru_cache(maxsize=32)
def _selected_poses(scene_path: str, variant, model, spec_hash: str, trial, residual: str, n, criterion: str,
                    sigma_t_m: float, sigma_r_rad: float, pool_seed: int) -> np.ndarray:
    """Poses (n, .) chosen by ``criterion`` from the scene's pose pool (cached per process): the
    pool is ``scene_poses(scene, rngs(pool_seed)[0])`` (all of a grid / configuration set), the
    problem is built at the nominal geometry from exact measurements weighted by the given pose
    sigmas and restricted to the parameters identifiable from the whole pool."""
    from ..identify import analyze
    from ..identify.pose_selection import select_poses
    from .scene import scene_poses
    from .setup import pose_cov_from_sigmas
    from .synthetic import BASE_SELECTION, rngs

    scene = _scene_for(scene_path, variant, model, spec_hash, trial)
    setup = scene.setup
    pool = scene_poses(scene, rngs(pool_seed)[0])
    meas = setup.synthetic_measurements(pool, setup.params.nominal, np.random.default_rng(0))
    meas = replace(meas, cov=pose_cov_from_sigmas(len(pool), sigma_t_m, sigma_r_rad))
    problem = setup.problem(meas, residual)
    rep = analyze(problem, selection=BASE_SELECTION)
    problem = problem.with_params(problem.params.only_free(rep.base_parameters))
    idx = select_poses(problem, len(pool) if n is None else int(n), criterion)
    out = np.asarray(pool)[idx]
    out.setflags(write=False)
    return out


def _cell_poses(spec: StudySpec, scene, s: dict, seed: int, residual: str) -> np.ndarray:
    """Identification poses of a run: a random subset (pose stream of the run seed) or, with
    ``pose_selection`` D/E, the cell's deterministic optimal subset of the scene's pose pool."""
    from .scene import scene_poses
    from .synthetic import rngs

    crit = s.get("pose_selection", "random")
    if crit == "random":
        return scene_poses(scene, rngs(seed)[0], s.get("n_poses"))
    st = scene.measurement["sigma_t_m"] if s.get("sigma_mm") is None else s["sigma_mm"] * 1e-3
    sr = scene.measurement["sigma_r_rad"] if s.get("sigma_deg") is None else float(np.radians(s["sigma_deg"]))
    return np.array(_selected_poses(str(spec.scene_path), s.get("variant"), s.get("model"), spec.hash,
                                    s.get("trial"), residual, s.get("n_poses"), crit, float(st), float(sr),
                                    run_seed(spec.seed, 0)))


# ----------------------------------------------------------------------------- one run
def run_cell(spec: StudySpec, cell: dict, repetition: int) -> dict:
    """One run (cell x repetition): a pure function of its arguments. Returns the row dict
    (see the module docstring); a VisionCalibError of the run becomes a row with ``error`` set."""
    s = {**spec.settings, **cell}
    seed = run_seed(spec.seed, repetition)
    row = {"study": spec.name, **cell, "repetition": int(repetition), "seed": seed, "error": ""}
    scene = _scene_for(str(spec.scene_path), s.get("variant"), s.get("model"), spec.hash, s.get("trial"))
    try:
        out = (_run_images if spec.mode == "images" else _run_synthetic)(spec, scene, s, seed)
    except (VisionCalibError, np.linalg.LinAlgError) as exc:
        row.update({"error": f"{type(exc).__name__}: {exc}", "converged": False})
        return row
    row.update({"converged": bool(out["converged"]), "iterations": int(out["iterations"]),
                "seconds": float(out["seconds"]), "n_free": int(out["n_free"])})
    if "accuracy" in spec.outputs:
        for when in ("before", "after"):
            for k in ACCURACY_KEYS:
                row[f"{when}_{k}"] = float(out[when][k])
    if "criteria" in spec.outputs and scene.kind == "h4":
        for when in ("before", "after"):
            for k in CRITERIA_KEYS:
                row[f"{when}_{k}"] = float(out[when].get(k, np.nan))
    if "condition" in spec.outputs:
        row["cond"] = float(out["cond"])
    if "parameters" in spec.outputs:
        for p in out["parameters"]:
            if spec.parameters is not None and p["name"] not in spec.parameters:
                continue
            free = p["free"] and p["true"] is not None
            row[f"err:{p['name']}"] = float(p["identified"] - p["true"]) if free else float("nan")
            row[f"std:{p['name']}"] = float(p["std"]) if free and p["std"] is not None else float("nan")
    return row


def _run_synthetic(spec: StudySpec, scene, s: dict, seed: int) -> dict:
    """Synthetic run (experiment.synthetic.run_synthetic) -> the fields run_cell records."""
    from .scene import true_parameters
    from .synthetic import STREAM_TRUTH, identifiability_report, parameters_table, run_synthetic

    residual = s.get("residual") or scene.identification["residual"]
    poses = _cell_poses(spec, scene, s, seed, residual)
    rep, _ = identifiability_report(scene, poses, residual)
    base = scene.setup.params.mask(rep.base_parameters)
    if spec.truth_variant is not None:
        return _run_synthetic_other_truth(spec, scene, s, seed, poses, base, rep, residual)
    x_true = None
    if spec.truth == "per_run":
        x_true = true_parameters(scene, np.random.default_rng([seed, STREAM_TRUTH]), base)
    out = run_synthetic(
        scene, method=s.get("method"), residual=residual, poses=poses, seed=seed, base=base, x_true=x_true,
        sigma_t_m=None if s.get("sigma_mm") is None else s["sigma_mm"] * 1e-3,
        sigma_r_rad=None if s.get("sigma_deg") is None else float(np.radians(s["sigma_deg"])),
    )
    res = out["result"]
    ps = scene.setup.params
    return {"converged": res.converged, "iterations": res.iterations, "seconds": out["seconds"],
            "n_free": int(res.free.sum()), "before": out["before"], "after": out["after"],
            "cond": rep.condition_number, "parameters": parameters_table(ps.names, ps.nominal, out["x_true"], res)}


def _run_synthetic_other_truth(spec, scene, s, seed, poses, base, rep, residual) -> dict:
    """Synthetic H4 run whose measurements come from another model (``truth_variant``, e.g. a
    model-31 robot with deviations on all its free parameters) while the cell's model is
    identified: the identified model may not fit the truth (model error, as on the real robot).
    Accuracy and V1..V3 are evaluated across models (joints of the TRUE robot, forward model of
    the identified one); parameter errors are recorded for names the two models share."""
    from .scene import scene_poses, true_parameters
    from .setup import accuracy_stats
    from .synthetic import STREAM_TRUTH, identify, parameters_table, rngs

    _, rn, rv = rngs(seed)
    tscene = _scene_for(str(spec.scene_path), spec.truth_variant, None, spec.hash)
    tsetup, setup = tscene.setup, scene.setup
    tseed = seed if spec.truth == "per_run" else tscene.truth["seed"]
    x_true = true_parameters(tscene, np.random.default_rng([tseed, STREAM_TRUTH]))
    st = scene.measurement["sigma_t_m"] if s.get("sigma_mm") is None else s["sigma_mm"] * 1e-3
    sr = scene.measurement["sigma_r_rad"] if s.get("sigma_deg") is None else float(np.radians(s["sigma_deg"]))
    sq = scene.measurement["sigma_q_rad"]
    validation = scene_poses(scene, rv, which="validation")
    t0 = time.perf_counter()
    meas = tsetup.synthetic_measurements(poses, x_true, rn, st, sr, sq)
    params = setup.params.only_free([n for n, b in zip(setup.params.names, base) if b])
    problem = setup.problem(meas, residual, params=params)
    result = identify(problem, s.get("method") or scene.identification["method"])
    seconds = time.perf_counter() - t0
    meas_val = tsetup.synthetic_measurements(validation, x_true, rv, st, sr, sq)
    truth_robot, robot = tsetup.robot, setup.robot

    def evaluate(x):
        X = validation
        Xh = robot.fgm(truth_robot.igm(X, x_true), x, X0=X)
        err = np.zeros((len(X), 6))
        err[:, :3] = Xh[:, :3] - X[:, :3]
        err[:, 5] = np.angle(np.exp(1j * (Xh[:, 3] - X[:, 3])))
        out = accuracy_stats(err)
        r = np.angle(np.exp(1j * (meas_val.joints - robot.igm_from_camera(meas_val.T_cam_target, x))))
        out["V1_rad"], out["V2_rad"] = float(np.mean(r)), float(np.sqrt(np.mean(r**2)))
        rect = []
        for line in setup.lines():
            P = robot.fgm(truth_robot.igm(line, x_true), x, X0=line)[:, :3]
            P = P - P.mean(axis=0)
            u = np.linalg.svd(P, full_matrices=False)[2][0]
            rect.append(np.sqrt(np.mean(np.sum((P - np.outer(P @ u, u)) ** 2, axis=1))))
        out["V3_m"] = float(np.mean(rect))
        return out

    tval = tsetup.params.values(x_true)
    ps = setup.params
    x_shared = np.array([tval.get(n, np.nan) for n in ps.names])
    table = parameters_table(ps.names, ps.nominal, x_shared, result)
    for p in table:
        if p["true"] is not None and not np.isfinite(p["true"]):
            p["true"] = None
    return {"converged": result.converged, "iterations": result.iterations, "seconds": seconds,
            "n_free": int(result.free.sum()), "before": evaluate(ps.nominal), "after": evaluate(result.identified),
            "cond": rep.condition_number, "parameters": table}


def _run_images(spec: StudySpec, scene, s: dict, seed: int) -> dict:
    """End-to-end run (render + measure + identify, experiment.simulate.run_simulation)."""
    if spec.truth == "per_run":
        raise ConfigError(f"{spec.path}: truth: per_run is not supported in mode images (use truth: scene)")
    try:
        from .simulate import run_simulation
    except ImportError as exc:  # pragma: no cover - depends on the installed tree
        raise ConfigError(f"{spec.path}: mode: images needs vision_calib.experiment.simulate ({exc})") from None
    if s.get("residual"):
        scene = replace(scene, identification={**scene.identification, "residual": s["residual"]})
    overrides = {k: s[k] for k in ("noise_grey", "blur_px", "sigma_mm", "sigma_deg") if s.get(k) is not None}
    rep = run_simulation(scene, out_dir=None, seed=seed, n_poses=s.get("n_poses"), frames=s.get("frames"),
                         method=s.get("method"), workers=1, progress=False, overrides=overrides)
    ident = rep["identification"]
    return {"converged": ident["converged"], "iterations": ident["iterations"],
            "seconds": rep.get("timings_s", {}).get("identify", float("nan")),
            "n_free": sum(1 for p in rep["parameters"] if p["free"]),
            "before": rep["accuracy"]["before"], "after": rep["accuracy"]["after"],
            "cond": rep["identifiability"]["condition_number"], "parameters": rep["parameters"]}


# ----------------------------------------------------------------------------- execution
def _run_task(spec, cell, rep):
    return cell, rep, run_cell(spec, cell, rep)


def _execute(spec, todo, workers, scheduler, on_done):
    """Run ``todo`` [(cell, rep)] and call on_done(cell, rep, row) as each finishes (in this process)."""
    if scheduler is not None:
        from distributed import Client, as_completed

        own = not isinstance(scheduler, Client)
        client = Client(scheduler) if own else scheduler
        try:
            futs = [client.submit(_run_task, spec, c, r, pure=False) for c, r in todo]
            try:
                for fut in as_completed(futs):
                    on_done(*fut.result())
            finally:
                client.cancel(futs)
        finally:
            if own:
                client.close()
        return
    if workers <= 1 or len(todo) <= 1:
        for c, r in todo:
            on_done(*_run_task(spec, c, r))
        return
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as ex:
        pending = {ex.submit(_run_task, spec, c, r) for c, r in todo}
        try:
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for f in done:
                    on_done(*f.result())
        except BaseException:
            for f in pending:
                f.cancel()
            raise


def _load_run(path: Path, spec_hash: str):
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if d.get("spec_hash") != spec_hash or d.get("format") != RUN_FORMAT or not isinstance(d.get("row"), dict):
        return None
    return d["row"]


def run_study(spec, out_dir, workers: int | None = None, scheduler=None, progress: bool = False,
              plots: bool = True) -> dict:
    """Run (or resume) a study and write its outputs in ``out_dir`` (see the module docstring).

    spec: StudySpec or path of the study file. workers: local processes (default: CPU count;
    1 = in this process). scheduler: Dask scheduler address (or a ``distributed.Client``): runs
    go to the cluster instead. plots: write the PNG plots. Returns {name, spec_hash, out_dir, n_runs, n_computed, n_reused,
    n_failed, files, summary (per cell: axes + {metric: {mean, std}}), summary_text}.
    """
    spec = spec if isinstance(spec, StudySpec) else load_study(spec)
    out = Path(out_dir)
    runs_dir = out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    cells = study_cells(spec)
    plan = [(c, r) for c in cells for r in range(spec.repetitions)]
    rows = {}
    todo = []
    for c, r in plan:
        k = cell_key(c, r)
        row = _load_run(runs_dir / f"{k}.json", spec.hash)
        if row is None:
            todo.append((c, r))
        else:
            rows[k] = row
    n_reused = len(rows)
    t0 = time.perf_counter()
    bar = None
    if progress and todo:
        from tqdm import tqdm

        bar = tqdm(total=len(todo), desc=spec.name, unit="run", file=sys.stderr)

    def on_done(c, r, row):
        k = cell_key(c, r)
        write_json_atomic(runs_dir / f"{k}.json", {"format": RUN_FORMAT, "spec_hash": spec.hash, "key": k, "row": row})
        rows[k] = row
        if bar is not None:
            bar.update(1)

    try:
        _execute(spec, todo, workers or os.cpu_count() or 1, scheduler, on_done)
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - t0
    table = [rows[cell_key(c, r)] for c, r in plan]
    files = write_outputs(spec, table, out, plots=plots)
    summary = cell_summary(spec, table)
    res = {"name": spec.name, "spec": str(spec.path), "spec_hash": spec.hash, "out_dir": str(out),
           "n_runs": len(plan), "n_computed": len(todo), "n_reused": n_reused,
           "n_failed": sum(1 for row in table if row.get("error")), "wall_seconds": wall, "files": files,
           "summary": summary}
    res["parameter_spread"] = parameter_spread(spec, table)
    res["parameters"] = parameter_table(spec, table)
    if res["parameters"]:
        files["parameters_csv"] = write_parameter_table(spec, res["parameters"], out)
    res["summary_text"] = summary_text(spec, res)
    return res


PARAMETER_COLUMNS = ("parameter", "kind", "true_deviation", "identifiable", "noise_free", "identified_mean", "mc_std",
                     "predicted_std", "mc_rms_error", "n", "note", "thesis_reported")


def _cell_reference(spec: StudySpec, cell: dict):
    """(scene, x_true (n,), identifiability report, noise-free identified vector (n,) or None) of a
    cell, on the poses of repetition 0."""
    from .synthetic import identifiability_report, run_synthetic, scene_truth

    s = {**spec.settings, **cell}
    scene = _scene_for(str(spec.scene_path), s.get("variant"), s.get("model"), spec.hash, s.get("trial"))
    residual = s.get("residual") or scene.identification["residual"]
    seed = run_seed(spec.seed, 0)
    poses = _cell_poses(spec, scene, s, seed, residual)
    rep, _ = identifiability_report(scene, poses, residual)
    x_true = scene_truth(scene)
    try:
        ref = run_synthetic(scene, method="igm" if scene.kind == "h4" else "lse", residual=residual, poses=poses,
                            validation=poses[:1], seed=seed, base=scene.setup.params.mask(rep.base_parameters),
                            x_true=x_true, sigma_t_m=0.0, sigma_r_rad=0.0)
        x_ref = ref["result"].identified
    except (VisionCalibError, np.linalg.LinAlgError):
        x_ref = None
    return scene, x_true, rep, x_ref


def _fixed_note(scene, name: str) -> str:
    if scene.kind == "serial":
        for a, b, why in scene.setup.chain.redundant_pairs():
            if name in (a, b):
                other = b if name == a else a
                return f"fixed: redundant with {other} ({why})"
    return "fixed (not free in the scene)"


def parameter_table(spec: StudySpec, table: list[dict]) -> list[dict]:
    """Per (cell, parameter) rows of ``parameters.csv`` (see the module docstring); SI units.
    Empty unless mode synthetic, ``truth: scene``, no ``truth_variant`` and ``parameters`` output."""
    if spec.mode != "synthetic" or spec.truth != "scene" or spec.truth_variant is not None \
            or "parameters" not in spec.outputs:
        return []
    groups = _group(spec, table)
    out = []
    for cell in study_cells(spec):
        rows = [r for r in groups.get(tuple(cell[a] for a in spec.axes), []) if not r.get("error")]
        scene, x_true, rep, x_ref = _cell_reference(spec, cell)
        ps = scene.setup.params
        dev = x_true - ps.nominal
        trial = scene.truth.get("trial")
        reported = {}
        if trial and scene.kind == "serial":
            reported = scene.setup.chain.meta.get("trials", {}).get(trial, {}).get("reported", {}) or {}
        couplings = {c["parameter"]: c for c in rep.couplings}
        names = [n for i, n in enumerate(ps.names) if ps.free[i] or abs(dev[i]) > 0 or n in reported]
        if spec.parameters is not None:
            names = [n for n in names if n in spec.parameters]
        for n in names:
            i = ps.index(n)
            err = np.array([_value(r, f"err:{n}") for r in rows])
            std = np.array([_value(r, f"std:{n}") for r in rows])
            err, std = err[np.isfinite(err)], std[np.isfinite(std)]
            ident = n in rep.base_parameters
            if n in couplings:
                comb = couplings[n]["combination_si"]
                note = ("no effect on the measurements" if not comb else
                        f"not identifiable: {n} acts as " + " ".join(f"{v:+.3g}*{k}" for k, v in comb.items()))
            elif not ps.free[i]:
                note = _fixed_note(scene, n)
            else:
                note = ""
            out.append({
                **cell, "parameter": n, "kind": ps.kinds[i], "true_deviation": float(dev[i]),
                "identifiable": "yes" if ident else "no",
                "noise_free": float(x_ref[i] - ps.nominal[i]) if x_ref is not None else float("nan"),
                "identified_mean": float(dev[i] + err.mean()) if err.size else float("nan"),
                "mc_std": float(err.std(ddof=1)) if err.size > 1 else float("nan"),
                "predicted_std": float(std.mean()) if std.size else float("nan"),
                "mc_rms_error": float(np.sqrt(np.mean(err**2))) if err.size else float("nan"),
                "n": int(err.size), "note": note,
                "thesis_reported": float(reported[n]) if n in reported else float("nan"),
            })
    return out


def write_parameter_table(spec: StudySpec, prows: list[dict], out: Path) -> str:
    """``parameters.csv`` (SI units; empty cells for NaN)."""
    cols = [*spec.axes, *PARAMETER_COLUMNS]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in prows:
        w.writerow(["" if isinstance(r[c], float) and math.isnan(r[c]) else repr(r[c]) if isinstance(r[c], float)
                    else r[c] for c in cols])
    return str(write_text_atomic(out / "parameters.csv", buf.getvalue()))


def parameter_text(spec: StudySpec, prows: list[dict]) -> list[str]:
    """Compact per-parameter lines: one block per value of the axes other than ``method``, one
    line per parameter (lengths in mm, angles in mrad), one column per method."""
    if not prows:
        return []
    axes = [a for a in spec.axes if a != "method"]
    methods = []
    for r in prows:
        m = r.get("method", "")
        if m not in methods:
            methods.append(m)
    blocks: dict = {}
    for r in prows:
        blocks.setdefault(tuple(r[a] for a in axes), {}).setdefault(r["parameter"], {})[r.get("method", "")] = r
    has_thesis = any(math.isfinite(r["thesis_reported"]) for r in prows)

    def f(v):
        return "-" if not math.isfinite(v) else f"{v * 1e3:.4g}"

    lines = ["parameters: deviation from nominal, mm / mrad (true, noise-free = the value the identifiable "
             "parameters take with exact data, identified mean ± Monte Carlo std)"]
    for key, params in blocks.items():
        title = " ".join(f"{a}={_fmt(v)}" for a, v in zip(axes, key)) or "all cells"
        head = ["param", "true", "ident", "noise-free"] + [f"{m or 'identified'} mean ± std" for m in methods]
        head += ["thesis"] if has_thesis else []
        head += ["note"]
        body = []
        for n, by_m in params.items():
            r0 = next(iter(by_m.values()))
            row = [n, f(r0["true_deviation"]), r0["identifiable"], f(r0["noise_free"])]
            for m in methods:
                r = by_m.get(m)
                if r is None or not math.isfinite(r["identified_mean"]):
                    row.append("-")
                else:
                    sd = f" ± {r['mc_std'] * 1e3:.2g}" if math.isfinite(r["mc_std"]) else ""
                    row.append(f"{r['identified_mean'] * 1e3:.4g}{sd}")
            if has_thesis:
                row.append(f(r0["thesis_reported"]))
            row.append(r0["note"].split(" (")[0])
            body.append(row)
        widths = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(head)]
        lines.append(f"[{title}]")
        lines.append("  " + "  ".join(h.rjust(w) if i < len(head) - 1 else h for i, (h, w) in enumerate(zip(head, widths))))
        lines.extend("  " + "  ".join(c.rjust(w) if i < len(head) - 1 else c for i, (c, w) in enumerate(zip(b, widths)))
                     for b in body)
    return lines


def parameter_spread(spec: StudySpec, table: list[dict]) -> list[dict]:
    """Per cell: geometric mean, over the parameters identified in every run of every cell (so the
    cells compare like with like), of the predicted std and of the Monte Carlo RMS error (SI), and
    the ratio of the predicted std to the first cell's."""
    rows_ok = [r for r in table if not r.get("error")]
    if not rows_ok:
        return []
    names = sorted(k[4:] for k in rows_ok[0] if k.startswith("std:"))
    names = [n for n in names
             if all(r.get(f"std:{n}") is not None and math.isfinite(r[f"std:{n}"]) and r[f"std:{n}"] > 0 for r in rows_ok)]
    if not names:
        return []
    groups: dict = {}
    for r in rows_ok:
        groups.setdefault(tuple(r[a] for a in spec.axes), []).append(r)
    out = []
    for key, rows in groups.items():
        pred = np.array([[r[f"std:{n}"] for n in names] for r in rows]).mean(axis=0)
        mc = np.sqrt(np.array([[r[f"err:{n}"] ** 2 for n in names] for r in rows]).mean(axis=0))
        out.append({**dict(zip(spec.axes, key)), "n_params": len(names),
                    "predicted_std_geomean": float(np.exp(np.mean(np.log(pred)))),
                    "mc_rms_error_geomean": float(np.exp(np.mean(np.log(np.maximum(mc, 1e-300)))))})
    for o in out:
        o["predicted_std_vs_first"] = o["predicted_std_geomean"] / out[0]["predicted_std_geomean"]
    return out


# ----------------------------------------------------------------------------- tables
def _columns(spec: StudySpec, table: list[dict]) -> list[str]:
    fixed = ["study", *spec.axes, "repetition", "seed", "error", "converged", "iterations", "seconds", "n_free"]
    rest = []
    for row in table:
        for k in row:
            if k not in fixed and k not in rest:
                rest.append(k)
    pre = [k for k in rest if ":" not in k]
    par = sorted((k for k in rest if ":" in k), key=lambda k: (k.split(":", 1)[1], k))
    return fixed + pre + par


def _metric_columns(spec, cols):
    skip = {"study", "repetition", "seed", "error", *spec.axes}
    return [c for c in cols if c not in skip]


def _value(row, c):
    v = row.get(c)
    if v is None or v == "":
        return float("nan")
    return float(v)


def write_outputs(spec: StudySpec, table: list[dict], out: Path, plots: bool = True) -> dict:
    """results.csv/.parquet, summary.csv and plots from the run rows; returns {kind: path}."""
    cols = _columns(spec, table)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for row in table:
        w.writerow(["" if row.get(c) is None or (isinstance(row.get(c), float) and math.isnan(row[c])) else
                    repr(row[c]) if isinstance(row.get(c), float) else row[c] for c in cols])
    files = {"results_csv": str(write_text_atomic(out / "results.csv", buf.getvalue()))}
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq

        numeric = set(_metric_columns(spec, cols)) - {"converged", "iterations", "n_free"}
        data = {}
        for c in cols:
            vals = [row.get(c) for row in table]
            if c in numeric:
                data[c] = pa.array([_value(row, c) for row in table], pa.float64())
            else:
                data[c] = pa.array(vals)
        sink = io.BytesIO()
        pq.write_table(pa.table(data), sink)
        files["results_parquet"] = str(write_bytes_atomic(out / "results.parquet", sink.getvalue()))
    except ImportError:  # pragma: no cover
        pass
    srows = summary_rows(spec, table, cols)
    buf = io.StringIO()
    scols = [*spec.axes, "metric", "n", "mean", "std", "rms", "p05", "p50", "p95"]
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(scols)
    for r in srows:
        w.writerow([repr(r[c]) if isinstance(r[c], float) else r[c] for c in scols])
    files["summary_csv"] = str(write_text_atomic(out / "summary.csv", buf.getvalue()))
    files["plots"] = write_plots(spec, table, cols, out) if plots else []
    return files


def _group(spec, table):
    groups = {}
    for row in table:
        groups.setdefault(tuple(row.get(a) for a in spec.axes), []).append(row)
    return groups


def _stats(v: np.ndarray) -> dict:
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {"n": 0, "mean": float("nan"), "std": float("nan"), "rms": float("nan"), "p05": float("nan"),
                "p50": float("nan"), "p95": float("nan")}
    p = np.percentile(v, [5, 50, 95])
    return {"n": int(v.size), "mean": float(v.mean()), "std": float(v.std(ddof=1)) if v.size > 1 else float("nan"),
            "rms": float(np.sqrt(np.mean(v**2))), "p05": float(p[0]), "p50": float(p[1]), "p95": float(p[2])}


def summary_rows(spec: StudySpec, table: list[dict], cols=None) -> list[dict]:
    """Long summary: one dict per (cell, metric) with n, mean, std, rms, p05, p50, p95."""
    cols = cols or _columns(spec, table)
    out = []
    for key, rows in _group(spec, table).items():
        for c in _metric_columns(spec, cols):
            st = _stats(np.array([_value(r, c) for r in rows]))
            out.append({**dict(zip(spec.axes, key)), "metric": c, **st})
    return out


def cell_summary(spec: StudySpec, table: list[dict]) -> list[dict]:
    """Per cell: the axes, n_runs, n_failed, converged fraction and {figure: {mean, std, p05, p95}}
    of the main figures and of the mean predicted / Monte Carlo parameter std."""
    out = []
    for key, rows in _group(spec, table).items():
        d = {**dict(zip(spec.axes, key)), "n_runs": len(rows), "n_failed": sum(1 for r in rows if r.get("error")),
             "converged": float(np.mean([bool(r.get("converged")) for r in rows]))}
        figs = {}
        for c, _, _ in MAIN_FIGURES:
            if any(c in r for r in rows):
                st = _stats(np.array([_value(r, c) for r in rows]))
                figs[c] = {k: st[k] for k in ("mean", "std", "p05", "p95")}
        d["figures"] = figs
        out.append(d)
    return out


def summary_text(spec: StudySpec, res: dict) -> str:
    """One screen: per cell mean ± std of the main figures."""
    figs = [(c, lab, f) for c, lab, f in MAIN_FIGURES if any(c in s["figures"] for s in res["summary"])]
    head = [*spec.axes, "runs", "conv"] + [lab for _, lab, _ in figs]
    lines = [f"study {spec.name}: {res['n_runs']} runs ({res['n_computed']} computed, {res['n_reused']} reused, "
             f"{res['n_failed']} failed) -> {res['out_dir']}"]
    body = []
    for s in res["summary"]:
        cells = [_fmt(s[a]) for a in spec.axes] + [str(s["n_runs"] - s["n_failed"]), f"{s['converged']:.2f}"]
        for c, _, f in figs:
            v = s["figures"].get(c)
            if v is None or not math.isfinite(v["mean"]):
                cells.append("-")
            elif c == "cond":
                cells.append(f"{v['mean']:.3g}")
            else:
                sd = f" ± {v['std'] * f:.2g}" if math.isfinite(v["std"]) else ""
                cells.append(f"{v['mean'] * f:.3g}{sd}")
        body.append(cells)
    widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h) for i, h in enumerate(head)]
    lines.append("  ".join(h.rjust(w) for h, w in zip(head, widths)))
    lines.extend("  ".join(c.rjust(w) for c, w in zip(b, widths)) for b in body)
    spread = res.get("parameter_spread") or []
    if spread:
        lines.append("parameter spread (geometric mean over the identified parameters; SI units):")
        for o in spread:
            cell = " ".join(f"{a}={_fmt(o[a])}" for a in spec.axes)
            lines.append(f"  {cell}: predicted std {o['predicted_std_geomean']:.3g}, Monte Carlo RMS error "
                         f"{o['mc_rms_error_geomean']:.3g} ({o['n_params']} parameters); predicted std x"
                         f"{o['predicted_std_vs_first']:.3g} of the first cell")
    if res.get("parameters") and ("trial" in spec.axes or len(res["summary"]) <= 2):
        lines.extend(parameter_text(spec, res["parameters"]))
    return "\n".join(lines)


# ----------------------------------------------------------------------------- plots
def _save_fig(fig, path: Path) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return str(write_bytes_atomic(path, buf.getvalue()))


def write_plots(spec: StudySpec, table: list[dict], cols, out: Path) -> list[str]:
    """PNG plots: for each swept axis, the main figures (median, 5-95 % band; one line per value
    of the other axes) and the Monte Carlo std of each identified parameter."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    ok = [r for r in table if not r.get("error")]
    if not ok:
        return paths
    for names, _ in spec.sweep:
        axis = names[0]  # linked axes (one group) are plotted against the group's first axis
        values = []
        for r in ok:
            if r[axis] not in values:
                values.append(r[axis])
        numeric = all(isinstance(v, (int, float)) for v in values)
        if numeric:
            values = sorted(values)
        xs = np.array(values, float) if numeric else np.arange(len(values), dtype=float)
        others = [a for a in spec.axes if a not in names]
        series = {}
        for r in ok:
            series.setdefault(tuple(r[a] for a in others), []).append(r)
        for c, lab, f in MAIN_FIGURES:
            if c not in cols:
                continue
            fig, ax = plt.subplots(figsize=(6, 4))
            for skey, rows in series.items():
                med, lo, hi = [], [], []
                for v in values:
                    vals = np.array([_value(r, c) for r in rows if r[axis] == v]) * f
                    vals = vals[np.isfinite(vals)]
                    p = np.percentile(vals, [5, 50, 95]) if vals.size else [np.nan] * 3
                    lo.append(p[0]), med.append(p[1]), hi.append(p[2])
                label = ", ".join(f"{a}={_fmt(v)}" for a, v in zip(others, skey)) or "median"
                line, = ax.plot(xs, med, "o-", label=label)
                ax.fill_between(xs, lo, hi, color=line.get_color(), alpha=0.2)
            ax.set_xlabel(axis)
            ax.set_ylabel(lab)
            if not numeric:
                ax.set_xticks(xs, [str(v) for v in values])
            if c == "cond":
                ax.set_yscale("log")
            ax.set_title(f"{spec.name}: {lab} (median, 5-95 %)")
            ax.legend(fontsize=7)
            ax.grid(alpha=0.3)
            paths.append(_save_fig(fig, out / f"{c}_vs_{axis}.png"))
        errs = [c for c in cols if c.startswith("err:")]
        if errs and len(series) == 1:
            fig, axs = plt.subplots(1, 2, figsize=(10, 4))
            rows = next(iter(series.values()))
            for c in errs:
                sd = []
                for v in values:
                    vals = np.array([_value(r, c) for r in rows if r[axis] == v])
                    vals = vals[np.isfinite(vals)]
                    sd.append(vals.std(ddof=1) * 1e3 if vals.size > 1 else np.nan)
                if not np.any(np.isfinite(sd)):
                    continue
                name = c[4:]
                is_angle = any(t in name.split(".")[-1] for t in ("alpha", "psi", "beta", "theta")) or name.startswith("q0")
                axs[1 if is_angle else 0].plot(xs, sd, "o-", label=name)
            for a, lab in zip(axs, ("length parameters: std [mm]", "angle parameters: std [mrad]")):
                a.set_xlabel(axis)
                a.set_ylabel(lab)
                a.set_yscale("log")
                if not numeric:
                    a.set_xticks(xs, [str(v) for v in values])
                if a.lines:
                    a.legend(fontsize=6, ncol=2)
                a.grid(alpha=0.3)
            fig.suptitle(f"{spec.name}: Monte Carlo std of identified parameters")
            paths.append(_save_fig(fig, out / f"param_std_vs_{axis}.png"))
        else:
            plt.close("all")
    return paths


__all__ = ["StudySpec", "load_study", "run_study", "run_cell", "study_cells", "run_seed", "cell_key", "scene_with",
           "scene_with_trial", "summary_rows", "cell_summary", "parameter_table"]
