"""The target kinds' common ground: the registry of kinds (:data:`KINDS`, :func:`register`), the base class of a
kind (:class:`TargetKind`), the keys every target has (:class:`TargetSpec`, the base of each kind's typed spec)
and the memory guard drawings use. The shipped kinds are registered by :mod:`vision_calib.targets.kinds`."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np

from ...errors import ConfigError
from ..coverage import accumulate_coverage
from .image_model import saddle_info

KINDS: dict = {}


def register(kind: "TargetKind") -> "TargetKind":
    """Register a target kind instance (of a :class:`TargetKind` subclass) under ``kind.name``; its
    ``spec_class`` (a :class:`TargetSpec` subclass) gets ``kind_impl = kind``."""
    if not isinstance(kind, TargetKind):
        raise TypeError(f"a target kind must be a TargetKind instance, got {type(kind).__name__}")
    spec_class = kind.spec_class
    if not (isinstance(spec_class, type) and issubclass(spec_class, TargetSpec)):
        raise TypeError(f"target kind {kind.name!r}: spec_class must be a TargetSpec subclass, got {spec_class!r}")
    spec_class.kind_impl = kind
    KINDS[kind.name] = kind
    return kind


def unregister(name: str) -> None:
    KINDS.pop(name, None)


def get_kind(name, where: str = "target") -> "TargetKind":
    """The TargetKind of a name; ConfigError naming ``where`` and the known kinds."""
    try:
        return KINDS[name]
    except (KeyError, TypeError):
        raise ConfigError(f"{where}: key 'kind' must be one of {tuple(KINDS)}, got {name!r}") from None


class TargetKind:
    """Base class of a target kind. ``spec`` arguments are TargetSpec instances (lengths in m).

    Class attributes:
    - name: the YAML ``kind`` value; spec_class: its :class:`TargetSpec` subclass (the kind's keys, besides
      kind, name, rows, cols, margin_m: :attr:`keys`); required: the keys a YAML file must give;
    - auto_refine: DetectConfig.refine "auto" -> this marker refinement (ArUco kinds);
    - auto_extra_subpix: whether DetectConfig.extra_subpix None (auto) runs the cornerSubPix pass;
    - phase_locked_share: the share of the systematic corner error locked to the pixel phase
      (measure/covariance.py; 0: none);
    - detect_uses_intrinsics: whether the detected corners depend on the camera intrinsics (circle centres
      corrected for perspective, tag edges fitted in undistorted pixels): False lets a run re-measure the same
      detections with other intrinsics instead of detecting again (default True: a kind that reads no intrinsics
      says so).
    The kind's corner error model: :meth:`corner_info` (image-model Fisher information, default: a saddle
    corner) and :meth:`bias_columns` (detector-bias terms, default: none), from :mod:`.image_model`.
    """

    name = ""
    spec_class: type = None
    required: tuple = ()
    auto_refine = "none"
    auto_extra_subpix = False
    phase_locked_share = 0.0
    detect_uses_intrinsics = True

    @property
    def keys(self) -> tuple[str, ...]:
        """The kind's own keys: the fields of :attr:`spec_class` besides the common ones."""
        return tuple(f.name for f in fields(self.spec_class) if f.name not in COMMON_KEYS)

    # ---------------------------------------------------------------- spec
    def validate(self, spec, where: str) -> None:
        """ConfigError naming ``where`` and the key for kind-specific bad values (common keys are checked
        by TargetSpec)."""

    def positive(self, spec, where, *keys) -> None:
        """ConfigError unless every key is > 0."""
        for key in keys:
            if getattr(spec, key) <= 0:
                raise ConfigError(f"{where}: key {key!r} must be > 0 [m], got {getattr(spec, key)}")

    def refuse_symmetric(self, spec, where, what: str, advice: str) -> None:
        """ConfigError when the pattern is 180-degree symmetric (:meth:`symmetric`) and the spec does not set
        ``allow_symmetric``; ``what``: "corner ids" / "ids", ``advice``: the layout to use instead."""
        why = self.symmetric(spec)
        if why and not spec.allow_symmetric:
            raise ConfigError(f"{where}: {why}; its {what} cannot be tied to the physical board, so poses "
                              f"cannot be measured with it. {advice}, or set 'allow_symmetric: true' to use it "
                              "for intrinsics calibration only")

    def symmetric(self, spec) -> str:
        """Why the pattern looks the same after a 180-degree rotation ("" when it does not): the detected
        ids then cannot be tied to the physical board, so poses cannot be measured with it."""
        return ""

    # ---------------------------------------------------------------- geometry
    def pattern_size_m(self, spec) -> tuple[float, float]:
        """(width, height) [m] of the pattern without margin."""
        raise NotImplementedError

    def corner_points(self, spec) -> tuple[np.ndarray, np.ndarray]:
        """ids (K,) int, p_target (K, 3) float64 [m], sorted by id."""
        raise NotImplementedError

    def n_corners(self, spec) -> int:
        return len(self.corner_points(spec)[0])

    def black_rects(self, spec) -> list:
        """Non-overlapping black axis-aligned rectangles (x0, y0, x1, y1) [m, target frame]."""
        return []

    def black_polygons(self, spec) -> np.ndarray:
        """(M, V, 2) further black polygons [m, target frame], vertices in the order TL -> TR -> BR -> BL
        (increasing angle in the target frame), not overlapping each other or the rectangles."""
        return np.zeros((0, 4, 2))

    def cv_board(self, spec):
        raise ConfigError(f"target {spec.name!r}: kind {self.name!r} has no OpenCV board object")

    # ---------------------------------------------------------------- corner error model
    def corner_info(self, spec, normals: np.ndarray, scale_px_per_m: np.ndarray, effects, half_win: int) -> np.ndarray:
        """(K, 2, 2) image-model Fisher information [1/px^2] of the corners with edge normals (K, 2, 2) and
        px per metre along the target axes (K, 2); half_win: the detector window's half size [px]. Default: a
        saddle corner refined in a (2 half_win + 1)^2 window (:func:`.image_model.saddle_info`)."""
        return saddle_info(normals, effects, half_win)

    def bias_columns(self, ids: np.ndarray, uv_px: np.ndarray, estimator: str) -> np.ndarray | None:
        """(2K, m) detector-bias columns of the systematic corner error (measure/covariance.py) for the corners
        ids (K,) at uv_px (K, 2), corner estimator "edges" | "opencv"; None: the detector has none."""
        return None

    # ---------------------------------------------------------------- detection
    def make_detector(self, spec, config):
        """The (cached by measure/detect.py) detector object passed to :meth:`find_corners`."""
        return None

    def find_corners(self, spec, det, img, config, diag: dict, intrinsics=None):
        """(ids (K,), uv (K, 2) float64 distorted px) or (None, reason) on a grey uint8 image; may fill diag."""
        raise NotImplementedError

    def seeded_mode(self, config) -> str | None:
        """measure/seeded.py refinement from a seed frame: "subpix" | "tag_edges" | "saddle" | None (per-frame)."""
        return None


