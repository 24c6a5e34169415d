"""Does a plan measure better than random poses, and does it predict what simulate gives? (issues 27, 34) For each
scene and seed S: `plan --seed S --frames F`, then `simulate --seed S --frames F` (images: render, measure, identify,
validate against the truth) over exactly the planned poses and over the scene's own random poses (``simulate
--poses N``: its pose region with its view check; for the H4 a random subset of its 81-pose grid). Prints per seed
and as medians over the seeds: the validation position RMS ratio plan / random, and the plan's predicted validation
RMS (first order, median over noise draws) over the simulated one. With ``--draws K`` each design is simulated
K times (seeds S, S + 1000, ...: other noise, other validation poses, and for random other poses) and the median of
the K simulated figures stands for the simulated one: the prediction is the median of a distribution whose 95th
percentile is ~1.8x its median, one run is one draw of it. Image runs take a few seconds each; a plan ~20 s (one
core).

    PYTHONPATH=. python benchmarks/bench_plan_accuracy.py --scenes ur5e_eye_in_hand.yaml,rx90_eye_in_hand.yaml --seeds 231-235
    PYTHONPATH=. python benchmarks/bench_plan_accuracy.py --scenes h4_vision.yaml,ur5e_cell.yaml --seeds 231-233
    PYTHONPATH=. python benchmarks/bench_plan_accuracy.py --seeds 231-235 --draws 3
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from vision_calib.errors import ConfigError
from vision_calib.experiment.simulate import run_simulation
from vision_calib.planning.plan import plan_cell
from vision_calib.rig import SCENES_DIR, load_scene


#: seed step between the draws of one design (--draws)
DRAW = 1000


def seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b) + 1)) if b else [int(v) for v in text.split(",")]


def _run(scene_path, seed, frames, n_poses=None) -> dict:
    t = time.perf_counter()
    rep = run_simulation(scene_path, None, seed=seed, frames=frames, n_poses=n_poses, plots=False, reference=False)
    h = (rep.get("holdout") or {}).get("overall") or {}
    acc = rep["measurements"].get("accuracy_vs_truth") or {}
    return {"n_valid": rep["measurements"]["n_valid"], "n_poses": rep["measurements"]["n_poses"],
            "pose_noise": (float(np.sqrt(np.mean(np.square(acc.get("translation_rms_mm", [np.nan]))))),
                           float(np.sqrt(np.mean(np.square(acc.get("rotation_rms_deg", [np.nan])))))),
            "validation_rms_mm": rep["accuracy"]["after"]["position_rms_mm"],
            "heldout_rms_mm": (h.get("after") or {}).get("position_rms_mm"), "status": rep["verdict"]["status"],
            "seconds": time.perf_counter() - t}


def _plan_row(scene_path: Path, n: int, seed: int, frames, work: Path) -> tuple[dict, float]:
    t = time.perf_counter()
    plan = plan_cell(scene_path, n, work, seed=seed, draws=0, frames=frames, plots=False)
    return plan, time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="ur5e_eye_in_hand.yaml,rx90_eye_in_hand.yaml",
                    help="comma-separated scene files of scenes/ (e.g. add h4_vision.yaml, ur5e_cell.yaml)")
    ap.add_argument("--poses", type=int, default=20)
    ap.add_argument("--seeds", default="231-235", help="plan seed = simulate seed, e.g. 231-235 or 231,233")
    ap.add_argument("--frames", type=int, default=2, help="frames per pose (plan --frames and simulate --frames)")
    ap.add_argument("--draws", type=int, default=1, help="simulations per design (seeds S + 1000 k); their median is "
                    "compared")
    args = ap.parse_args()
    print(f"{args.poses} poses, {args.frames} frames; per seed S: plan --seed S --frames F, simulate over exactly the "
          "planned poses and over the scene's own random poses (same simulate seed S: noise, truth, validation poses)")
    for name in args.scenes.split(","):
        scene_path = SCENES_DIR / name.strip()
        scene = load_scene(scene_path)
        baseline = scene_path
        if scene.poses.kind == "configurations":  # a named set (thesis): random poses of the scene's own sampler
            baseline = replace(scene, poses=replace(scene.poses, kind="random"))
            print(f"{name}: its identification poses are a named configuration set; random: the scene's own sampler "
                  "(its region, target in view)")
        rows = []
        for s in seeds(args.seeds):
            work = Path(tempfile.mkdtemp(prefix="bench_plan_"))
            try:
                plan, tp = _plan_row(scene_path, args.poses, s, args.frames, work)
            except ConfigError as exc:  # e.g. a scene without camera or target: nothing to plan
                print(f"{name}: not planned: {exc}", flush=True)
                break
            pv = plan["design"]["predicted_validation_rms"]
            runs_a = [_run(work / "simulate_plan.yaml", s + DRAW * k, args.frames) for k in range(args.draws)]
            runs_b = [_run(baseline, s + DRAW * k, args.frames, args.poses) for k in range(args.draws)]
            a, b = runs_a[0], runs_b[0]
            va = float(np.median([r["validation_rms_mm"] for r in runs_a]))
            vb = float(np.median([r["validation_rms_mm"] for r in runs_b]))
            rows.append((pv["plan"]["median_mm"], va, vb))
            clear = [p.get("clearance_m") for p in plan["poses"] if p.get("clearance_m") is not None]
            print(f"{name} seed {s}: plan {tp:.0f} s ({plan['screening']['kept']} of {plan['screening']['candidates']} "
                  f"candidates kept), predicted {pv['plan']['median_mm']:.4g} mm (random {pv['random']['median_mm']:.4g})"
                  f"; simulated plan {va:.4g} mm ({a['n_valid']}/{a['n_poses']} measured), random "
                  f"{vb:.4g} mm ({b['n_valid']}/{b['n_poses']})"
                  + (f" (medians of {args.draws} draws: plan "
                     + ", ".join(f"{r['validation_rms_mm']:.4g}" for r in runs_a) + "; random "
                     + ", ".join(f"{r['validation_rms_mm']:.4g}" for r in runs_b) + ")" if args.draws > 1 else "")
                  + f"; plan/random {va / vb:.3f}, predicted/simulated {pv['plan']['median_mm'] / va:.3f}"
                  + (f"; clearance {min(clear) * 1e3:.1f}-{max(clear) * 1e3:.1f} mm" if clear else ""), flush=True)
        if not rows:
            continue
        pr, sa, sb = (np.array(v, float) for v in zip(*rows))
        print(f"{name}: median over {len(rows)} seeds: plan/random {np.median(sa / sb):.3f} (medians "
              f"{np.median(sa):.4g} / {np.median(sb):.4g} mm -> {np.median(sa) / np.median(sb):.3f}); predicted/simulated "
              f"{np.median(pr / sa):.3f}", flush=True)


if __name__ == "__main__":
    main()
