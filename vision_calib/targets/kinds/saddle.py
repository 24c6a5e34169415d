"""Sub-pixel X-corner (chessboard saddle point) estimator: a weighted quadratic fit, re-centred to its fixed point.

Around a corner estimate c the image is fitted in the least-squares sense, with weights
w(p) = (1 - |p - c|^2 / rho^2)^2 inside the window radius rho (0 outside: a biweight, smooth at its border,
so the estimate is continuous in c; measured: a Gaussian truncated at 3 sigma made the fixed point jump by
~0.003 px with the start point, Gaussian x biweight windows had more bias and scatter), by

    I(c + d) ~ a dx^2 + b dx dy + c2 dy^2 + e dx + f dy + g       (d = p - c, p the integer pixel centres)

and the stationary point of the quadratic, d* = -[[2a, b], [b, 2 c2]]^-1 [e, f], gives the next estimate
c + d*; the window is re-centred there and the fit repeated until |d*| < :data:`TOL_PX` (at most
:data:`MAX_ITER` fits). Why the fixed point is unbiased: an X-corner of two straight edges (a chessboard
corner under any homography), blurred by any point-symmetric PSF (defocus, pixel area), is point-symmetric
about the crossing, and so is a weight centred there; the odd terms of the fit (e, f) then vanish and the
crossing is a fixed point. What is left comes from sampling the window on the pixel grid (a pixel-phase
error, ~0.004 px RMS at rho 11-12 px on exact-coverage renders: the chessboard kind's figures).
The window must stay inside the point-symmetric region (about one square around the corner):
:func:`window_radii` takes rho = min(:data:`RHO_MAX`, d / 2) per corner, d the distance to its nearest
detected neighbour. RHO_MAX chosen by measurement (targets/kinds/chessboard.py): radius 12 vs 16 px gave
corner scatter 0.0174 vs 0.0169 px at read noise 8 for 3x the time.

Rejected corners (ok False): the fit is not a saddle (Hessian determinant 4 a c2 - b^2 >= 0), an estimate
moves more than ``max_move`` px from the start, the window would leave the image (rho is first shrunk
per corner to fit, down to :data:`RHO_MIN`), or the iteration does not settle.

Pixel convention: OpenCV's, pixel centres at integer coordinates (pixel (0, 0) covers [-0.5, 0.5]^2);
the image is read only at pixel centres (no interpolation), so the output is in the same convention.
The pixels read when started from uv are exactly those of :func:`read_mask` (measure/seeded.py draws the
noise of later frames only there).
"""

from __future__ import annotations

import numpy as np

#: largest / smallest window radius [px]
RHO_MAX, RHO_MIN = 12.0, 3.0
#: convergence: step [px] below which the fixed point is reached; at most MAX_ITER fits
TOL_PX, MAX_ITER = 1e-4, 12
#: a corner is refused when its last step is still larger than this after MAX_ITER fits [px]
SETTLE_PX = 1e-2


