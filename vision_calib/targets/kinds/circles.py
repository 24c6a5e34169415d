"""Asymmetric circle grid (``circles_asymmetric``), OpenCV's ``CALIB_CB_ASYMMETRIC_GRID`` pattern.

YAML keys: rows, cols, spacing_m, diameter_m, margin_m, allow_symmetric (optional).
- rows, cols: OpenCV's pattern size convention, ``patternSize = (cols, rows)``: ``cols`` circles in each
  row, ``rows`` rows (OpenCV's sample board is cols 4, rows 11).
- spacing_m = s, OpenCV's "square size" of this pattern (its calibration sample and gen_pattern.py):
  circle j of row i has its centre at ((2 j + i mod 2) s, i s) from circle 0: circles in a row are 2 s
  apart, rows are s apart and every other row is shifted by s, so nearest (diagonal) neighbours are
  s sqrt(2) apart. diameter_m < s sqrt(2) (circles must not touch).
- Target frame: origin at the outer top-left corner of the pattern's bounding box, so circle 0's centre is
  at (d/2, d/2, 0); id = i * cols + j (row-major, OpenCV's order for an upright board).

Orientation: the dot set maps onto itself under a 180-degree rotation iff rows is even (row i -> row
rows-1-i keeps its shift iff rows-1 is odd); such a board is refused unless ``allow_symmetric: true``
(intrinsics only). OpenCV's point order is tied to the board by fitting a homography to each ordering
the dot set allows (its symmetries) and keeping the front-facing one with the smallest residual.

Centres: OpenCV's blob centres (SimpleBlobDetector, areas 6 px .. 5 % of the image). They estimate the
centre of the dot's image, an ellipse whose centre is not the projected circle centre under
perspective: the offset grows with tilt and with (d / distance)^2. With ``intrinsics`` given,
:meth:`find_corners` removes it (PnP on the centres -> predicted offset of each ellipse centre from the
image conic -> corrected centres, twice). Measured on polygon-renderer images at the H4 geometry
(1024 x 768, f 1013 px, 0.6-0.76 m, tilt up to 35 deg, SensorEffects() defaults, circles_asymmetric_a4,
8 poses x 3 frames; /tmp script, same numbers by ``benchmarks/bench_detect.py --targets circles_asymmetric``):
centre error RMS 0.014 px without the correction, 0.005 px with it. A dark-area centroid refinement of
the blob centres measured worse (0.019 px, 0.012 px corrected) and is not used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ...errors import ConfigError
from .base import TargetKind, TargetSpec, check_memory
from ._grid import apply_h, fit_homography, front_facing
from .dot_lattice import refine_grid
from .image_model import circle_info
from .dot_grid import MAX_OFF_GRID, candidate_grids, check_blob_settings, grid_consistency, not_found_message

N_VERTICES = 128  # polygon vertices per dot (area-preserving radius: exact area and centroid)


def _blob_tuple(spec) -> None:
    """A spec's blob_detector (a mapping in YAML) as a sorted tuple of (name, value) pairs (hashable)."""
    bd = spec.blob_detector
    if isinstance(bd, (list, tuple, dict)) and len(bd) == 0 or bd is None:
        object.__setattr__(spec, "blob_detector", ())
    else:
        object.__setattr__(spec, "blob_detector", check_blob_settings(
            [tuple(kv) for kv in bd] if isinstance(bd, list) else bd, f"target {spec.name!r}"))


def _blob_dict(d: dict) -> dict:
    """to_dict of a dot-grid spec: blob_detector as a mapping, left out when empty."""
    if d["blob_detector"]:
        d["blob_detector"] = dict(d["blob_detector"])
    else:
        del d["blob_detector"]
    return d


