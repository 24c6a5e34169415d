"""Identifiability figures of the shipped setups (what the seeds report, recomputed by our analysis):

- RX-90 with base + flange-side transforms: rank with full-pose and position-only residuals;
- the thesis' chapter-3 setup (flange position only, parameters l5, a, theta, d): a6 not identifiable;
- H4 model 12 + external parameters (paper: 19 of 20) and model 31 + externals (paper: 36);
- H4 condition numbers of the geometric parameters over 100 random poses (paper table 1: 257 for
  model 12, 421 for model 31 without d, 1900 with d), columns scaled to unit norm.

    .venv/bin/python benchmarks/bench_identifiability.py
"""

from __future__ import annotations

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import numpy as np

from vision_calib.rig import SCENES_DIR, load_scene
from vision_calib.study import scene_with
from vision_calib.experiment.steps import analyze_setup, rngs
from vision_calib.experiment.synthetic import identifiability_json
from vision_calib.rig import scene_poses
from vision_calib.identify import analyze
from vision_calib.identify.serial_problem import serial_problem
from vision_calib.kinematics.h4 import random_workspace_poses
from vision_calib.kinematics.serial import load_serial_robot


def _line(label, out):
    print(f"{label}: {out['n_params']} parameters, rank {out['rank']}, cond {out['condition_number']:.4g}; "
          f"not identifiable: {', '.join(out['non_identifiable']) or 'none'}")


def serial_figures():
    for res in ("pose", "position"):
        _line(f"RX-90 eye-in-hand, {res} residuals (all parameters)",
              identifiability_json(SCENES_DIR / "rx90_eye_in_hand.yaml", residual=res, all_params=True))
    arm = load_serial_robot(SCENES_DIR / "robots" / "thesis_arm.yaml")
    names = ["l5"] + [f"{p}{i}" for p in ("a", "theta", "d") for i in range(1, 7)]
    for label, q in (("50 random joint sets", np.random.default_rng(2).uniform(-np.pi, np.pi, (50, 6))),
                     ("the thesis' 7 configurations", arm.meta["configurations"]["six_plus_one"]["q"])):
        T = arm.forward(q)
        problem = serial_problem(arm, q, T, residual="position", sigma_t_m=1e-3)
        # the thesis' parameter list keeps d2 and d3 both (redundant): the analysis must find it
        rep = analyze(problem.with_params(problem.params.only_free(names)), selection="order")
        print(f"thesis arm, chapter 3, flange position, {label}: {rep.n_params} parameters, rank {rep.rank}; "
              f"not identifiable: {', '.join(rep.non_identifiable)}")
        for c in rep.couplings:
            print(f"    {c['parameter']} ~ " + (" ".join(f"{v:+.3g}*{k}" for k, v in c["combination_si"].items())
                                              or "(no effect on the measurements)"))


def h4_figures():
    scene = load_scene(SCENES_DIR / "h4_vision.yaml")
    _line("H4 model 12 + 8 external parameters", identifiability_json(scene, all_params=True))
    s31 = scene_with(scene, model="31")
    rp, _, _ = rngs(0)
    rep, _ = analyze_setup(s31.setup, scene_poses(s31, rp), all_params=True)
    print(f"H4 model 31 + 8 external parameters: {rep.n_params} parameters, rank {rep.rank}; not identifiable: "
          f"{', '.join(rep.non_identifiable)}")
    for c in rep.couplings:
        print(f"    {c['parameter']} ~ " + " ".join(f"{v:+.3g}*{k}" for k, v in c["combination_si"].items()))
    X = random_workspace_poses(100, np.random.default_rng(1))
    r12, r31 = scene.setup.robot, s31.setup.robot
    rows = (("model 12", r12, list(r12.names[:12]), 257),
            ("model 31 without d", r31, [n for n in r31.names[:31] if n != "h4.d"], 421),
            ("model 31 with d", r31, list(r31.names[:31]), 1900))
    print("H4 condition numbers, geometric parameters, nacelle pose known, 100 random poses, unit-norm columns:")
    for label, robot, names, paper in rows:
        J = robot.igm_jacobian_params(X)[..., robot.params.indices(names)].reshape(-1, len(names))
        s = np.linalg.svd(J / np.linalg.norm(J, axis=0), compute_uv=False)
        print(f"    {label:<20} ({len(names)} parameters): cond {s[0] / s[-1]:8.0f}   (paper {paper})")


if __name__ == "__main__":
    serial_figures()
    h4_figures()
