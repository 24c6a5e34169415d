"""Finding the dots of a circle grid on photographs (the circle-grid kinds' detector, :mod:`.circles`).

OpenCV's ``findCirclesGrid`` with one fixed blob detector fails on real photos: texture in the background
(carpet, cardboard) gives blobs that break its clustering, and dots in a shadow or in uneven light, or dots of
a few pixels, fall outside fixed thresholds and areas. The dot candidates are therefore found in stages, each
tried only when the ones before give no grid:

1. ``given``: the recording's own blob-detector settings (OpenCV ``SimpleBlobDetector_Params`` names, the target's
   ``blob_detector`` mapping; ``import-rosi`` fills it from ROS-I's ``circle_detector_params``);
2. ``default``: dark blobs of 6 px .. 5 % of the image (the settings used before photos were supported);
3. ``lattice`` (symmetric grids: the modified circle grid): the dark ellipses of the image divided by its local
   background (:func:`dark_ellipses`: connected components at 3 levels, filled-ellipse and dark-on-light tests,
   which hold for dots seen at 60 deg and in a shadow), a point lattice grown from them with each next cell
   predicted by the homography of the cells found (:func:`.dot_lattice.lattice_grids`: background specks beside the
   board trimmed, a dot missing from the candidates or a whole missing edge line measured where the lattice
   predicts it), the board's rows and columns told from a sheared lattice basis by the smallest bounding box;
4. ``sized``: a permissive detector (thresholds 10..245, areas 4 px .. 10 % of the image, no circularity
   filter), its blobs kept when they are dark on a uniform lighter surround (:func:`dark_on_light`: dots on the
   board, not background texture) and in the size window that holds the expected number of dots with the fewest others
   (window: a factor ``SIZE_WINDOW`` in blob diameter; the modified grid's origin dot, twice as large, is kept
   beside it) and whose diameter / nearest-neighbour distance is within a factor 2 of the target's
   diameter / spacing (when the target gives its diameter);
5. ``flattened``: stage 4 on the image divided by its local background (grey closing over ~6 dot diameters):
   removes shadows and uneven lighting.

In stages 1, 2, 4 and 5 the kept blobs are redrawn as clean discs on white (radius 0.3 x nearest-neighbour
distance) and ``findCirclesGrid`` runs on that drawing (it takes no point list from Python); its centres are
snapped back to the photo's blob centres. Each grid is returned to the kind, which ties its order to the board
and checks it (:func:`grid_consistency`); the first grid that passes wins. For the modified circle grid every
dot of a grid is first re-measured (:func:`.dot_lattice.refine_dot`: darkness-weighted centroid over a local background
plane, or an inpainted background across a shadow edge; the blob detector's centres were off by up to 9 px at
60 deg) and the origin dot is the corner whose dark area, over the perspective's local area scale, is largest.
When no grid passes, :func:`not_found_message` says what was found: the blobs of the best size window, their
sizes, and the count needed.

Centres are the centres of the dots' image ellipses, not the projections of the circle centres: at 60 deg tilt
they differ by up to ~1 px (``benchmarks/bench_dot_photos.py``: 0.05 px mean, 0.83 px max over 40 views with
dots of 12-40 px); the kinds remove that offset when intrinsics are given (``ellipse_centre_offset``: 0.010 px
mean, 0.043 px max left on the same views).
"""

from __future__ import annotations

import cv2
import numpy as np

from ...errors import ConfigError
from .dot_lattice import lattice_grids, nearest_distance

#: OpenCV SimpleBlobDetector_Params fields a target's ``blob_detector`` mapping may set, with their types
BLOB_KEYS = {"minThreshold": float, "maxThreshold": float, "thresholdStep": float, "minRepeatability": int,
             "minDistBetweenBlobs": float, "filterByColor": bool, "blobColor": int, "filterByArea": bool,
             "minArea": float, "maxArea": float, "filterByCircularity": bool, "minCircularity": float,
             "maxCircularity": float, "filterByInertia": bool, "minInertiaRatio": float, "maxInertiaRatio": float,
             "filterByConvexity": bool, "minConvexity": float, "maxConvexity": float}