@dataclass(frozen=True)
class CircleGridSpec(TargetSpec):
    """Asymmetric circle grid: spacing_m, diameter_m [m]; allow_symmetric (an even number of rows; intrinsics
    only); blob_detector: OpenCV SimpleBlobDetector parameters tried first on each image (:mod:`.dot_grid`)."""

    spacing_m: float = 0.0
    diameter_m: float = 0.0
    allow_symmetric: bool = False
    blob_detector: tuple = ()

    def __post_init__(self):
        _blob_tuple(self)
        super().__post_init__()

    def to_dict(self) -> dict:
        return _blob_dict(super().to_dict())


@dataclass(frozen=True)
class ModifiedCircleGridSpec(TargetSpec):
    """ROS-I modified circle grid: spacing_m, diameter_m (0: unknown), origin_diameter_m (0: twice diameter_m,
    ROS-I's generator) [m]; blob_detector as :class:`CircleGridSpec`'s."""

    spacing_m: float = 0.0
    diameter_m: float = 0.0
    origin_diameter_m: float = 0.0
    blob_detector: tuple = ()

    def __post_init__(self):
        _blob_tuple(self)
        super().__post_init__()

    def to_dict(self) -> dict:
        return _blob_dict(super().to_dict())


class AsymmetricCirclesKind(TargetKind):
    name = "circles_asymmetric"
    spec_class = CircleGridSpec
    required = ("spacing_m", "diameter_m")

    def corner_info(self, spec, normals, scale_px_per_m, effects, half_win):
        """Dot centres from their whole edge (:func:`.image_model.circle_info`)."""
        return circle_info(scale_px_per_m.mean(axis=1) * spec.diameter_m / 2, effects)
    correct_ellipse = True

    def validate(self, spec, where):
        if spec.rows < 3 or spec.cols < 2:
            raise ConfigError(f"{where}: circles_asymmetric keys 'rows' (>= 3) and 'cols' (>= 2, circles per row) "
                              f"out of range, got rows {spec.rows}, cols {spec.cols}")
        self.positive(spec, where, "spacing_m", "diameter_m")
        if spec.diameter_m >= spec.spacing_m * math.sqrt(2):
            raise ConfigError(f"{where}: key 'diameter_m' ({spec.diameter_m}) must be smaller than the diagonal "
                              f"spacing spacing_m * sqrt(2) ({spec.spacing_m * math.sqrt(2):.4g}): circles would touch")
        self.refuse_symmetric(spec, where, "ids", "Use an odd number of rows")

    def symmetric(self, spec):
        if spec.rows % 2 == 0:
            return (f"asymmetric circle grid with {spec.rows} rows looks the same after a 180-degree rotation "
                    "(even rows)")
        return ""

    def pattern_size_m(self, spec):
        s, d = spec.spacing_m, spec.diameter_m
        return (2 * (spec.cols - 1) + 1) * s + d, (spec.rows - 1) * s + d

    def n_corners(self, spec):
        return spec.rows * spec.cols

    def corner_points(self, spec):
        i, j = np.divmod(np.arange(self.n_corners(spec)), spec.cols)
        s, r = spec.spacing_m, spec.diameter_m / 2
        p = np.column_stack([r + (2 * j + i % 2) * s, r + i * s, np.zeros(i.size)])
        return np.arange(p.shape[0]), p

    def black_polygons(self, spec):
        """Each dot as a regular N_VERTICES-gon of the circle's area (:func:`dot_ring`)."""
        _check_polygon_memory(spec, self.n_corners(spec))
        _, p = self.corner_points(spec)
        return p[:, None, :2] + dot_ring(spec.diameter_m / 2)[None]

    # ---------------------------------------------------------------- detection
    def make_detector(self, spec, config):
        return None

    def _orderings(self, spec) -> list[np.ndarray]:
        """Permutations sigma of the ids under the symmetries of the dot set (identity first)."""
        _, p = self.corner_points(spec)
        w, h = self.pattern_size_m(spec)
        out = [np.arange(len(p))]
        for sx, sy in ((-1, -1), (-1, 1), (1, -1)):
            q = p[:, :2].copy()
            if sx < 0:
                q[:, 0] = w - q[:, 0]
            if sy < 0:
                q[:, 1] = h - q[:, 1]
            dist = np.linalg.norm(q[:, None] - p[None, :, :2], axis=2)
            perm = np.argmin(dist, axis=1)
            if np.all(dist[np.arange(len(p)), perm] < 1e-9 + 1e-6 * spec.spacing_m):
                out.append(perm)
        return out

    def find_corners(self, spec, det, img, config, diag, intrinsics=None):
        _, p = self.corner_points(spec)
        orderings = self._orderings(spec)

        def order(D, pattern, areas):
            best = None
            for perm in orderings:
                uv = np.empty_like(D)
                uv[perm] = D
                H = fit_homography(p[:, :2], uv)
                if H is None or not front_facing(H, p[:, :2].mean(axis=0)):
                    continue
                res = float(np.sqrt(np.mean(np.sum((apply_h(H, p[:, :2]) - uv) ** 2, axis=1))))
                if best is None or res < best[0]:
                    best = (res, uv)
            if best is None:
                return None, "circle grid order could not be tied to the board (no front-facing ordering)"
            return best[1], best[0]

        flags = cv2.CALIB_CB_ASYMMETRIC_GRID
        found = find_ordered(spec, img, diag, intrinsics, [(spec.cols, spec.rows)], [flags, flags | cv2.CALIB_CB_CLUSTERING],
                             order, f"asymmetric circle grid of {spec.cols} x {spec.rows} dots", big=False)
        if found[0] is None:
            return found
        uv = found[1]
        if self.correct_ellipse and intrinsics is not None:
            uv = uv - ellipse_centre_offset(spec, p, uv, intrinsics)
        return np.arange(len(uv)), uv


