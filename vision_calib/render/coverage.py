"""Exact pixel-area coverage of a planar target under a homography (the ``"polygon"`` backend).

Every target is white inside its outline with non-overlapping, axis-aligned black rectangles
(:meth:`TargetSpec._black_rects`, the same rectangles its texture is drawn from). A homography maps
straight lines to straight lines, so each rectangle projects to an exact convex quadrilateral whose
vertices are the projected corners; the ideal image (pixel value = mean of the board's radiance over
the pixel's square, the limit of supersampling by s -> infinity) is then

    I = background + (face - background) * cover(outline) - face * sum_k cover(rect_k)   (front face)
    I = background + (back_grey - background) * cover(outline)                           (back face)

with cover(Q) the exact fraction of each pixel inside quad Q. :func:`accumulate_coverage` computes it by
signed-area accumulation (as in font rasterisers): every polygon edge is cut at each integer x and y
(pixel borders), each piece lying in one pixel cell adds its signed height dy times the part of the cell
right of it to that cell and the rest to the next cell; a cumulative sum along each row then gives the
covered area of every pixel, exactly up to float64 rounding (no texture, no sampling, no aliasing).
Pixel u covers [u - 0.5, u + 0.5] (OpenCV centres): pixel coordinates are shifted by + 0.5 first.
"""

from __future__ import annotations

import math

import numpy as np

from ..camera import CameraIntrinsics
from ..targets.spec import TargetSpec


def _rect_corners(rects: np.ndarray) -> np.ndarray:
    """(N, 4, 2) corners TL, TR, BR, BL of rectangles (N, 4) = (x0, y0, x1, y1)."""
    x0, y0, x1, y1 = rects.T
    return np.stack([np.stack([x0, y0], -1), np.stack([x1, y0], -1), np.stack([x1, y1], -1),
                     np.stack([x0, y1], -1)], axis=1)