@runtime_checkable
class MarkerKind(Protocol):
    """Optional capability of a target kind: a board of coded markers (the ArUco kinds ``charuco``,
    ``apriltag_grid``). ``spec``: the kind's TargetSpec. :meth:`TargetSpec.marker_ids` & co. name a kind
    without it."""

    def cv_dictionary(self, spec): ...

    def marker_ids(self, spec) -> np.ndarray: ...

    def marker_corners(self, spec) -> np.ndarray: ...


#: upper bound of rows x cols (squares, tags or dots) of a board: a 50 MP image holds ~5e7 px, a feature needs
#: ~10 x 10 px to be found; each dot of a circle grid is also a 128-vertex polygon (2 kB) when it is drawn
MAX_FEATURES = 1_000_000
MAX_TARGET_M = 10.0  # a larger board is a unit mistake (mm given as m), refused on load
COMMON_KEYS = ("kind", "name", "rows", "cols", "margin_m")


@dataclass(frozen=True)
class TargetSpec:
    """A planar calibration target: the keys every kind has (lengths in metres). Each kind adds its own keys in
    its own frozen dataclass, a subclass declared beside the kind (``TargetKind.spec_class``; e.g.
    :class:`~vision_calib.targets.kinds.aruco.CharucoSpec`), so a spec holds, writes and reads only its kind's keys.

    ``TargetSpec(kind=..., name=..., rows=..., cols=..., **keys)`` builds the kind's class (ConfigError naming a
    key of another kind). kind: a registered kind (:mod:`vision_calib.targets.kinds`); rows, cols: squares,
    tags or dots, as the kind says; margin_m: white margin around the pattern.
    """

    kind: str
    name: str
    rows: int
    cols: int
    margin_m: float = 0.01
    #: the registered TargetKind of this class (set by :func:`register`)
    kind_impl: ClassVar["TargetKind"] = None

    def __new__(cls, *args, **kwargs):
        if cls is TargetSpec:  # dispatch to the kind's class
            name = kwargs.get("name", args[1] if len(args) > 1 else None)
            cls = get_kind(kwargs.get("kind", args[0] if args else None), f"target {name!r}").spec_class
            own = {f.name for f in fields(cls)}
            for key in kwargs:
                if key not in own and any(key in k.keys for k in KINDS.values()):
                    raise ConfigError(f"target {name!r}: key {key!r} does not apply to kind {cls.kind_impl.name!r} "
                                      f"(its keys: {', '.join(COMMON_KEYS[2:] + cls.kind_impl.keys)})")
        return super().__new__(cls)

    def __post_init__(self):
        where = f"target {self.name!r}"
        if not isinstance(self.name, str):
            raise ConfigError(f"{where}: key 'name' must be a string, got {self.name!r}")
        kind = get_kind(self.kind, where)
        if type(self) is not kind.spec_class:
            raise ConfigError(f"{where}: kind {self.kind!r} is described by {kind.spec_class.__name__}, not "
                              f"{type(self).__name__}")
        typed = {f.name: f.type for f in fields(self)}  # annotations are strings (from __future__ import annotations)
        for key in (k for k, t in typed.items() if t == "int"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise ConfigError(f"{where}: key {key!r} must be an integer, got {v!r}")
        for key in (k for k, t in typed.items() if t == "float"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
                raise ConfigError(f"{where}: key {key!r} must be a finite number [m], got {v!r}")
            object.__setattr__(self, key, float(v))
        for key in (k for k, t in typed.items() if t == "bool"):
            if not isinstance(getattr(self, key), (bool, np.bool_)):
                raise ConfigError(f"{where}: key {key!r} must be true or false, got {getattr(self, key)!r}")
        if self.margin_m < 0:
            raise ConfigError(f"{where}: key 'margin_m' must be >= 0 [m], got {self.margin_m}")
        if self.rows * self.cols > MAX_FEATURES:  # before any per-feature array (corner points, dot polygons)
            raise ConfigError(f"{where}: keys 'rows' x 'cols' = {self.rows} x {self.cols} = {self.rows * self.cols:.4g} "
                              f"features, more than {MAX_FEATURES:.0e} (no camera image resolves more on one board; "
                              "the arrays for them would not fit in memory)")
        kind.validate(self, where)
        size = max(self.outline_m())
        if size > MAX_TARGET_M:
            lengths = [k for k, t in typed.items() if t == "float" and k != "margin_m"]
            raise ConfigError(f"{where}: the board would be {size:.4g} m wide, more than {MAX_TARGET_M:g} m "
                              f"(lengths are in metres: {', '.join(lengths)}, margin_m)")

    def symmetric(self) -> str:
        """Why the board looks the same after a 180-degree rotation ("" when it does not)."""
        return self.kind_impl.symmetric(self)

    def check_pose_measurable(self, where: str = "") -> None:
        """ConfigError when poses cannot be measured with this target (180-degree-symmetric board)."""
        why = self.symmetric()
        if why:
            raise ConfigError(f"{where or 'target ' + repr(self.name)}: {why}: the detected ids can be those of the "
                              "board rotated by 180 degrees, so poses measured with it are ambiguous; it is allowed "
                              "(allow_symmetric) for intrinsics calibration only. Use a board with rows + cols odd "
                              "(chessboard) or an odd number of rows (circles_asymmetric)")

    # ------------------------------------------------------------------ geometry
    def pattern_size_m(self) -> tuple[float, float]:
        """(width, height) [m] of the pattern without margin (along target x and y)."""
        return self.kind_impl.pattern_size_m(self)

    def outline_m(self) -> tuple[float, float]:
        """(width, height) [m] of the physical board including the white margin."""
        w, h = self.pattern_size_m()
        return w + 2 * self.margin_m, h + 2 * self.margin_m

    def measured_outline_m(self) -> np.ndarray:
        """(4, 3) [m, target frame, z = 0]: the rectangle bounding the points the measurement uses
        (:meth:`corner_points`), the outline a pose must hold in view (the scenes' pose sampler, the planner)."""
        _, pts = self.corner_points()
        lo, hi = np.min(pts, axis=0), np.max(pts, axis=0)
        return np.array([[lo[0], lo[1], 0], [hi[0], lo[1], 0], [hi[0], hi[1], 0], [lo[0], hi[1], 0]], float)

    def texture_extent_m(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) [m, target frame] covered by :meth:`texture` (the whole board)."""
        w, h = self.pattern_size_m()
        m = self.margin_m
        return (-m, -m, w + m, h + m)

    def marker_ids(self) -> np.ndarray:
        """(M,) int ids of the board's markers/tags, in the order of :meth:`marker_corners` (ArUco kinds)."""
        return self._markers("marker_ids").marker_ids(self)

    def marker_corners(self) -> np.ndarray:
        """(M, 4, 3) float64 [m, target frame] marker corners in OpenCV order (TL, TR, BR, BL) (ArUco kinds).

        Computed in float64 (OpenCV stores float32); which squares hold markers comes from OpenCV's board.
        """
        return self._markers("marker_corners").marker_corners(self)

    def corner_points(self) -> tuple[np.ndarray, np.ndarray]:
        """Corner ids (K,) int and their 3-D positions p_target (K, 3) float64 [m], z = 0, sorted by id."""
        return self.kind_impl.corner_points(self)

    @property
    def n_corners(self) -> int:
        """Number of corner points K."""
        return self.kind_impl.n_corners(self)

    # ------------------------------------------------------------------ OpenCV objects
    def _markers(self, method: str) -> "MarkerKind":
        """This target's kind as a :class:`MarkerKind`; ConfigError naming the target and ``method`` if it has
        no markers."""
        if not isinstance(self.kind_impl, MarkerKind):
            raise ConfigError(f"target {self.name!r}: kind {self.kind!r} has no markers ({method})")
        return self.kind_impl

    def cv_dictionary(self):
        """cv2.aruco.Dictionary of this target (ArUco kinds)."""
        return self._markers("cv_dictionary").cv_dictionary(self)

    def cv_board(self):
        """A fresh cv2.aruco.CharucoBoard (charuco) or cv2.aruco.GridBoard (apriltag_grid)."""
        return self.kind_impl.cv_board(self)

    # ------------------------------------------------------------------ texture
    def black_rects(self) -> list[tuple[float, float, float, float]]:
        """Non-overlapping black rectangles (x0, y0, x1, y1) [m, target frame] making up the pattern
        (with :meth:`black_polygons`)."""
        return self.kind_impl.black_rects(self)

    def black_polygons(self) -> np.ndarray:
        """(M, V, 2) further black polygons [m, target frame] (circle dots), TL -> TR -> BR -> BL order."""
        return np.asarray(self.kind_impl.black_polygons(self), dtype=float)

    def texture_shape(self, px_per_m: float) -> tuple[int, int]:
        """(H, W) of :meth:`texture` for a requested resolution px_per_m [px/m]."""
        w, h = self.outline_m()
        return max(1, int(round(h * px_per_m))), max(1, int(round(w * px_per_m)))

    def texture(self, px_per_m: float) -> np.ndarray:
        """uint8 (H, W) image of the whole board incl. margin; row 0 at y_min, column 0 at x_min.

        The image spans exactly :meth:`texture_extent_m`; (H, W) = round(size * px_per_m), so the
        effective scale differs from px_per_m by < 0.5 px over the board (independently in x and y).
        Pixel values are the exact white-area fraction of each pixel (0 = black, 255 = white).
        """
        if not (px_per_m > 0 and math.isfinite(px_per_m)):
            raise ConfigError(f"target {self.name!r}: texture px_per_m must be > 0, got {px_per_m}")
        H, W = self.texture_shape(px_per_m)
        check_memory(H * W * 9, f"target {self.name!r}: a {W} x {H} px texture ({px_per_m:.0f} px/m)")
        return np.round(255.0 * self._coverage(px_per_m)).astype(np.uint8)

    def _coverage(self, px_per_m: float) -> np.ndarray:
        """float64 (H, W) white-area fraction per texture pixel (see :meth:`texture`)."""
        H, W = self.texture_shape(px_per_m)
        x_min, y_min, x_max, y_max = self.texture_extent_m()
        sx = W / (x_max - x_min)
        sy = H / (y_max - y_min)
        img = np.ones((H, W), dtype=float)
        for x0, y0, x1, y1 in self.black_rects():
            ox, i0 = _overlap_1d((x0 - x_min) * sx, (x1 - x_min) * sx, W)
            oy, j0 = _overlap_1d((y0 - y_min) * sy, (y1 - y_min) * sy, H)
            if ox.size and oy.size:
                img[j0:j0 + oy.size, i0:i0 + ox.size] -= oy[:, None] * ox[None, :]
        polys = self.black_polygons()
        if len(polys):
            px = (polys - [x_min, y_min]) * [sx, sy]
            img -= accumulate_coverage(px, -np.ones(len(px)), H, W)  # TL->TR->BR->BL counts -1 per area
        return np.clip(img, 0.0, 1.0)

    def to_dict(self) -> dict:
        """Plain dict of the kind's keys (the YAML schema of :func:`~vision_calib.targets.spec.load_target`):
        this kind's fields only, never another kind's."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


def _overlap_1d(a: float, b: float, n: int) -> tuple[np.ndarray, int]:
    """Length of [a, b] (pixel units) inside each pixel [i, i+1], i = i0 .. ; clipped to [0, n)."""
    i0 = max(0, int(math.floor(a)))
    i1 = min(n, int(math.ceil(b)))
    if i1 <= i0:
        return np.zeros(0), i0
    i = np.arange(i0, i1, dtype=float)
    return np.clip(np.minimum(b, i + 1) - np.maximum(a, i), 0.0, 1.0), i0


def available_memory() -> int | None:
    """Bytes of memory available now (Linux MemAvailable), None where unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(nbytes: int, what: str, fraction: float = 0.5) -> None:
    """ConfigError before an allocation of ``nbytes`` larger than ``fraction`` of the available memory."""
    avail = available_memory()
    if avail is not None and nbytes > fraction * avail:
        raise ConfigError(f"{what} needs about {nbytes / 2**30:.3g} GiB of memory, more than {fraction:.0%} of the "
                          f"{avail / 2**30:.3g} GiB available; use a lower resolution (dpi)")
