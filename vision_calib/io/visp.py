"""Readers for ViSP files: camera XML (vpXmlParserCamera) and pose YAML (t + theta-u vectors)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .. import frames
from ..camera import CameraIntrinsics
from ..errors import ConfigError, DataError


def read_visp_camera_xml(path, camera_name: str | None = None) -> CameraIntrinsics:
    """ViSP camera XML -> CameraIntrinsics. px, py [px] -> fx, fy; u0, v0 -> cx, cy.

    ViSP's distortion model (kud/kdu, single radial term) differs from Brown–Conrady: only
    ``perspectiveProjWithoutDistortion`` or zero kud/kdu are accepted; a non-zero one raises
    ConfigError. camera_name selects a <camera> by <name> (default: the first)."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(f"{path}: cannot read ViSP camera XML ({exc})") from None
    cams = root.findall("camera")
    if camera_name is not None:
        cams = [c for c in cams if (c.findtext("name") or "").strip() == camera_name]
    if not cams:
        raise ConfigError(f"{path}: no <camera> element" + (f" named {camera_name!r}" if camera_name else ""))
    cam = cams[0]

    def num(el, key, where):
        txt = el.findtext(key)
        if txt is None:
            raise ConfigError(f"{path}: {where}: missing <{key}>")
        try:
            return float(txt)
        except ValueError:
            raise ConfigError(f"{path}: {where}: <{key}> is not a number ({txt!r})") from None

    w = int(num(cam, "image_width", "camera"))
    h = int(num(cam, "image_height", "camera"))
    models = cam.findall("model")
    if not models:
        raise ConfigError(f"{path}: camera: missing <model>")
    model = next((m for m in models if (m.findtext("type") or "").strip() == "perspectiveProjWithoutDistortion"),
                 models[0])
    mtype = (model.findtext("type") or "").strip()
    if mtype == "perspectiveProjWithDistortion":
        for key in ("kud", "kdu"):
            if model.findtext(key) is not None and num(model, key, "model") != 0.0:
                raise ConfigError(f"{path}: model {mtype}: non-zero <{key}> (ViSP radial model) is not supported")
    return CameraIntrinsics(w, h, num(model, "px", "model"), num(model, "py", "model"),
                            num(model, "u0", "model"), num(model, "v0", "model"))


def read_visp_pose_yaml(path) -> np.ndarray:
    """ViSP pose YAML (rows: 6, cols: 1, data: [tx, ty, tz (m), theta-u (rad)]) -> (4, 4) transform."""
    import yaml

    path = Path(path)
    try:
        d = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise DataError(f"{path}: cannot read ViSP pose YAML ({exc})") from None
    try:
        v = np.asarray(d["data"], dtype=float).reshape(-1)
    except (TypeError, KeyError, ValueError) as exc:
        raise DataError(f"{path}: key 'data' must hold 6 numbers (t [m], theta-u [rad]) ({exc})") from None
    if v.size != 6:
        raise DataError(f"{path}: key 'data' must hold 6 numbers (t [m], theta-u [rad]), got {v.size}")
    frames.check_finite(f"{path}: data", v)
    return frames.T_from_xyz_rotvec(v)
