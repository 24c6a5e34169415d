"""Exact pixel-area coverage of a planar target under a homography (the ``"polygon"`` backend).

Every target is white inside its outline with non-overlapping black shapes: axis-aligned rectangles
(:meth:`TargetSpec.black_rects`) and polygons (:meth:`TargetSpec.black_polygons`: a circle grid's dots as
area-preserving 128-gons), the same shapes its texture is drawn from. A homography maps straight lines
to straight lines, so each shape projects to an exact polygon whose vertices are the projected
vertices; the ideal image (pixel value = mean of the board's radiance over
the pixel's square, the limit of supersampling by s -> infinity) is then

    I = background + (face - background) * cover(outline) - face * sum_k cover(rect_k)   (front face)
    I = background + (back_grey - background) * cover(outline)                           (back face)

with cover(Q) the exact fraction of each pixel inside quad Q.
:func:`~vision_calib.targets.coverage.accumulate_coverage` computes it by signed-area accumulation (as in font rasterisers): every polygon edge is cut at each integer x and y
(pixel borders), each piece lying in one pixel cell adds its signed height dy times the part of the cell
right of it to that cell and the rest to the next cell; a cumulative sum along each row then gives the
covered area of every pixel, exactly up to float64 rounding (no texture, no sampling, no aliasing).
Pixel u covers [u - 0.5, u + 0.5] (OpenCV centres): pixel coordinates are shifted by + 0.5 first.
"""

from __future__ import annotations

import math

import numpy as np

from ..camera import CameraIntrinsics
from ..targets.coverage import accumulate_coverage
from ..targets.spec import TargetSpec


def _rect_corners(rects: np.ndarray) -> np.ndarray:
    """(N, 4, 2) corners TL, TR, BR, BL of rectangles (N, 4) = (x0, y0, x1, y1)."""
    x0, y0, x1, y1 = rects.T
    return np.stack([np.stack([x0, y0], -1), np.stack([x1, y0], -1), np.stack([x1, y1], -1),
                     np.stack([x0, y1], -1)], axis=1)


def _subdivide(q: np.ndarray, n_sub: int) -> np.ndarray:
    """(N, V, 2) polygons -> (N, V n_sub, 2): every edge cut into n_sub equal chords (same shape)."""
    t = np.arange(n_sub) / n_sub
    a, b = q, np.roll(q, -1, axis=1)
    return (a[:, :, None, :] + t[None, None, :, None] * (b - a)[:, :, None, :]).reshape(len(q), -1, 2)


class PolygonRenderer:
    """Exact area-coverage image of a planar target (see the module docstring).

    target: TargetSpec; intrinsics: camera; background, back_grey: grey levels [0, 255] of empty pixels and
    of the board's back face; the printed face is white 255 / black 0.
    distort: False (default): pinhole projection, the intrinsics' distortion ignored (the sensor stage
    resamples the image); True: the distortion drawn geometrically: every edge cut into chords of at most
    ``max_chord_px`` (chosen per pose and per group of equal-size shapes from the projected edge lengths)
    whose end points go through OpenCV's forward model (``CameraIntrinsics.project``), so pixel areas stay
    exact and every board corner is a vertex (exact). The chord error is the sagitta of a distorted edge,
    l^2 kappa / 8 for a chord l and the curvature kappa of the distorted line: with l = 4 px and kappa <= 3e-4
    /px (k1 = -0.1 at 500 px from the centre, f = 1000 px) below 1e-3 px."""

    def __init__(self, target: TargetSpec, intrinsics: CameraIntrinsics, background: float, back_grey: float,
                 distort: bool = False, max_chord_px: float = 4.0):
        self.K = intrinsics
        self.background, self.back_grey = float(background), float(back_grey)
        x0, y0, x1, y1 = target.texture_extent_m()
        self._outline = _rect_corners(np.array([[x0, y0, x1, y1]], float))  # (1, 4, 2)
        rects = _rect_corners(np.array(target.black_rects(), float).reshape(-1, 4))  # (N, 4, 2)
        polys = target.black_polygons()  # (M, V, 2)
        self._shapes = [g for g in (rects, polys) if len(g)]  # groups of equal vertex count
        self.distort = bool(distort and np.any(np.asarray(intrinsics.dist) != 0))
        self.max_chord_px = float(max_chord_px)
        if self.distort:  # split the groups by edge length (octaves): each is cut into its own chord count
            groups = []
            for g in self._shapes:
                side = np.max(np.linalg.norm(np.roll(g, -1, axis=1) - g, axis=2), axis=1)
                octave = np.floor(np.log2(side / side.max()) + 1e-9).astype(int)
                groups += [g[octave == o] for o in np.unique(octave)]
            self._shapes = groups
        self._blank = np.full((intrinsics.height, intrinsics.width), self.background, np.float32)

    def _shape_px(self, T: np.ndarray, g: np.ndarray) -> np.ndarray:
        """(N, V', 2) pixel-border coordinates of the polygons g (N, V, 2) [m]; with ``distort`` each edge
        cut into chords of at most ``max_chord_px`` (V' = n V) before projection."""
        q = self._project(T, g)
        if not self.distort:
            return q
        longest = float(np.max(np.linalg.norm(np.roll(q, -1, axis=1) - q, axis=2)))
        n = int(min(64, max(1, math.ceil(longest / self.max_chord_px))))
        return q if n == 1 else self._project(T, _subdivide(g, n))

    def _project(self, T: np.ndarray, pts: np.ndarray) -> np.ndarray:
        """(..., 2) target points [m] -> pixel-border coordinates (u + 0.5, v + 0.5)."""
        if self.distort:
            pc = pts.reshape(-1, 2) @ T[:3, :2].T + T[:3, 3]
            return self.K.project(pc).reshape(pts.shape) + 0.5
        Hm = self.K.K @ np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]])
        p = pts @ Hm[:, :2].T + Hm[:, 2]
        return p[..., :2] / p[..., 2:] + 0.5

    def render(self, T_cam_target: np.ndarray) -> np.ndarray:
        """Ideal grey image (H, W) float32 [0, 255] at pose T_cam_target (4, 4) [m, OpenCV camera frame];
        every outline corner must be in front of the camera (:func:`~vision_calib.render.warp.planar_warp_ok`)."""
        T = np.asarray(T_cam_target, float)
        K, bg = self.K, self.background
        out = self._blank.copy()
        outline = self._shape_px(T, self._outline)
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
            cov = accumulate_coverage(outline - shift, sign * np.array([255.0 - bg]), v1 - v0, u1 - u0)
            for g in self._shapes:
                cov += accumulate_coverage(self._shape_px(T, g) - shift, np.full(len(g), -255.0 * sign),
                                           v1 - v0, u1 - u0)
        else:
            cov = accumulate_coverage(outline - shift, sign * np.array([self.back_grey - bg]), v1 - v0, u1 - u0)
        out[v0:v1, u0:u1] += cov.astype(np.float32)
        return out
