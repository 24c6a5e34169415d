"""Calibration target definitions: ChArUco boards and AprilTag grids (cv2 + numpy only).

Target frame (the same as OpenCV 4.14's board object points, ``board.getChessboardCorners()`` /
``board.getObjPoints()``; checked in ``tests/targets/test_spec.py``):

- origin at the *outer* top-left corner of the pattern (first chessboard square for ChArUco, top-left
  corner of tag 0's black border for an AprilTag grid), as seen in the texture / printed image;
- x along the pattern's columns (to the right in the image), y along its rows (down in the image);
- z = x × y points *into* the board, away from a viewer who looks at the printed face. A camera seeing
  the board upright therefore has ``R_cam_target ~= I`` (OpenCV camera: x right, y down, z forward).
- The white margin ``margin_m`` lies outside the pattern: the board spans
  ``[-margin_m, width_pattern + margin_m] x [-margin_m, height_pattern + margin_m]`` (:meth:`texture_extent_m`).

Corner ids:
- ChArUco: OpenCV's charuco ids (``CharucoDetector.detectBoard`` returns them); inner chessboard corners,
  row-major from the origin, id = r * (cols - 1) + c, at ((c + 1) * square_m, (r + 1) * square_m, 0).
- AprilTag grid: id = 4 * tag_id + k, k = 0..3 in OpenCV's marker corner order (top-left, top-right,
  bottom-right, bottom-left of the tag's black border, i.e. +x then +y in the target frame).
  Tag ids are ``first_id .. first_id + rows*cols - 1``, row-major.

Texture (:meth:`TargetSpec.texture`): white = 255, black = 0, drawn with exact *area coverage* of every
pixel (all features are axis-aligned rectangles), so edges are not quantised to texture pixels.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields
from pathlib import Path

import cv2
import numpy as np

from ..errors import ConfigError

KINDS = ("charuco", "apriltag_grid")
MAX_TARGET_M = 10.0  # a larger board is a unit mistake (mm given as m), refused on load
_BORDER_BITS = 1  # OpenCV markers: one black border bit around the data bits


def _dictionary_id(name: str) -> int:
    if not isinstance(name, str) or not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
        known = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_"))
        raise ConfigError(f"unknown dictionary {name!r}; expected one of cv2.aruco's names: {', '.join(known)}")
    return int(getattr(cv2.aruco, name))


@dataclass(frozen=True)
class TargetSpec:
    """A planar calibration target. Lengths in metres.

    kind: "charuco" | "apriltag_grid". rows, cols: number of squares (charuco) or tags (apriltag_grid)
    along y and x. dictionary: cv2.aruco dictionary name ("DICT_5X5_100", "DICT_APRILTAG_36h11").
    square_m, marker_m: charuco square and marker sides. tag_m: apriltag side (outer edge of the black
    border); spacing_m: white gap between tags. legacy_pattern: OpenCV < 4.6 charuco layout.
    margin_m: white margin around the pattern. first_id: id of the first marker/tag.
    """

    kind: str
    name: str
    rows: int
    cols: int
    dictionary: str
    square_m: float = 0.0
    marker_m: float = 0.0
    tag_m: float = 0.0
    spacing_m: float = 0.0
    legacy_pattern: bool = False
    margin_m: float = 0.01
    first_id: int = 0

    def __post_init__(self):
        where = f"target {self.name!r}"
        if not isinstance(self.name, str):
            raise ConfigError(f"{where}: key 'name' must be a string, got {self.name!r}")
        if self.kind not in KINDS:
            raise ConfigError(f"{where}: key 'kind' must be one of {KINDS}, got {self.kind!r}")
        for key in ("rows", "cols", "first_id"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise ConfigError(f"{where}: key {key!r} must be an integer, got {v!r}")
        for key in ("square_m", "marker_m", "tag_m", "spacing_m", "margin_m"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
                raise ConfigError(f"{where}: key {key!r} must be a finite number [m], got {v!r}")
            object.__setattr__(self, key, float(v))
        if not isinstance(self.legacy_pattern, (bool, np.bool_)):
            raise ConfigError(f"{where}: key 'legacy_pattern' must be true or false, got {self.legacy_pattern!r}")
        try:
            _dictionary_id(self.dictionary)
        except ConfigError as exc:
            raise ConfigError(f"{where}: key 'dictionary': {exc}") from None
        if self.margin_m < 0:
            raise ConfigError(f"{where}: key 'margin_m' must be >= 0 [m], got {self.margin_m}")
        if self.first_id < 0:
            raise ConfigError(f"{where}: key 'first_id' must be >= 0, got {self.first_id}")
        if self.kind == "charuco":
            if self.rows < 2 or self.cols < 2:
                raise ConfigError(f"{where}: charuco keys 'rows' and 'cols' (squares) must be >= 2, got {self.rows}x{self.cols}")
            for key in ("square_m", "marker_m"):
                if getattr(self, key) <= 0:
                    raise ConfigError(f"{where}: key {key!r} must be > 0 [m], got {getattr(self, key)}")
            if self.marker_m >= self.square_m:
                raise ConfigError(
                    f"{where}: key 'marker_m' ({self.marker_m}) must be smaller than 'square_m' ({self.square_m})"
                )
            n_markers = (self.rows * self.cols) // 2
        else:
            if self.rows < 1 or self.cols < 1:
                raise ConfigError(f"{where}: apriltag_grid keys 'rows' and 'cols' (tags) must be >= 1")
            for key in ("tag_m", "spacing_m"):
                if getattr(self, key) <= 0:
                    raise ConfigError(f"{where}: key {key!r} must be > 0 [m], got {getattr(self, key)}")
            n_markers = self.rows * self.cols
        size = max(self.outline_m())
        if size > MAX_TARGET_M:
            raise ConfigError(f"{where}: the board would be {size:.4g} m wide, more than {MAX_TARGET_M:g} m "
                              "(lengths are in metres: square_m, marker_m, tag_m, spacing_m, margin_m)")
        dict_size = self.cv_dictionary().bytesList.shape[0]
        if self.first_id + n_markers > dict_size:
            raise ConfigError(
                f"{where}: needs marker ids {self.first_id}..{self.first_id + n_markers - 1} but dictionary "
                f"{self.dictionary} has only {dict_size} markers (keys 'dictionary', 'first_id', 'rows', 'cols')"
            )

    # ------------------------------------------------------------------ geometry
    def pattern_size_m(self) -> tuple[float, float]:
        """(width, height) [m] of the pattern without margin (along target x and y)."""
        if self.kind == "charuco":
            return self.cols * self.square_m, self.rows * self.square_m
        return (
            self.cols * self.tag_m + (self.cols - 1) * self.spacing_m,
            self.rows * self.tag_m + (self.rows - 1) * self.spacing_m,
        )

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
        """(M,) int ids of the board's markers/tags, in the order of :meth:`marker_corners`."""
        return np.asarray(self.cv_board().getIds(), dtype=int).reshape(-1)

    def marker_corners(self) -> np.ndarray:
        """(M, 4, 3) float64 [m, target frame] marker corners in OpenCV order (TL, TR, BR, BL).

        Computed in float64 (OpenCV stores float32); which squares hold markers comes from OpenCV's board.
        """
        cv_pts = np.asarray(self.cv_board().getObjPoints(), dtype=float).reshape(-1, 4, 3)
        if self.kind == "charuco":
            s, m = self.square_m, self.marker_m
            sq = np.floor(cv_pts.mean(axis=1)[:, :2] / s)  # (M, 2) square column, row
            tl = sq * s + (s - m) / 2
            side = m
        else:
            pitch = self.tag_m + self.spacing_m
            i = np.arange(self.rows * self.cols)
            tl = np.column_stack([(i % self.cols) * pitch, (i // self.cols) * pitch]).astype(float)
            side = self.tag_m
        out = np.zeros((tl.shape[0], 4, 3))
        out[:, :, :2] = tl[:, None, :] + side * np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
        return out

    def corner_points(self) -> tuple[np.ndarray, np.ndarray]:
        """Corner ids (K,) int and their 3-D positions p_target (K, 3) float64 [m], z = 0, sorted by id."""
        if self.kind == "charuco":
            r, c = np.divmod(np.arange(self.n_corners), self.cols - 1)
            p = np.column_stack([(c + 1) * self.square_m, (r + 1) * self.square_m, np.zeros(r.size)])
            return np.arange(p.shape[0]), p
        ids = self.marker_ids()
        corners = self.marker_corners()
        cid = (4 * ids[:, None] + np.arange(4)[None, :]).reshape(-1)
        p = corners.reshape(-1, 3)
        order = np.argsort(cid, kind="stable")
        return cid[order], p[order]

    @property
    def n_corners(self) -> int:
        """Number of corner points K."""
        if self.kind == "charuco":
            return (self.rows - 1) * (self.cols - 1)
        return 4 * self.rows * self.cols

    # ------------------------------------------------------------------ OpenCV objects
    def cv_dictionary(self):
        """cv2.aruco.Dictionary of this target."""
        return cv2.aruco.getPredefinedDictionary(_dictionary_id(self.dictionary))

    def cv_board(self):
        """A fresh cv2.aruco.CharucoBoard (charuco) or cv2.aruco.GridBoard (apriltag_grid)."""
        d = self.cv_dictionary()
        if self.kind == "charuco":
            n = (self.rows * self.cols) // 2
            ids = np.arange(self.first_id, self.first_id + n, dtype=np.int32)
            board = cv2.aruco.CharucoBoard((self.cols, self.rows), self.square_m, self.marker_m, d, ids)
            board.setLegacyPattern(bool(self.legacy_pattern))
            return board
        n = self.rows * self.cols
        ids = np.arange(self.first_id, self.first_id + n, dtype=np.int32)
        return cv2.aruco.GridBoard((self.cols, self.rows), self.tag_m, self.spacing_m, d, ids)

    # ------------------------------------------------------------------ texture
    def black_rects(self) -> list[tuple[float, float, float, float]]:
        """Non-overlapping black rectangles (x0, y0, x1, y1) [m, target frame] making up the pattern."""
        rects = []
        d = self.cv_dictionary()
        ids = self.marker_ids()
        corners = self.marker_corners()
        nb = d.markerSize + 2 * _BORDER_BITS
        for mid, c in zip(ids, corners):
            x0, y0 = c[0, 0], c[0, 1]
            x1, y1 = c[2, 0], c[2, 1]
            bits = np.zeros((nb, nb), dtype=np.uint8)
            data = cv2.aruco.Dictionary.getBitsFromByteList(d.bytesList[int(mid)][None], d.markerSize)
            bits[_BORDER_BITS:-_BORDER_BITS, _BORDER_BITS:-_BORDER_BITS] = data
            xs = np.linspace(x0, x1, nb + 1)
            ys = np.linspace(y0, y1, nb + 1)
            for r in range(nb):  # merge runs of black bits along each row
                c0 = None
                for cc in range(nb + 1):
                    black = cc < nb and bits[r, cc] == 0
                    if black and c0 is None:
                        c0 = cc
                    elif not black and c0 is not None:
                        rects.append((xs[c0], ys[r], xs[cc], ys[r + 1]))
                        c0 = None
        if self.kind == "charuco":
            s = self.square_m
            marker_centres = corners.mean(axis=1)[:, :2]
            has_marker = np.zeros((self.rows, self.cols), dtype=bool)
            for cx, cy in marker_centres:
                has_marker[int(cy // s), int(cx // s)] = True
            for r in range(self.rows):
                for c in range(self.cols):
                    if not has_marker[r, c]:
                        rects.append((c * s, r * s, (c + 1) * s, (r + 1) * s))
        return rects

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
        return np.clip(img, 0.0, 1.0)

    def to_dict(self) -> dict:
        """Plain dict (the YAML schema of :func:`load_target`)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


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
    missing = [k for k in ("kind", "rows", "cols", "dictionary") if k not in d]
    if missing:
        raise ConfigError(f"{where}: missing key(s) {missing}")
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
