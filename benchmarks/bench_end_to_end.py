"""End-to-end wall time and peak memory on this machine:

1. the H4 default scene, 81 poses x 10 rendered frames (render, sensor effects, detection + PnP
   in worker processes, then identification and evaluation), with the per-stage split;
2. a 100-run Monte Carlo study of synthetic identifications (H4 model 12, 71 of the 81 poses).

    .venv/bin/python benchmarks/bench_end_to_end.py [--workers 2] [--runs 100]

Target: the 81-pose run (810 rendered frames) in under 60 s on 2 cores.
"""

from __future__ import annotations

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import argparse
import resource
import tempfile
import time

import numpy as np

from vision_calib.rig import load_scene, scene_poses
from vision_calib.experiment.simulate import DEFAULT_SCENE, run_simulation
from vision_calib.experiment.steps import analyze_setup, rngs
from vision_calib.experiment.synthetic import run_synthetic


def _peak_mb():
    """Peak RSS of this process [MiB] (workers report their own, see run_simulation timings)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--runs", type=int, default=100)
    args = ap.parse_args(argv)

    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        rep = run_simulation(DEFAULT_SCENE, out_dir=d, seed=0, workers=args.workers)
        wall = time.perf_counter() - t0
    me = _peak_mb()
    t = rep["timings_s"]
    n_frames = rep["settings"]["poses"] * rep["settings"]["frames"]
    print(f"H4 default scene: {rep['settings']['poses']} poses x {rep['settings']['frames']} frames = {n_frames} frames")
    print(f"  wall time {wall:.1f} s ({n_frames / wall:.1f} frames/s overall; target < 60 s)")
    print(f"  render+measure wall {t['render_measure_wall']:.1f} s; CPU time summed over workers: "
          f"render {t['render_cpu']:.1f} s, effects {t['effects_cpu']:.1f} s, measure {t['measure_cpu']:.1f} s")
    print(f"  identify {t['identify'] * 1e3:.0f} ms, evaluate + synthetic reference {t['evaluate'] * 1e3:.0f} ms")
    print(f"  peak RSS: main process {me:.0f} MiB, largest render/measure worker {t['worker_peak_rss_mib']:.0f} MiB")
    a, b = rep["accuracy"]["after"], rep["accuracy"]["before"]
    print(f"  V2 {b['V2_rad']:.3g} -> {a['V2_rad']:.3g} rad ({100 * (1 - a['V2_rad'] / b['V2_rad']):.1f} % better); "
          f"validation position RMS {b['position_rms_mm']:.3f} -> {a['position_rms_mm']:.3f} mm; synthetic "
          f"reference {rep['synthetic_reference']['accuracy_after']['position_rms_mm']:.3f} mm")

    scene = load_scene(DEFAULT_SCENE)
    rp, _, rv = rngs(0)
    poses = scene_poses(scene, rp, 71)
    validation = scene_poses(scene, rv, which="validation")
    rep0, _ = analyze_setup(scene.setup, poses)
    base = scene.setup.params.mask(rep0.base_parameters)
    t0 = time.perf_counter()
    pos = []
    for k in range(args.runs):
        out = run_synthetic(scene, seed=k, poses=poses, validation=validation, base=base)
        pos.append(out["after"]["position_rms_mm"])
    mc = time.perf_counter() - t0
    print(f"\nMonte Carlo: {args.runs} synthetic identifications + evaluations (H4 model 12, 71 poses): "
          f"{mc:.2f} s ({mc / args.runs * 1e3:.1f} ms each, one process); validation position RMS after "
          f"calibration: median {np.median(pos):.3f} mm, 95th percentile {np.percentile(pos, 95):.3f} mm")
    print(f"  peak RSS main process {_peak_mb():.0f} MiB")


if __name__ == "__main__":
    main()