def find_ordered(spec, img, diag, intrinsics, patterns, flags_list, order, what, big):
    """The first dot grid of :func:`.dot_grid.candidate_grids` that ``order`` (centres (K, 2) px in OpenCV's grid
    order, its patternSize, dark areas (K,) px^2 or None -> (uv (K, 2) by id, homography RMS px) or (None, why))
    ties to the board and whose point order is consistent (:func:`.dot_grid.grid_consistency`: no dot more than
    MAX_OFF_GRID x the dot spacing off the board's homography, on undistorted points when intrinsics are given).
    ``big`` (the modified grid): the lattice stage runs and every dot is re-measured (:func:`.dot_lattice.refine_grid`:
    darkness-weighted centroid and dark area) before ``order``. Returns (ids, uv) or (None, reason naming what was
    found and why each grid was refused)."""
    _, p = spec.corner_points()
    dr = spec.diameter_m / spec.spacing_m if spec.diameter_m > 0 else 0.0
    report, refused = {}, []
    for stage, pattern, D in candidate_grids(img, len(p), patterns, flags_list, spec.blob_detector, dr, big, report,
                                             lattice=big):
        areas = None
        if big:
            G, areas = refine_grid(img, D.reshape(pattern[1], pattern[0], 2))
            if G is None:
                refused.append(areas)
                continue
            D, areas = G.reshape(-1, 2), areas.reshape(-1)
        uv, how = order(D, pattern, areas)
        if uv is None:
            refused.append(how)
            continue
        q = uv if intrinsics is None else cv2.undistortPoints(
            uv.reshape(-1, 1, 2), intrinsics.K, np.asarray(intrinsics.dist, float), P=intrinsics.K).reshape(-1, 2)
        off_px, off = grid_consistency(p[:, :2], q, spec.spacing_m)
        if not off <= MAX_OFF_GRID:
            refused.append(f"point order inconsistent (a dot {off_px:.1f} px = {off:.2f} dot spacings off the board's "
                           "homography: ids shifted by a row or column, or a stray blob in the grid)")
            continue
        diag.update(dot_stage=stage, homography_rms_px=float(how), max_off_grid_px=off_px, blobs=report)
        return np.arange(len(uv)), uv
    diag["blobs"] = report
    return None, not_found_message(what, len(p), report, refused)


