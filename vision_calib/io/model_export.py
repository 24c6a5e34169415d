"""Calibrated robot model files: the robot file the scene used + the identified parameter values.

Format (YAML)::

    format: vision_calib.calibrated_model/1
    kind: serial | h4
    robot: /abs/path/to/robots/rx90.yaml     # the nominal robot file
    model: "12"                              # H4 only
    mounts: {left: T_target_base, right: T_flange_cam}   # serial only (+ nominal mount rotations)
    units: {length: m, angle: rad}
    parameters: {name: {value: .., std: .. or null, identified: true|false}}

:func:`load_calibrated_model` returns a robot (SerialChain or H4Robot) whose nominal values are
the identified ones, usable everywhere a robot is.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from ..config import Section, load_yaml
from ..errors import ConfigError, ParameterError
from .atomic import write_text_atomic

FORMAT = "vision_calib.calibrated_model/1"


def calibrated_model_dict(setup, x, std=None, free=None) -> dict:
    """JSON/YAML-ready description of setup's robot with parameter values x (n,) SI."""
    ps = setup.params
    std = np.full(len(ps), np.nan) if std is None else np.asarray(std, float)
    free = ps.free if free is None else np.asarray(free, bool)
    d = {"format": FORMAT, "kind": setup.kind, "units": {"length": "m", "angle": "rad"}}
    if setup.kind == "h4":
        d["model"] = setup.robot.model
        d["variant"] = setup.meta.get("variant")  # E..H share one arm length: the loader needs it
        d["shared_L"] = bool(setup.robot.shared_L)
        d["robot"] = str(Path(setup.meta.get("robot_path", "")).resolve()) if setup.meta.get("robot_path") else None
        d["tilts"] = {"R_BC0": setup.robot.R_BC0.tolist(), "R_ME0": setup.robot.R_ME0.tolist()}
    else:
        ch = setup.chain
        d["robot"] = str(Path(setup.meta.get("robot_path", "")).resolve()) if setup.meta.get("robot_path") else None
        d["mounts"] = {"left": ch.left, "right": ch.right, "left_R_nominal": ch.left_R_nominal.tolist(),
                       "right_R_nominal": ch.right_R_nominal.tolist()}
    d["parameters"] = {
        n: {"value": float(v), "std": None if not np.isfinite(s) else float(s), "identified": bool(f)}
        for n, v, s, f in zip(ps.names, x, std, free)
    }
    return d


def write_calibrated_model(path, setup, x, std=None, free=None) -> Path:
    return write_text_atomic(path, yaml.safe_dump(calibrated_model_dict(setup, x, std, free), sort_keys=False))


def load_calibrated_model(path):
    """Robot (SerialChain or H4Robot) with the file's parameter values as nominal."""
    path = Path(path)
    top = Section(load_yaml(path), path)
    if top.get("format", str) != FORMAT:
        raise top.error("format", f"expected {FORMAT!r}")
    kind = top.get("kind", str, choices=("serial", "h4"))
    robot_path = top.path_value("robot")
    values = {}
    ps_sec = top.section("parameters")
    for name in ps_sec.keys():
        values[str(name)] = ps_sec.section(name).get("value", float)
    if kind == "h4":
        from ..kinematics.h4 import load_h4_robot

        robot = load_h4_robot(robot_path, model=str(top.get("model", str, "12")))
        variant = top.get("variant", str, None)
        if variant:
            robot = robot.variant(variant)
        elif top.get("shared_L", bool, False) and not robot.shared_L:
            robot = robot._share_L()
        tilts = top.section("tilts", default={})
        from dataclasses import replace

        if "R_BC0" in tilts:
            robot = replace(robot, R_BC0=np.asarray(tilts.get("R_BC0", list), float),
                            R_ME0=np.asarray(tilts.get("R_ME0", list), float))
        params = robot.params
    else:
        from ..experiment.scene import _remount
        from ..kinematics.serial import load_serial_robot

        chain = load_serial_robot(robot_path)
        m = top.section("mounts")
        chain = _remount(chain, m.get("left", str), m.get("right", str), np.eye(4), np.eye(4))
        from dataclasses import replace

        chain = replace(chain, left_R_nominal=np.asarray(m.get("left_R_nominal", list), float),
                        right_R_nominal=np.asarray(m.get("right_R_nominal", list), float))
        robot = chain
        params = chain.params
    missing = sorted(set(params.names) - set(values))
    if missing:
        raise ConfigError(f"{path}: parameters: missing values for {missing}")
    try:
        params = params.with_nominal({n: values[n] for n in params.names})
    except ParameterError as exc:
        raise ConfigError(f"{path}: parameters: {exc}") from None
    if kind == "h4":
        return robot.with_values(params.nominal)
    return robot.with_params(params)
