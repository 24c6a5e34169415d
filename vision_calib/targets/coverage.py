"""Exact area coverage of polygons on a pixel grid by signed-area accumulation (as in font rasterisers): the
target's texture (:meth:`~vision_calib.targets.spec.TargetSpec.texture`) and the CPU renderer
(:mod:`vision_calib.render.coverage`) both draw the board's black shapes with it. numpy only.

Every polygon edge is cut at each integer x and y (cell borders), each piece lying in one cell adds its
signed height dy times the part of the cell right of it to that cell and the rest to the next cell; a
cumulative sum along each row then gives the covered area of every cell, exactly up to float64 rounding.
"""

from __future__ import annotations

import numpy as np


def _cut(e: tuple, axis: int, lo: int, hi: int) -> tuple[tuple, np.ndarray]:
    """Cut segments e = (xa, ya, xb, yb) (four (E,) arrays) at every integer value of coordinate ``axis``
    (0: x, 1: y) strictly between their end points and within [lo, hi]. Returns the pieces (four (P,)
    arrays; each segment's pieces in order along it, the cuts being generated in that order: no sorting)
    and the index (P,) of the segment each piece comes from."""
    xa, ya, xb, yb = e
    a, b = (xa, xb) if axis == 0 else (ya, yb)
    k0 = np.maximum(np.floor(np.minimum(a, b)) + 1, lo)
    k1 = np.minimum(np.ceil(np.maximum(a, b)) - 1, hi)
    n = np.maximum(k1 - k0 + 1, 0).astype(np.int64)  # cuts per segment -> n + 1 pieces
    m = n + 1
    i = np.repeat(np.arange(len(a)), m)
    r = np.arange(i.size) - np.repeat(np.cumsum(m) - m, m)  # rank of the piece within its segment
    ai, bi, ni = a[i], b[i], n[i]
    first = np.where(b > a, k0, k1)[i]
    step = np.where(b > a, 1.0, -1.0)[i]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / (bi - ai)
        t0 = np.where(r == 0, 0.0, (first + step * (r - 1) - ai) * inv)
        t1 = np.where(r == ni, 1.0, (first + step * r - ai) * inv)
    xai, yai, dx, dy = xa[i], ya[i], (xb - xa)[i], (yb - ya)[i]
    return (xai + t0 * dx, yai + t0 * dy, xai + t1 * dx, yai + t1 * dy), i


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
    e = (a[keep, 0], a[keep, 1], b[keep, 0], b[keep, 1])
    w = w[keep]
    size = height * (width + 2)
    if len(w) == 0:
        return np.zeros((height, width))
    rows, i1 = _cut(e, 1, 0, height)
    (xa, ya, xb, yb), i2 = _cut(rows, 0, 0, width)
    dy = yb - ya
    row = np.floor(0.5 * (ya + yb)).astype(np.int64)
    ok = (row >= 0) & (row < height) & (dy != 0)
    xm = np.clip(0.5 * (xa[ok] + xb[ok]), 0.0, width)
    col = np.floor(xm).astype(np.int64)
    frac = xm - col
    h = (w[i1[i2]] * dy)[ok]
    flat = row[ok] * (width + 2) + col
    # the piece's dy split between its cell (part right of it) and the next cell; row sums then give areas
    acc = np.bincount(np.concatenate([flat, flat + 1]), np.concatenate([h * (1.0 - frac), h * frac]), size)
    acc = acc.reshape(height, width + 2)
    return np.cumsum(acc, axis=1)[:, :width]
