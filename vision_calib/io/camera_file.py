"""camera.yaml: the output of ``vision-calib calibrate-camera`` (README "File formats").

The keys width, height, fx, fy, cx, cy, dist are exactly the ``camera:`` block of recording.yaml
(:meth:`CameraIntrinsics.to_dict`, px; dist = [k1, k2, p1, p2, k3]); the rest says how good they are::

    format: vision_calib.camera/1
    width: 1024
    height: 768
    fx: ..  fy: ..  cx: ..  cy: ..
    dist: [k1, k2, p1, p2, k3]
    std: {fx, fy, cx, cy, dist: [5]}     # 1-sigma, same units
    rms_px: 0.06                         # reprojection RMS, 2-D error per corner [px]
    n_views_used: 20
    n_views_rejected: 1
    coverage: {grid: [8, 6], fraction: 0.98, radius_frac: 0.87, warnings: [...]}
    warnings: [...]                      # coverage + views dropped as outliers
    views: [{name, n_corners, rms_px, used, reason}]
"""

from __future__ import annotations

from pathlib import Path

import yaml

from ..camera import CameraIntrinsics
from ..config import Section, check_keys, load_yaml
from ..errors import ConfigError
from ..serialize import write_text_atomic

FORMAT = "vision_calib.camera/1"
_CAMERA_KEYS = ("width", "height", "fx", "fy", "cx", "cy", "dist")
_SCHEMA = {"format": None, **{k: None for k in _CAMERA_KEYS}, "std": None, "distortion_px": None, "rms_px": None,
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
