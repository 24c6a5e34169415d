"""Helpers shared by the grid kinds (chessboard, circle grid): orientation of detected point grids."""

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


# ------------------------------------------------------------------ lattice of points (dot grids seen in photos)
def _unimodular(n: int = 2) -> list[np.ndarray]:
    """2x2 integer matrices with entries in [-n, n] and determinant +-1 (changes of lattice basis)."""
    r = range(-n, n + 1)
    return [np.array([[a, b], [c, d]]) for a in r for b in r for c in r for d in r if abs(a * d - b * c) == 1]


_BASES = _unimodular()


def _predict(ij_known: np.ndarray, uv_known: np.ndarray, ij: np.ndarray) -> np.ndarray | None:
    """Image position (2,) px of lattice cell ij (2,) from the known cells nearest to it (homography of the <= 12
    nearest in lattice distance, or their affine map when fewer than 6); None when they are collinear."""
    d = np.abs(ij_known - ij).sum(axis=1)
    near = np.argsort(d, kind="stable")[:12]
    a, b = ij_known[near].astype(np.float64), uv_known[near]
    if np.linalg.matrix_rank(a - a.mean(axis=0), tol=1e-6) < 2:
        return None
    if len(near) >= 6:
        Hm, _ = cv2.findHomography(a, b, 0)
        if Hm is not None and np.all(np.isfinite(Hm)):
            return apply_h(Hm, ij[None].astype(np.float64))[0]
    A = np.column_stack([a, np.ones(len(a))])
    coef, *_ = np.linalg.lstsq(A, b, rcond=None)
    return np.array([ij[0], ij[1], 1.0]) @ coef


def grow_lattice(pts: np.ndarray, seed: int, tol: float = 0.3, areas: np.ndarray | None = None) -> dict:
    """{(i, j) lattice cell: index into pts} of the point lattice grown from pts[seed] (pts (M, 2) px): the two
    non-collinear vectors to the seed's 6 nearest neighbours with the smallest sum of lengths whose cell closes (a
    point at seed + a + b, within 0.25 of the shorter) span the first cells; each empty cell one or two steps from a
    found one is predicted from the found ones (:func:`_predict`) and takes the nearest point within ``tol`` x the
    local spacing (and, with ``areas`` (M,), of 0.2-6 x the median area of its found neighbours: a dot, not a speck
    of background beside the board). Empty dict when the seed has no such neighbours. The basis is a lattice
    basis, not necessarily the board's axes (see :func:`board_axes`)."""
    d = np.linalg.norm(pts - pts[seed], axis=1)
    nb = np.argsort(d)[1:7]
    v = pts[nb] - pts[seed]
    n = np.linalg.norm(v, axis=1)
    basis = None
    for x in range(len(nb)):
        for y in range(x + 1, len(nb)):
            cross = abs(v[x, 0] * v[y, 1] - v[x, 1] * v[y, 0])
            if cross < 0.5 * n[x] * n[y] or max(n[x], n[y]) > 3 * min(n[x], n[y]):
                continue
            # a lattice cell: the fourth corner seed + v_x + v_y is a point too
            if np.min(np.linalg.norm(pts - (pts[seed] + v[x] + v[y]), axis=1)) < 0.25 * min(n[x], n[y]):
                if basis is None or n[x] + n[y] < basis[0]:
                    basis = (n[x] + n[y], v[x], v[y])
    if basis is None:
        return {}
    a, b = basis[1], basis[2]

    def sized(k, nbs):
        if areas is None:
            return True
        r = areas[k] / np.median(areas[nbs])
        return 0.2 < r < 6.0

    cells = {(0, 0): seed}
    used = {seed}
    for ij, vec in (((1, 0), a), ((-1, 0), -a), ((0, 1), b), ((0, -1), -b)):
        k = int(np.argmin(np.linalg.norm(pts - (pts[seed] + vec), axis=1)))
        if (k not in used and np.linalg.norm(pts[k] - pts[seed] - vec) < tol * min(np.linalg.norm(a), np.linalg.norm(b))
                and sized(k, [seed])):
            cells[ij] = k
            used.add(k)
    frontier = True
    while frontier:
        frontier = False
        ij_known = np.array(list(cells.keys()))
        uv_known = pts[list(cells.values())]
        # next cells, and the cells beyond them (growth goes past a dot missing from pts)
        todo = {(i + di, j + dj) for i, j in cells
                for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1), (2, 0), (-2, 0), (0, 2), (0, -2))} - set(cells)
        for ij in sorted(todo):
            q = _predict(ij_known, uv_known, np.array(ij))
            if q is None:
                continue
            # local spacing: distance from the prediction to the nearest found neighbour cell
            nbs = [cells[n] for n in ((ij[0] + s, ij[1]) for s in (1, -1, 2, -2)) if n in cells]
            nbs += [cells[n] for n in ((ij[0], ij[1] + s) for s in (1, -1, 2, -2)) if n in cells]
            step = min(np.linalg.norm(q - pts[n]) / max(abs(np.subtract(c, ij)).sum(), 1)
                       for c, n in cells.items() if n in nbs)
            dd = np.linalg.norm(pts - q, axis=1)
            k = int(np.argmin(dd))
            if dd[k] < tol * step and k not in used and sized(k, nbs):
                cells[ij] = k
                used.add(k)
                frontier = True
    return cells


def board_axes(cells) -> np.ndarray:
    """(N, 2) int cell coordinates of the lattice cells (an iterable of (i, j)) in the lattice basis whose bounding
    box is smallest (the board's rows and columns: a sheared basis spans a larger box), shifted to start at 0."""
    ij = np.array(list(cells), dtype=np.int64).reshape(-1, 2)
    best = None
    for M in _BASES:
        c = ij @ M.T
        ext = c.max(axis=0) - c.min(axis=0) + 1
        key = (int(ext[0] * ext[1]), int(abs(M).sum()))
        if best is None or key < best[0]:
            best = (key, c - c.min(axis=0))
    return best[1]
