"""Calibrated robot model files: the robot file the scene used + the identified parameter values.

Format (YAML)::

    format: vision_calib.calibrated_model/1
    kind: serial | h4 | ...                  # a robot kind of vision_calib.rig.registry
    robot: robot/rx90.yaml                   # the nominal robot file: a copy next to this file, relative to it
                                             # (io.portable: the folder stays whole when moved)
    # kind-specific keys (Setup.model_dict): serial: mounts {left, right, left_R_nominal, right_R_nominal};
    # h4: model, variant, shared_L, tilts {R_BC0, R_ME0}
    units: {length: m, angle: rad}
    parameters: {name: {value: .., std: .. or null, identified: true|false}}

:func:`load_calibrated_model` returns the kind's robot (SerialChain, H4Robot, ...) whose nominal values are
the identified ones, usable everywhere a robot is.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

from ..config import Section, load_yaml
from ..errors import ConfigError, ParameterError
from ..serialize import write_text_atomic

FORMAT = "vision_calib.calibrated_model/1"


def calibrated_model_dict(setup, x, std=None, free=None, robot_ref: str | None = None) -> dict:
    """JSON/YAML-ready description of setup's robot with parameter values x (n,) SI: the common part
    here, the kind-specific part from ``setup.model_dict()``. robot_ref: the ``robot`` entry (a path relative
    to the file written; :func:`write_calibrated_model` copies the robot file and gives it), else the robot
    file's name only (never an absolute path)."""
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
    return d


def write_calibrated_model(path, setup, x, std=None, free=None) -> Path:
    """Write the calibrated-model file ``path`` and a copy of the robot file it refers to
    (``<path's folder>/robot/<robot file name>``, named relatively): the folder can be moved whole."""
    from .portable import copy_robot_file

    robot_path = setup.meta.get("robot_path")
    ref = copy_robot_file(robot_path, Path(path).parent) if robot_path else None
    return write_text_atomic(path, yaml.safe_dump(calibrated_model_dict(setup, x, std, free, ref), sort_keys=False))


def load_calibrated_model(path):
    """The robot of a calibrated-model file (its kind's robot object, e.g. SerialChain or H4Robot)
    with the file's parameter values as nominal."""
    from ..rig.registry import get_kind

    path = Path(path)
    top = Section(load_yaml(path), path)
    if top.get("format", str) != FORMAT:
        raise top.error("format", f"expected {FORMAT!r}")
    kind = get_kind(top.get("kind", str), where=top.where("kind"))
    ps_sec = top.section("parameters")
    values = {str(name): ps_sec.section(name).get("value", float) for name in ps_sec.keys()}
    robot = kind.load_model(top, top.path_value("robot"))
    missing = sorted(set(robot.params.names) - set(values))
    if missing:
        raise ConfigError(f"{path}: parameters: missing values for {missing}")
    try:
        params = robot.params.with_nominal({n: values[n] for n in robot.params.names})
    except ParameterError as exc:
        raise ConfigError(f"{path}: parameters: {exc}") from None
    return replace(robot, params=params)
