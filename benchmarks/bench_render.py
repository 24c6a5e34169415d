"""Render speed and accuracy of the backends side by side (issue 11). Prints figures, asserts nothing.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_render.py [--poses 8] [--reps 3]

1. Speed, per pose of the H4 default scene (``scenes/h4_vision.yaml``: its camera, board and poses under
   the true robot): ``TargetRenderer`` with backend "polygon" (the default), "warp" (mip-mapped texture,
   4x) and "pyrender" (s = 2, as the image chain runs it), beside the floor (``cv2.warpPerspective`` of
   the 4096-texel board texture at 2x + area average, as in ``bench_end_to_end.py``), min of ``--reps``
   interleaved repetitions, one process, one OpenCV / llvmpipe thread; ratios to the floor.
2. Accuracy on the H4 board, the A5 board and the AprilTag grid (``vision_calib.sim.render_bench.SCENES``,
   first pose fronto-parallel, then random views tilted up to the scene's limit): cornerSubPix corners of
   each render minus the same detector on the 8x CPU reference (``sim.render_bench.reference_image``): mean,
   RMS, max [px].
"""

from __future__ import annotations

import os

os.environ.setdefault("LP_NUM_THREADS", "1")

import argparse
import time
from pathlib import Path

import cv2
import numpy as np

from vision_calib.camera import CameraIntrinsics
from vision_calib.render import TargetRenderer, look_at_target
from vision_calib.sim.render_bench import SCENES, reference_image, subpix_at
from vision_calib.render.warp import supersampled_K
from vision_calib.targets import TargetSpec, load_target

ROOT = Path(__file__).resolve().parents[1]
BACKENDS = (("polygon", 2), ("warp", 2), ("pyrender", 2))


class Floor:
    """cv2.warpPerspective of the full board texture at 2x + INTER_AREA average (the issue's floor)."""

    def __init__(self, spec, K: CameraIntrinsics):
        self.K, self.tex = K, spec.texture(4096 / max(spec.outline_m())).astype(np.float32)
        x0, y0, x1, y1 = spec.texture_extent_m()
        Ht, Wt = self.tex.shape
        self.A = np.array([[(x1 - x0) / Wt, 0, x0 + 0.5 * (x1 - x0) / Wt],
                           [0, (y1 - y0) / Ht, y0 + 0.5 * (y1 - y0) / Ht], [0, 0, 1]])
        self.Ks = supersampled_K(K, 2)

    def render(self, T):
        H = self.Ks @ np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]]) @ self.A
        hi = cv2.warpPerspective(self.tex, H, (2 * self.K.width, 2 * self.K.height), flags=cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=128)
        return cv2.resize(hi, self.K.size, interpolation=cv2.INTER_AREA)


def h4_scene_poses(n: int):
    """(K, spec, T_cam_target (n, 4, 4)) of the H4 default scene's first n poses under the true robot."""
    from vision_calib.experiment.simulate import DEFAULT_SCENE
    from vision_calib.experiment.steps import rngs, scene_truth
    from vision_calib.rig import load_scene, scene_poses

    scene = load_scene(DEFAULT_SCENE)
    rp, _, _ = rngs(0)
    Ts = scene.setup.T_cam_target(scene_poses(scene, rp, n), scene_truth(scene))
    return scene.setup.camera.without_distortion(), load_target(scene.target_path), Ts


def speed(n_poses: int, reps: int) -> None:
    K, spec, Ts = h4_scene_poses(n_poses)
    renderers = {name: TargetRenderer(spec, K, supersample=s, backend=name) for name, s in BACKENDS}
    fns = {name: r.render for name, r in renderers.items()}
    fns["floor"] = Floor(spec, K).render
    for f in fns.values():
        f(Ts[0])  # warm-up (texture pyramid, shader compilation)
    t = {name: np.full((reps, len(Ts)), np.inf) for name in fns}
    for rep in range(reps):
        for i, T in enumerate(Ts):
            for name, f in fns.items():
                t0 = time.perf_counter()
                f(T)
                t[name][rep, i] = time.perf_counter() - t0
    best = {name: 1e3 * v.min(axis=0) for name, v in t.items()}
    names = [n for n, _ in BACKENDS]
    print(f"H4 default scene, {K.width}x{K.height}, {len(Ts)} poses: ms per pose (min of {reps}), ratio to the floor")
    print("pose  " + "".join(f"{n:>10s}" for n in names) + f"{'floor':>10s}" + "".join(f"{n + '/fl':>13s}" for n in names))
    rows = list(range(len(Ts))) + ["mean"]
    for i in rows:
        v = {n: (best[n].mean() if i == "mean" else best[n][i]) for n in best}
        print(f"{i!s:5s} " + "".join(f"{v[n]:10.1f}" for n in names) + f"{v['floor']:10.1f}"
              + "".join(f"{v[n] / v['floor']:13.2f}" for n in names))
    for r in renderers.values():
        r.close()


def accuracy(n_poses: int, seed: int) -> None:
    cases = dict(SCENES)
    cases["april"] = ("apriltag_grid.yaml", (1024, 768, 1100.0, 1000.0, 520.8, 361.2), (0.4, 0.6), 0.5)
    cases["h4 oblique"] = cases["h4"][:3] + (0.8,)  # up to 46 deg about each axis
    variants = (("polygon", 2), ("warp", 4), ("pyrender", 2), ("pyrender", 4))
    print("\ncornerSubPix corners minus the same on the 8x reference: mean (du, dv) / RMS / max [px]")
    for name, (tgt, cam, dist, tilt) in cases.items():
        spec = load_target(ROOT / "targets" / tgt) if isinstance(tgt, str) else TargetSpec(**tgt)
        K = CameraIntrinsics(*cam)
        rng = np.random.default_rng(seed)
        poses = [look_at_target(spec, np.mean(dist))] + [
            look_at_target(spec, rng.uniform(*dist), rng.uniform(-tilt, tilt, 3), rng.uniform(-0.03, 0.03, 2))
            for _ in range(n_poses - 1)]
        _, P = spec.corner_points()
        uvs = [cv2.projectPoints(P, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], K.K, None)[0].reshape(-1, 2) for T in poses]
        refs = [subpix_at(reference_image(spec, K, T, px_per_m=4096 / max(spec.outline_m())), uv)
                for T, uv in zip(poses, uvs)]
        print(f"[{name}] {spec.name}: {len(poses)} poses at {dist[0]}-{dist[1]} m, tilt up to "
              f"{np.degrees(tilt):.0f} deg per axis, {P.shape[0]} corners each")
        for backend, s in variants:
            with TargetRenderer(spec, K, supersample=s, backend=backend) as r:
                d = np.concatenate([subpix_at(r.render(T), uv) - ref for T, uv, ref in zip(poses, uvs, refs)])
            label = backend if backend == "polygon" else f"{backend} s={s}"
            print(f"  {label:12s} ({d[:, 0].mean():+.4f}, {d[:, 1].mean():+.4f}) / "
                  f"{np.sqrt((d ** 2).sum(1).mean()):.4f} / {np.abs(d).max():.4f}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--poses", type=int, default=8)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip-accuracy", action="store_true")
    a = ap.parse_args(argv)
    cv2.setNumThreads(1)
    speed(a.poses, a.reps)
    if not a.skip_accuracy:
        accuracy(a.poses, a.seed)


if __name__ == "__main__":
    main()