def _check_polygon_memory(spec, n_dots: int) -> None:
    """ConfigError before drawing n_dots polygons would take more than half the available memory (the polygon
    array, its pixel copy and the coverage pass: about 4 x n_dots x N_VERTICES x 2 float64)."""
    check_memory(4 * n_dots * N_VERTICES * 2 * 8, f"target {spec.name!r}: drawing {n_dots} dots")


def dot_ring(radius: float) -> np.ndarray:
    """(N_VERTICES, 2) [m] regular polygon of a circle's area (radius scaled by sqrt(2 pi / (N sin(2 pi / N)))):
    exact area and centroid, radial error < 2e-4 of the diameter; vertices TL -> TR -> BR -> BL."""
    n = N_VERTICES
    rho = radius * math.sqrt(2 * math.pi / (n * math.sin(2 * math.pi / n)))
    a = -0.75 * math.pi + 2 * math.pi * np.arange(n) / n  # increasing angle: TL -> TR -> BR -> BL
    return rho * np.column_stack([np.cos(a), np.sin(a)])


def ellipse_centre_offset(spec, p, uv, intrinsics, iterations: int = 2, radii=None) -> np.ndarray:
    """(K, 2) px offset of each dot's image centre (the centre of the projected ellipse) from the projection
    of its circle's centre, at the pose PnP gives on the corrected centres (``iterations`` passes).
    p: (K, 3) circle centres [m]; uv: (K, 2) measured ellipse centres [distorted px]; radii: (K,) circle radii
    [m] (default: spec.diameter_m / 2 for every dot). The offset is computed for the pinhole image and
    applied unchanged to distorted pixels (distortion's local scale ~1)."""
    K, dist = intrinsics.K, np.asarray(intrinsics.dist, float)
    radii = np.full(len(p), spec.diameter_m / 2) if radii is None else np.asarray(radii, float)
    off = np.zeros_like(uv)
    for _ in range(iterations):
        ok, rvec, tvec = cv2.solvePnP(p, (uv - off).reshape(-1, 1, 2), K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            return off
        R, _ = cv2.Rodrigues(rvec)
        Hn = np.column_stack([R[:, 0], R[:, 1], tvec.ravel()])  # target (x, y, 1) -> normalised camera
        Hinv = np.linalg.inv(Hn)
        new = np.empty_like(uv)
        for k, (cx, cy, _) in enumerate(p):
            r = radii[k]
            Q = np.array([[1, 0, -cx], [0, 1, -cy], [-cx, -cy, cx * cx + cy * cy - r * r]])
            C = Hinv.T @ Q @ Hinv
            z = np.linalg.solve(C[:2, :2], -C[:2, 2])
            q = Hn @ np.array([cx, cy, 1.0])
            new[k] = (z - q[:2] / q[2]) * [intrinsics.fx, intrinsics.fy]
        off = new
    return off


class ModifiedCircleGridKind(TargetKind):
    """ROS-Industrial's modified circle grid (``modified_circle_grid``; industrial_calibration's
    ``ModifiedCircleGridTarget``): a symmetric grid of dark dots on white, one of them -- the *origin* dot,
    first of the last row -- larger, which ties the point order to the board.

    YAML keys: rows, cols (dots), spacing_m (centre distance), diameter_m (dots; optional, 0 = unknown:
    needed only to draw the board and for the ellipse-centre correction), origin_diameter_m (the large dot;
    0 = twice diameter_m, as ROS-I's generator draws it).
    Target frame (ours: x right, y down as the printed face is seen, z into the board): dot (r, c), id
    r * cols + c, at (D/2 + c s, d/2 + r s, 0) with d, D the dot and origin-dot diameters (origin at the
    outer top-left corner of the pattern's bounding box); the origin dot is id (rows - 1) * cols. The ids are
    ROS-I's point order (row by row from the row opposite the origin dot); ROS-I's own frame has its origin
    at the origin dot with y towards row 0 and z out of the board: p_rosi = (x - D/2, (rows - 1) s + d/2 - y, 0).

    Detection: ``cv2.findCirclesGrid`` (symmetric grid, clustering; the board may also be found with rows and
    cols swapped, i.e. seen turned by 90 degrees), then the orderings the dot grid allows (its symmetries,
    front-facing only) are told apart by the origin dot: the grid corner whose dark area, relative to its two
    grid neighbours', is largest (at least :data:`ORIGIN_RATIO` x the next corner's). Centres as for
    circles_asymmetric (ellipse-centre correction when the diameters and intrinsics are known)."""

    name = "modified_circle_grid"
    spec_class = ModifiedCircleGridSpec
    required = ("spacing_m",)

    def corner_info(self, spec, normals, scale_px_per_m, effects, half_win):
        """Dot centres from their whole edge (:func:`.image_model.circle_info`)."""
        return circle_info(scale_px_per_m.mean(axis=1) * spec.diameter_m / 2, effects)

    def validate(self, spec, where):
        if spec.rows < 2 or spec.cols < 2 or spec.rows * spec.cols < 6:
            raise ConfigError(f"{where}: modified_circle_grid keys 'rows' and 'cols' (dots) must be >= 2 with at "
                              f"least 6 dots, got {spec.rows}x{spec.cols}")
        self.positive(spec, where, "spacing_m")
        for key in ("diameter_m", "origin_diameter_m"):
            if getattr(spec, key) < 0:
                raise ConfigError(f"{where}: key {key!r} must be >= 0 [m] (0: unknown / default), "
                                  f"got {getattr(spec, key)}")
        d, D = self.diameters(spec)
        if d > 0 and (D <= d or (d + D) / 2 >= spec.spacing_m):
            raise ConfigError(f"{where}: keys 'diameter_m' ({d:.4g}) and 'origin_diameter_m' ({D:.4g}): the origin dot "
                              f"must be larger than the others and must not touch its neighbours ((d + D) / 2 < "
                              f"spacing_m = {spec.spacing_m:.4g})")

    def diameters(self, spec) -> tuple[float, float]:
        """(dot diameter d, origin-dot diameter D) [m]; (0, 0) when unknown."""
        d = spec.diameter_m
        return d, (spec.origin_diameter_m or 2 * d)

    def origin_id(self, spec) -> int:
        return (spec.rows - 1) * spec.cols

    def pattern_size_m(self, spec):
        d, D = self.diameters(spec)
        s = spec.spacing_m
        return (spec.cols - 1) * s + (d + D) / 2, (spec.rows - 1) * s + (d + D) / 2

    def n_corners(self, spec):
        return spec.rows * spec.cols

    def corner_points(self, spec):
        r, c = np.divmod(np.arange(self.n_corners(spec)), spec.cols)
        d, D = self.diameters(spec)
        s = spec.spacing_m
        p = np.column_stack([D / 2 + c * s, d / 2 + r * s, np.zeros(r.size)])
        return np.arange(p.shape[0]), p

    def radii(self, spec) -> np.ndarray:
        """(K,) dot radii [m] by id."""
        d, D = self.diameters(spec)
        out = np.full(self.n_corners(spec), d / 2)
        out[self.origin_id(spec)] = D / 2
        return out

    def black_polygons(self, spec):
        """Each dot as a regular N_VERTICES-gon of its circle's area (:func:`dot_ring`)."""
        if not spec.diameter_m > 0:
            raise ConfigError(f"target {spec.name!r}: key 'diameter_m' is needed to draw a modified_circle_grid "
                              "(detection and pose measurement do without it)")
        _check_polygon_memory(spec, self.n_corners(spec))
        _, p = self.corner_points(spec)
        return np.stack([p[k, :2] + dot_ring(r) for k, r in enumerate(self.radii(spec))])

    def make_detector(self, spec, config):
        return None

    def _grid_orderings(self, rows: int, cols: int, grid_shape) -> list:
        """Index arrays (rows, cols) into the detected grid (flattened, shape grid_shape) for every symmetry of
        a rows x cols dot grid that maps the detected grid onto it."""
        idx = np.arange(grid_shape[0] * grid_shape[1]).reshape(grid_shape)
        cands = []
        for g in (idx, idx.T):
            if g.shape != (rows, cols):
                continue
            cands += [g, g[::-1, ::-1], g[:, ::-1], g[::-1, :]]
        return cands

    def find_corners(self, spec, det, img, config, diag, intrinsics=None):
        rows, cols = spec.rows, spec.cols
        _, p = self.corner_points(spec)
        origin = self.origin_id(spec)
        patterns = [(cols, rows), (rows, cols)] if rows != cols else [(cols, rows)]

        def order(D, pattern, areas):
            shape = (pattern[1], pattern[0])  # OpenCV's patternSize (per row, rows) -> grid (rows, per row)
            corners = corner_area_ratios(D.reshape(*shape, 2), areas.reshape(shape))
            ranked = sorted(corners, key=corners.get, reverse=True)
            big, second = corners[ranked[0]], corners[ranked[1]]
            diag["origin_dot_ratio"] = float(big)
            if not (big >= ORIGIN_RATIO * second):
                return None, (f"the origin (large) dot is not recognisable: dark areas of the grid corners relative to "
                              f"the grid's median dot {[round(float(v), 2) for v in sorted(corners.values(), reverse=True)]}")
            for g in self._grid_orderings(rows, cols, shape):
                flat = g.reshape(-1)
                if flat[origin] != ranked[0]:
                    continue
                uv = D[flat]
                H = fit_homography(p[:, :2], uv)
                if H is None or not front_facing(H, p[:, :2].mean(axis=0)):
                    continue
                return uv, float(np.sqrt(np.mean(np.sum((apply_h(H, p[:, :2]) - uv) ** 2, axis=1))))
            return None, "grid order could not be tied to the board (no front-facing ordering with the origin dot)"

        flags = cv2.CALIB_CB_SYMMETRIC_GRID
        found = find_ordered(spec, img, diag, intrinsics, patterns, [flags | cv2.CALIB_CB_CLUSTERING, flags], order,
                             f"modified circle grid of {cols} x {rows} dots", big=True)
        if found[0] is None:
            return found
        uv = found[1]
        d, _ = self.diameters(spec)
        diag["ellipse_correction"] = bool(d > 0 and intrinsics is not None)
        if diag["ellipse_correction"]:
            uv = uv - ellipse_centre_offset(spec, p, uv, intrinsics, radii=self.radii(spec))
        return np.arange(len(uv)), uv


#: the origin dot's dark area relative to its grid neighbours must be at least this many times the next grid
#: corner's (ROS-I's generator: 4x the area of the other dots)
ORIGIN_RATIO = 1.5


def corner_area_ratios(G: np.ndarray, A: np.ndarray) -> dict:
    """{flat index of a corner of the detected dot grid G (R, C, 2) px: its dark area / the median dark area of the
    grid's dots}, with A (R, C) the dots' dark areas [px^2] (:func:`.dot_lattice.refine_grid`) each divided by the
    local area scale of the perspective, |det J| = |det H| / w^3 of the homography H fitted from grid indices to
    G (a dot's image area is its printed area times |det J|)."""
    R, C = G.shape[:2]
    ij = np.stack(np.meshgrid(np.arange(C, dtype=np.float64), np.arange(R, dtype=np.float64)), -1).reshape(-1, 2)
    H = fit_homography(ij, G.reshape(-1, 2))
    if H is None:
        scale = np.ones(R * C)
    else:
        w = np.column_stack([ij, np.ones(len(ij))]) @ H[2]
        scale = np.abs(np.linalg.det(H) / w ** 3)
    a = A.reshape(-1) / np.maximum(scale, 1e-12)
    med = float(np.median(a))
    return {r * C + c: float(a[r * C + c] / max(med, 1e-12)) for r, c in ((0, 0), (0, C - 1), (R - 1, 0), (R - 1, C - 1))}
