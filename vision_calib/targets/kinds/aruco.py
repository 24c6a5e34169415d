"""ArUco-based kinds: ChArUco boards (``charuco``) and AprilTag grids (``apriltag_grid``).

YAML keys: charuco: rows, cols (squares), dictionary, square_m, marker_m, legacy_pattern, first_id;
apriltag_grid: rows, cols (tags), dictionary, tag_m (outer edge of the black border), spacing_m (white
gap), first_id. Ids: see :mod:`vision_calib.targets.spec`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ...errors import ConfigError
from .base import TargetKind, TargetSpec
from .image_model import apriltag_terms, tag_edge_info
from ._grid import SquareCorners

_BORDER_BITS = 1  # OpenCV markers: one black border bit around the data bits

_REFINE = {
    "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG,
    "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
    "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
    "none": cv2.aruco.CORNER_REFINE_NONE,
}


def dictionary_id(name: str) -> int:
    if not isinstance(name, str) or not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
        known = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_"))
        raise ConfigError(f"unknown dictionary {name!r}; expected one of cv2.aruco's names: {', '.join(known)}")
    return int(getattr(cv2.aruco, name))


@dataclass(frozen=True)
class CharucoSpec(TargetSpec):
    """ChArUco board: dictionary (cv2.aruco name, e.g. "DICT_5X5_100"), square_m and marker_m [m] (square and
    marker sides), legacy_pattern (OpenCV < 4.6 layout), first_id (id of the first marker)."""

    dictionary: str = ""
    square_m: float = 0.0
    marker_m: float = 0.0
    legacy_pattern: bool = False
    first_id: int = 0


@dataclass(frozen=True)
class AprilTagGridSpec(TargetSpec):
    """AprilTag grid: dictionary (e.g. "DICT_APRILTAG_36h11"), tag_m [m] (outer edge of the black border),
    spacing_m [m] (white gap between tags), first_id (id of the first tag)."""

    dictionary: str = ""
    tag_m: float = 0.0
    spacing_m: float = 0.0
    first_id: int = 0


class _ArucoKind(TargetKind):
    """Common part: a marker dictionary, marker bits drawn as black rectangles."""

    required = ("dictionary",)

    def n_markers(self, spec) -> int:
        raise NotImplementedError

    def validate(self, spec, where):
        if spec.first_id < 0:
            raise ConfigError(f"{where}: key 'first_id' must be >= 0, got {spec.first_id}")
        try:
            dictionary_id(spec.dictionary)
        except ConfigError as exc:
            raise ConfigError(f"{where}: key 'dictionary': {exc}") from None
        n = self.n_markers(spec)
        dict_size = self.cv_dictionary(spec).bytesList.shape[0]
        if spec.first_id + n > dict_size:
            raise ConfigError(
                f"{where}: needs marker ids {spec.first_id}..{spec.first_id + n - 1} but dictionary "
                f"{spec.dictionary} has only {dict_size} markers (keys 'dictionary', 'first_id', 'rows', 'cols')")

    def cv_dictionary(self, spec):
        return cv2.aruco.getPredefinedDictionary(dictionary_id(spec.dictionary))

    def marker_ids(self, spec) -> np.ndarray:
        return np.asarray(self.cv_board(spec).getIds(), dtype=int).reshape(-1)

    def _marker_tl(self, spec, cv_pts) -> tuple[np.ndarray, float]:
        raise NotImplementedError

    def marker_corners(self, spec) -> np.ndarray:
        """(M, 4, 3) float64 marker corners (TL, TR, BR, BL); which squares hold markers comes from OpenCV."""
        cv_pts = np.asarray(self.cv_board(spec).getObjPoints(), dtype=float).reshape(-1, 4, 3)
        tl, side = self._marker_tl(spec, cv_pts)
        out = np.zeros((tl.shape[0], 4, 3))
        out[:, :, :2] = tl[:, None, :] + side * np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
        return out

    def black_rects(self, spec):
        rects = []
        d = self.cv_dictionary(spec)
        nb = d.markerSize + 2 * _BORDER_BITS
        for mid, c in zip(self.marker_ids(spec), self.marker_corners(spec)):
            x0, y0, x1, y1 = c[0, 0], c[0, 1], c[2, 0], c[2, 1]
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
        return rects

    def _params(self, spec, config):
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = _REFINE[config.refine_for(spec.kind)]
        params.cornerRefinementWinSize = 3
        return params


#: marker decoding (ChArUco): each bit read in the central 40 % of its cell (IgnoredMarginPerCell 0.3, 8 px per
#: cell): on defocused or tilted markers the cell borders mix the neighbours' grey; measured on
#: benchmarks/bench_target_photos.py views (see :data:`FALLBACKS`).
DECODE = {"perspectiveRemovePixelPerCell": 8, "perspectiveRemoveIgnoredMarginPerCell": 0.3}


def unsharp(img, sigma_px: float = 2.0, amount: float = 2.0):
    """img + amount (img - Gaussian(img, sigma_px)), clipped to uint8: restores the contrast of marker bits
    blurred by a defocus of about sigma_px."""
    f = img.astype(np.float32)
    return np.clip(f + amount * (f - cv2.GaussianBlur(f, (0, 0), sigma_px)), 0, 255).astype(np.uint8)


#: fallback marker passes (name, img -> (scale, image)): a sharpened image (defocus), then the image upsampled
#: 2x (bicubic: small or steeply tilted markers, whose contours are too coarse at 1 px per step). Measured
#: (bench_target_photos.py, ChArUco 20-45 px squares, 12 views per kind): 'sizes' 6 -> 12 / 12, perspective 60 deg
#: 5 -> 10 / 12, the other kinds unchanged or better; ~10 ms per pass at 800 x 600.
FALLBACKS = (("sharpened", lambda img: (1.0, unsharp(img))),
             ("upsampled 2x", lambda img: (2.0, cv2.resize(img, None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC))))


def merge_markers(corners, ids, corners2, ids2):
    """The union of two marker sets ((M,) tuples of (1, 4, 2) float32 corners, (M, 1) int32 ids), the first set's
    corners kept for ids in both."""
    have = {} if ids is None else {int(i): c for c, i in zip(corners, ids.ravel())}
    for c, i in zip(corners2, ids2.ravel()):
        have.setdefault(int(i), np.asarray(c, dtype=np.float32).reshape(1, 4, 2))
    keys = sorted(have)
    return tuple(have[k] for k in keys), np.array(keys, dtype=np.int32).reshape(-1, 1)


def missing_in_view(spec, corners, ids, shape, border_px: float = 2.0) -> bool:
    """Whether a marker of the board is missing from a detection (corners, ids as cv2.aruco returns them) although
    it should lie inside the image (H, W) by border_px: predicted by the homography of the detected markers'
    corners (>= 2 markers), else True when any marker is missing."""
    board_ids = spec.marker_ids()
    found = set() if ids is None else {int(i) for i in ids.ravel()}
    missing = [k for k, i in enumerate(board_ids) if int(i) not in found]
    if not missing:
        return False
    if len(found) < 2:
        return True
    pos = {int(i): k for k, i in enumerate(board_ids)}
    obj = spec.marker_corners()[:, :, :2]
    mine = [(obj[pos[int(i)]], np.asarray(c, dtype=np.float64).reshape(4, 2)) for c, i in zip(corners, ids.ravel())
            if int(i) in pos]
    if len(mine) < 2:
        return True
    src, dst = (np.concatenate(x) for x in zip(*mine))
    H, _ = cv2.findHomography(src, dst)
    if H is None:
        return True
    q = obj[missing].reshape(-1, 2) @ H[:, :2].T + H[:, 2]
    uv = (q[:, :2] / q[:, 2:]).reshape(len(missing), 4, 2)
    h, w = shape[:2]
    inside = np.all((uv >= border_px) & (uv <= np.array([w - 1, h - 1]) - border_px), axis=(1, 2)) & np.all(
        q[:, 2].reshape(len(missing), 4) > 0, axis=1)
    return bool(inside.any())


class CharucoKind(SquareCorners, _ArucoKind):
    """ChArUco board: rows x cols squares of square_m, markers of marker_m in the white squares."""

    name = "charuco"
    spec_class = CharucoSpec
    required = ("dictionary", "square_m", "marker_m")
    auto_extra_subpix = True
    #: corners from cv2.cornerSubPix: pixel-phase-locked errors (measure/covariance.py; measured:
    #: ``benchmarks/bench_measure.py --phase-terms``)
    phase_locked_share = 0.92
    detect_uses_intrinsics = False

    def n_markers(self, spec):
        return (spec.rows * spec.cols) // 2

    def validate(self, spec, where):
        if spec.rows < 2 or spec.cols < 2:
            raise ConfigError(f"{where}: charuco keys 'rows' and 'cols' (squares) must be >= 2, got {spec.rows}x{spec.cols}")
        self.positive(spec, where, "square_m", "marker_m")
        if spec.marker_m >= spec.square_m:
            raise ConfigError(f"{where}: key 'marker_m' ({spec.marker_m}) must be smaller than 'square_m' ({spec.square_m})")
        super().validate(spec, where)

    def cv_board(self, spec):
        ids = np.arange(spec.first_id, spec.first_id + self.n_markers(spec), dtype=np.int32)
        board = cv2.aruco.CharucoBoard((spec.cols, spec.rows), spec.square_m, spec.marker_m,
                                       self.cv_dictionary(spec), ids)
        board.setLegacyPattern(bool(spec.legacy_pattern))
        return board

    def _marker_tl(self, spec, cv_pts):
        s, m = spec.square_m, spec.marker_m
        sq = np.floor(cv_pts.mean(axis=1)[:, :2] / s)  # (M, 2) square column, row
        return sq * s + (s - m) / 2, m

    def black_rects(self, spec):
        rects = super().black_rects(spec)
        s = spec.square_m
        has_marker = np.zeros((spec.rows, spec.cols), dtype=bool)
        for cx, cy in self.marker_corners(spec).mean(axis=1)[:, :2]:
            has_marker[int(cy // s), int(cx // s)] = True
        for r in range(spec.rows):
            for c in range(spec.cols):
                if not has_marker[r, c]:
                    rects.append((c * s, r * s, (c + 1) * s, (r + 1) * s))
        return rects

    def make_detector(self, spec, config):
        """(CharucoDetector, ArucoDetector) with the decoding settings of :data:`DECODE` (:meth:`find_corners`)."""
        params = self._params(spec, config)
        for key, value in DECODE.items():
            setattr(params, key, value)
        return (cv2.aruco.CharucoDetector(self.cv_board(spec), cv2.aruco.CharucoParameters(), params),
                cv2.aruco.ArucoDetector(self.cv_dictionary(spec), params))

    def find_corners(self, spec, det, img, config, diag, intrinsics=None):
        """Markers on the image, then, when markers of the board that should be in view are missing
        (:func:`missing_in_view`), on the fallback images of :data:`FALLBACKS` (marker sets merged, the first
        pass's corners kept); the ChArUco corners are interpolated and refined on the original image."""
        board_det, marker_det = det
        m_corners, m_ids, _ = marker_det.detectMarkers(img)
        diag["marker_passes"] = ["image"]
        for name, make in FALLBACKS:
            if not missing_in_view(spec, m_corners, m_ids, img.shape):
                break
            scale, alt = make(img)
            c2, i2, _ = marker_det.detectMarkers(alt)
            if i2 is not None and len(i2):
                m_corners, m_ids = merge_markers(m_corners, m_ids, [(c + 0.5) / scale - 0.5 for c in c2], i2)
            diag["marker_passes"].append(name)
        if m_ids is None or not len(m_ids):
            diag["n_markers"], diag["marker_ids"] = 0, []
            return None, "target not visible: no marker of the target dictionary detected"
        ch_corners, ch_ids, m_corners, m_ids = board_det.detectBoard(img, markerCorners=m_corners, markerIds=m_ids)
        n_markers = 0 if m_ids is None else len(m_ids)
        diag["n_markers"] = n_markers
        diag["marker_ids"] = [] if m_ids is None else sorted(int(i) for i in m_ids.ravel())
        if ch_ids is None or len(ch_ids) == 0:
            return None, ("target not visible: no marker of the target dictionary detected" if n_markers == 0
                          else f"no ChArUco corner interpolated from {n_markers} marker(s)")
        return ch_ids.ravel().astype(int), ch_corners.reshape(-1, 2).astype(np.float64)

    def seeded_mode(self, config):
        # without the cornerSubPix pass there is no per-frame estimator to seed: per-frame path
        return "subpix" if config.extra_subpix_for(self.name) else None


class AprilTagGridKind(_ArucoKind):
    """Grid of rows x cols AprilTags of tag_m with white gaps spacing_m."""

    name = "apriltag_grid"
    spec_class = AprilTagGridSpec
    required = ("dictionary", "tag_m", "spacing_m")
    auto_refine = "apriltag"

    def corner_info(self, spec, normals, scale_px_per_m, effects, half_win):
        """Tag corners from two fitted sides of tag_m (:func:`.image_model.tag_edge_info`)."""
        return tag_edge_info(normals, scale_px_per_m * spec.tag_m, effects)

    def bias_columns(self, ids, uv_px, estimator):
        """Common shift, tag growth and smooth field terms (:func:`.image_model.apriltag_terms`)."""
        return apriltag_terms(ids, uv_px, estimator)

    def n_markers(self, spec):
        return spec.rows * spec.cols

    def validate(self, spec, where):
        if spec.rows < 1 or spec.cols < 1:
            raise ConfigError(f"{where}: apriltag_grid keys 'rows' and 'cols' (tags) must be >= 1")
        self.positive(spec, where, "tag_m", "spacing_m")
        super().validate(spec, where)

    def pattern_size_m(self, spec):
        return (spec.cols * spec.tag_m + (spec.cols - 1) * spec.spacing_m,
                spec.rows * spec.tag_m + (spec.rows - 1) * spec.spacing_m)

    def n_corners(self, spec):
        return 4 * spec.rows * spec.cols

    def corner_points(self, spec):
        ids = self.marker_ids(spec)
        cid = (4 * ids[:, None] + np.arange(4)[None, :]).reshape(-1)
        p = self.marker_corners(spec).reshape(-1, 3)
        order = np.argsort(cid, kind="stable")
        return cid[order], p[order]

    def cv_board(self, spec):
        ids = np.arange(spec.first_id, spec.first_id + self.n_markers(spec), dtype=np.int32)
        return cv2.aruco.GridBoard((spec.cols, spec.rows), spec.tag_m, spec.spacing_m, self.cv_dictionary(spec), ids)

    def _marker_tl(self, spec, cv_pts):
        pitch = spec.tag_m + spec.spacing_m
        i = np.arange(spec.rows * spec.cols)
        return np.column_stack([(i % spec.cols) * pitch, (i // spec.cols) * pitch]).astype(float), spec.tag_m

    def make_detector(self, spec, config):
        return cv2.aruco.ArucoDetector(self.cv_dictionary(spec), self._params(spec, config))

    def find_corners(self, spec, det, img, config, diag, intrinsics=None):
        m_corners, m_ids, _rej = det.detectMarkers(img)
        all_ids = [] if m_ids is None else [int(i) for i in m_ids.ravel()]
        diag["n_markers"] = len(all_ids)
        diag["marker_ids"] = sorted(all_ids)
        first, last = spec.first_id, spec.first_id + self.n_markers(spec)
        ids_l, uv_l = [], []
        for mid, c in zip(all_ids, m_corners):
            if first <= mid < last:
                ids_l.append(4 * mid + np.arange(4))
                uv_l.append(c.reshape(4, 2))
        if not ids_l:
            return None, ("target not visible: no marker of the target dictionary detected" if not all_ids
                          else f"detected marker ids {sorted(all_ids)} do not belong to the target "
                               f"(wrong dictionary or wrong board?)")
        uv = np.concatenate(uv_l).astype(np.float64)
        if config.refine_for(self.name) == "apriltag":
            uv += config.apriltag_offset_px
        return np.concatenate(ids_l), uv

    def seeded_mode(self, config):
        return "tag_edges"

    def tag_cells(self, spec) -> int:
        """Bits across a tag incl. the black border (measure/tag_edges.py)."""
        return self.cv_dictionary(spec).markerSize + 2 * _BORDER_BITS