#: blob diameters kept together in stage 3 span at most this factor (perspective up to 60 deg, board depth)
SIZE_WINDOW = 2.6
#: a dot farther than this fraction of the local dot spacing from the grid's homography: the grid order is wrong
MAX_OFF_GRID = 0.25


def check_blob_settings(d, where: str) -> tuple:
    """A ``blob_detector`` mapping {OpenCV SimpleBlobDetector_Params field: value} -> sorted tuple of (name, value)
    pairs (hashable, for the frozen TargetSpec); ConfigError naming the key for an unknown field or a bad value."""
    if isinstance(d, (tuple, list)):
        try:
            d = dict(d)
        except (TypeError, ValueError):
            raise ConfigError(f"{where}: key 'blob_detector': expected a mapping of OpenCV SimpleBlobDetector "
                              f"parameters, got {d!r}") from None
    if not isinstance(d, dict):
        raise ConfigError(f"{where}: key 'blob_detector': expected a mapping of OpenCV SimpleBlobDetector "
                          f"parameters, got {type(d).__name__}")
    out = []
    for k, v in d.items():
        if k not in BLOB_KEYS:
            raise ConfigError(f"{where}: blob_detector: {k}: unknown OpenCV SimpleBlobDetector parameter; allowed: "
                              f"{', '.join(sorted(BLOB_KEYS))}")
        t = BLOB_KEYS[k]
        ok = isinstance(v, bool) if t is bool else (not isinstance(v, bool) and isinstance(v, (int, float))
                                                     and np.isfinite(v) and v >= 0 and (t is float or v == int(v)))
        if not ok:
            raise ConfigError(f"{where}: blob_detector: {k}: expected {'true/false' if t is bool else 'a number >= 0'}"
                              f", got {v!r}")
        out.append((str(k), t(v)))
    s = dict(out)
    if s.get("minThreshold", 10) >= s.get("maxThreshold", 220) or s.get("minArea", 25) > s.get("maxArea", 5000):
        raise ConfigError(f"{where}: blob_detector: minThreshold must be < maxThreshold and minArea <= maxArea")
    return tuple(sorted(out))


def make_blob_detector(settings: dict):
    p = cv2.SimpleBlobDetector_Params()
    for k, v in settings.items():
        setattr(p, k, v)
    return cv2.SimpleBlobDetector_create(p)


def default_settings(img) -> dict:
    """Dark dots of 6 px .. 5 % of the image (stage 2)."""
    return dict(minArea=6.0, maxArea=0.05 * img.shape[0] * img.shape[1], minDistBetweenBlobs=2.0,
                filterByCircularity=True, minCircularity=0.5, filterByConvexity=True, minConvexity=0.8,
                filterByInertia=True, minInertiaRatio=0.05)


def permissive_settings(img) -> dict:
    """Stage 3: every dark blob of 4 px .. 10 % of the image seen at >= 2 of 24 thresholds."""
    return dict(minThreshold=10.0, maxThreshold=245.0, thresholdStep=10.0, minRepeatability=2, minArea=4.0,
                maxArea=0.1 * img.shape[0] * img.shape[1], minDistBetweenBlobs=1.0, filterByCircularity=False,
                filterByConvexity=True, minConvexity=0.7, filterByInertia=True, minInertiaRatio=0.1)


