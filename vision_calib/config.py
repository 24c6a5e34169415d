"""Loading and validating YAML files (scenes, studies, recordings) with errors that name the file,
the key and the expected value.

Unit handling: lengths and angles in files carry explicit units. A mapping may hold a ``units``
entry ``{length: m|cm|mm, angle: rad|deg}`` that applies to the values below it; keys whose name
ends with a unit suffix (``_mm``, ``_m``, ``_cm``, ``_deg``, ``_rad``, ``_px``) are in that unit.
Everything is converted to SI on load.

Strict schemas (project issue 9): every loader rejects unknown keys, with the closest known key
suggested (``frames_per_poses`` -> "did you mean 'frames_per_pose'?"), and checks required keys,
types, units and ranges up front, naming the file and the dotted key. Two calls do it:

- :func:`check_keys` (or :meth:`Section.check_known` for one mapping) validates a whole file's key
  tree in one call: ``check_keys(sec, {"camera": {"width", "height", ...}, "notes": ANY, "poses": [{...}]})``;
- :meth:`Section.get` / :meth:`Section.number` read a value with its type and range
  (``sec.number("sigma_length_mm", min=0)`` refuses -1 with the file and key named).

Why not pydantic (or another validation library): it is not a dependency today, and it would not
make these schemas shorter. Our files carry unit suffixes (``_mm``/``_deg``) and ``units`` blocks
converted on load, the error format must name ``file: dotted.key`` in one line for the CLI, and
pydantic's ``extra="forbid"`` says "Extra inputs are not permitted" without suggesting the
intended key. A key tree plus typed getters on :class:`Section` is a few dozen lines, keeps every
existing loader as it is, and gives the lead the same one-call check for scene and study files.
"""

from __future__ import annotations

import copy
import difflib
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import yaml

from .errors import ConfigError
from .shipped import data_dir, shipped_tree_of

#: folders the user allowed explicitly (``--allow-path DIR`` of every command sets it; os.pathsep-separated)
ALLOW_ENV = "VISION_CALIB_ALLOW_PATHS"
#: the user's pixel limit of an image file, in megapixels (:func:`max_image_pixels`)
MAX_IMAGE_ENV = "VISION_CALIB_MAX_IMAGE_MPX"
#: default pixel limit of an image file [Mpx]: 50 Mpx is above every machine-vision camera we calibrate with
#: (8K = 33 Mpx) and decodes in 50 MB grey; the detectors then take a few hundred MB
DEFAULT_MAX_IMAGE_MPX = 50.0

LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
ANGLE_UNITS = {"rad": 1.0, "deg": 3.141592653589793 / 180.0}
_MISSING = object()
#: in a :func:`check_keys` tree: any value (a leaf, or a mapping whose keys are not checked)
ANY = None


def did_you_mean(key: str, known) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``known`` (difflib), or ``""``."""
    close = difflib.get_close_matches(str(key), [str(k) for k in known], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def unit_keys(base: str, kind: str = "length") -> set[str]:
    """The spellings of a unit-suffixed key: ``base_m, base_mm, base_cm`` or ``base_rad, base_deg``."""
    suffixes = ("_m", "_mm", "_cm") if kind == "length" else ("_rad", "_deg")
    return {base + s for s in suffixes}


def check_keys(sec: "Section", tree) -> None:
    """Refuse unknown keys in a whole key tree, in one call; ConfigError naming file and dotted key
    with the closest known key suggested.

    tree: a set/list/tuple of allowed key names (values not descended into), or a dict
    ``{key: subtree}`` where subtree is :data:`ANY` (any value), a nested tree for a mapping,
    or a one-element list ``[subtree]`` for a list of mappings. The key ``"*"`` in a dict
    matches any name (e.g. named configurations), its subtree applies to each."""
    if isinstance(tree, (set, frozenset, list, tuple)):
        tree = {k: ANY for k in tree}
    if "*" not in tree:
        sec.check_known(tree)
    for key in list(sec.keys()):
        sub = tree.get(key, tree.get("*"))
        if sub is ANY or sec.data[key] is None:
            continue
        if isinstance(sub, list):
            items = sec.data[key]
            if not isinstance(items, list):
                raise sec.error(str(key), f"expected a list, got {items!r}")
            for i, item in enumerate(items):
                check_keys(Section(item, sec.file, sec._join(f"{key}[{i}]")), sub[0])
        else:
            check_keys(sec.section(str(key)), sub)


def allowed_dirs() -> tuple[Path, ...]:
    """The folders outside a file's own folder that the paths it names may lead into: the installed package's
    shipped data (:func:`vision_calib.shipped.data_dir`) and the folders the user allowed (:data:`ALLOW_ENV`,
    set by ``--allow-path``), resolved."""
    extra = tuple(Path(p).resolve() for p in os.environ.get(ALLOW_ENV, "").split(os.pathsep) if p)
    return (data_dir().resolve(),) + extra


def max_image_pixels() -> int:
    """The largest image (width x height, px) any reader decodes: :data:`DEFAULT_MAX_IMAGE_MPX`, or the user's
    :data:`MAX_IMAGE_ENV` (megapixels, > 0; through the environment so that worker processes inherit it).
    ConfigError naming the variable when its value is not a positive number."""
    text = os.environ.get(MAX_IMAGE_ENV, "").strip()
    if not text:
        return int(DEFAULT_MAX_IMAGE_MPX * 1e6)
    try:
        v = float(text)
        if not (0 < v < 1e6):
            raise ValueError
    except ValueError:
        raise ConfigError(f"environment variable {MAX_IMAGE_ENV}={text!r}: expected a number of megapixels > 0 "
                          f"(default {DEFAULT_MAX_IMAGE_MPX:g})") from None
    return int(v * 1e6)


def machine_memory_bytes() -> int:
    """This machine's physical memory [bytes] (``os.sysconf``), 0 where it cannot be read."""
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return 0


