"""Calibration target definitions (cv2 + numpy only): reading and writing target files. The kinds (ChArUco
boards, AprilTag grids, chessboards, circle grids) live in :mod:`vision_calib.targets.kinds`, the one registry of
kinds; each has its typed spec, a :class:`TargetSpec` subclass beside the kind (:mod:`.kinds.base`) that holds
that kind's YAML values only and delegates everything kind-specific to the kind.

Target frame (the same as OpenCV 4.14's board object points, ``board.getChessboardCorners()`` /
``board.getObjPoints()``; checked in ``tests/targets/test_spec.py``):

- origin at the *outer* top-left corner of the pattern (first chessboard square for ChArUco and
  chessboards, top-left corner of tag 0's black border for an AprilTag grid, top-left corner of the
  bounding box of the dots for a circle grid), as seen in the texture / printed image;
- x along the pattern's columns (to the right in the image), y along its rows (down in the image);
- z = x × y points *into* the board, away from a viewer who looks at the printed face. A camera seeing
  the board upright therefore has ``R_cam_target ~= I`` (OpenCV camera: x right, y down, z forward).
- The white margin ``margin_m`` lies outside the pattern: the board spans
  ``[-margin_m, width_pattern + margin_m] x [-margin_m, height_pattern + margin_m]`` (:meth:`texture_extent_m`).

Corner ids:
- ChArUco and chessboard: inner chessboard corners, row-major from the origin, id = r * (cols - 1) + c,
  at ((c + 1) * square_m, (r + 1) * square_m, 0) (ChArUco: OpenCV's charuco ids).
- AprilTag grid: id = 4 * tag_id + k, k = 0..3 in OpenCV's marker corner order (top-left, top-right,
  bottom-right, bottom-left of the tag's black border, i.e. +x then +y in the target frame).
  Tag ids are ``first_id .. first_id + rows*cols - 1``, row-major.
- Asymmetric circle grid: dot centres, id = i * cols + j (:mod:`.kinds.circles`).

Texture (:meth:`TargetSpec.texture`): white = 255, black = 0, drawn with exact *area coverage* of every
pixel (rectangles exactly; dots as area-preserving 128-gons, exact by signed-area accumulation), so
edges are not quantised to texture pixels.
"""

from __future__ import annotations

from dataclasses import fields as fields_of
from pathlib import Path

from ..errors import ConfigError
from .kinds import KINDS as _REGISTRY
from .kinds.base import (COMMON_KEYS, MAX_FEATURES, MAX_TARGET_M, TargetSpec, available_memory,  # noqa: F401
                         check_memory, get_kind)

__all__ = ["KINDS", "MAX_FEATURES", "MAX_TARGET_M", "TargetSpec", "available_memory", "check_memory",
           "load_target", "target_from_dict"]

KINDS = tuple(_REGISTRY)  # names of the kinds registered on import (the registry: targets/kinds/__init__.py)
_EXTRA_KEYS = {"description", "units"}


def _is_default(value, default) -> bool:
    """Whether a value read from a file equals a field's default (0, 0.0, false, "", an empty mapping/list)."""
    if isinstance(value, (list, tuple, dict)) or isinstance(default, (list, tuple, dict)):
        return not value and not default
    if isinstance(value, bool) or isinstance(default, bool):
        return value is default
    return isinstance(value, (int, float, str)) and value == default


def target_from_dict(d: dict, where: str = "target") -> TargetSpec:
    """The kind's typed spec from a dict of its keys (+ optional 'description', 'units': m).

    ``name`` defaults to ``where``. Keys of another kind are refused, except with their default value (files
    written before the specs were typed carry every kind's keys, e.g. ``tag_m: 0.0`` on a ChArUco board).
    Raises ConfigError naming ``where`` and the key.
    """
    if not isinstance(d, dict):
        raise ConfigError(f"{where}: expected a mapping of target keys, got {type(d).__name__}")
    from ..config import did_you_mean

    defaults = {}  # every registered kind's key -> its defaults over the kinds
    for k in _REGISTRY.values():
        for f in fields_of(k.spec_class):
            defaults.setdefault(f.name, []).append(f.default)
    allowed = sorted(set(defaults) | _EXTRA_KEYS)
    for key in d:
        if key not in allowed:
            raise ConfigError(f"{where}: {key}: unknown key{did_you_mean(key, allowed)}; allowed: {', '.join(allowed)}")
    if "units" in d and d["units"] not in ("m", "metre", "meter", "metres", "meters"):
        raise ConfigError(f"{where}: key 'units' must be 'm' (lengths are in metres), got {d['units']!r}")
    missing = [k for k in ("kind", "rows", "cols") if k not in d]
    if not missing:
        missing = [k for k in get_kind(d["kind"], where).required if k not in d]
    if missing:
        raise ConfigError(f"{where}: missing key(s) {missing} (kind {d.get('kind')!r})")
    own = {f.name for f in fields_of(get_kind(d["kind"], where).spec_class)}
    kw = {k: v for k, v in d.items() if k in own
          or k in defaults and k not in _EXTRA_KEYS and not any(_is_default(v, x) for x in defaults[k])}
    kw.setdefault("name", where)
    try:
        return TargetSpec(**kw)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def load_target(path) -> TargetSpec:
    """Load a target YAML file (the kind's keys, lengths in m). ConfigError names file and key."""
    from ..config import load_yaml

    path = Path(path)
    d = dict(load_yaml(path))  # ConfigError on a missing, non-UTF-8, invalid or non-mapping file
    d.setdefault("name", path.stem)
    return target_from_dict(d, where=str(path))
