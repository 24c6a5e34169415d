"""Seeded sub-pixel refinement of square-marker corners (AprilTag grids) by straight-edge fits.

A marker's outer black border is a square whose corners are L-corners (one black quadrant), where
``cv2.cornerSubPix`` is biased (~0.15 px per corner, measured: benchmarks/bench_detect.py). Instead,
from seed corners (another frame's detection of the same view), each of the 4 sides is sampled by
intensity profiles across the edge over the middle of the side; the edge position on each profile
is found by the integral (area) method, unbiased for any symmetric blur; a straight line is fitted
to the edge points of each side (in undistorted pixels when the intrinsics are given, so that lens
distortion does not bend the fitted sides) and adjacent lines are intersected.
Pixel convention: OpenCV pixel centres at integer coordinates (the image is sampled bilinearly
there), so the corners come out in the same convention as the seeds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import CameraIntrinsics

#: profile sampling step across an edge [px]; edge points per side at most / at least
STEP_PX = 0.25
MAX_SAMPLES, MIN_SAMPLES = 40, 4
#: minimum grey-level contrast across a side for a usable fit
MIN_CONTRAST = 10.0
#: profile samples at each end that give the grey level on that side of the edge
N_LEVEL = 3


def _bilinear(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear samples of img (H, W) float at pixel coordinates x, y (any equal shapes), clamped to the image."""
    h, w = img.shape
    x = np.clip(x, 0.0, w - 1.000001)
    y = np.clip(y, 0.0, h - 1.000001)
    x0 = np.floor(x).astype(np.intp)
    y0 = np.floor(y).astype(np.intp)
    fx, fy = x - x0, y - y0
    i00 = img[y0, x0]
    i01 = img[y0, x0 + 1]
    i10 = img[y0 + 1, x0]
    i11 = img[y0 + 1, x0 + 1]
    return (i00 * (1 - fx) + i01 * fx) * (1 - fy) + (i10 * (1 - fx) + i11 * fx) * fy


def _undistort(uv: np.ndarray, intr: CameraIntrinsics | None) -> np.ndarray:
    if intr is None or not any(intr.dist):
        return uv
    from .pnp import undistort_px

    return undistort_px(uv.reshape(-1, 2), intr).reshape(uv.shape)


def _distort(uv: np.ndarray, intr: CameraIntrinsics | None) -> np.ndarray:
    if intr is None or not any(intr.dist):
        return uv
    flat = uv.reshape(-1, 2)
    p = np.column_stack([(flat[:, 0] - intr.cx) / intr.fx, (flat[:, 1] - intr.cy) / intr.fy, np.ones(len(flat))])
    return intr.project(p).reshape(uv.shape)


def _profiles(quads: np.ndarray, cells: int):
    """Sampling geometry of the sides of (M, 4, 2) quads: profile centres base (M, 4, S, 2), sample points
    pts (M, 4, S, P, 2), offsets along the normal offs (P,), unit normals n (M, 4, 2), half-width h [px]."""
    a = quads
    b = np.roll(quads, -1, axis=1)
    length = np.linalg.norm(b - a, axis=2)  # (M, 4)
    t = (b - a) / np.maximum(length, 1e-9)[..., None]
    n = np.stack([-t[..., 1], t[..., 0]], axis=-1)
    cell_px = float(np.median(length)) / cells
    h = float(np.clip(0.3 * cell_px, 1.0, 3.0))  # half-width of the profile window [px]
    offs = np.arange(-h, h + 1e-9, STEP_PX)
    n_s = int(np.clip(np.median(length) / 2.0, MIN_SAMPLES, MAX_SAMPLES))
    s = np.linspace(0.15, 0.85, n_s)
    base = a[:, :, None, :] + (s[None, None, :, None] * length[..., None, None]) * t[:, :, None, :]  # (M,4,S,2)
    pts = base[:, :, :, None, :] + offs[None, None, None, :, None] * n[:, :, None, None, :]  # (M,4,S,P,2)
    return base, pts, offs, n, h