def window_radii(uv: np.ndarray) -> np.ndarray:
    """(K,) window radius [px] per corner of a detected set uv (K, 2) px: min(RHO_MAX, d_k / 2) with d_k the
    distance to the nearest other corner, rounded down to 0.5 px, at least RHO_MIN (RHO_MAX alone)."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    if len(uv) < 2:
        return np.full(len(uv), RHO_MAX)
    d = np.linalg.norm(uv[:, None] - uv[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return np.clip(np.floor(d.min(axis=1)) / 2, RHO_MIN, RHO_MAX)


def corner_radii(uv: np.ndarray, shape, rho, max_move: float) -> np.ndarray:
    """(K,) per-corner window radius [px]: rho (scalar or (K,)), shrunk so that the window around any point
    within max_move of the start uv (K, 2) stays inside the image; < RHO_MIN: refused."""
    h, w = shape
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    room = np.min(np.stack([uv[:, 0], uv[:, 1], w - 1 - uv[:, 0], h - 1 - uv[:, 1]]), axis=0) - max_move
    return np.minimum(rho, room)


def read_mask(uv: np.ndarray, shape, max_move: float, rho=None) -> np.ndarray:
    """(H, W) bool: every pixel :func:`refine_saddles` (img of ``shape``, uv (K, 2), max_move, rho) reads:
    the discs of radius rho_k + max_move around the start points (the estimate never leaves the max_move
    disc while it reads, and reads only where the weight is > 0)."""
    h, w = shape
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    rk = corner_radii(uv, shape, window_radii(uv) if rho is None else rho, max_move)
    mask = np.zeros(shape, dtype=bool)
    for (x, y), rho_k in zip(uv, rk):
        if not rho_k >= RHO_MIN:
            continue
        r = rho_k + max_move + 1e-6
        x0, x1 = max(0, int(np.floor(x - r))), min(w - 1, int(np.ceil(x + r)))
        y0, y1 = max(0, int(np.floor(y - r))), min(h - 1, int(np.ceil(y + r)))
        yy, xx = np.mgrid[y0:y1 + 1, x0:x1 + 1]
        mask[y0:y1 + 1, x0:x1 + 1] |= (xx - x) ** 2 + (yy - y) ** 2 <= r * r
    return mask


def weights(r2: np.ndarray, rho) -> np.ndarray:
    """Window weights (1 - r^2 / rho^2)^2 at squared distances r2 [px^2] for radii rho [px] (broadcast), 0 outside."""
    return np.clip(1.0 - r2 / (rho * rho), 0.0, None) ** 2


def refine_saddles(img: np.ndarray, uv: np.ndarray, max_move: float = 1.0, rho=None):
    """Sub-pixel saddle points near uv (K, 2) px in a grey image (H, W) (module docstring); rho: window
    radius [px], scalar or (K,), default :func:`window_radii` (uv).

    Returns (uv (K, 2) float64 px, ok (K,) bool); rejected corners keep their start position.
    Vectorised over the corners: one batched 6 x 6 solve per iteration."""
    img = np.asarray(img)
    h, w = img.shape
    c0 = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    rk = corner_radii(c0, img.shape, window_radii(c0) if rho is None else rho, max_move)
    ok = rk >= RHO_MIN
    c = c0.copy()
    done = np.zeros(len(c0), dtype=bool)
    R = int(np.ceil(max(float(np.max(rk, initial=0.0)), RHO_MIN)))
    g = np.arange(-R, R + 1)
    gx, gy = (a.ravel() for a in np.meshgrid(g, g))
    last = np.zeros(len(c0))
    for _ in range(MAX_ITER):
        act = np.flatnonzero(ok & ~done)
        if not len(act):
            break
        ci = np.rint(c[act]).astype(np.intp)
        X, Y = ci[:, :1] + gx, ci[:, 1:] + gy  # (k, N) pixel centres of the window
        dx, dy = X - c[act, :1], Y - c[act, 1:]
        wt = weights(dx * dx + dy * dy, rk[act, None])
        v = np.where(wt > 0, img[np.clip(Y, 0, h - 1), np.clip(X, 0, w - 1)], 0).astype(np.float64)
        A = np.stack([dx * dx, dx * dy, dy * dy, dx, dy, np.ones_like(dx)], axis=1)  # (k, 6, N)
        Aw = A * wt[:, None, :]
        M = Aw @ A.transpose(0, 2, 1)
        p = np.linalg.solve(M, (Aw @ v[:, :, None]))[:, :, 0]
        a, b, c2, e, f = p[:, 0], p[:, 1], p[:, 2], p[:, 3], p[:, 4]
        det = 4 * a * c2 - b * b
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.column_stack([(b * f - 2 * c2 * e) / det, (b * e - 2 * a * f) / det])
        new = c[act] + step
        bad = ~(det < 0) | ~np.all(np.isfinite(new), axis=1) | ~(np.linalg.norm(new - c0[act], axis=1) <= max_move)
        good = act[~bad]
        c[good] = new[~bad]
        last[good] = np.linalg.norm(step[~bad], axis=1)
        ok[act[bad]] = False
        done[good[last[good] < TOL_PX]] = True
    ok &= done | (last < SETTLE_PX)
    c[~ok] = c0[~ok]
    return c, ok


def asymmetry(img: np.ndarray, uv: np.ndarray, rho) -> np.ndarray:
    """(K,) point-symmetry residual of the image about each point uv (K, 2) px in its window of radius rho (scalar
    or (K,)): sqrt(sum w (I(c + d) - I(c - d))^2 / (2 sum w (I(c + d) - mean)^2)), bilinear samples, weights
    :func:`weights`. 0 for an X-corner under uniform light and a point-symmetric blur at its crossing; ~1 for an
    image unrelated to its mirror. Measured on bench_target_photos.py views (saddle fit converged): corners
    within 0.3 px of the truth 0.02-0.2 (95 % below 0.17, JPEG 30 up to 0.21), corners biased by a shadow
    edge through the window (>= 0.3 px off) 0.16-0.6 (median 0.25-0.4)."""
    img = np.asarray(img, dtype=np.float64)
    h, w = img.shape
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    rho = np.broadcast_to(np.asarray(rho, dtype=np.float64), (len(uv),))
    out = np.full(len(uv), np.inf)
    for k, ((x, y), r) in enumerate(zip(uv, rho)):
        R = int(np.ceil(r))
        g = np.arange(-R, R + 1, dtype=np.float64)
        dx, dy = (a.ravel() for a in np.meshgrid(g, g))
        wt = weights(dx * dx + dy * dy, r)
        pts = np.stack([np.column_stack([x + dx, y + dy]), np.column_stack([x - dx, y - dy])])
        if pts.min() < 0 or np.any(pts[..., 0] > w - 1) or np.any(pts[..., 1] > h - 1):
            continue
        x0, y0 = np.floor(pts[..., 0]).astype(np.intp), np.floor(pts[..., 1]).astype(np.intp)
        x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
        fx, fy = pts[..., 0] - x0, pts[..., 1] - y0
        v = (img[y0, x0] * (1 - fx) * (1 - fy) + img[y0, x1] * fx * (1 - fy) + img[y1, x0] * (1 - fx) * fy
             + img[y1, x1] * fx * fy)
        m = np.sum(wt * v[0]) / np.sum(wt)
        out[k] = np.sqrt(np.sum(wt * (v[0] - v[1]) ** 2) / max(2 * np.sum(wt * (v[0] - m) ** 2), 1e-12))
    return out


def recapture(img: np.ndarray, uv: np.ndarray, ok: np.ndarray, max_move: float, max_asym: float):
    """Start points for the corners a fit from uv (K, 2) rejected (ok False): the saddle fit from uv allowed to
    move up to max_move px (the detector's corner of a defocused board can be 1-3 px off), kept where the image
    is point-symmetric about the result (:func:`asymmetry` < max_asym: an X-corner, not a corner pulled by a
    shadow edge). Returns (start points (K, 2): uv with the recaptured corners replaced, recaptured (K,) bool)."""
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    bad = np.flatnonzero(~np.asarray(ok, dtype=bool))
    start = uv.copy()
    got = np.zeros(len(uv), dtype=bool)
    if not len(bad):
        return start, got
    rho = window_radii(uv)
    wide, okw = refine_saddles(img, uv[bad], max_move, rho[bad])
    sym = np.full(len(bad), np.inf)
    sym[okw] = asymmetry(img, wide[okw], rho[bad][okw])
    keep = okw & (sym < max_asym)
    start[bad[keep]] = wide[keep]
    got[bad[keep]] = True
    return start, got


def refine_detected(img: np.ndarray, uv: np.ndarray, max_move: float = 1.0):
    """Saddle refinement of a full detection's corners uv (K, 2) px -> (uv (K, 2), ok (K,)), with the windows
    that :func:`refine_saddles` will choose when later started from the returned corners (the seeded batch
    mode starts every other frame of the pose there): windows from uv, then the corners whose
    :func:`window_radii` changed with the refined positions are refined again with the new windows."""
    c0 = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    s1 = window_radii(c0)
    out, ok = refine_saddles(img, c0, max_move, s1)
    s2 = s1.copy()
    s2[ok] = window_radii(out[ok])  # the rejected corners are dropped from the detection
    if np.any(s2 != s1):
        redo, ok2 = refine_saddles(img, c0, max_move, s2)
        ch = s2 != s1
        out[ch], ok[ch] = redo[ch], ok2[ch]
    return out, ok
