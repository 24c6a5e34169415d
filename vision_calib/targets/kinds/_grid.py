"""Helpers shared by the grid kinds (chessboard, ChArUco, circle grids): homographies and the orientation of detected
point grids, the square-board corner layout (:class:`SquareCorners`). The dot lattice of circle grids seen in photos
is :mod:`.dot_lattice`."""

from __future__ import annotations

import cv2
import numpy as np


def fit_homography(xy: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(3, 3) least-squares homography xy (K, 2) -> uv (K, 2) (all points, no RANSAC)."""
    H, _ = cv2.findHomography(np.asarray(xy, np.float64), np.asarray(uv, np.float64), 0)
    return H


def apply_h(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    p = np.asarray(xy, float) @ H[:, :2].T + H[:, 2]
    return p[..., :2] / p[..., 2:]


def front_facing(H: np.ndarray, xy_centre) -> bool:
    """Whether H maps the target's x and y axes (x right, y down, seen from the printed face) to image
    directions of the same handedness at xy_centre (False: the point order is mirrored)."""
    e = 1e-3
    c = np.asarray(xy_centre, float)
    p0, px, py = apply_h(H, np.array([c, c + [e, 0], c + [0, e]]))
    dx, dy = px - p0, py - p0
    return float(dx[0] * dy[1] - dx[1] * dy[0]) > 0


def sample_mean(img: np.ndarray, uv: np.ndarray) -> float:
    """Mean bilinear grey value of img at the points uv (N, 2) [px, pixel-centre convention]."""
    m = np.asarray(uv, np.float32).reshape(-1, 1, 2)
    v = cv2.remap(img, m[..., 0], m[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return float(np.mean(v))


class SquareCorners:
    """Mixin: the inner corners of a board of rows x cols squares of side square_m (ChArUco, chessboard),
    ids row-major from the origin: id = r (cols - 1) + c at ((c + 1) square_m, (r + 1) square_m, 0)."""

    def pattern_size_m(self, spec):
        return spec.cols * spec.square_m, spec.rows * spec.square_m

    def n_corners(self, spec):
        return (spec.rows - 1) * (spec.cols - 1)

    def corner_points(self, spec):
        r, c = np.divmod(np.arange(self.n_corners(spec)), spec.cols - 1)
        p = np.column_stack([(c + 1) * spec.square_m, (r + 1) * spec.square_m, np.zeros(r.size)])
        return np.arange(p.shape[0]), p
