"""Chessboard / ChArUco / circle-grid detection on generated photographs (issue 17): detection rate per target
kind and degradation, and the corner error against the true projected corners.

    .venv/bin/python benchmarks/bench_target_photos.py [--targets chessboard,charuco] [--views 40] [--seed 0]
                                                       [--kinds lighting,mixed,...] [--sizes 5,6,8,10,12,15,20]

Views: tests/targets/photo_views.py (800 x 600, f 900 px, textured background, sensor noise 2 grey levels), boards
of photo_views.board_for (chessboard n x (n - 1) squares, n <= 11; ChArUco n x (n - 1) squares, n <= 10, DICT_4X4_50
markers of 0.75 square; the circle grid of bench_dot_photos), frontal view <= ~60 % of the image width, random
roll; only views where the whole board is inside the image count. Kinds (photo_views.degradation; square side or
dot diameter log-uniform 12-40 px unless said; ChArUco: 40-80 px, 'sizes' 20-80 px, photo_views.SIZE_RANGES):
- lighting: brightness ramp 0.6 across the image;  defocus: Gaussian blur sigma 2 px;  jpeg: quality 30;
- perspective: tilt 60 deg;  shadow: a half-plane over the board darkened by 50 %;
- sizes: 5-60 px, tilt 0-30 deg, ramp 0.2, blur sigma min(0.8, size / 8);
- mixed: all at once, each at a random strength: tilt U(0, 60) deg, ramp U(0, 0.6), shadow U(0, 0.5), blur
  sigma U(0, 2) px, JPEG quality U(30, 95).
--sizes: also one row per fixed square side / dot diameter [px] (the 'sizes' view conditions at that size).
Two rates: 'all': every corner of the board is found (default DetectConfig, per-frame measure.detect) with the
right id, each within :data:`TOL_SQUARE` of a square (dot diameter) of its true position (a wrong id is a whole
square off); 'board': a valid detection whose every corner has the right id (same tolerance) and that holds at
least :data:`MIN_SHARE` of the corners (the chessboard's saddle fit drops the corners a shadow edge crosses). Corner errors |detected - true projection| px, over the detected
views: mean and max; circle grids: the raw image-ellipse centres (no intrinsics; see bench_dot_photos).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "targets"))

import numpy as np  # noqa: E402

from photo_views import KINDS, board_for, degradation, degraded_view, photo_view  # noqa: E402
from vision_calib.measure.detect import detect  # noqa: E402

#: largest corner error of a detected view, in squares (dot diameters)
TOL_SQUARE = 0.25
#: smallest share of the board's corners of a 'board' detection
MIN_SHARE = 0.9


def check(spec, img, uv, size_px):
    """(all corners right, board right, errors (K,) px of the board's corners or None, reason) of one view."""
    d = detect(img, spec)
    if not d.valid:
        return False, False, None, d.reason
    e = np.linalg.norm(d.uv_px - uv[d.ids], axis=1)
    if e.max() >= TOL_SQUARE * size_px:
        return False, False, None, f"wrong corners/ids: max error {e.max():.2f} px"
    if d.n_corners != len(uv):
        board = d.n_corners >= MIN_SHARE * len(uv)
        return False, board, e if board else None, f"{d.n_corners} of {len(uv)} corners"
    return True, True, e, ""


def sized_view(target, size_px, rng):
    """One view at a fixed feature size with the 'sizes' conditions: (spec, img, uv, size, kwargs)."""
    spec = board_for(target, size_px)
    while True:
        _, kw = degradation("sizes", rng)
        img, uv, whole = photo_view(spec, rng, size_px, **kw)
        if whole:
            return spec, img, uv, size_px, kw


def row(label, views, verbose):
    ok, okb, errs, dt = 0, 0, [], 0.0
    n = 0
    for spec, img, uv, size, kw in views:
        n += 1
        t0 = time.perf_counter()
        good, board, e, why = check(spec, img, uv, size)
        dt += time.perf_counter() - t0
        ok += good
        okb += board
        if board:
            errs.append(e)
        if not good and verbose:
            print(f"    {label} view {n}: {size:.1f} px {({k: round(x, 2) for k, x in kw.items()})}: {why}")
    dt /= max(n, 1)
    e = np.concatenate(errs) if errs else np.full(1, np.nan)
    print(f"  {label:12s} {ok:4d} / {n:<4d} {ok / n:6.1%}  {okb:4d} / {n:<4d} {okb / n:6.1%}   {e.mean():8.3f} / "
          f"{e.max():<7.3f}   {dt:6.3f}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", default="chessboard,charuco")
    ap.add_argument("--views", type=int, default=40, help="views per kind (whole board visible)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--kinds", default=",".join(KINDS), help="degradation kinds ('' for none)")
    ap.add_argument("--sizes", default="", help="fixed square sides / dot diameters [px], e.g. 5,6,8,10,12")
    ap.add_argument("--verbose", action="store_true", help="print each failed view")
    a = ap.parse_args(argv)
    print(f"bench_target_photos: {a.views} views per row, seed {a.seed}; all: every corner, right id, error < "
          f"{TOL_SQUARE} square; board: >= {MIN_SHARE:.0%} of the corners, all right; errors over the 'board' views")
    for ti, target in enumerate(a.targets.split(",")):
        print(f"{target}\n  {'kind':12s} {'all':>11s} {'rate':>6s}  {'board':>11s} {'rate':>6s}   {'err mean/max px':>16s}   {'s/view':>6s} (detection)")
        for ki, kind in enumerate(k for k in a.kinds.split(",") if k):
            rng = np.random.default_rng([a.seed, ti, ki])
            row(kind, (degraded_view(kind, rng, target) for _ in range(a.views)), a.verbose)
        for s in (float(x) for x in a.sizes.split(",") if x):
            rng = np.random.default_rng([a.seed, ti, 100, int(10 * s)])
            row(f"{s:g} px", (sized_view(target, s, rng) for _ in range(a.views)), a.verbose)


if __name__ == "__main__":
    main()
