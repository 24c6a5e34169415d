"""Speed of the planner's screening (issue 27: 100 000 candidates screened for visibility and collisions in under a
minute on 2 cores): candidates per second through each stage on the UR5e cell (scenes/ur5e_cell.yaml: a table, a
fixture, a lamp post, the board), and the broad phase's gain over FCL on every pair, measured in the same run.

Stages: draw the candidates in the scene's pose region, reachability (joint limits), the camera's view of the board
(vectorised forward kinematics + projection), the collision screen of the measurable ones (numpy broad phase on
capsule hulls, FCL for the undecided pairs). A second pass screens the same number of candidates drawn in the whole
joint range for collisions only (every candidate checked: the collision screen's own rate), and the baseline runs
FCL on every checked pair of a subset (what the broad phase saves).

    PYTHONPATH=. python benchmarks/bench_plan.py [--candidates 100000] [--baseline 2000] [--scene ur5e_cell.yaml]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from vision_calib.planning.plan import CandidateSource, candidate_poses, collision_setup, screen
from vision_calib.rig import SCENES_DIR, load_scene


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--candidates", type=int, default=100_000)
    ap.add_argument("--baseline", type=int, default=2000, help="candidates of the all-pairs FCL baseline")
    ap.add_argument("--scene", default="ur5e_cell.yaml")
    args = ap.parse_args()
    scene = load_scene(SCENES_DIR / args.scene)
    setup = scene.setup
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    model, checker = collision_setup(scene)
    t_model = time.perf_counter() - t0
    t = time.perf_counter()
    cand = candidate_poses(scene, CandidateSource(), args.candidates, rng)
    t_draw = time.perf_counter() - t
    res = screen(scene, cand, checker)
    c = res["counts"]
    total = t_draw + res["seconds"]
    print(f"{args.scene}: {len(model.bodies)} bodies, {len(model.obstacles)} obstacles, "
          f"{len(model.obstacle_pairs)} body-obstacle + {len(model.self_pairs)} link pairs; model built in {t_model:.2f} s")
    print(f"region: {c['candidates']} candidates drawn in {t_draw:.2f} s, screened in {res['seconds']:.2f} s "
          f"-> {c['candidates'] / total:.0f} candidates/s (draw + screen; target: 100000 in < 60 s = 1667/s)")
    print(f"  {c['unreachable']} unreachable, {c['not_measurable']} board not measurable "
          f"{c['not_measurable_by_reason']}, {c['colliding']} colliding, {c['kept']} kept; "
          f"{res['fcl_queries']} FCL queries")
    # collisions only, every candidate checked (the whole joint range: many collide)
    q = setup.generic_poses(np.random.default_rng(1), args.candidates)
    t = time.perf_counter()
    n_fcl0 = checker.n_fcl
    ok = np.zeros(len(q), bool)
    for s in range(0, len(q), 20000):
        F = setup.link_frames(q[s:s + 20000])
        ok[s:s + 20000] = checker.screen(F)[0]
    t_col = time.perf_counter() - t
    print(f"collisions only, whole joint range: {len(q)} candidates in {t_col:.2f} s -> {len(q) / t_col:.0f}/s "
          f"({(~ok).sum()} colliding, {checker.n_fcl - n_fcl0} FCL queries)")
    # baseline: FCL on every checked pair
    nb = min(args.baseline, len(q))
    F = setup.link_frames(q[:nb])
    t = time.perf_counter()
    exact = np.array([r["clearance_m"] for r in checker.clearances(F)])
    t_base = time.perf_counter() - t
    t = time.perf_counter()
    ok_b = checker.screen(F)[0]
    t_scr = time.perf_counter() - t
    agree = np.mean(ok_b == (exact >= scene.planning.clearance_m - 1e-9))
    print(f"baseline, FCL on all {len(model.obstacle_pairs) + len(model.self_pairs)} pairs: {nb / t_base:.0f}/s; "
          f"broad phase + FCL: {nb / t_scr:.0f}/s ({t_base / t_scr:.1f}x); decisions agree on {100 * agree:.1f} %")


if __name__ == "__main__":
    main()
