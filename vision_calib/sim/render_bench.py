"""Render speed and accuracy figures (prints; no assertions). ``python -m vision_calib.sim.render_bench``.

For each scene (``a5``: ``targets/charuco_a5.yaml`` at 0.3-0.6 m; ``h4``: the H4 9 x 6 ChArUco, whose
texture is not a power of two, at 0.6-0.76 m, f = 1013 px), for the polygon backend and pyrender at each
supersample factor s: frames/s of :meth:`TargetRenderer.render` at 1024 x 768 (set ``LP_NUM_THREADS=1`` for single-thread figures), the
cornerSubPix corner shift between the rendered image and a CPU reference (``cv2.warpPerspective`` of
the same texture at 8x, box-averaged) at the same projected ChArUco corners (mean and RMS), and the
solvePnP pose error from the rendered corners; plus, for the reference, the detector's own bias
(detected - ``cv2.projectPoints``) and the PnP error it alone causes. Poses: one fronto-parallel, the
rest random.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from ..camera import CameraIntrinsics
from ..shipped import targets_dir
from ..targets import load_target
from ..render.renderer import TargetRenderer, look_at_target

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


def _pnp_error(P, uv, K: CameraIntrinsics, T):
    """(rotation error [deg], tz error [mm]) of solvePnP on corners uv (N, 2) against the true T."""
    ok, rvec, tvec = cv2.solvePnP(P, np.asarray(uv, np.float64), K.K, None, flags=cv2.SOLVEPNP_ITERATIVE)
    dR = cv2.Rodrigues(rvec)[0] @ T[:3, :3].T
    return np.degrees(np.linalg.norm(cv2.Rodrigues(dR)[0])), 1e3 * (tvec.ravel()[2] - T[2, 3])


SCENES = {  # name: (target YAML or TargetSpec kwargs, CameraIntrinsics args, distance range [m], max tilt [rad])
    "a5": ("charuco_a5.yaml", (1024, 768, 1100, 1000, 480.3, 410.7), (0.3, 0.6), 0.5),
    # H4 scene (seed 000): 9 x 6 x 25 mm ChArUco -> texture 4096 x 2821 texels (not a power of two)
    "h4": (dict(kind="charuco", name="h4_9x6", rows=6, cols=9, dictionary="DICT_4X4_50", square_m=0.025,
                marker_m=0.019, margin_m=0.008), (1024, 768, 1013.3, 1013.3, 511.5, 383.5), (0.6, 0.76), 0.35),
}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scene", choices=sorted(SCENES), nargs="+", default=["a5", "h4"])
    ap.add_argument("--poses", type=int, default=8)
    ap.add_argument("--factors", type=int, nargs="+", default=[1, 2, 3, 4])
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    from ..targets import TargetSpec

    for name in a.scene:
        tgt, cam, dist, tilt = SCENES[name]
        spec = load_target(targets_dir() / tgt) if isinstance(tgt, str) else TargetSpec(**tgt)
        K = CameraIntrinsics(*cam)
        rng = np.random.default_rng(a.seed)
        # first pose fronto-parallel and centred, then random ones
        poses = [look_at_target(spec, np.mean(dist))] + [
            look_at_target(spec, rng.uniform(*dist), rng.uniform(-tilt, tilt, 3), rng.uniform(-0.03, 0.03, 2))
            for _ in range(a.poses - 1)]
        _, P = spec.corner_points()
        refs, uvs = [], []
        for T in poses:
            uv, _ = cv2.projectPoints(P, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], K.K, None)
            uvs.append(uv.reshape(-1, 2))
            refs.append(subpix_at(reference_image(spec, K, T, px_per_m=4096 / max(spec.outline_m())), uvs[-1]))
        det_bias = np.concatenate([r - uv for r, uv in zip(refs, uvs)])
        pe = np.array([_pnp_error(P, r, K, T) for r, T in zip(refs, poses)])
        print(f"[{name}] {spec.name}, camera {K.width}x{K.height} f={K.fx:g}, {a.poses} poses at {dist[0]}-{dist[1]} m, "
              f"{P.shape[0]} corners each. cornerSubPix on the CPU reference: bias vs projectPoints RMS "
              f"{np.sqrt((det_bias ** 2).sum(1).mean()):.4f} px; PnP error RMS {np.sqrt((pe[:, 0] ** 2).mean()):.4f} deg, "
              f"tz {np.sqrt((pe[:, 1] ** 2).mean()):.4f} mm")
        for backend, s in [("polygon", 1)] + [("pyrender", f) for f in a.factors]:
            with TargetRenderer(spec, K, supersample=s, backend=backend) as r:
                r.render(poses[0])  # warm-up (shader compilation)
                t0 = time.perf_counter()
                imgs = [r.render(T) for T in poses]
                dt = (time.perf_counter() - t0) / len(poses)
                got = [subpix_at(img, uv) for img, uv in zip(imgs, uvs)]
                d = np.concatenate([g - ref for g, ref in zip(got, refs)])
                pe = np.array([_pnp_error(P, g, K, T) for g, T in zip(got, poses)])
                print(f"  {backend if backend == 'polygon' else f'pyrender s={s}'}: {1 / dt:6.1f} frames/s; render - reference corner shift: mean ({d[:, 0].mean():+.4f}, "
                      f"{d[:, 1].mean():+.4f}) RMS {np.sqrt((d ** 2).sum(1).mean()):.4f} max {np.abs(d).max():.4f} px; "
                      f"PnP error RMS {np.sqrt((pe[:, 0] ** 2).mean()):.4f} deg, tz {np.sqrt((pe[:, 1] ** 2).mean()):.4f} mm; "
                      f"anisotropy {r.anisotropy:g}", flush=True)


if __name__ == "__main__":
    main()
