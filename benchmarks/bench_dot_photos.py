"""Circle-grid detection on generated photographs (issue 17): detection rate per degradation kind and mixed,
and the dot-centre error against the true projected circle centres.

    .venv/bin/python benchmarks/bench_dot_photos.py [--views 40] [--seed 0] [--kinds lighting,mixed,...]

Views: tests/targets/photo_views.py (800 x 600, f 900 px, textured background, sensor noise 2 grey levels), a
modified circle grid (dot diameter 0.4 x spacing, up to 10 x 9 dots, frontal view <= ~60 % of the image width),
random roll; only views where the whole board is inside the image count. Kinds (dot size log-uniform 12-40 px
unless said):
- lighting: brightness ramp 0.6 across the image;  defocus: Gaussian blur sigma 2 px;  jpeg: quality 30;
- perspective: tilt 60 deg;  shadow: a half-plane over the board darkened by 50 %;
- sizes: dots log-uniform 5-60 px, tilt 0-30 deg, ramp 0.2, blur sigma min(0.8, dot / 8);
- mixed: all at once, each at a random strength: tilt U(0, 60) deg, ramp U(0, 0.6), shadow U(0, 0.5), blur
  sigma U(0, 2) px, JPEG quality U(30, 95).
A view counts as detected when every dot is found with the right id, each within 0.2 dot diameters + 1 px of
its true centre. Centre errors (over the detected views): 'raw' = the detector's centres (image-ellipse centres,
no intrinsics), 'corrected' = after the ellipse-centre correction the kinds apply when intrinsics are given
(:func:`vision_calib.targets.kinds.circles.ellipse_centre_offset` with the true K).
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

from photo_views import F, H, KINDS, W, degraded_view  # noqa: E402
from vision_calib.camera import CameraIntrinsics  # noqa: E402
from vision_calib.measure.detect import detect  # noqa: E402
from vision_calib.targets.kinds.circles import ellipse_centre_offset  # noqa: E402

INTR = CameraIntrinsics(W, H, F, F, W / 2, H / 2)


def run_view(kind: str, rng):
    """One view where the whole board is visible: (detected right, raw errors (K,) px or None, corrected errors,
    kwargs, dot px, reason)."""
    spec, img, uv, dot, kw = degraded_view(kind, rng)
    d = detect(img, spec)
    if not (d.valid and d.n_corners == len(uv)):
        return False, None, None, kw, dot, d.reason
    e = np.linalg.norm(d.uv_px - uv[d.ids], axis=1)
    if e.max() >= 0.2 * dot + 1.0:
        return False, None, None, kw, dot, f"wrong centres/ids: max error {e.max():.1f} px"
    _, p = spec.corner_points()
    corr = d.uv_px - ellipse_centre_offset(spec, p, d.uv_px, INTR, radii=spec.kind_impl.radii(spec))
    return True, e, np.linalg.norm(corr - uv, axis=1), kw, dot, ""


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--views", type=int, default=40, help="views per kind (whole board visible)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--verbose", action="store_true", help="print each failed view")
    a = ap.parse_args(argv)
    print(f"bench_dot_photos: {a.views} views per kind, seed {a.seed}")
    print(f"{'kind':12s} {'detected':>10s} {'rate':>6s}   {'raw err mean/max px':>20s}   {'corrected mean/max px':>22s}"
          f"   {'s/view':>6s}")
    for ki, kind in enumerate(a.kinds.split(",")):
        rng = np.random.default_rng([a.seed, ki])
        ok, raw, cor = 0, [], []
        t0 = time.perf_counter()
        for v in range(a.views):
            good, e, c, kw, dot, why = run_view(kind, rng)
            ok += good
            if good:
                raw.append(e)
                cor.append(c)
            elif a.verbose:
                print(f"  {kind} view {v}: dot {dot:.1f} px {({k: round(x, 2) for k, x in kw.items()})}: {why}")
        dt = (time.perf_counter() - t0) / a.views
        r, c = (np.concatenate(raw), np.concatenate(cor)) if raw else (np.full(1, np.nan), np.full(1, np.nan))
        print(f"{kind:12s} {ok:4d} / {a.views:<4d} {ok / a.views:6.1%}   {r.mean():9.3f} / {r.max():<8.3f}   "
              f"{c.mean():10.3f} / {c.max():<8.3f}   {dt:6.2f}", flush=True)


if __name__ == "__main__":
    main()