def _split_pieces(e: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut edges e (E, 4) = (xa, ya, xb, yb) [cell units] at integer y and at integer x in [0, width].
    Returns (edge index (P,), start (P, 2), end (P, 2)) of the pieces, in order along each edge."""
    xa, ya, xb, yb = e.T
    ky0 = np.floor(np.minimum(ya, yb)) + 1  # integers strictly inside (min y, max y) ...
    ny = np.maximum(np.ceil(np.maximum(ya, yb)) - ky0, 0).astype(np.int64)
    lo, hi = np.minimum(xa, xb), np.maximum(xa, xb)
    kx0 = np.maximum(np.floor(lo) + 1, 0)  # ... and integers in (min x, max x) clipped to [0, width]
    nx = np.maximum(np.minimum(np.ceil(hi) - 1, width) - kx0 + 1, 0).astype(np.int64)
    n = ny + nx
    idx = np.repeat(np.arange(len(e)), n)
    start = np.cumsum(n) - n
    k = np.arange(idx.size) - np.repeat(start, n)  # rank of each cut within its edge
    is_y = k < ny[idx]
    val = np.where(is_y, ky0[idx] + k, kx0[idx] + k - ny[idx])
    dy, dx = (yb - ya)[idx], (xb - xa)[idx]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(is_y, (val - ya[idx]) / dy, (val - xa[idx]) / dx)
    # all cut parameters, plus 0 and 1 per edge, sorted within each edge
    all_idx = np.concatenate([np.arange(len(e)), idx, np.arange(len(e))])
    all_t = np.concatenate([np.zeros(len(e)), np.clip(t, 0.0, 1.0), np.ones(len(e))])
    order = np.lexsort((all_t, all_idx))
    all_idx, all_t = all_idx[order], all_t[order]
    same = all_idx[1:] == all_idx[:-1]
    i, t0, t1 = all_idx[1:][same], all_t[:-1][same], all_t[1:][same]
    p0 = np.stack([xa[i] + t0 * (xb - xa)[i], ya[i] + t0 * (yb - ya)[i]], -1)
    p1 = np.stack([xa[i] + t1 * (xb - xa)[i], ya[i] + t1 * (yb - ya)[i]], -1)
    return i, p0, p1


def accumulate_coverage(polys: np.ndarray, weights: np.ndarray, height: int, width: int) -> np.ndarray:
    """Sum over polygons of weight * (signed) covered area per cell, (height, width) float64.

    polys: (N, V, 2) vertices [cell units: cell (r, c) = [c, c + 1] x [r, r + 1]]; weights: (N,).
    A polygon counter-clockwise on the screen (y down; e.g. TL, BL, BR, TR) counts +1, clockwise -1.
    Parts outside [0, width] x [0, height] are ignored."""
    N, V, _ = polys.shape
    a = polys.reshape(-1, 2)
    b = np.roll(polys, -1, axis=1).reshape(-1, 2)
    w = np.repeat(np.asarray(weights, float), V)
    keep = (a[:, 1] != b[:, 1]) & (np.maximum(a[:, 1], b[:, 1]) > 0) & (np.minimum(a[:, 1], b[:, 1]) < height)
    e = np.concatenate([a[keep], b[keep]], axis=1)
    w = w[keep]
    acc = np.zeros((height, width + 2))
    if len(e) == 0:
        return acc[:, :width]
    i, p0, p1 = _split_pieces(e, width)
    ym = 0.5 * (p0[:, 1] + p1[:, 1])
    dy = p1[:, 1] - p0[:, 1]
    row = np.floor(ym).astype(np.int64)
    ok = (row >= 0) & (row < height) & (dy != 0)
    xm = np.clip(0.5 * (p0[ok, 0] + p1[ok, 0]), 0.0, width)
    col = np.floor(xm).astype(np.int64)
    frac = xm - col
    h = (w[i] * dy)[ok]
    flat = row[ok] * (width + 2) + col
    size = height * (width + 2)
    acc += (np.bincount(flat, h * (1.0 - frac), size) + np.bincount(flat + 1, h * frac, size)).reshape(acc.shape)
    return np.cumsum(acc, axis=1)[:, :width]


class PolygonRenderer:
    """Exact area-coverage image of a planar target (see the module docstring).

    target: TargetSpec; intrinsics: pinhole camera (distortion ignored); background, back_grey: grey
    levels [0, 255] of empty pixels and of the board's back face; the printed face is white 255 / black 0."""

    def __init__(self, target: TargetSpec, intrinsics: CameraIntrinsics, background: float, back_grey: float):
        self.K = intrinsics
        self.background, self.back_grey = float(background), float(back_grey)
        x0, y0, x1, y1 = target.texture_extent_m()
        self._outline = _rect_corners(np.array([[x0, y0, x1, y1]], float))  # (1, 4, 2)
        self._rects = _rect_corners(np.array(target._black_rects(), float).reshape(-1, 4))  # (N, 4, 2)

    def _project(self, T: np.ndarray, pts: np.ndarray) -> np.ndarray:
        """(..., 2) target points [m] -> pixel-border coordinates (u + 0.5, v + 0.5)."""
        Hm = self.K.K @ np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]])
        p = pts @ Hm[:, :2].T + Hm[:, 2]
        return p[..., :2] / p[..., 2:] + 0.5

    def render(self, T_cam_target: np.ndarray) -> np.ndarray:
        """Ideal grey image (H, W) float32 [0, 255] at pose T_cam_target (4, 4) [m, OpenCV camera frame];
        every outline corner must be in front of the camera (:func:`~vision_calib.render.warp.planar_warp_ok`)."""
        T = np.asarray(T_cam_target, float)
        K, bg = self.K, self.background
        out = np.full((K.height, K.width), bg, np.float32)
        outline = self._project(T, self._outline)
        u0 = max(0, int(math.floor(outline[..., 0].min())))
        v0 = max(0, int(math.floor(outline[..., 1].min())))
        u1 = min(K.width, int(math.ceil(outline[..., 0].max())))
        v1 = min(K.height, int(math.ceil(outline[..., 1].max())))
        if u1 <= u0 or v1 <= v0:
            return out
        q = outline[0]
        area2 = np.sum(q[:, 0] * np.roll(q[:, 1], -1) - np.roll(q[:, 0], -1) * q[:, 1])
        sign = -1.0 if area2 > 0 else 1.0  # TL, TR, BR, BL clockwise on the screen: coverage -1 (see above)
        front = float(T[:3, 2] @ T[:3, 3]) > 0  # camera on the -z side of the board: printed face
        shift = np.array([u0, v0], float)
        if front:
            polys = np.concatenate([outline, self._project(T, self._rects)]) - shift
            weights = sign * np.concatenate([[255.0 - bg], np.full(len(self._rects), -255.0)])
        else:
            polys, weights = outline - shift, sign * np.array([self.back_grey - bg])
        cov = accumulate_coverage(polys, weights, v1 - v0, u1 - u0)
        out[v0:v1, u0:u1] += cov.astype(np.float32)
        return out
