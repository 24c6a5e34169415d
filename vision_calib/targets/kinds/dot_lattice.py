"""The dot lattice of circle grids seen in photos (:mod:`.dot_grid`'s ``lattice`` stage, :mod:`.circles`): a point
lattice grown from dot candidates with each next cell predicted by the homography of the cells found
(:func:`grow_lattice`, :func:`lattice_grids`), the board's rows and columns told from a sheared lattice basis
(:func:`board_axes`), and the measurement of each dot (:func:`refine_dot`, :func:`refine_grid`). Pixel
coordinates: pixel-centre convention, (u, v) = (column, row)."""

from __future__ import annotations

import cv2
import numpy as np

from ._grid import apply_h

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


def nearest_distance(pts: np.ndarray) -> np.ndarray:
    """(M,) distance of each point to its nearest other point (inf for a single point)."""
    if len(pts) < 2:
        return np.full(len(pts), np.inf)
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return d.min(axis=1)


def _dot_component(win: np.ndarray, q: np.ndarray, lo: float, hi: float):
    """(labels, index of the dot's component) of the window win cut at the first of the levels 0.5, 0.35, 0.25,
    0.65 between lo and hi where the dark component holding the dark pixel nearest q (px, window coordinates) is
    ellipse-like (:func:`_components`' fill test), of >= 4 px and inside the window; or None."""
    h, w = win.shape
    for f in (0.5, 0.35, 0.25, 0.65):
        n, lab, st, _ = cv2.connectedComponentsWithStats((win < lo + f * (hi - lo)).astype(np.uint8), connectivity=8)
        if n < 2:
            continue
        dy, dx = np.nonzero(lab)
        j = int(np.argmin((dx - q[0]) ** 2 + (dy - q[1]) ** 2))
        k = int(lab[dy[j], dx[j]])
        x0, y0, bw, bh, a = st[k]
        if a < 4 or x0 == 0 or y0 == 0 or x0 + bw == w or y0 + bh == h:
            continue
        yy, xx = np.nonzero(lab == k)
        cov = np.cov(np.vstack([xx, yy])) + np.eye(2) / 12 if a > 2 else np.eye(2)
        fill = a / (4 * np.pi * np.sqrt(max(np.linalg.det(cov), 1e-12)))
        if 0.8 < fill < 1.2:
            return lab, k
    return None


def refine_dot(img: np.ndarray, uv, radius: float):
    """(centre (2,) px, dark area px^2) of the dot nearest uv (2,) px, or None: the darkness-weighted centroid of
    the dot's image (the centre of its ellipse for any symmetric blur). In the window of half-size ``radius``
    (~ the distance to the dot's farthest grid neighbour), the dot is the ellipse-like dark component nearest uv
    (:func:`_dot_component`, levels between the window's 2nd and 95th percentiles: a shadow edge across the
    window is cut away at the lower levels); the background is a plane fitted to the ring around it (2-4 px beyond
    the component, other dark components masked out), the darkness w = clip((plane - I) / (plane - dot level), 0, 1)
    is summed over the component grown by a margin of max(2, a third of its radius) px. Where the ring is not
    flat (residual > 8 % of the dot's contrast: a shadow edge), the background inside the grown component is
    inpainted from its surround (Telea) and w = clip((1 - I / background) / (1 - core ratio), 0, 1)."""
    h, w = img.shape
    r = int(np.ceil(radius))
    x0, x1, y0, y1 = max(int(uv[0]) - r, 0), min(int(uv[0]) + r + 2, w), max(int(uv[1]) - r, 0), min(int(uv[1]) + r + 2, h)
    win = img[y0:y1, x0:x1].astype(np.float64)
    if win.size < 9:
        return None
    lo, hi = np.percentile(win, [2, 95])
    if hi - lo < 10:
        return None
    got = _dot_component(win, np.asarray(uv, float) - [x0, y0], lo, hi)
    if got is None:
        return None
    lab, k = got
    comp = (lab == k).astype(np.uint8)
    a = float(comp.sum())
    yy, xx = np.mgrid[0:win.shape[0], 0:win.shape[1]].astype(np.float64)
    c = comp.astype(bool)
    fallback = np.array([xx[c].mean() + x0, yy[c].mean() + y0]), a
    m = max(2, int(round(np.sqrt(a / np.pi) / 3)))
    ker = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * m + 1, 2 * m + 1))
    grown = cv2.dilate(comp, ker)
    ring = cv2.dilate(grown, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))) & ~grown & 1
    other = cv2.dilate(((lab > 0) & (lab != k)).astype(np.uint8), ker)
    ring &= 1 - other
    grown &= 1 - other
    sel = ring.astype(bool)
    if sel.sum() < 12:
        return fallback
    A = np.column_stack([xx[sel], yy[sel], np.ones(sel.sum())])
    coef, *_ = np.linalg.lstsq(A, win[sel], rcond=None)
    plane = xx * coef[0] + yy * coef[1] + coef[2]
    core = cv2.erode(comp, np.ones((3, 3), np.uint8)) if a > 30 else comp
    level = float(np.median(win[core.astype(bool)]))
    g = grown.astype(bool)
    resid = float(np.sqrt(np.mean((win[sel] - plane[sel]) ** 2)))
    if resid > 0.08 * (float(np.median(plane[sel])) - level):
        # not flat (a shadow edge): the background inside the dot inpainted from around it, the darkness from the
        # ratio I / background (shading multiplies), relative to the dot core's ratio
        bg = cv2.inpaint(np.clip(win, 0, 255).astype(np.uint8), (grown | other).astype(np.uint8), 3,
                         cv2.INPAINT_TELEA).astype(np.float64)
        ratio = win / np.maximum(bg, 1.0)
        rho = float(np.median(ratio[core.astype(bool)]))
        if not rho < 0.8:
            return fallback
        wt = np.clip((1 - ratio[g]) / (1 - rho), 0, 1)
    else:
        wt = np.clip((plane[g] - win[g]) / np.maximum(plane[g] - level, 1.0), 0, 1)
    s = wt.sum()
    if s <= 0:
        return fallback
    return np.array([(wt * xx[g]).sum() / s + x0, (wt * yy[g]).sum() / s + y0]), float(s)