def read_mask(quads: np.ndarray, cells: int, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) bool: every pixel :func:`refine_quads` (one pass) reads to refine ``quads`` (M, 4, 2)."""
    quads = np.asarray(quads, dtype=np.float64).reshape(-1, 4, 2)
    mask = np.zeros(shape, dtype=bool)
    if len(quads) == 0:
        return mask
    pts = _profiles(quads, cells)[1]
    h, w = shape
    x0 = np.floor(np.clip(pts[..., 0], 0.0, w - 1.000001)).astype(np.intp).reshape(-1)
    y0 = np.floor(np.clip(pts[..., 1], 0.0, h - 1.000001)).astype(np.intp).reshape(-1)
    for dy in (0, 1):
        for dx in (0, 1):
            mask[y0 + dy, x0 + dx] = True
    return mask


def _edge_points(img: np.ndarray, quads: np.ndarray, cells: int):
    """Edge points per side: (M, 4, S, 2) px, their validity (M, 4, S) and per-side validity (M, 4) bool."""
    base, pts, offs, n, h = _profiles(quads, cells)
    prof = _bilinear(img, pts[..., 0], pts[..., 1])  # (M,4,S,P)
    # grey levels on either side, per profile (the dark or bright level may vary along a side: glare, shading)
    lo = prof[..., :N_LEVEL].mean(axis=-1)  # (M,4,S), -n side
    hi = prof[..., -N_LEVEL:].mean(axis=-1)
    contrast = hi - lo
    side_contrast = np.median(contrast, axis=2)
    ok = np.abs(side_contrast) >= MIN_CONTRAST
    good = np.sign(contrast) == np.sign(side_contrast)[..., None]
    good &= np.abs(contrast) >= 0.5 * np.abs(side_contrast)[..., None]
    u = (prof - lo[..., None]) / np.where(good, contrast, 1.0)[..., None]
    # integral of the normalised step over [-h, h] is h - e (trapezoid rule)
    area = STEP_PX * (u[..., 1:] + u[..., :-1]).sum(axis=-1) / 2.0
    e = np.where(good, offs[-1] - area, np.nan)  # (M,4,S)
    good &= np.abs(e) < h - 0.5
    ok &= good.sum(axis=2) >= MIN_SAMPLES
    return base + np.where(good, e, 0.0)[..., None] * n[:, :, None, :], good, ok


def _fit_lines(q: np.ndarray, w: np.ndarray):
    """Total least-squares lines through (M, 4, S, 2) points with weights (M, 4, S) (0/1): centroids
    (M, 4, 2), unit directions (M, 4, 2)."""
    c = (w[..., None] * q).sum(axis=2) / np.maximum(w.sum(axis=2), 1)[..., None]
    d = (q - c[:, :, None, :]) * np.sqrt(w)[..., None]
    cov = np.einsum("mksi,mksj->mkij", d, d)
    _, vec = np.linalg.eigh(cov)
    return c, vec[..., :, 1]  # eigenvector of the largest eigenvalue


@dataclass(frozen=True, eq=False)
class EdgeSamples:
    """The edge points :func:`refine_quads` fitted its corners to, for M markers: points (M, 4, S, 2) float32
    [distorted px, side k from corner k to k + 1], good (M, 4, S) bool (points used), ok_side (M, 4) bool (sides
    with contrast and enough points). The image is read only to find them: :func:`corners_from_edges` fits the
    corners again under other intrinsics without it."""

    points: np.ndarray
    good: np.ndarray
    ok_side: np.ndarray

    def take(self, keep: np.ndarray) -> "EdgeSamples":
        """The samples of the markers ``keep`` ((M,) bool or indices)."""
        return EdgeSamples(self.points[keep], self.good[keep], self.ok_side[keep])


def refine_quads(img: np.ndarray, quads: np.ndarray, cells: int, intrinsics: CameraIntrinsics | None = None,
                 samples: bool = False):
    """Refine marker corners from seeds.

    img: (H, W) grey image (uint8 or float). quads: (M, 4, 2) seed corners [distorted px] in OpenCV's
    marker order (consecutive corners share a side). cells: marker side in bits incl. the border
    (markerSize + 2). intrinsics: when given with distortion, lines are fitted in undistorted pixels.
    Returns (corners (M, 4, 2) distorted px, ok (M,) bool: all four sides had contrast and an edge
    inside the sampling window), and the :class:`EdgeSamples` when ``samples``."""
    quads = np.asarray(quads, dtype=np.float64).reshape(-1, 4, 2)
    if len(quads) == 0:
        empty = EdgeSamples(np.zeros((0, 4, 0, 2), np.float32), np.zeros((0, 4, 0), bool), np.zeros((0, 4), bool))
        return (quads.copy(), np.zeros(0, dtype=bool)) + ((empty,) if samples else ())
    q, good, ok_side = _edge_points(np.asarray(img, dtype=np.float32), quads, cells)
    corners, ok = _corners(q, good, ok_side, intrinsics)
    if not samples:
        return corners, ok
    return corners, ok, EdgeSamples(q.astype(np.float32), good, ok_side)


def corners_from_edges(edges: EdgeSamples, intrinsics: CameraIntrinsics | None = None):
    """(corners (M, 4, 2) distorted px, ok (M,) bool) of :func:`refine_quads` fitted to its ``edges`` under
    ``intrinsics`` (the lines in their undistorted pixels; None or no distortion: in raw pixels): no image read."""
    if len(edges.points) == 0:
        return np.zeros((0, 4, 2)), np.zeros(0, dtype=bool)
    return _corners(edges.points.astype(np.float64), edges.good, edges.ok_side, intrinsics)


def _corners(q, good, ok_side, intrinsics):
    """The corners and their validity from the edge points q (M, 4, S, 2) [distorted px] (module docstring)."""
    q = _undistort(q, intrinsics)
    c, d = _fit_lines(q, good.astype(np.float64))
    # corner k is the intersection of side k-1 (corner k-1 -> k) and side k (corner k -> k+1)
    c1, d1 = np.roll(c, 1, axis=1), np.roll(d, 1, axis=1)
    A = np.stack([d1, -d], axis=-1)  # (M, 4, 2, 2): c1 + a d1 = c + b d
    det = A[..., 0, 0] * A[..., 1, 1] - A[..., 0, 1] * A[..., 1, 0]
    good = np.abs(det) > 1e-3
    rhs = c - c1
    alpha = (rhs[..., 0] * A[..., 1, 1] - rhs[..., 1] * A[..., 0, 1]) / np.where(good, det, 1.0)
    corners = _distort(c1 + alpha[..., None] * d1, intrinsics)
    ok = np.all(ok_side, axis=1) & np.all(good, axis=1) & np.all(np.isfinite(corners), axis=(1, 2))
    return corners, ok
