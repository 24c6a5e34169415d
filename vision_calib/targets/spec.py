"""Calibration target definitions (cv2 + numpy only). The kinds (ChArUco boards, AprilTag grids,
chessboards, asymmetric circle grids) live in :mod:`vision_calib.targets.kinds`, the one registry of kinds;
:class:`TargetSpec` holds the YAML values and delegates everything kind-specific to it.

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

import math
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from ..errors import ConfigError
from .coverage import accumulate_coverage
from .kinds.base import check_memory
from .kinds import KINDS as _REGISTRY
from .kinds import get_kind

KINDS = tuple(_REGISTRY)  # names of the registered kinds (the registry: targets/kinds/__init__.py)
#: upper bound of rows x cols (squares, tags or dots) of a board: a 50 MP image holds ~5e7 px, a feature needs
#: ~10 x 10 px to be found; each dot of a circle grid is also a 128-vertex polygon (2 kB) when it is drawn
MAX_FEATURES = 1_000_000
MAX_TARGET_M = 10.0  # a larger board is a unit mistake (mm given as m), refused on load
_COMMON = ("kind", "name", "rows", "cols", "margin_m")
_LENGTHS = ("square_m", "marker_m", "tag_m", "spacing_m", "diameter_m", "origin_diameter_m", "margin_m")


@dataclass(frozen=True)
class TargetSpec:
    """A planar calibration target. Lengths in metres. Which keys a kind uses: :mod:`.kinds`.

    kind: a registered kind ("charuco" | "apriltag_grid" | "chessboard" | "circles_asymmetric" |
    "modified_circle_grid").
    rows, cols: squares (charuco, chessboard), tags (apriltag_grid), rows / dots per row
    (circles_asymmetric, OpenCV's patternSize = (cols, rows)). dictionary: cv2.aruco dictionary name
    ("DICT_5X5_100", "DICT_APRILTAG_36h11"; ArUco kinds). square_m, marker_m: square and marker sides.
    tag_m: apriltag side (outer edge of the black border); spacing_m: white gap between tags, or the
    circle grid's spacing. diameter_m: dot diameter; origin_diameter_m: the large origin dot of a
    modified_circle_grid (0: twice diameter_m, ROS-I's generator). legacy_pattern: OpenCV < 4.6 charuco layout.
    margin_m: white margin around the pattern. first_id: id of the first marker/tag. allow_symmetric:
    accept a 180-degree-symmetric board (intrinsics calibration only; poses are refused). blob_detector: circle
    grids: OpenCV SimpleBlobDetector parameters tried first on each image (a mapping in YAML; e.g. a ROS-I data
    set's ``circle_detector_params``; :mod:`.kinds.dot_grid`).
    """

    kind: str
    name: str
    rows: int
    cols: int
    dictionary: str = ""
    square_m: float = 0.0
    marker_m: float = 0.0
    tag_m: float = 0.0
    spacing_m: float = 0.0
    legacy_pattern: bool = False
    margin_m: float = 0.01
    first_id: int = 0
    diameter_m: float = 0.0
    allow_symmetric: bool = False
    origin_diameter_m: float = 0.0
    blob_detector: tuple = ()

    def __post_init__(self):
        where = f"target {self.name!r}"
        if not isinstance(self.name, str):
            raise ConfigError(f"{where}: key 'name' must be a string, got {self.name!r}")
        kind = get_kind(self.kind, where)
        for key in ("rows", "cols", "first_id"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise ConfigError(f"{where}: key {key!r} must be an integer, got {v!r}")
        for key in _LENGTHS:
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
                raise ConfigError(f"{where}: key {key!r} must be a finite number [m], got {v!r}")
            object.__setattr__(self, key, float(v))
        bd = self.blob_detector  # a mapping in YAML, a sorted tuple of (name, value) pairs here (hashable)
        if isinstance(bd, (list, tuple, dict)) and len(bd) == 0 or bd is None:
            object.__setattr__(self, "blob_detector", ())
        else:
            from .kinds.dot_grid import check_blob_settings

            object.__setattr__(self, "blob_detector", check_blob_settings(
                [tuple(kv) for kv in bd] if isinstance(bd, list) else bd, where))
        for key in ("legacy_pattern", "allow_symmetric"):
            if not isinstance(getattr(self, key), (bool, np.bool_)):
                raise ConfigError(f"{where}: key {key!r} must be true or false, got {getattr(self, key)!r}")
        for f in fields(self):  # keys of other kinds must keep their defaults
            if f.name not in _COMMON and f.name not in kind.keys and getattr(self, f.name) != f.default:
                raise ConfigError(f"{where}: key {f.name!r} does not apply to kind {self.kind!r} "
                                  f"(its keys: {', '.join(_COMMON[2:] + kind.keys)})")
        if self.margin_m < 0:
            raise ConfigError(f"{where}: key 'margin_m' must be >= 0 [m], got {self.margin_m}")
        if self.first_id < 0:
            raise ConfigError(f"{where}: key 'first_id' must be >= 0, got {self.first_id}")
        if self.rows * self.cols > MAX_FEATURES:  # before any per-feature array (corner points, dot polygons)
            raise ConfigError(f"{where}: keys 'rows' x 'cols' = {self.rows} x {self.cols} = {self.rows * self.cols:.4g} "
                              f"features, more than {MAX_FEATURES:.0e} (no camera image resolves more on one board; "
                              "the arrays for them would not fit in memory)")
        kind.validate(self, where)
        size = max(self.outline_m())
        if size > MAX_TARGET_M:
            raise ConfigError(f"{where}: the board would be {size:.4g} m wide, more than {MAX_TARGET_M:g} m "
                              f"(lengths are in metres: {', '.join(k for k in _LENGTHS if k in kind.keys)}, margin_m)")

    @property
    def kind_impl(self):
        """The registered :class:`~vision_calib.targets.kinds.TargetKind` of this target."""
        return _REGISTRY[self.kind]

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

    def texture_extent_m(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) [m, target frame] covered by :meth:`texture` (the whole board)."""
        w, h = self.pattern_size_m()
        m = self.margin_m
        return (-m, -m, w + m, h + m)

    def marker_ids(self) -> np.ndarray:
        """(M,) int ids of the board's markers/tags, in the order of :meth:`marker_corners` (ArUco kinds)."""
        return self._aruco("marker_ids")

    def marker_corners(self) -> np.ndarray:
        """(M, 4, 3) float64 [m, target frame] marker corners in OpenCV order (TL, TR, BR, BL) (ArUco kinds).

        Computed in float64 (OpenCV stores float32); which squares hold markers comes from OpenCV's board.
        """
        return self._aruco("marker_corners")

    def corner_points(self) -> tuple[np.ndarray, np.ndarray]:
        """Corner ids (K,) int and their 3-D positions p_target (K, 3) float64 [m], z = 0, sorted by id."""
        return self.kind_impl.corner_points(self)

    @property
    def n_corners(self) -> int:
        """Number of corner points K."""
        return self.kind_impl.n_corners(self)

    # ------------------------------------------------------------------ OpenCV objects
    def _aruco(self, method):
        fn = getattr(self.kind_impl, method, None)
        if fn is None:
            raise ConfigError(f"target {self.name!r}: kind {self.kind!r} has no markers ({method})")
        return fn(self)

    def cv_dictionary(self):
        """cv2.aruco.Dictionary of this target (ArUco kinds)."""
        return self._aruco("cv_dictionary")

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
        """Plain dict of the kind's keys (the YAML schema of :func:`load_target`)."""
        keep = _COMMON + self.kind_impl.keys
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name in keep}
        if "blob_detector" in out:
            if out["blob_detector"]:
                out["blob_detector"] = dict(out["blob_detector"])
            else:
                del out["blob_detector"]
        return out


def _overlap_1d(a: float, b: float, n: int) -> tuple[np.ndarray, int]:
    """Length of [a, b] (pixel units) inside each pixel [i, i+1], i = i0 .. ; clipped to [0, n)."""
    i0 = max(0, int(math.floor(a)))
    i1 = min(n, int(math.ceil(b)))
    if i1 <= i0:
        return np.zeros(0), i0
    i = np.arange(i0, i1, dtype=float)
    return np.clip(np.minimum(b, i + 1) - np.maximum(a, i), 0.0, 1.0), i0


_YAML_KEYS = {f.name for f in fields(TargetSpec)}
_EXTRA_KEYS = {"description", "units"}


def target_from_dict(d: dict, where: str = "target") -> TargetSpec:
    """TargetSpec from a dict with the keys of :class:`TargetSpec` (+ optional 'description', 'units': m).

    ``name`` defaults to ``where``. Raises ConfigError naming ``where`` and the key.
    """
    if not isinstance(d, dict):
        raise ConfigError(f"{where}: expected a mapping of target keys, got {type(d).__name__}")
    from ..config import did_you_mean

    allowed = sorted(_YAML_KEYS | _EXTRA_KEYS)
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
    kw = {k: v for k, v in d.items() if k in _YAML_KEYS}
    kw.setdefault("name", where)
    try:
        return TargetSpec(**kw)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def load_target(path) -> TargetSpec:
    """Load a target YAML file (keys of :class:`TargetSpec`, lengths in m). ConfigError names file and key."""
    from ..config import load_yaml

    path = Path(path)
    d = dict(load_yaml(path))  # ConfigError on a missing, non-UTF-8, invalid or non-mapping file
    d.setdefault("name", path.stem)
    return target_from_dict(d, where=str(path))
