"""H4 scene-file loader (scenes/robots/h4.yaml): geometry, external parameters, workspace,
column scales. Split from :mod:`.h4` (imported from it, never the reverse)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import ConfigError, ParameterError
from ..frames import rot_x, rot_y, rot_z
from .h4 import (
    DEFAULT_CENTER,
    DEFAULT_SIZE,
    DEFAULT_THETA_DEG,
    EXTERNAL_NAMES,
    MODEL12_NAMES,
    H4Robot,
    param_kind,
    model31_names,
)
from .h4_variants import to_model31, variant
from .params import ParameterSet


def _get(d, key, path, where, kind=float):
    if key not in d:
        raise ConfigError(f"{path}: missing key '{where}{key}'")
    try:
        if kind is float:
            return float(d[key])
        arr = np.asarray(d[key], float)
        if arr.shape != kind:
            raise ValueError
        return arr
    except (TypeError, ValueError):
        raise ConfigError(f"{path}: key '{where}{key}' must be {'a number' if kind is float else f'a list of {kind[0]} numbers'}, got {d[key]!r}") from None


_FRAME_KEYS = {"x", "y", "z", "theta_deg", "tilt_rpy_deg"}
#: key tree of an H4 robot file (config.check_keys): unknown keys are errors, closest key suggested
_H4_SCHEMA = {
    "kind": None, "model": None, "name": None, "description": None, "source": None, "notes": None,
    "geometry": {"R", "L", "l", "h", "d", "alpha_deg", "q0_deg"},
    "external": {"B_T_C": _FRAME_KEYS, "M_T_E": _FRAME_KEYS},
    "workspace": {"center", "size", "theta_deg"},
    "scale": {"length_m", "angle_deg"},
    "fixed": None,
}


def load_h4_robot(path, model: str | None = None) -> H4Robot:
    """Load an H4 scene file (see scenes/robots/h4.yaml; lengths m, angles in *_deg keys).
    model: "12" or "31" (default: the file's ``model``); model 31 is built from the model-12
    nominal by :func:`.h4_variants.to_model31`. Free mask: variant D (model 12) or H (model 31),
    then the file's optional ``fixed`` list of names is applied."""
    from ..config import parse_yaml

    path = Path(path)
    doc = parse_yaml(path, ConfigError, "H4 robot file")
    if not isinstance(doc, dict) or doc.get("kind") != "h4":
        raise ConfigError(f"{path}: expected a mapping with 'kind: h4'")
    from ..config import Section, check_keys

    check_keys(Section(doc, path), _H4_SCHEMA)
    g = doc.get("geometry")
    if not isinstance(g, dict):
        raise ConfigError(f"{path}: missing mapping 'geometry'")
    geo = {nm: _get(g, k, path, "geometry.") for nm, k in
           (("h4.R", "R"), ("h4.L", "L"), ("h4.l", "l"), ("h4.h", "h"))}  # fmt: skip
    d12 = _get(g, "d", path, "geometry.")
    alpha = np.deg2rad(_get(g, "alpha_deg", path, "geometry.", (4,)))
    q0 = np.deg2rad(_get(g, "q0_deg", path, "geometry.", (4,))) if "q0_deg" in g else np.zeros(4)
    for i in range(4):
        geo[f"h4.alpha{i + 1}"] = alpha[i]
        geo[f"q0_{i + 1}"] = q0[i]
    for k in ("h4.R", "h4.L", "h4.l", "h4.h"):
        if geo[k] <= 0:
            raise ConfigError(f"{path}: geometry.{k[3:]} must be > 0 (m), got {geo[k]}")
    ext = doc.get("external") or {}
    vals = dict(geo)
    tilts = {}
    for fr in ("B_T_C", "M_T_E"):
        e = ext.get(fr)
        if not isinstance(e, dict):
            raise ConfigError(f"{path}: missing mapping 'external.{fr}'")
        for c in "xyz":
            vals[f"{fr}.{c}"] = _get(e, c, path, f"external.{fr}.")
        vals[f"{fr}.theta"] = np.deg2rad(_get(e, "theta_deg", path, f"external.{fr}."))
        rpy = np.deg2rad(_get(e, "tilt_rpy_deg", path, f"external.{fr}.", (3,))) if "tilt_rpy_deg" in e else \
            np.array([np.pi, 0, 0])  # fmt: skip
        tilts[fr] = rot_z(rpy[2]) @ rot_y(rpy[1]) @ rot_x(rpy[0])
    names = MODEL12_NAMES + EXTERNAL_NAMES
    sc = Section(doc.get("scale") or {}, path, "scale")
    scale_len = sc.number("length_m", float, 1e-3, min=0, min_open=True, unit="m")
    scale_ang = np.deg2rad(sc.number("angle_deg", float, float(np.rad2deg(1e-3)), min=0, min_open=True, unit="deg"))
    kinds = [param_kind(n) for n in names]
    ps = ParameterSet.from_lists(names, [vals[n] for n in names], kinds,
                                 scale=[scale_len if k == "length" else scale_ang for k in kinds])  # fmt: skip
    ws = doc.get("workspace", {}) or {}
    center = _get(ws, "center", path, "workspace.", (3,)) if "center" in ws else DEFAULT_CENTER
    size = _get(ws, "size", path, "workspace.", (3,)) if "size" in ws else DEFAULT_SIZE
    th = tuple(Section(ws, path, "workspace").floats("theta_deg", None, np.asarray(DEFAULT_THETA_DEG, float)))
    robot = variant(H4Robot("12", ps, d12=d12, R_BC0=tilts["B_T_C"], R_ME0=tilts["M_T_E"], center=center, size=size,
                            theta_deg=th), "D")  # fmt: skip
    model = str(doc.get("model", "12")) if model is None else str(model)
    if model not in ("12", "31"):
        raise ConfigError(f"{path}: 'model' must be \"12\" or \"31\", got {model!r}")
    if model == "31":
        robot = to_model31(robot)
    fixed = doc.get("fixed") or []
    if fixed:
        try:
            robot = replace(robot, params=robot.params.fix([f for f in fixed if f in robot.names]))
        except ParameterError as e:
            raise ConfigError(f"{path}: key 'fixed': {e}") from None
        unknown = [f for f in fixed if f not in robot.names and f not in MODEL12_NAMES + model31_names()]
        if unknown:
            raise ConfigError(f"{path}: key 'fixed' names unknown parameters {unknown}")
    return robot
