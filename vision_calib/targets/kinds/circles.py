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

import cv2
import numpy as np

from ...errors import ConfigError
from . import TargetKind
from ._grid import apply_h, fit_homography, front_facing

N_VERTICES = 128  # polygon vertices per dot (area-preserving radius: exact area and centroid)


class AsymmetricCirclesKind(TargetKind):
    name = "circles_asymmetric"
    keys = ("spacing_m", "diameter_m", "allow_symmetric")
    required = ("spacing_m", "diameter_m")
    info_model = "circle"
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
        """Each dot as a regular N_VERTICES-gon of the circle's area (radius scaled by
        sqrt(2 pi / (N sin(2 pi / N)))): exact area and centroid, radial error < 2e-4 d."""
        n = N_VERTICES
        rho = spec.diameter_m / 2 * math.sqrt(2 * math.pi / (n * math.sin(2 * math.pi / n)))
        a = -0.75 * math.pi + 2 * math.pi * np.arange(n) / n  # increasing angle: TL -> TR -> BR -> BL
        ring = rho * np.column_stack([np.cos(a), np.sin(a)])
        _, p = self.corner_points(spec)
        return p[:, None, :2] + ring[None]

    # ---------------------------------------------------------------- detection
    def make_detector(self, spec, config):
        return None

    def _blob_detector(self, img):
        p = cv2.SimpleBlobDetector_Params()
        p.minArea = 6.0
        p.maxArea = 0.05 * img.shape[0] * img.shape[1]
        p.minDistBetweenBlobs = 2.0
        p.filterByCircularity = True
        p.minCircularity = 0.5
        p.filterByConvexity = True
        p.minConvexity = 0.8
        p.filterByInertia = True
        p.minInertiaRatio = 0.05
        return cv2.SimpleBlobDetector_create(p)

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
        ok, centres = cv2.findCirclesGrid(img, (spec.cols, spec.rows), flags=cv2.CALIB_CB_ASYMMETRIC_GRID,
                                          blobDetector=self._blob_detector(img))
        if not ok or centres is None:
            return None, (f"asymmetric circle grid of {spec.cols} x {spec.rows} not found "
                          "(the whole board must be visible)")
        D = centres.reshape(-1, 2).astype(np.float64)
        _, p = self.corner_points(spec)
        best = None
        for perm in self._orderings(spec):
            uv = np.empty_like(D)
            uv[perm] = D
            H = fit_homography(p[:, :2], uv)
            if H is None or not front_facing(H, p[:, :2].mean(axis=0)):
                continue
            res = float(np.sqrt(np.mean(np.sum((apply_h(H, p[:, :2]) - uv) ** 2, axis=1))))
            if best is None or res < best[0]:
                best = (res, uv, H)
        if best is None:
            return None, "circle grid order could not be tied to the board (no front-facing ordering)"
        diag["homography_rms_px"] = best[0]
        uv = best[1]
        if self.correct_ellipse and intrinsics is not None:
            uv = uv - ellipse_centre_offset(spec, p, uv, intrinsics)
        return np.arange(len(uv)), uv


def ellipse_centre_offset(spec, p, uv, intrinsics, iterations: int = 2) -> np.ndarray:
    """(K, 2) px offset of each dot's image centre (the centre of the projected ellipse) from the projection
    of its circle's centre, at the pose PnP gives on the corrected centres (``iterations`` passes).
    p: (K, 3) circle centres [m]; uv: (K, 2) measured ellipse centres [distorted px]. The offset is computed
    for the pinhole image and applied unchanged to distorted pixels (distortion's local scale ~1)."""
    K, dist = intrinsics.K, np.asarray(intrinsics.dist, float)
    r = spec.diameter_m / 2
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
            Q = np.array([[1, 0, -cx], [0, 1, -cy], [-cx, -cy, cx * cx + cy * cy - r * r]])
            C = Hinv.T @ Q @ Hinv
            z = np.linalg.solve(C[:2, :2], -C[:2, 2])
            q = Hn @ np.array([cx, cy, 1.0])
            new[k] = (z - q[:2] / q[2]) * [intrinsics.fx, intrinsics.fy]
        off = new
    return off