def _grid_step(G: np.ndarray) -> np.ndarray:
    """(R, C) largest distance [px] of each dot of the grid G (R, C, 2) to its row/column neighbours."""
    R, C = G.shape[:2]
    s = np.zeros((R, C))
    if C > 1:
        dx = np.linalg.norm(np.diff(G, axis=1), axis=2)
        s[:, 1:] = np.maximum(s[:, 1:], dx)
        s[:, :-1] = np.maximum(s[:, :-1], dx)
    if R > 1:
        dy = np.linalg.norm(np.diff(G, axis=0), axis=2)
        s[1:] = np.maximum(s[1:], dy)
        s[:-1] = np.maximum(s[:-1], dy)
    return s


def refine_grid(img: np.ndarray, G: np.ndarray):
    """Each dot of the grid G (R, C, 2) px re-measured by :func:`refine_dot` (window: 0.75 x the distance to its
    farthest row/column neighbour): (centres (R, C, 2) px, dark areas (R, C) px^2) or (None, why) when a dot is
    not found or lies farther than 0.3 x its nearest neighbour's distance from the grid position."""
    step = _grid_step(G)
    out, area = np.empty_like(G), np.empty(G.shape[:2])
    near = nearest_distance(G.reshape(-1, 2)).reshape(G.shape[:2])
    for r, c in np.ndindex(*G.shape[:2]):
        got = refine_dot(img, G[r, c], 0.75 * step[r, c])
        if got is None or np.linalg.norm(got[0] - G[r, c]) > 0.3 * near[r, c]:
            return None, f"dot ({r}, {c}) of the grid (near {G[r, c].round(1).tolist()} px) not measurable"
        out[r, c], area[r, c] = got
    return out, area


