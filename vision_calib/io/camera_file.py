"""camera.yaml: the output of ``vision-calib calibrate-camera`` (README "File formats").

The keys width, height, fx, fy, cx, cy, dist are exactly the ``camera:`` block of recording.yaml
(:meth:`CameraIntrinsics.to_dict`, px; dist = [k1, k2, p1, p2, k3]); the rest says how good they are::

    format: vision_calib.camera/1
    width: 1024
    height: 768
    fx: ..  fy: ..  cx: ..  cy: ..
    dist: [k1, k2, p1, p2, k3]
    std: {fx, fy, cx, cy, dist: [5]}     # 1-sigma, same units
    covariance: {names: [fx, fy, cx, cy, k1, k2, p1, p2, k3], matrix: 9 x 9}   # of those (std^2 on its diagonal)
    rms_px: 0.06                         # reprojection RMS, 2-D error per corner [px]
    n_views_used: 20
    n_views_rejected: 1
    coverage: {grid: [8, 6], fraction: 0.98, radius_frac: 0.87, warnings: [...]}
    warnings: [...]                      # coverage + views dropped as outliers
    views: [{name, n_corners, rms_px, used, reason}]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from ..camera import CameraIntrinsics
from ..config import Section, check_keys, load_yaml
from ..errors import ConfigError
from ..serialize import write_text_atomic

FORMAT = "vision_calib.camera/1"
_CAMERA_KEYS = ("width", "height", "fx", "fy", "cx", "cy", "dist")
_SCHEMA = {"format": None, **{k: None for k in _CAMERA_KEYS}, "std": None, "covariance": None, "distortion_px": None,
           "rms_px": None,
           "n_views_used": None,
           "n_views_rejected": None, "coverage": None, "warnings": None, "views": None}


def write_camera_yaml(path, result) -> Path:
    """Write an ``measure.intrinsics.IntrinsicsResult`` to path (atomic); views named by an absolute image path
    are named relative to the file's folder (io.portable), in ``views`` and ``warnings`` alike."""
    from .portable import relative_ref

    doc = {"format": FORMAT, **result.to_dict()}
    rel = {v["name"]: relative_ref(v["name"], Path(path).parent) for v in doc.get("views") or ()
           if isinstance(v.get("name"), str) and Path(v["name"]).is_absolute()}
    for v in doc.get("views") or ():
        v["name"] = rel.get(v.get("name"), v.get("name"))
    warnings = []
    for w in doc.get("warnings") or ():
        for a, r in sorted(rel.items(), key=lambda kv: -len(kv[0])):
            w = w.replace(a, r) if isinstance(w, str) else w
        warnings.append(w)
    if "warnings" in doc:
        doc["warnings"] = warnings
    return write_text_atomic(Path(path), yaml.safe_dump(doc, sort_keys=False))


def load_camera_yaml(path) -> CameraIntrinsics:
    """The CameraIntrinsics of a camera.yaml; ConfigError naming the file and key."""
    path = Path(path)
    top = Section(load_yaml(path), path)
    check_keys(top, _SCHEMA)
    fmt = top.get("format", str, FORMAT)
    if fmt != FORMAT:
        raise top.error("format", f"expected {FORMAT!r}, got {fmt!r}")
    return CameraIntrinsics.from_dict({k: top.data[k] for k in _CAMERA_KEYS if k in top.data},
                                      where=str(path), require_dist=True)


def load_camera_uncertainty(path) -> tuple[dict | None, np.ndarray | None]:
    """(std {fx, fy, cx, cy, k1, k2, p1, p2, k3} [px; dist unitless] or None when the file gives none, covariance
    (9, 9) of those or None) of a camera.yaml; ConfigError naming the file and key for a std that is not a finite
    number >= 0, or a covariance that is not a 9 x 9 symmetric matrix of those names with std^2 on its diagonal
    (to 1 %)."""
    from ..measure.intrinsics import PARAM_NAMES

    path = Path(path)
    top = Section(load_yaml(path), path)
    if "std" not in top.data:
        return None, None
    s = top.section("std").only("fx", "fy", "cx", "cy", "dist")
    vals = [s.get(k, float) for k in ("fx", "fy", "cx", "cy")]
    dist = s.get("dist", list)
    if len(dist) != 5:
        raise s.error("dist", f"expected 5 numbers (k1, k2, p1, p2, k3), got {len(dist)}")
    try:
        vals += [float(v) for v in dist]
    except (TypeError, ValueError):
        raise s.error("dist", f"expected numbers, got {dist!r}") from None
    v = np.array(vals, float)
    if not np.all(np.isfinite(v) & (v >= 0)):
        raise s.error(None, f"expected finite numbers >= 0, got {vals}")
    std = dict(zip(PARAM_NAMES, (float(x) for x in v)))
    if "covariance" not in top.data:
        return std, None
    c = top.section("covariance").only("names", "matrix")
    if list(c.get("names", list)) != list(PARAM_NAMES):
        raise c.error("names", f"expected {list(PARAM_NAMES)}")
    try:
        C = np.array(c.get("matrix", list), float)
    except (TypeError, ValueError):
        raise c.error("matrix", "expected a 9 x 9 matrix of numbers") from None
    if C.shape != (9, 9) or not np.all(np.isfinite(C)):
        raise c.error("matrix", f"expected a finite 9 x 9 matrix, got shape {C.shape}")
    if np.max(np.abs(C - C.T)) > 1e-9 * max(float(np.max(np.abs(C))), 1e-300):
        raise c.error("matrix", "not symmetric")
    if not np.allclose(np.sqrt(np.maximum(np.diag(C), 0.0)), v, rtol=1e-2, atol=1e-12):
        raise c.error("matrix", "its diagonal is not the square of std (a file edited by hand?)")
    return std, C


def load_camera_for_images(path, image_size, where: str) -> CameraIntrinsics:
    """:func:`load_camera_yaml`, its width x height checked against the images' (width, height) image_size
    (None: not checked). where: who names the file (``recording.yaml camera_file``, ``--camera``), quoted
    in the ConfigError for a missing file or a size mismatch."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{where}: camera file {path} not found (write one with `vision-calib calibrate-camera`)")
    cam = load_camera_yaml(path)
    if image_size is not None and tuple(image_size) != cam.size:
        raise ConfigError(f"{where}: {path} is for {cam.width}x{cam.height} px images but the recording's are "
                          f"{image_size[0]}x{image_size[1]} px")
    return cam