@contextmanager
def allow_paths(dirs):
    """Within the block, paths named in files may also lead into ``dirs`` (the user's explicit allowance;
    through the environment, so that worker processes started inside inherit it)."""
    old = os.environ.get(ALLOW_ENV)
    parts = [p for p in (old or "").split(os.pathsep) if p] + [str(Path(d).resolve()) for d in dirs or ()]
    if parts:
        os.environ[ALLOW_ENV] = os.pathsep.join(parts)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(ALLOW_ENV, None)
        else:
            os.environ[ALLOW_ENV] = old


def _inside(p: Path, root: Path) -> bool:
    return p == root or root in p.parents


def confine(path, root, where: str, error=ConfigError, allow: bool = False, hint: str = "--allow-path DIR") -> Path:
    """The ONE rule for a path that a file names (issue 21): it must lead (symbolic links resolved) inside
    ``root`` (the folder of the file that names it, or the recorded/imported folder), the shipped data, the
    shipped data tree ``root`` itself lies in (a checkout's own ``scenes/`` naming its ``targets/``:
    :func:`vision_calib.shipped.shipped_tree_of`), or a folder the user allowed (:func:`allowed_dirs`); ``allow``: the caller's explicit allowance (e.g.
    ``--allow-symlinks``). Returns ``path``; else ``error`` naming ``where`` and saying whether a symbolic
    link or the path itself leads out (nothing outside is opened)."""
    path = Path(path)
    if allow:
        return path
    real, base = path.resolve(), Path(root).resolve()
    tree = shipped_tree_of(base / "_")
    if _inside(real, base) or (tree is not None and _inside(real, tree)) or any(_inside(real, d) for d in allowed_dirs()):
        return path
    lexical, lbase = Path(os.path.normpath(path.absolute())), Path(os.path.normpath(Path(root).absolute()))
    why = (f"a symbolic link leading out of the folder {base} (to {real})" if _inside(lexical, lbase)
           else f"{real} is outside the folder {base}")
    raise error(f"{where}: {why}; refused: files may only name files inside their own folder or the shipped "
                f"scenes/targets (copy the file into the folder, or allow it explicitly: {hint})")


def check_output_apart(out, inputs, flag: str = "--out") -> None:
    """ConfigError naming both paths when the output ``out`` (a folder, or a file) is an input, lies inside an
    input folder, or (folder inputs given as files: ``(path, "file")``) writes into the folder of an input
    file. ``inputs``: [(path, "folder" | "file")]; the paths are resolved (symbolic links included)."""
    o = Path(out).resolve()
    for path, kind in inputs:
        if path is None:
            continue
        i = Path(path).resolve()
        if kind == "folder" and _inside(o, i):
            where = "is the input folder" if o == i else "lies inside the input folder"
            raise ConfigError(f"{flag} {out}: {where} {path}; outputs never go into an input: choose a folder "
                              "outside it")
        if kind == "file" and (o == i or o == i.parent):
            where = "is the input file" if o == i else "is the folder of the input file"
            raise ConfigError(f"{flag} {out}: {where} {path}; outputs never go into an input folder: choose "
                              "another folder (e.g. a new subfolder)")


def read_text(path: str | os.PathLike, error=ConfigError, what: str = "file") -> str:
    """The ONE place a text file we read is decoded: UTF-8, a BOM dropped (spreadsheets write one).
    ``error`` (ConfigError for settings files, DataError for data) naming the file on a missing or
    unreadable file, and the line, column and byte of the first non-UTF-8 byte (issue 21: no
    UnicodeDecodeError traceback, whichever reader)."""
    p = Path(path)
    if not p.is_file():
        raise error(f"{p}: {what} not found")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise error(f"{p}: cannot read {what} ({exc.strerror})") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        col = exc.start - data.rfind(b"\n", 0, exc.start)
        raise error(f"{p}: line {line}: not UTF-8 text (byte 0x{data[exc.start]:02x} at column {col}); "
                    "save the file as UTF-8") from None