def flatten(img: np.ndarray, dot_px: float) -> np.ndarray:
    """The image divided by its local background (grey closing with a disc of ~6 dot diameters, smoothed), x 255."""
    k = int(np.clip(6 * dot_px, 9, max(img.shape) // 2)) | 1
    small = max(1, k // 31)  # close on a reduced image: the kernel stays <= ~31 px
    im = cv2.resize(img, (img.shape[1] // small, img.shape[0] // small), interpolation=cv2.INTER_AREA) if small > 1 else img
    ks = max(3, (k // small) | 1)
    bg = cv2.morphologyEx(im, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (ks, ks)))
    bg = cv2.GaussianBlur(bg, (0, 0), ks / 4)
    if small > 1:
        bg = cv2.resize(bg, (img.shape[1], img.shape[0]), interpolation=cv2.INTER_LINEAR)
    return np.clip(255.0 * img / np.maximum(bg.astype(np.float64), 8.0), 0, 255).astype(np.uint8)


#: levels (fraction of the local background) at which the flattened image is cut into dark components
LEVELS = (0.35, 0.5, 0.65)


def _components(flat: np.ndarray, level: float, max_area: float):
    """Dark connected components of the flattened image below level x 255 that look like a filled ellipse:
    (centres (M, 2) px, covariances (M, 2, 2) px^2 of their pixels, areas (M,) px). Kept: 4 px <= area <= max_area,
    not touching the image border, area / area of the moment ellipse (4 pi sqrt(det cov)) in 0.8-1.2, axis ratio
    < 4."""
    n, lab, st, _ = cv2.connectedComponentsWithStats((flat < level * 255).astype(np.uint8), connectivity=8)
    h, w = flat.shape
    area = st[:, cv2.CC_STAT_AREA].astype(np.float64)
    x0, y0 = st[:, cv2.CC_STAT_LEFT], st[:, cv2.CC_STAT_TOP]
    ok = ((area >= 4) & (area <= max_area) & (x0 > 0) & (y0 > 0) & (x0 + st[:, cv2.CC_STAT_WIDTH] < w)
          & (y0 + st[:, cv2.CC_STAT_HEIGHT] < h))
    ok[0] = False
    if not ok.any():
        return np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0)
    yy, xx = np.nonzero(np.isin(lab, np.flatnonzero(ok)))
    L = lab[yy, xx]
    m = np.bincount(L, minlength=n).astype(np.float64)
    sx, sy = np.bincount(L, xx, n), np.bincount(L, yy, n)
    sxx, syy, sxy = np.bincount(L, xx * xx, n), np.bincount(L, yy * yy, n), np.bincount(L, xx * yy, n)
    idx = np.flatnonzero(ok)
    mm = m[idx]
    cx, cy = sx[idx] / mm, sy[idx] / mm
    # pixel covariance (+ 1/12: a pixel's own extent)
    cxx, cyy, cxy = sxx[idx] / mm - cx * cx + 1 / 12, syy[idx] / mm - cy * cy + 1 / 12, sxy[idx] / mm - cx * cy
    det = np.maximum(cxx * cyy - cxy * cxy, 1e-12)
    fill = mm / (4 * np.pi * np.sqrt(det))
    tr = cxx + cyy
    disc = np.sqrt(np.maximum(tr * tr / 4 - det, 0))
    ratio = np.sqrt((tr / 2 + disc) / np.maximum(tr / 2 - disc, 1e-12))
    good = (fill > 0.8) & (fill < 1.2) & (ratio < 4)
    cov = np.stack([np.stack([cxx, cxy], -1), np.stack([cxy, cyy], -1)], -2)
    return np.column_stack([cx, cy])[good], cov[good], mm[good]


def _on_board(img: np.ndarray, c: np.ndarray, cov: np.ndarray) -> bool:
    """Whether the dark ellipse (centre c px, pixel covariance cov) lies on a uniform lighter surround (a dot on the
    board, not background texture): as :func:`dark_on_light`, with the ellipse's own shape (inner: within 0.6 of
    its boundary, ring: 1.5-2.1 times its size)."""
    h, w = img.shape
    R = int(np.ceil(2.2 * 2 * np.sqrt(np.linalg.eigvalsh(cov)[1]))) + 1
    x0, x1, y0, y1 = int(c[0]) - R, int(c[0]) + R + 1, int(c[1]) - R, int(c[1]) + R + 1
    if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
        return False
    win = img[y0:y1, x0:x1].astype(np.float64)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    d = np.stack([xx - c[0], yy - c[1]], -1)
    rho = np.sqrt(np.einsum("...i,ij,...j->...", d, np.linalg.inv(cov), d)) / 2  # 1 on the ellipse's boundary
    inner, ring = win[rho <= 0.6], win[(rho >= 1.5) & (rho <= 2.1)]
    if inner.size == 0 or ring.size < 8:
        return False
    lo, med, hi = np.percentile(ring, [10, 50, 90])
    con = med - inner.mean()
    return bool(con > 15 and con > 1.2 * (hi - lo) and con > 0.5 * med)


def dark_ellipses(img: np.ndarray, report: dict | None = None):
    """Dot candidates of a photo: (centres (M, 2) px, pixel covariances (M, 2, 2) px^2, areas (M,) px) of the dark
    ellipses on a lighter surround, at every level of :data:`LEVELS` of the image flattened by its local
    background (:func:`flatten`; first with a kernel for dots of 1/36 of the image size, then again for the
    median dot found when it differs by more than 1.5 x). A dot seen at several levels is kept once (the first
    level at which it is seen, 0.5 first)."""
    dot_px = max(img.shape) / 36
    found = []
    for attempt in range(2):
        flat = flatten(img, dot_px)
        for level in (LEVELS[1], LEVELS[0], LEVELS[2]):
            c, cov, a = _components(flat, level, 0.05 * img.size)
            for k in range(len(c)):
                if _on_board(img, c[k], cov[k]):
                    found.append((c[k], cov[k], a[k]))
        if not found or attempt:
            break
        new = float(np.median([2 * np.sqrt(a / np.pi) for _, _, a in found]))
        if max(new, dot_px) / min(new, dot_px) < 1.5:
            break
        dot_px = new
    keep = []
    for c, cov, a in found:
        inv = np.linalg.inv(cov)
        if not any(np.sqrt((c - k[0]) @ inv @ (c - k[0])) / 2 < 1.0 or np.linalg.norm(c - k[0]) < 1.0 for k in keep):
            keep.append((c, cov, a))
    if report is not None:
        report["ellipses"] = len(keep)
    if not keep:
        return np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0)
    return np.array([k[0] for k in keep]), np.array([k[1] for k in keep]), np.array([k[2] for k in keep])


def _blobs(img, settings) -> tuple[np.ndarray, np.ndarray]:
    """(centres (M, 2) px, diameters (M,) px) of the blobs; of two blobs whose centres are closer than half the
    larger one's diameter and of more than half its size (one dot split at some thresholds) the larger is kept."""
    kp = make_blob_detector(settings).detect(img)
    pts = np.array([k.pt for k in kp], np.float64).reshape(-1, 2)
    sizes = np.array([k.size for k in kp], np.float64)
    if len(pts) > 1:
        order = np.argsort(-sizes)
        pts, sizes = pts[order], sizes[order]
        keep = np.ones(len(pts), bool)
        d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
        for i in range(len(pts)):
            if keep[i]:
                dup = (d[i] < 0.5 * sizes[i]) & (sizes > 0.5 * sizes[i]) & (np.arange(len(pts)) > i)
                keep[dup] = False
        pts, sizes = pts[keep], sizes[keep]
    return pts, sizes


def dark_on_light(img, pts, sizes) -> np.ndarray:
    """(M,) bool: blobs darker than a uniform lighter surround (a dot on the board, not a blob of background
    texture): the median of the ring at 1.5-2.2 radii minus the mean inside 0.6 radius exceeds 15 grey levels,
    1.2 x the ring's 10-90 % spread and half the ring's median (printed dots are near black)."""
    h, w = img.shape[:2]
    out = np.zeros(len(pts), bool)
    for k, ((x, y), d) in enumerate(zip(pts, sizes)):
        r = max(d / 2, 1.5)
        R = int(np.ceil(2.2 * r)) + 1
        x0, x1, y0, y1 = int(x) - R, int(x) + R + 1, int(y) - R, int(y) + R + 1
        if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
            continue
        win = img[y0:y1, x0:x1].astype(np.float64)
        yy, xx = np.mgrid[y0:y1, x0:x1]
        rho = np.hypot(xx - x, yy - y)
        inner, ring = win[rho <= 0.6 * r], win[(rho >= 1.5 * r) & (rho <= 2.2 * r)]
        if inner.size == 0 or ring.size < 8:
            continue
        lo, med, hi = np.percentile(ring, [10, 50, 90])
        c = med - inner.mean()
        out[k] = c > 15 and c > 1.2 * (hi - lo) and c > 0.5 * med
    return out


def size_windows(pts, sizes, n_dots: int, dot_ratio: float = 0.0, big: bool = False, max_windows: int = 8):
    """Index arrays of blob subsets (stage 3), best first: the blobs whose diameter lies in [s, SIZE_WINDOW s]
    for s = each blob's diameter, that hold >= n_dots blobs and at most 2 n_dots + 10, larger blobs first (plus, with ``big``, up to one
    blob of 1.5-2.5x the window's median: the origin dot). dot_ratio: the target's diameter / spacing (0:
    unknown): blobs whose diameter / nearest-neighbour distance is off it by more than a factor 2 are left out."""
    keep = np.ones(len(sizes), bool)
    if dot_ratio > 0 and len(pts) > 1:
        r = sizes / nearest_distance(pts)
        keep = (r > dot_ratio / 2) & (r < dot_ratio * 2 * (2.2 if big else 1.0))
    idx = np.flatnonzero(keep)
    out, seen = [], set()
    for s in np.unique(sizes[idx]):
        w = idx[(sizes[idx] >= s) & (sizes[idx] <= SIZE_WINDOW * s)]
        if len(w) < n_dots - (1 if big else 0):
            continue
        if big:
            med = float(np.median(sizes[w]))
            large = idx[(sizes[idx] > SIZE_WINDOW * s) & (sizes[idx] > 1.5 * med) & (sizes[idx] < 2.5 * med)]
            if len(large):
                w = np.union1d(w, large[[int(np.argmax(sizes[large]))]])
        key = tuple(w)
        if key not in seen:
            seen.add(key)
            out.append(w)
    # few others (at most 2 n_dots + 10), larger blobs first (background texture gives small blobs)
    out = [w for w in out if len(w) <= 2 * n_dots + 10]
    out.sort(key=lambda w: -float(np.median(sizes[w])))
    return out[:max_windows]


def best_count(sizes) -> tuple[int, float, float]:
    """(most blobs within one size window, its smallest and largest diameter [px]) for a message."""
    best = (0, 0.0, 0.0)
    for s in np.unique(sizes):
        w = sizes[(sizes >= s) & (sizes <= SIZE_WINDOW * s)]
        if len(w) > best[0]:
            best = (len(w), float(w.min()), float(w.max()))
    return best


def grid_from_points(pts, shape_img, pattern, flags) -> np.ndarray | None:
    """``findCirclesGrid`` on the points pts (M, 2) px drawn as clean discs; (a * b, 2) centres snapped back to
    pts (OpenCV's order) or None. pattern: (a, b) = OpenCV's patternSize."""
    if len(pts) < pattern[0] * pattern[1]:
        return None
    nn = nearest_distance(pts)
    rad = np.clip(0.3 * nn, 2.0, 200.0)
    canvas = np.full(shape_img, 255, np.uint8)
    for (x, y), r in zip(pts, rad):
        cv2.circle(canvas, (int(round(x * 16)), int(round(y * 16))), int(round(r * 16)), 0, -1, cv2.LINE_AA, 4)
    p = dict(minThreshold=50.0, maxThreshold=200.0, thresholdStep=50.0, minRepeatability=2, minArea=4.0,
             maxArea=float(np.pi * rad.max() ** 2 * 2 + 10), minDistBetweenBlobs=1.0, filterByCircularity=False,
             filterByConvexity=False, filterByInertia=False)
    ok, c = cv2.findCirclesGrid(canvas, pattern, flags=flags, blobDetector=make_blob_detector(p))
    if not ok or c is None:
        return None
    c = c.reshape(-1, 2).astype(np.float64)
    d = np.linalg.norm(c[:, None] - pts[None], axis=2)
    j = np.argmin(d, axis=1)
    if len(set(j.tolist())) != len(j) or np.any(d[np.arange(len(j)), j] > 0.5 * rad[j] + 1.0):
        return None
    return pts[j]


def candidate_grids(img, n_dots: int, patterns, flags_list, given: tuple = (), dot_ratio: float = 0.0,
                    big: bool = False, report: dict | None = None, lattice: bool = False):
    """Yield (stage, pattern, centres (n_dots, 2) px in OpenCV's grid order) for each grid found, stages as in the
    module docstring (``lattice``: the lattice stage, symmetric grids only, after 'default'). report: filled with
    {stage: (blobs found, best window count, min size, max size)}."""
    report = {} if report is None else report
    stages = []
    if given:
        stages.append(("given", img, dict(given), False))
    stages.append(("default", img, default_settings(img), False))
    if lattice:
        stages.append(("lattice", None, None, False))
    stages += [("sized", img, permissive_settings(img), True), ("flattened", None, permissive_settings(img), True)]
    dot_px = 0.0
    for name, im, settings, windows in stages:
        if name == "lattice":
            pts, _, areas = dark_ellipses(img)
            sizes = 2 * np.sqrt(areas / np.pi)
            report[name] = (len(pts), len(pts), float(sizes.min()) if len(sizes) else 0.0, float(sizes.max(initial=0)))
            for pattern, G in lattice_grids(img, pts, areas, patterns):
                yield name, pattern, G.reshape(-1, 2)
            continue
        if im is None:
            im = flatten(img, dot_px or max(img.shape) / 50)
        pts, sizes = _blobs(im, settings)
        report[name] = (len(pts), *best_count(sizes))
        if name == "sized" and report[name][1]:
            dot_px = float(np.sqrt(report[name][2] * report[name][3]))  # geometric mean of the best window's sizes
        if windows:  # dots on the board only, then by size
            on = np.flatnonzero(dark_on_light(im, pts, sizes))
            pts, sizes = pts[on], sizes[on]
            report[name] = (len(pts), *best_count(sizes))
        subsets = size_windows(pts, sizes, n_dots, dot_ratio, big) if windows else [np.arange(len(pts))]
        for w in subsets:
            if len(w) > 4 * n_dots + 20:
                continue
            for pattern in patterns:
                for flags in flags_list:
                    c = grid_from_points(pts[w], img.shape[:2], pattern, flags)
                    if c is not None:
                        yield name, pattern, c


def not_found_message(what: str, n_dots: int, report: dict, rejected: list) -> str:
    """'<what> not found: <n> dot-like blobs of one size at best (<a>-<b> px), <n_dots> needed; ...'."""
    if not report:
        return f"{what} not found"
    name = "sized" if "sized" in report else max(report, key=lambda k: report[k][1])
    n_all, n, lo, hi = report[name]
    msg = (f"{what} not found: at best {n} blobs of one size ({lo:.1f}-{hi:.1f} px across, stage '{name}', "
           f"{n_all} blobs in all), {n_dots} dots needed")
    if n >= n_dots:
        msg += "; no grid of that shape among them (dots hidden, merged, or the board only partly visible)"
    if rejected:
        msg += "; grids found but refused: " + "; ".join(sorted(set(rejected))[:2])
    return msg


def grid_consistency(xy: np.ndarray, uv: np.ndarray, spacing_m: float) -> tuple[float, float]:
    """(largest distance of a dot from the homography fitted robustly to all of them [px], the same as a fraction of
    the local dot spacing in px) for the board points xy (K, 2) m and their image points uv (K, 2) px. A grid
    whose ids are shifted by a row or a column somewhere has dots about one spacing off."""
    H, _ = cv2.findHomography(xy, uv, cv2.LMEDS)
    if H is None or not np.all(np.isfinite(H)):
        return float("inf"), float("inf")
    p = np.column_stack([xy, np.ones(len(xy))]) @ H.T
    pr = p[:, :2] / p[:, 2:]
    r = np.linalg.norm(uv - pr, axis=1)
    # local spacing: image distance of a spacing step along x at each point
    q = np.column_stack([xy + [spacing_m, 0.0], np.ones(len(xy))]) @ H.T
    step = np.linalg.norm(q[:, :2] / q[:, 2:] - pr, axis=1)
    k = int(np.argmax(r / np.maximum(step, 1e-9)))
    return float(r.max()), float(r[k] / max(step[k], 1e-9))
