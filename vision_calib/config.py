"""Loading and validating YAML files (scenes, studies, recordings) with errors that name the file,
the key and the expected value.

Unit handling: lengths and angles in files carry explicit units. A mapping may hold a ``units``
entry ``{length: m|cm|mm, angle: rad|deg}`` that applies to the values below it; keys whose name
ends with a unit suffix (``_mm``, ``_m``, ``_cm``, ``_deg``, ``_rad``, ``_px``) are in that unit.
Everything is converted to SI on load.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

from .errors import ConfigError

LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
ANGLE_UNITS = {"rad": 1.0, "deg": 3.141592653589793 / 180.0}
_MISSING = object()


def load_yaml(path: str | os.PathLike) -> dict:
    """Read a YAML mapping; ConfigError naming the file on a missing file or a syntax error."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: file not found")
    try:
        with open(p, encoding="utf-8") as fh:
            data = yaml.safe_load(fh)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: invalid YAML ({' '.join(str(exc).split())})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{p}: not a UTF-8 text file") from None
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read ({exc.strerror})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: expected a mapping at the top level, got {type(data).__name__}")
    return data


class Section:
    """A view of one mapping of a YAML file that knows where it came from, for error messages.

    ``Section(data, file, "camera").get("width", int)`` raises ConfigError
    ``"scene.yaml: camera.width: expected int, got 'abc'"``.
    """

    def __init__(self, data: dict, file: str | os.PathLike, path: str = ""):
        if not isinstance(data, dict):
            raise ConfigError(f"{file}: {path or '<top>'}: expected a mapping, got {type(data).__name__}")
        self.data = data
        self.file = Path(file)
        self.path = path

    def where(self, key: str | None = None) -> str:
        key_path = ".".join(k for k in (self.path, key) if k)
        return f"{self.file}: {key_path or '<top>'}"

    def error(self, key: str | None, message: str) -> ConfigError:
        return ConfigError(f"{self.where(key)}: {message}")

    def __contains__(self, key: str) -> bool:
        return key in self.data

    def keys(self):
        return self.data.keys()

    def get(self, key: str, typ=None, default: Any = _MISSING, choices=None):
        """Value of ``key`` converted with ``typ`` (int, float, str, bool, list...), checked against ``choices``."""
        if key not in self.data or self.data[key] is None:
            if default is _MISSING:
                raise self.error(key, "missing required key")
            return default
        val = self.data[key]
        if typ is not None:
            if typ is bool and not isinstance(val, bool):
                raise self.error(key, f"expected true/false, got {val!r}")
            if typ in (list, dict) and not isinstance(val, typ):
                raise self.error(key, f"expected a {'list' if typ is list else 'mapping'}, got {val!r}")
            if typ is int and isinstance(val, float) and not val.is_integer():
                raise self.error(key, f"expected an integer, got {val!r}")
            try:
                val = typ(val)
            except (TypeError, ValueError):
                raise self.error(key, f"expected {typ.__name__}, got {val!r}") from None
            if typ is float and val != val:  # NaN
                raise self.error(key, "expected a finite number, got NaN")
        if choices is not None and val not in choices:
            raise self.error(key, f"expected one of {sorted(map(str, choices))}, got {val!r}")
        return val

    def positive(self, key: str, typ=float, default: Any = _MISSING):
        val = self.get(key, typ, default)
        if val is not None and val is not default and not val > 0:
            raise self.error(key, f"expected a positive value, got {val!r}")
        return val

    def nonnegative(self, key: str, typ=float, default: Any = _MISSING):
        val = self.get(key, typ, default)
        if val is not None and val is not default and not val >= 0:
            raise self.error(key, f"expected a value >= 0, got {val!r}")
        return val

    def floats(self, key: str, n: int | None = None, default: Any = _MISSING):
        """A list of finite numbers (n of them when n is given) as a float64 array."""
        import numpy as np

        val = self.get(key, list, default)
        if val is default:
            return val
        try:
            arr = np.asarray(val, dtype=float)
        except (TypeError, ValueError):
            raise self.error(key, f"expected a list of numbers, got {val!r}") from None
        if arr.ndim != 1 or (n is not None and arr.size != n) or not np.all(np.isfinite(arr)):
            raise self.error(key, f"expected a list of {n if n is not None else ''} finite numbers, got {val!r}".replace("  ", " "))
        return arr

    def section(self, key: str, default: Any = _MISSING) -> "Section":
        if key not in self.data or self.data[key] is None:
            if default is _MISSING:
                raise self.error(key, "missing required section")
            return Section(default if default is not None else {}, self.file, ".".join(k for k in (self.path, key) if k))
        return Section(self.data[key], self.file, ".".join(k for k in (self.path, key) if k))

    def path_value(self, key: str, default: Any = _MISSING) -> Path | None:
        """A file path relative to this file's folder; ConfigError if it does not exist."""
        val = self.get(key, str, default)
        if val is None or val is default:
            return val
        p = Path(val)
        if not p.is_absolute():
            p = self.file.parent / p
        if not p.exists():
            raise self.error(key, f"file not found: {p}")
        return p

    def units(self, default_length: str = "m", default_angle: str = "rad") -> tuple[float, float]:
        """(length factor to m, angle factor to rad) from an optional ``units`` entry."""
        u = self.section("units", default={})
        lu = u.get("length", str, default_length, choices=LENGTH_UNITS)
        au = u.get("angle", str, default_angle, choices=ANGLE_UNITS)
        return LENGTH_UNITS[lu], ANGLE_UNITS[au]


def length_key(sec: Section, base: str, default: Any = _MISSING) -> float:
    """Read a length given as ``<base>_m``, ``<base>_mm`` or ``<base>_cm``; returns metres."""
    for suffix, f in (("_m", 1.0), ("_mm", 1e-3), ("_cm", 1e-2)):
        if base + suffix in sec:
            return sec.get(base + suffix, float) * f
    if default is _MISSING:
        raise sec.error(base + "_mm", f"missing required key (give {base}_m, {base}_mm or {base}_cm)")
    return default


def angle_key(sec: Section, base: str, default: Any = _MISSING) -> float:
    """Read an angle given as ``<base>_rad`` or ``<base>_deg``; returns radians."""
    for suffix, f in (("_rad", 1.0), ("_deg", ANGLE_UNITS["deg"])):
        if base + suffix in sec:
            return sec.get(base + suffix, float) * f
    if default is _MISSING:
        raise sec.error(base + "_deg", f"missing required key (give {base}_deg or {base}_rad)")
    return default