#: a YAML file may use at most this many aliases (``*name``), standing for at most this many nodes in all (each
#: alias counted as the size of the node it repeats): a hand-written file uses a few small ones; an alias tree
#: ("billion laughs": 9 levels of 9) stands for 9^9 nodes and exhausts the memory of whatever prints or walks it
MAX_YAML_ALIASES = 1000
MAX_YAML_ALIAS_NODES = 100_000


class BoundedLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that counts the aliases it resolves and the nodes they stand for
    (:data:`MAX_YAML_ALIASES`, :data:`MAX_YAML_ALIAS_NODES`) and refuses an alias inside the node it names (a
    recursive structure): a ``yaml.composer.ComposerError`` at the alias's line, while composing, before any
    value is built. Every YAML file the package reads goes through it (:func:`safe_load`)."""

    def __init__(self, stream):
        super().__init__(stream)
        self._aliases, self._alias_nodes = 0, 0
        self._sizes: dict[int, int] = {}
        self._open: list = []  # anchors of the collections being composed

    def _refuse(self, problem: str, mark):
        raise yaml.composer.ComposerError(None, None, problem, mark)

    def _nodes(self, node) -> int:
        """Nodes in ``node`` with every alias expanded (memoised per node)."""
        n = self._sizes.get(id(node))
        if n is None:
            if isinstance(node, yaml.MappingNode):
                n = 1 + sum(self._nodes(k) + self._nodes(v) for k, v in node.value)
            elif isinstance(node, yaml.SequenceNode):
                n = 1 + sum(self._nodes(v) for v in node.value)
            else:
                n = 1
            self._sizes[id(node)] = n
        return n

    def compose_node(self, parent, index):
        ev = self.peek_event()
        if isinstance(ev, yaml.AliasEvent) and ev.anchor in self.anchors:
            if ev.anchor in self._open:
                self._refuse(f"the alias *{ev.anchor} is inside the node &{ev.anchor} it repeats (a recursive "
                             "structure): refused", ev.start_mark)
            self._aliases += 1
            self._alias_nodes += self._nodes(self.anchors[ev.anchor])
            if self._aliases > MAX_YAML_ALIASES or self._alias_nodes > MAX_YAML_ALIAS_NODES:
                self._refuse(f"aliases expand beyond the limit ({self._aliases} aliases standing for "
                             f"{self._alias_nodes} nodes by *{ev.anchor}; at most {MAX_YAML_ALIASES} aliases and "
                             f"{MAX_YAML_ALIAS_NODES} nodes): an alias tree, refused before it is expanded",
                             ev.start_mark)
        if isinstance(ev, (yaml.SequenceStartEvent, yaml.MappingStartEvent)) and ev.anchor is not None:
            self._open.append(ev.anchor)
            try:
                return super().compose_node(parent, index)
            finally:
                self._open.pop()
        return super().compose_node(parent, index)


#: the values of the last texts :func:`safe_load` parsed, by text (a robot file is read by the scene, the
#: calibrated-model export and the accuracy map's kinematics: parsed once); at most _PARSED_KEPT texts, each
#: below _PARSED_MAX_CHARS
_PARSED: dict[str, Any] = {}
_PARSED_KEPT = 16
_PARSED_MAX_CHARS = 1_000_000


def safe_load(text: str):
    """``yaml.safe_load`` through :class:`BoundedLoader` (aliases bounded); yaml.YAMLError on a bad file. A text
    without an anchor (no "&" anywhere) can hold no alias to expand: it is parsed by libyaml's safe loader when
    PyYAML has it (the same values, ~7x faster on the robot files). A text parsed before gives a copy of its values
    (the same text, the same values: parsed once)."""
    if text in _PARSED:
        return copy.deepcopy(_PARSED[text])
    if "&" not in text and getattr(yaml, "CSafeLoader", None) is not None:
        data = yaml.load(text, Loader=yaml.CSafeLoader)
    else:
        loader = BoundedLoader(text)
        try:
            data = loader.get_single_data()
        finally:
            loader.dispose()
    if len(text) <= _PARSED_MAX_CHARS:
        _PARSED[text] = copy.deepcopy(data)
        for old in list(_PARSED)[:-_PARSED_KEPT]:
            del _PARSED[old]
    return data


def safe_dump(data, **kwargs) -> str:
    """``yaml.safe_dump(data, **kwargs)`` (a str) through libyaml's emitter when PyYAML has it: the same text (the
    representer is the same Python one; the emitter a port of it), ~4x faster on a calibrated-model file."""
    dumper = getattr(yaml, "CSafeDumper", None)
    if dumper is None:
        return yaml.safe_dump(data, **kwargs)
    return yaml.dump(data, Dumper=dumper, **kwargs)


def parse_yaml(path: str | os.PathLike, error=ConfigError, what: str = "file"):
    """Any YAML value of a file (:func:`read_text`); ``error`` naming the file on a syntax error."""
    text = read_text(path, error, what)
    try:
        return safe_load(text)
    except yaml.YAMLError as exc:
        raise error(f"{path}: invalid YAML in {what} ({' '.join(str(exc).split())})") from None


def load_yaml(path: str | os.PathLike) -> dict:
    """Read a YAML mapping; ConfigError naming the file on a missing, unreadable or non-UTF-8 file or a
    syntax error."""
    p = Path(path)
    text = read_text(p, ConfigError)
    try:
        data = safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: invalid YAML ({' '.join(str(exc).split())})") from None
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

    def _join(self, key: str) -> str:
        return ".".join(k for k in (self.path, key) if k)

    def check_known(self, allowed) -> "Section":
        """ConfigError on the first key not in ``allowed``, with the closest allowed key suggested; returns self."""
        allowed = [str(k) for k in allowed]
        for key in self.data:
            if str(key) not in allowed:
                raise self.error(str(key), f"unknown key{did_you_mean(key, allowed)}; allowed here: "
                                           f"{', '.join(sorted(allowed)) or 'none'}")
        return self

    def only(self, *keys: str) -> "Section":
        """Same as :meth:`check_known` with the keys as arguments: ``sec.only("width", "height")``."""
        return self.check_known(keys)

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

    def number(self, key: str, typ=float, default: Any = _MISSING, *, min=None, max=None,
               min_open: bool = False, unit: str = ""):
        """A finite number in [min, max] (``min_open``: > min); ConfigError naming the key and the range."""
        val = self.get(key, typ, default)
        if val is default and default is not _MISSING:
            return val
        u = f" {unit}" if unit else ""
        if isinstance(val, float) and val in (float("inf"), float("-inf")):
            raise self.error(key, f"expected a finite number, got {val!r}")
        if min is not None and (val <= min if min_open else val < min):
            raise self.error(key, f"expected a value {'>' if min_open else '>='} {min}{u}, got {val!r}")
        if max is not None and val > max:
            raise self.error(key, f"expected a value <= {max}{u}, got {val!r}")
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
        """A file path relative to this file's folder, inside it (or the shipped data, or a folder the user
        allowed: :func:`confine`); ConfigError if it leads elsewhere or does not exist."""
        val = self.get(key, str, default)
        if val is None or val is default:
            return val
        p = Path(val)
        if not p.is_absolute():
            p = self.file.parent / p
        confine(p, self.file.parent, f"{self.where(key)}: {val!r}")
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


#: tolerance on |quaternion norm - 1| of a mount read from a file (pose loggers write unit quaternions
#: to 6+ digits; a larger error is a wrong field order or a truncated value, not rounding)
QUAT_NORM_TOL = 1e-3


def transform_from(sec: Section, Lf: float = 1.0, Af: float = 1.0, extra=()):
    """(4, 4) transform [m] of a mapping ``{xyz: [x, y, z], rpy: [roll, pitch, yaw]}`` or
    ``{xyz: [..], quat: [qx, qy, qz, qw]}`` (scalar-last, the pose loggers' form; unit norm within
    QUAT_NORM_TOL, normalised). xyz in the file's length unit (factor ``Lf`` to m), rpy in its angle
    unit (``Af`` to rad; R = Rz(yaw) Ry(pitch) Rx(roll)); the quaternion has no unit. Missing xyz /
    rotation -> zero / identity. ``extra``: other keys allowed in the mapping. ConfigError naming the
    file and key on unknown keys, both rpy and quat, or a non-unit quaternion."""
    import numpy as np

    from .frames import T_from_xyz_quat, T_from_xyz_rpy

    sec.check_known(("xyz", "rpy", "quat") + tuple(extra))
    xyz = sec.floats("xyz", 3, np.zeros(3)) * Lf
    if "quat" in sec:
        if "rpy" in sec:
            raise sec.error("quat", "give either rpy or quat, not both")
        q = sec.floats("quat", 4)
        norm = float(np.linalg.norm(q))
        if abs(norm - 1.0) > QUAT_NORM_TOL:
            raise sec.error("quat", f"expected a unit quaternion [qx, qy, qz, qw] (scalar last), got norm "
                                    f"{norm:.6g} (|norm - 1| > {QUAT_NORM_TOL:g})")
        return T_from_xyz_quat(xyz, q / norm)
    return T_from_xyz_rpy(xyz, sec.floats("rpy", 3, np.zeros(3)) * Af)
