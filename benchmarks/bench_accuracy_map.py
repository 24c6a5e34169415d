"""The accuracy map and `compare` checked by simulation (issue 37). Each run is `simulate` in image mode (render,
measure, identify), no plots, no synthetic reference, written to a temporary folder (compare reads folders).

1. coverage: per seed, the share of the map's points whose true tool position error (calibrated model against the
   true robot, registered on the calibration poses as the map is) is within the predicted r95; pooled over the
   seeds (target 90-98 %), with the mean squared normalised error (1 when the predicted covariance is right), and
   judged against the coverage a correct map gives (``coverage.under_the_map`` of each report, pooled one draw per
   seed: ``accuracy_map.pooled_coverage_law``): its 5-95 % interval, the chance of a pooled coverage at least the
   observed one (near 0: conservative, near 1: optimistic) and the chance a correct map lands in the 90-98 % band;
2. compare, same robot: run `seed` against run `seed + 1000` of the same truth (other noise): consistent (exit 0)
   in >= 95 % of the pairs;
3. compare, a changed robot: the same, the second run's true robot with one joint offset moved by --offset-deg
   (each joint offset compare tests, in turn): flagged (exit 3) in >= 90 %; and, with --other-truth, a second run of
   another true robot (truth seed + 1).

    PYTHONPATH=. python benchmarks/bench_accuracy_map.py [--scenes rx90_eye_in_hand] [--seeds 1-8] [--poses 12]
        [--frames 2] [--new-truth] [--offset-deg 0.02] [--joints theta2,theta3] [--no-compare]

``--new-truth`` draws a new truth per seed (truth.seed = seed) for every run of that seed.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from vision_calib.errors import VisionCalibError
from vision_calib.experiment.accuracy_map import pooled_coverage_law
from vision_calib.experiment.compare import compare_results
from vision_calib.experiment.simulate import run_simulation
from vision_calib.experiment.steps import scene_truth
from vision_calib.rig import SCENES_DIR, load_scene

#: seed offset of the second run of a pair
PAIR = 1000


def seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b) + 1)) if b else [int(v) for v in text.split(",")]


def run(scene, seed: int, folder: Path, args) -> dict | None:
    try:
        rep = run_simulation(scene, out_dir=folder, seed=seed, n_poses=args.poses, frames=args.frames, plots=False,
                             reference=False, workers=1)
    except VisionCalibError as exc:
        print(f"  seed {seed}: error {exc}", flush=True)
        return None
    if not rep.get("accuracy_map"):
        print(f"  seed {seed}: no map ({rep['verdict']['status']}: {rep['verdict'].get('message', '')[:120]})",
              flush=True)
        return None
    return rep


def with_offset(scene, name: str, delta_rad: float):
    """The scene with its truth's ``name`` moved by delta (the other parameters as the scene's truth draws them)."""
    x = scene_truth(scene)
    ps = scene.setup.params
    i = ps.index(name)
    devs = {**scene.truth.deviations, name: float(x[i] - ps.nominal[i] + delta_rad)}
    return replace(scene, truth=replace(scene.truth, deviations=devs))


def joint_offsets(rep_dir: Path, other: Path) -> list[str]:
    """The joint offsets (theta*/q0_*) compare tests for these two results."""
    out = compare_results(rep_dir, other)
    return [r["name"] for r in out["parameters"]["compared"] if r["name"].startswith(("theta", "q0_"))]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="rx90_eye_in_hand")
    ap.add_argument("--seeds", default="1-8")
    ap.add_argument("--poses", type=int, default=12)
    ap.add_argument("--frames", type=int, default=2)
    ap.add_argument("--new-truth", action="store_true", help="a new truth per seed (truth.seed = seed)")
    ap.add_argument("--offset-deg", type=float, default=0.02)
    ap.add_argument("--joints", default=None, help="joint offsets to move (default: every one compare tests)")
    ap.add_argument("--no-compare", action="store_true", help="coverage only")
    ap.add_argument("--other-truth", action="store_true", help="also compare against another true robot")
    ap.add_argument("--keep", action="store_true", help="keep the result folders (their path is printed)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_map_"))
    try:
        run_scenes(args, tmp)
    finally:
        if args.keep:
            print(f"result folders kept in {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)


def run_scenes(args, tmp: Path) -> None:
    for name in args.scenes.split(","):
        scene0 = load_scene(SCENES_DIR / f"{name}.yaml")
        t0 = time.perf_counter()
        hits, hits_r, z2, n_pts, laws = [], [], [], 0, []
        same, changed, other = [], {}, []
        joints = None if args.joints is None else args.joints.split(",")
        print(f"== {name}: {args.poses} poses x {args.frames} frames, seeds {args.seeds}"
              + (", a new truth per seed" if args.new_truth else ", the scene's truth"), flush=True)
        for s in seeds(args.seeds):
            sc = replace(scene0, truth=replace(scene0.truth, seed=s)) if args.new_truth else scene0
            a_dir = tmp / f"{name}_{s}"
            rep = run(sc, s, a_dir, args)
            if rep is None:
                continue
            m = rep["accuracy_map"]
            e = np.array([p["true_error_mm"] for p in m["points"]])
            r = np.array([p["r95_mm"] for p in m["points"]])
            ed = np.array([p["true_error_deg"] for p in m["points"]])
            rd = np.array([p["r95_deg"] for p in m["points"]])
            hits.append(np.mean(e <= r))
            hits_r.append(np.mean(ed <= rd))
            z2.append(m["coverage"]["mean_z2_over_3"])
            law = m["coverage"]["under_the_map"]
            laws.append(law["draws"])
            n_pts += len(e)
            line = (f"seed {s}: {len(e)} points ({m['n_extrapolated']} extrapolated), r95 median "
                    f"{np.median(r):.3f} mm; true error within r95: position {100 * hits[-1]:.1f} %, rotation "
                    f"{100 * hits_r[-1]:.1f} %; mean z^2/3 {z2[-1]:.2f}; a correct map: {100 * law['p05']:.1f}-"
                    f"{100 * law['p95']:.1f} %, P(>= observed) {law['p_at_least_observed']:.2f}")
            if not args.no_compare:
                b_dir = tmp / f"{name}_{s + PAIR}"
                if run(sc, s + PAIR, b_dir, args) is not None:
                    c = compare_results(a_dir, b_dir)
                    same.append(c["decision"]["consistent"])
                    line += (f"; compare same robot: {'consistent' if same[-1] else 'DIFFER'} (chi2 p "
                             f"{c['parameters']['chi2_p']:.3g}, min Bonferroni p "
                             f"{c['parameters']['min_p_bonferroni']:.3g})")
                    js = joints or joint_offsets(a_dir, b_dir)
                    for j in js:
                        jd = tmp / f"{name}_{s + PAIR}_{j}"
                        if run(with_offset(sc, j, np.radians(args.offset_deg)), s + PAIR, jd, args) is None:
                            continue
                        c = compare_results(a_dir, jd)
                        flagged = not c["decision"]["consistent"]
                        changed.setdefault(j, []).append(flagged)
                        named = j in c["decision"]["moved"] or any(
                            j in r.get("or", []) for r in c["parameters"]["compared"] if r["moved"])
                        line += f"; {j} +{args.offset_deg:g} deg: {'flagged' if flagged else 'missed'}" + \
                                (" (named)" if named else "")
                    if args.other_truth:
                        od = tmp / f"{name}_{s + PAIR}_other"
                        sco = replace(sc, truth=replace(sc.truth, seed=sc.truth.seed + 1))
                        if run(sco, s + PAIR, od, args) is not None:
                            other.append(not compare_results(a_dir, od)["decision"]["consistent"])
                            line += f"; another true robot: {'flagged' if other[-1] else 'MISSED'}"
            print(line, flush=True)
        if hits:
            print(f"== {name}: coverage of r95 over {len(hits)} seeds ({n_pts} points): position "
                  f"{100 * np.mean(hits):.1f} % (per seed {100 * min(hits):.1f}-{100 * max(hits):.1f} %), rotation "
                  f"{100 * np.mean(hits_r):.1f} %; mean z^2/3 {np.mean(z2):.2f}", flush=True)
            pooled = pooled_coverage_law(laws, np.random.default_rng(0))
            obs = float(np.mean(hits))
            print(f"== {name}: a correct map pooled over these {len(hits)} seeds: mean {100 * pooled.mean():.1f} %, "
                  f"5-95 % {100 * np.percentile(pooled, 5):.1f}-{100 * np.percentile(pooled, 95):.1f} %; "
                  f"P(pooled >= observed {100 * obs:.1f} %) {np.mean(pooled >= obs - 1e-12):.2f}; P(in the 90-98 % "
                  f"band) {np.mean((pooled >= 0.9) & (pooled <= 0.98)):.2f}", flush=True)
        if same:
            print(f"== {name}: compare, same truth: consistent in {sum(same)} of {len(same)} pairs "
                  f"({100 * np.mean(same):.0f} %)", flush=True)
        for j, v in changed.items():
            print(f"== {name}: compare, {j} moved by {args.offset_deg:g} deg: flagged in {sum(v)} of {len(v)} "
                  f"({100 * np.mean(v):.0f} %)", flush=True)
        if changed:
            allv = [f for v in changed.values() for f in v]
            print(f"== {name}: compare, one joint offset moved by {args.offset_deg:g} deg: flagged in {sum(allv)} of "
                  f"{len(allv)} ({100 * np.mean(allv):.0f} %)", flush=True)
        if other:
            print(f"== {name}: compare, another true robot: flagged in {sum(other)} of {len(other)}", flush=True)
        print(f"== {name}: {time.perf_counter() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    main()
