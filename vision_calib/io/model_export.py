"""Calibrated robot model files: the robot file the scene used + the identified parameter values, their full
covariance, what was fixed and what the base-parameter reduction folded, and the joint offsets a controller
can take.

Format (YAML)::

    format: vision_calib.calibrated_model/2  # /1 (no covariance, fixed, folded, joint_offsets) is still read
    kind: serial | h4 | ...                  # a robot kind of vision_calib.rig.registry
    robot: robot/rx90.yaml                   # the nominal robot file: a copy next to this file, relative to it
                                             # (io.portable: the folder stays whole when moved)
    # kind-specific keys (Setup.model_dict): serial: mounts {left, right, left_R_nominal, right_R_nominal};
    # h4: model, variant, shared_L, tilts {R_BC0, R_ME0}
    units: {length: m, angle: rad}
    parameters: {name: {value: .., std: .. or null, identified: true|false}}
    covariance:                              # of the identified parameters (SI: m, rad), from the identification
      names: [d2, theta2, ...]               # the order of the rows and columns
      matrix: [[..], ..]                     # symmetric, positive semi-definite
    fixed:                                   # every parameter not identified, at its value
      d3: {value: 0.0, prior_std: null, reason: "fixed: redundant with d2 (...)"}
    priors: {name: std}                      # identified parameters that also had a prior row (e.g. H4 tilts)
    folded:                                  # base-parameter reduction (identify.identifiability couplings):
      - {parameter: q0_2, into: {j2.rz: 1.0}}  # a deviation of `parameter` is absorbed as sum(ratio * base
                                               # parameter), SI ratios; the parameter stays at its value
    joint_offsets:                           # robots with kinematics.protocols.JointOffsetForm
      convention: "..."                      # model joint value = controller reading + offset
      offsets: {q1: {parameter: q0_1, offset: .., unit: rad}, ...}

:func:`load_calibrated_model` returns the kind's robot (SerialChain, H4Robot, ...) whose nominal values are
the identified ones, usable everywhere a robot is; :func:`read_calibrated_model` returns everything in the file
(:class:`CalibratedModel`: both robots, the full covariance, fixed / folded parameters, notes). Files without a
covariance (format 1) give a diagonal covariance from the std, with a note saying so.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..config import Section, load_yaml, safe_dump
from ..errors import ConfigError, ParameterError
from ..serialize import write_text_atomic

FORMAT = "vision_calib.calibrated_model/2"
#: formats :func:`read_calibrated_model` reads (the first has no covariance, fixed, folded or joint offsets)
READ_FORMATS = ("vision_calib.calibrated_model/1", FORMAT)
#: the meaning of ``joint_offsets`` (written into the file)
OFFSET_CONVENTION = ("model joint value = controller joint reading + offset (offset = calibrated - nominal joint "
                     "zero, equivalent joint-offset form: every rotation about / translation along a joint's own "
                     "axis at its origin carried by its offset); the nominal kinematics fed with reading + offset "
                     "turn each joint as the calibrated model does; the other corrections need the full model "
                     "(URDF, DH table, UR kinematics YAML)")
#: |asymmetry| and negative eigenvalue tolerated in a read covariance, relative to its largest diagonal entry
COV_TOL_REL = 1e-9


def calibrated_model_dict(setup, x, std=None, free=None, robot_ref: str | None = None, result=None, problem=None,
                          identifiability: dict | None = None) -> dict:
    """JSON/YAML-ready description of setup's robot with parameter values x (n,) SI: the common part
    here, the kind-specific part from ``setup.model_dict()``. robot_ref: the ``robot`` entry (a path relative
    to the file written; :func:`write_calibrated_model` copies the robot file and gives it), else the robot
    file's name only (never an absolute path). result (``identify.IdentificationResult``), problem
    (``IdentificationProblem``) and identifiability (``IdentifiabilityReport.to_dict()``): the fit, for the
    ``covariance``, ``fixed``, ``priors`` and ``folded`` entries (each optional)."""
    ps = setup.params
    std = np.full(len(ps), np.nan) if std is None else np.asarray(std, float)
    free = ps.free if free is None else np.asarray(free, bool)
    robot_path = setup.meta.get("robot_path")
    d = {"format": FORMAT, "kind": setup.kind, "units": {"length": "m", "angle": "rad"},
         "robot": robot_ref if robot_ref is not None else (Path(robot_path).name if robot_path else None),
         **setup.model_dict()}
    d["parameters"] = {
        n: {"value": float(v), "std": None if not np.isfinite(s) else float(s), "identified": bool(f)}
        for n, v, s, f in zip(ps.names, x, std, free)
    }
    d.update(fit_entries(setup, x, free, result, problem, identifiability))
    return d


def fit_entries(setup, x, free, result=None, problem=None, identifiability: dict | None = None) -> dict:
    """The ``covariance``, ``fixed``, ``priors`` and ``folded`` entries (module docstring) of a fit of setup's
    parameters: x (n,) values, free (n,) bool; result.covariance (n_free, n_free) in ``free`` order (left out
    when it does not match); problem: its prior rows and prior std; identifiability: the couplings."""
    names = setup.params.names
    out = {}
    fi = np.flatnonzero(free)
    cov = None if result is None else np.asarray(getattr(result, "covariance", None), float)
    if cov is not None and cov.shape == (fi.size, fi.size) and fi.size and np.all(np.isfinite(cov)):
        cov = 0.5 * (cov + cov.T)
        out["covariance"] = {"names": [names[i] for i in fi], "matrix": [[float(v) for v in row] for row in cov]}
    prior = {}
    if problem is not None and problem.prior_std is not None:
        sd = np.asarray(problem.prior_std, float)
        prior = {n: float(sd[names.index(n)]) for n in problem.prior_rows if n in names}
    folded = []
    for c in (identifiability or {}).get("couplings", []):
        if c["parameter"] in names and not free[names.index(c["parameter"])]:
            folded.append({"parameter": c["parameter"],
                           "into": {k: float(v) for k, v in c.get("combination_si", {}).items()},
                           **({"no_effect": True} if c.get("no_effect") else {})})
    why = {f["parameter"]: ("no effect on the measurements" if f.get("no_effect") else
                            "not identifiable from the poses: its deviation is absorbed as "
                            + (" + ".join(f"{v:+.4g}*{k}" for k, v in f["into"].items()) or "nothing"))
           for f in folded}
    fixed = {}
    for i, n in enumerate(names):
        if not free[i]:
            fixed[n] = {"value": float(x[i]), "prior_std": prior.get(n), "reason": why.get(n) or setup.fixed_note(n)}
    if fixed:
        out["fixed"] = fixed
    free_prior = {n: s for n, s in prior.items() if free[names.index(n)]}
    if free_prior:
        out["priors"] = free_prior
    if folded:
        out["folded"] = folded
    return out


def write_calibrated_model(path, setup, x, std=None, free=None, result=None, problem=None,
                           identifiability: dict | None = None) -> Path:
    """Write the calibrated-model file ``path`` and a copy of the robot file it refers to
    (``<path's folder>/robot/<robot file name>``, named relatively): the folder can be moved whole.
    result / problem / identifiability: the fit (:func:`calibrated_model_dict`): its covariance, fixed and folded
    parameters. The joint offsets are added for robots with ``kinematics.protocols.JointOffsetForm``."""
    from .portable import copy_robot_file

    path = Path(path)
    robot_path = setup.meta.get("robot_path")
    ref = copy_robot_file(robot_path, path.parent) if robot_path else None
    d = calibrated_model_dict(setup, x, std, free, ref, result, problem, identifiability)
    if ref is not None:
        offsets = _joint_offsets(Section(d, path), path.parent / ref, setup.params.values(x))
        if offsets:
            d["joint_offsets"] = {"convention": OFFSET_CONVENTION, "offsets": offsets}
    return write_text_atomic(path, safe_dump(d, sort_keys=False, default_flow_style=None))


def _robots(top: Section, robot_path: Path, values: dict):
    """(calibrated robot (nominal = ``values``), the robot file's nominal robot) of a calibrated-model file."""
    from ..rig.registry import get_kind

    kind = get_kind(top.get("kind", str), where=top.where("kind"))
    nominal = kind.load_model(top, robot_path)
    missing = sorted(set(nominal.params.names) - set(values))
    if missing:
        raise ConfigError(f"{top.file}: parameters: missing values for {missing}")
    try:
        params = nominal.params.with_nominal({n: values[n] for n in nominal.params.names})
    except ParameterError as exc:
        raise ConfigError(f"{top.file}: parameters: {exc}") from None
    return replace(nominal, params=params), nominal


def _joint_offsets(top: Section, robot_path: Path, values: dict) -> dict:
    """{"q<i>": {parameter, offset (calibrated - nominal, equivalent joint-offset form), unit}} of a robot with
    ``JointOffsetForm``; {} for another."""
    from ..kinematics.protocols import JointOffsetForm, PrismaticJoints

    cal, nom = _robots(top, robot_path, values)
    if not isinstance(cal, JointOffsetForm):
        return {}
    return joint_offsets(cal, cal.params.nominal, nom.params.nominal,
                         getattr(cal, "prismatic", None) if isinstance(cal, PrismaticJoints) else None)


def joint_offsets(robot, x, x_nominal, prismatic=None) -> dict:
    """The joint offsets a controller can take (:data:`OFFSET_CONVENTION`): {"q<i>": {"parameter": the offset
    parameter's name, "offset": calibrated - nominal joint zero of the equivalent joint-offset form (rad, or m
    for a prismatic joint), "unit"}} for a robot with ``kinematics.protocols.JointOffsetForm`` at parameter
    vectors x and x_nominal (n,) SI; prismatic: (n_joints,) bool or None."""
    _, off = robot.joint_offset_form(x)
    _, off0 = robot.joint_offset_form(x_nominal)
    d = off - off0
    rev = ~np.asarray(prismatic, bool) if prismatic is not None else np.ones(d.size, bool)
    d = np.where(rev, (d + np.pi) % (2 * np.pi) - np.pi, d)
    names = robot.params.names
    param = [next((c for c in (f"q0_{i}", f"theta{i}") if c in names), None) for i in range(1, d.size + 1)]
    return {f"q{i + 1}": {"parameter": param[i], "offset": float(d[i]), "unit": "rad" if rev[i] else "m"}
            for i in range(d.size)}


@dataclass(frozen=True)
class CalibratedModel:
    """Everything in a calibrated-model file (read by :func:`read_calibrated_model`).

    robot: the kind's robot with the identified values as nominal; nominal_robot: the robot file's own values
    (mount parameters: the robot file's, usually identity: take the calibrated mounts for a nominal arm).
    names / x / std (n,): parameter names, values and std (NaN: not identified or unknown), SI; free (n,) bool:
    identified. covariance (n, n) SI in ``names`` order: the file's covariance of the identified parameters,
    prior_std^2 on the diagonal of fixed parameters that have one, zeros elsewhere (a file without covariance:
    diag(std^2), see ``notes``). fixed {name: {value, prior_std, reason}}, folded [{parameter, into}],
    joint_offsets {q<i>: {parameter, offset, unit}} (empty when the file has none). notes: what the reader
    assumed (e.g. no covariance in the file)."""

    path: Path
    kind: str
    robot: object
    nominal_robot: object
    names: tuple
    x: np.ndarray
    std: np.ndarray
    free: np.ndarray
    covariance: np.ndarray
    covariance_source: str
    fixed: dict = field(default_factory=dict)
    folded: tuple = ()
    joint_offsets: dict = field(default_factory=dict)
    notes: tuple = ()
    doc: dict = field(default_factory=dict, repr=False)

    def value(self, name: str) -> float:
        return float(self.x[self.names.index(name)])


def _read_covariance(top: Section, names: tuple, free: np.ndarray, std: np.ndarray) -> tuple[np.ndarray, str, list]:
    """(covariance (n, n), source, notes) of the file's ``covariance`` entry, or diag(std^2) without one."""
    n = len(names)
    C = np.zeros((n, n))
    notes = []
    if "covariance" not in top:
        s = np.where(np.isfinite(std) & free, std, 0.0)
        C[np.diag_indices(n)] = s**2
        unknown = [nm for nm, f, sd in zip(names, free, std) if f and not np.isfinite(sd)]
        notes.append("the file has no covariance (written before format 2, or the fit gave none): the covariance is "
                     "diagonal, from the parameters' std; their correlations are ignored"
                     + (f"; no std for {unknown} (taken as 0)" if unknown else ""))
        return C, "diagonal (std of the parameters; no covariance in the file)", notes
    cs = top.section("covariance").check_known(("names", "matrix"))
    cn = [str(v) for v in cs.get("names", list)]
    bad = [v for v in cn if v not in names]
    if bad or len(set(cn)) != len(cn):
        raise cs.error("names", f"unknown or repeated parameter names {bad or cn}")
    try:
        M = np.asarray(cs.get("matrix", list), float)
    except (TypeError, ValueError):
        raise cs.error("matrix", "expected a square list of lists of numbers") from None
    k = len(cn)
    if M.shape != (k, k) or not np.all(np.isfinite(M)):
        raise cs.error("matrix", f"expected a finite {k} x {k} matrix (one row per name), got shape {M.shape}")
    scale = max(float(np.max(np.abs(np.diag(M)))) if k else 0.0, np.finfo(float).tiny)
    if np.max(np.abs(M - M.T), initial=0.0) > COV_TOL_REL * scale:
        raise cs.error("matrix", "not symmetric")
    if k and np.linalg.eigvalsh(0.5 * (M + M.T))[0] < -COV_TOL_REL * scale * k:
        raise cs.error("matrix", "not positive semi-definite")
    idx = [names.index(v) for v in cn]
    C[np.ix_(idx, idx)] = 0.5 * (M + M.T)
    return C, "identification (full covariance of the identified parameters)", notes


def read_calibrated_model(path) -> CalibratedModel:
    """The content of a calibrated-model file (:class:`CalibratedModel`); ConfigError naming the file and the key
    on a bad entry."""
    path = Path(path)
    top = Section(load_yaml(path), path)
    fmt = top.get("format", str)
    if fmt not in READ_FORMATS:
        raise top.error("format", f"expected one of {', '.join(READ_FORMATS)}, got {fmt!r}")
    ps_sec = top.section("parameters")
    values, stds, ident = {}, {}, {}
    for name in ps_sec.keys():
        p = ps_sec.section(name)
        values[str(name)] = p.get("value", float)
        stds[str(name)] = p.get("std", float, float("nan"))
        ident[str(name)] = p.get("identified", bool, False)
    robot, nominal = _robots(top, top.path_value("robot"), values)
    names = tuple(robot.params.names)
    x = robot.params.nominal.copy()
    std = np.array([stds[n] for n in names])
    free = np.array([ident[n] for n in names], bool)
    C, source, notes = _read_covariance(top, names, free, std)
    fixed = {str(k): dict(v) for k, v in (top.get("fixed", dict, {}) or {}).items()}
    for n, f in fixed.items():
        if n not in names:
            raise top.error(f"fixed.{n}", "not a parameter of the model")
        ps = f.get("prior_std")
        if ps is not None:
            if not (isinstance(ps, (int, float)) and np.isfinite(ps) and ps >= 0):
                raise top.error(f"fixed.{n}.prior_std", f"expected a number >= 0 or null, got {ps!r}")
            C[names.index(n), names.index(n)] += float(ps) ** 2
    folded = tuple(dict(f) for f in (top.get("folded", list, []) or []))
    offs = top.section("joint_offsets", default={}).get("offsets", dict, {}) or {}
    return CalibratedModel(path, top.get("kind", str), robot, nominal, names, x, std, free, C, source, fixed, folded,
                           {str(k): dict(v) for k, v in offs.items()}, tuple(notes), top.data)


def load_calibrated_model(path):
    """The robot of a calibrated-model file (its kind's robot object, e.g. SerialChain or H4Robot)
    with the file's parameter values as nominal (:func:`read_calibrated_model`'s ``robot``)."""
    return read_calibrated_model(path).robot