def lattice_grids(img: np.ndarray, pts: np.ndarray, areas: np.ndarray, patterns, max_seeds: int = 40):
    """Yield (pattern, grid (rows, per row, 2) px) for each point lattice grown from the dot candidates pts (M, 2)
    (:func:`grow_lattice`; seeds: the largest candidates first, each lattice once, at most max_seeds) whose board axes
    (:func:`board_axes`) span one of the patterns (OpenCV patternSize (per row, rows)). A lattice one
    row or column short is extended on the side where the predicted dots are found in the image
    (:func:`refine_dot`); an outer row with at most 30 % of its dots (strays on the lattice) is dropped; empty
    cells inside are predicted from the lattice and measured."""
    if len(pts) < 4:
        return
    seeds = np.argsort(-areas, kind="stable")  # large first: background specks are small
    tried, n_seeds = set(), 0
    for s in seeds:
        if int(s) in tried:
            continue
        n_seeds += 1
        if n_seeds > max_seeds:
            return
        cells = grow_lattice(pts, int(s), areas=areas)
        tried.update(cells.values())
        tried.add(int(s))
        if len(cells) < 4:
            continue
        ij = board_axes(cells)
        idx = np.array(list(cells.values()))
        ij, uv = _fit_extent(img, ij, pts[idx], patterns)
        if ij is None:
            continue
        n1, n2 = ij.max(axis=0) + 1
        G = np.full((n2, n1, 2), np.nan)
        G[ij[:, 1], ij[:, 0]] = uv
        holes = np.argwhere(np.isnan(G[..., 0]))
        if len(holes) > 0.25 * n1 * n2:
            continue
        Hm, _ = cv2.findHomography(ij.astype(np.float64), uv, 0)
        ok = Hm is not None
        for r, c in holes if ok else []:
            q = apply_h(Hm, np.array([[c, r]], np.float64))[0]
            step = float(np.linalg.norm(apply_h(Hm, np.array([[c + 1.0, r]]))[0] - q))
            step2 = float(np.linalg.norm(apply_h(Hm, np.array([[c, r + 1.0]]))[0] - q))
            got = refine_dot(img, q, 0.75 * max(step, step2))
            if got is None or np.linalg.norm(got[0] - q) > 0.3 * min(step, step2):
                ok = False
                break
            G[r, c] = got[0]
        if ok:
            yield (int(n1), int(n2)), G


def _line_count(ij: np.ndarray, axis: int, value: int) -> int:
    return int(np.sum(ij[:, axis] == value))


def _fit_extent(img, ij: np.ndarray, uv: np.ndarray, patterns):
    """(ij, uv) of a lattice (cells ij (N, 2) from 0, their points uv (N, 2) px) fitted to span a pattern (n1, n2) of
    ``patterns``, or (None, None): outer lines holding at most 30 % of a line's dots (background specks taken
    into the lattice) are dropped while the lattice is longer than the pattern, and one missing line per axis is
    searched for on both sides."""
    for _ in range(24):
        ext = tuple(int(e) for e in ij.max(axis=0) + 1)
        if ext in [tuple(p) for p in patterns]:
            return ij, uv
        fits = [p for p in patterns if all(ext[a] >= int(p[a]) - 1 for a in (0, 1))]
        if not fits:
            return None, None
        want = min(fits, key=lambda p: abs(ext[0] - p[0]) + abs(ext[1] - p[1]))
        axis = next(a for a in (0, 1) if ext[a] != want[a])
        if ext[axis] > want[axis]:  # drop the outer line with fewer dots if it has few
            lo, hi = _line_count(ij, axis, 0), _line_count(ij, axis, ext[axis] - 1)
            if min(lo, hi) > 0.3 * min(want):
                return None, None
            keep = ij[:, axis] != (0 if lo <= hi else ext[axis] - 1)
            ij, uv = ij[keep], uv[keep]
            ij = ij - ij.min(axis=0)
            continue
        # one line short: predict the line beyond each end, keep the side where its dots are found
        Hm, _ = cv2.findHomography(ij.astype(np.float64), uv, 0)
        if Hm is None:
            return None, None
        best = None
        h, w = img.shape
        for v in (-1, ext[axis]):
            cells = np.array([[v, t] if axis == 0 else [t, v] for t in range(ext[1 - axis])], np.float64)
            inner = cells + (np.array([1.0, 0]) if axis == 0 else np.array([0, 1.0])) * (1 if v < 0 else -1)
            found = []
            for cell, qq, qi in zip(cells, apply_h(Hm, cells), apply_h(Hm, inner)):
                st = float(np.linalg.norm(qq - qi))
                got = refine_dot(img, qq, 0.75 * st) if 0 <= qq[0] < w and 0 <= qq[1] < h else None
                if got is not None and np.linalg.norm(got[0] - qq) < 0.3 * st:
                    found.append((cell, got[0]))
            if len(found) >= 0.7 * len(cells) and (best is None or len(found) > len(best)):
                best = found
        if best is None:
            return None, None
        ij = np.vstack([ij, np.array([f[0] for f in best], np.int64)])
        uv = np.vstack([uv, np.array([f[1] for f in best])])
        ij = ij - ij.min(axis=0)
    return None, None
