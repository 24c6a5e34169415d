"""Render speed and accuracy figures (prints; no assertions). ``python -m vision_calib.render.bench``.

For each supersample factor s: frames/s of :meth:`TargetRenderer.render` at 1024 x 768, and the
cornerSubPix corner shift between the rendered image and a CPU reference (``cv2.warpPerspective`` of
the same texture at 8x, box-averaged) at the same projected ChArUco corners, plus the detector's own
bias on the reference (detected - ``cv2.projectPoints``), over random poses of ``targets/charuco_a5.yaml``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np

from ..camera import CameraIntrinsics
from ..targets import load_target
from .renderer import TargetRenderer, look_at_target

_CRIT = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-5)


def reference_image(spec, K: CameraIntrinsics, T_cam_target, s: int = 8, px_per_m: float = 4096 / 0.195, background=128.0):
    """CPU reference (H, W) float32: homography warp of the target texture at s x, box-averaged."""
    tex = spec.texture(px_per_m).astype(np.float32)
    x0, y0, x1, y1 = spec.texture_extent_m()
    Ht, Wt = tex.shape
    A = np.array([[(x1 - x0) / Wt, 0, x0 + 0.5 * (x1 - x0) / Wt], [0, (y1 - y0) / Ht, y0 + 0.5 * (y1 - y0) / Ht], [0, 0, 1]])
    Ks = K.K.copy()
    Ks[:2, :2] *= s
    Ks[0, 2] = s * (K.cx + 0.5) - 0.5
    Ks[1, 2] = s * (K.cy + 0.5) - 0.5
    T = np.asarray(T_cam_target)
    H = Ks @ np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]]) @ A
    hi = cv2.warpPerspective(tex, H, (K.width * s, K.height * s), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=background)
    return cv2.resize(hi, K.size, interpolation=cv2.INTER_AREA)


def subpix_at(img, uv, win=4):
    """cornerSubPix started 0.7 px off the given points uv (N, 2) -> refined (N, 2)."""
    start = (np.asarray(uv, np.float32) + 0.7).reshape(-1, 1, 2)
    return cv2.cornerSubPix(np.asarray(img, np.float32), start, (win, win), (-1, -1), _CRIT).reshape(-1, 2)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--target", default=str(Path(__file__).resolve().parents[2] / "targets" / "charuco_a5.yaml"))
    ap.add_argument("--poses", type=int, default=8)
    ap.add_argument("--factors", type=int, nargs="+", default=[1, 2, 3, 4])
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    spec = load_target(a.target)
    K = CameraIntrinsics(1024, 768, 1100, 1000, 480.3, 410.7)
    rng = np.random.default_rng(a.seed)
    poses = [look_at_target(spec, rng.uniform(0.3, 0.6), rng.uniform(-0.5, 0.5, 3), rng.uniform(-0.05, 0.05, 2))
             for _ in range(a.poses)]
    _, P = spec.corner_points()
    refs, uvs = [], []
    for T in poses:
        uv, _ = cv2.projectPoints(P, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], K.K, None)
        uvs.append(uv.reshape(-1, 2))
        refs.append(reference_image(spec, K, T))
    det_bias = np.concatenate([subpix_at(r, uv) - uv for r, uv in zip(refs, uvs)])
    print(f"camera 1024x768, {a.poses} poses, {P.shape[0]} corners each; "
          f"cornerSubPix bias on the reference: RMS {np.sqrt((det_bias ** 2).sum(1).mean()):.4f} px")
    for s in a.factors:
        with TargetRenderer(spec, K, supersample=s) as r:
            t0 = time.perf_counter()
            imgs = [r.render(T) for T in poses]
            dt = (time.perf_counter() - t0) / len(poses)
            d = np.concatenate([subpix_at(img, uv) - subpix_at(ref, uv) for img, ref, uv in zip(imgs, refs, uvs)])
            print(f"s={s}: {1 / dt:6.1f} frames/s, render-vs-reference corner shift RMS "
                  f"{np.sqrt((d ** 2).sum(1).mean()):.4f} px, max {np.abs(d).max():.4f} px, anisotropy {r.anisotropy:g}")


if __name__ == "__main__":
    main()
