"""Does a plan measure better than random poses? (issue 27) `plan` a cell, then `simulate` (images: render, measure,
identify, validate against the truth) over exactly the planned poses and over random measurable poses, seed by seed,
and compare the validation position RMS (the identified robot against the truth on the scene's random validation
poses over the workspace) and the held-out RMS (k-fold on the measured poses).

Random measurable poses: ``screened`` (default) draws N of the plan's own screened candidates (reachable,
measurable, collision-free) per seed and simulates them through a pose file; ``scene`` uses the scene's own random
poses (``simulate --poses N``: its pose region with the scene's view check; for the H4 a random subset of the
81-pose grid). Both sets go through the same simulate seed (noise, truth, validation poses).

    PYTHONPATH=. python benchmarks/bench_plan_accuracy.py --scene ur5e_cell.yaml --poses 20 --seeds 0-4
    PYTHONPATH=. python benchmarks/bench_plan_accuracy.py --scene h4_vision.yaml --poses 20 --seeds 0-4 --baseline scene
"""

from __future__ import annotations

import argparse
import csv
import io
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from vision_calib.experiment.simulate import run_simulation
from vision_calib.planning.plan import CandidateSource, candidate_poses, collision_setup, plan_cell, screen
from vision_calib.rig import SCENES_DIR, load_scene


def seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b) + 1)) if b else [int(v) for v in text.split(",")]


def _pose_scene(plan_dir: Path, name: str, joints: np.ndarray) -> Path:
    """A copy of the plan's simulate_plan.yaml whose poses are ``joints`` (N, n) rad (a pose file beside it)."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["pose_id"] + [f"q{j + 1}" for j in range(joints.shape[1])])
    for i, q in enumerate(joints):
        w.writerow([f"{i:03d}"] + [repr(float(v)) for v in q])
    (plan_dir / f"{name}.csv").write_text(buf.getvalue())
    doc = yaml.safe_load((plan_dir / "simulate_plan.yaml").read_text())
    doc["poses"] = {**doc["poses"], "path": f"{name}.csv"}  # the region keys stay: the same validation poses
    doc["name"] = name
    p = plan_dir / f"{name}.yaml"
    p.write_text(yaml.safe_dump(doc, sort_keys=False))
    return p


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="ur5e_cell.yaml")
    ap.add_argument("--poses", type=int, default=20)
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--frames", type=int, default=None, help="frames per pose (default: the scene's)")
    ap.add_argument("--baseline", choices=("screened", "scene"), default="screened")
    ap.add_argument("--plan-seed", type=int, default=0)
    ap.add_argument("--draws", type=int, default=10, help="Monte Carlo draws of the plan's prediction")
    args = ap.parse_args()
    scene_path = SCENES_DIR / args.scene
    work = Path(tempfile.mkdtemp(prefix="bench_plan_"))
    t = time.perf_counter()
    plan = plan_cell(scene_path, args.poses, work, seed=args.plan_seed, draws=args.draws)
    row = next(r for r in plan["predicted_accuracy"]["rows"] if r["count"] == args.poses)
    print(f"plan {args.scene} --poses {args.poses} --seed {args.plan_seed}: {time.perf_counter() - t:.1f} s; predicted "
          f"validation RMS plan {row['plan']['rms_median_mm']:.4g} mm, random {row['random']['rms_median_mm']:.4g} mm "
          f"(ratio {row['ratio_rms']:.3f}, {plan['predicted_accuracy']['draws']} draws); smallest clearance "
          + (f"{min(p['clearance_m'] for p in plan['poses']) * 1e3:.1f} mm" if plan["poses"][0].get("clearance_m")
             is not None else "n/a (no collision model)"))
    scene = load_scene(scene_path)
    pool = None
    if args.baseline == "screened":
        _, checker = collision_setup(scene)
        cand = candidate_poses(scene, CandidateSource(), 20000, np.random.default_rng([args.plan_seed, 99]))
        pool = cand[screen(scene, cand, checker)["kept"]]
    rows = []
    for s in seeds(args.seeds):
        a = _run(work / "simulate_plan.yaml", s, args.frames)
        if pool is not None:
            pick = pool[np.sort(np.random.default_rng([s, 98]).choice(len(pool), args.poses, replace=False))]
            b = _run(_pose_scene(work, f"random_{s}", scene.setup.joints(pick, scene.setup.params.nominal)), s,
                     args.frames)
        else:
            b = _run(scene_path, s, args.frames, args.poses)
        rows.append((s, a, b))
        print(f"seed {s}: plan {a['n_valid']}/{a['n_poses']} measured, validation RMS {a['validation_rms_mm']:.4g} mm, "
              f"held-out {a['heldout_rms_mm']:.4g} mm ({a['status']}, {a['seconds']:.0f} s) | random "
              f"{b['n_valid']}/{b['n_poses']}, validation RMS {b['validation_rms_mm']:.4g} mm, held-out "
              f"{b['heldout_rms_mm']:.4g} mm ({b['status']}, {b['seconds']:.0f} s)", flush=True)
    pa = np.median([a["validation_rms_mm"] for _, a, _ in rows])
    pb = np.median([b["validation_rms_mm"] for _, _, b in rows])
    ha = np.median([a["heldout_rms_mm"] for _, a, _ in rows])
    hb = np.median([b["heldout_rms_mm"] for _, _, b in rows])
    print(f"median over {len(rows)} seeds: validation RMS plan {pa:.4g} mm vs random {pb:.4g} mm -> ratio {pa / pb:.3f}; "
          f"held-out RMS plan {ha:.4g} mm vs random {hb:.4g} mm -> ratio {ha / hb:.3f}")
    print(f"predicted (plan's report): {row['plan']['rms_median_mm']:.4g} vs {row['random']['rms_median_mm']:.4g} mm "
          f"(ratio {row['ratio_rms']:.3f}) at the scene's synthetic pose noise {scene.measurement.sigma_t_m * 1e3:.3g} mm, "
          f"{np.degrees(scene.measurement.sigma_r_rad):.3g} deg per component; the images measured the poses to "
          f"{np.median([a['pose_noise'][0] for _, a, _ in rows]):.3g} mm, "
          f"{np.median([a['pose_noise'][1] for _, a, _ in rows]):.3g} deg RMS per component (plan, median of seeds)")


if __name__ == "__main__":
    main()
