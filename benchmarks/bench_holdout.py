"""The verdict that protects the robot (issue 26): false failures of the held-out decision on clean shipped scenes,
and the held-out figures, over seeds. Each run is `simulate` in image mode (render, measure, identify, k-fold held
out, validation against the truth), no plots, no synthetic reference. Prints one line per run (held-out position
RMS before -> after, observed / predicted, truth validation before -> after, the failure if any), then per scene
the count of failed verdicts by kind, and the median observed / predicted ratio.

    PYTHONPATH=. python benchmarks/bench_holdout.py [--seeds 0-19] [--frames 3] [--scenes rx90_eye_in_hand,...]

The truth of each run is the scene's own truth draw; ``--new-truth`` draws a new truth per seed (truth.seed = seed).
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from dataclasses import replace

import numpy as np

from vision_calib.errors import VisionCalibError
from vision_calib.experiment.simulate import run_simulation
from vision_calib.rig import SCENES_DIR, load_scene

#: the clean shipped cells (h4_unmodelled is the scene built to fail: its true robot is not the model)
CLEAN = ("h4_vision", "rx90_eye_in_hand", "ur5e_eye_in_hand", "thesis_arm_eye_in_hand", "thesis_arm_tripod_probe")


def seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b) + 1)) if b else [int(v) for v in text.split(",")]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-19")
    ap.add_argument("--frames", type=int, default=3, help="frames per pose (default 3; the scene's: 0)")
    ap.add_argument("--scenes", default=",".join(CLEAN))
    ap.add_argument("--new-truth", action="store_true", help="a new truth per seed (truth.seed = seed)")
    args = ap.parse_args()
    for name in args.scenes.split(","):
        scene = load_scene(SCENES_DIR / f"{name}.yaml")
        kinds, ratios, t0 = Counter(), [], time.perf_counter()
        for s in seeds(args.seeds):
            sc = replace(scene, truth=replace(scene.truth, seed=s)) if args.new_truth else scene
            try:
                rep = run_simulation(sc, seed=s, frames=args.frames or None, plots=False, reference=False, workers=1)
            except VisionCalibError as exc:
                kinds["error"] += 1
                print(f"{name} seed {s}: error {exc}")
                continue
            h, acc, v = rep.get("holdout"), rep["accuracy"], rep["verdict"]
            kinds[v.get("failure") or ("failed" if not v["usable"] else "usable")] += 1
            line = f"{name} seed {s}: verdict {v['status']}"
            if h and "overall" in h:
                o = h["overall"]
                r = (h.get("predicted") or {}).get("ratio_observed_to_predicted")
                ratios += [r] if r else []
                line += (f"; held-out position RMS {o['before']['position_rms_mm']:.3f} -> "
                         f"{o['after']['position_rms_mm']:.3f} mm, observed/predicted {r:.2f}" if r else "")
            line += (f"; truth validation {acc['before']['position_rms_mm']:.3f} -> "
                     f"{acc['after']['position_rms_mm']:.3f} mm")
            if v.get("failure"):
                line += f"; FAILED: {rep['failure']['message'][:160]}"
            elif v["status"] != "ok":
                line += f"; WARNING: {v['message'][:300]}"
            print(line, flush=True)
        print(f"== {name}: {sum(kinds.values())} runs, {dict(kinds)}; held-out observed/predicted median "
              f"{np.median(ratios) if ratios else float('nan'):.2f} (range {min(ratios, default=np.nan):.2f}-"
              f"{max(ratios, default=np.nan):.2f}); {time.perf_counter() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    main()
