"""Deploying a calibration (issue 26): per shipped scene (RX-90, UR5e, H4), a synthetic calibration (the scene's
poses and noise, ``sim.deploy_truth.calibrate_scene``) loaded as a ``CalibratedRobot``, then over 200 workspace
joint sets (``sim.deploy_truth.workspace_joints``):

- round trips on the model: inverse(forward(q)) from the nominal model's solution, and compensate(q) against the
  nominal model's tool pose, largest translation [m] and rotation [rad] error, and their times;
- the forward covariance: largest difference analytic vs central differences, relative to its largest entry;
- the truth robot: compensated joints through the TRUE robot vs where the nominal model meant them (camera frame),
  RMS translation / rotation, against the predicted RMS (covariance) and the uncompensated error, per seed.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_deploy.py [--seeds 1 2 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import numpy as np

from vision_calib import frames as F
from vision_calib.deploy import CalibratedRobot
from vision_calib.sim.deploy_truth import calibrate_scene, compensation_against_truth, workspace_joints

SCENES = ("rx90_eye_in_hand", "ur5e_eye_in_hand", "h4_vision")


def _worst(Ta, Tb) -> tuple[float, float]:
    e = F.pose_error(Ta, Tb)
    return float(np.linalg.norm(e[:, :3], axis=1).max()), float(np.linalg.norm(e[:, 3:], axis=1).max())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        print("round trips on the model, 200 workspace poses (largest error; time)")
        for name in SCENES:
            run, folder = calibrate_scene(name, Path(tmp) / f"{name}_rt")
            r = CalibratedRobot.load(folder)
            q = workspace_joints(r, run.setup, 200)
            T, C = r.forward(q)
            t0 = time.perf_counter()
            qi = r.inverse(T)
            t_inv = time.perf_counter() - t0
            t0 = time.perf_counter()
            qc = r.compensate(q)
            t_comp = time.perf_counter() - t0
            ei, ec = _worst(T, r.forward(qi)[0]), _worst(r.nominal.forward(q)[0], r.forward(qc)[0])
            Cf = r.forward(q, fd=True)[1]
            print(f"  {name:18s} inverse {ei[0]:.1e} m {ei[1]:.1e} rad ({t_inv:.2f} s); compensate {ec[0]:.1e} m "
                  f"{ec[1]:.1e} rad ({t_comp:.2f} s); covariance analytic vs FD {np.abs(C - Cf).max() / np.abs(C).max():.1e}")
        print("truth robot, 200 workspace poses, camera frame: RMS translation [mm] / rotation [mrad]")
        print(f"  {'scene':18s} seed  compensated    predicted      uncompensated   comp/pred    comp/uncomp")
        for name in SCENES:
            for seed in args.seeds:
                run, folder = calibrate_scene(name, Path(tmp) / f"{name}_{seed}", seed=seed)
                r = CalibratedRobot.load(folder)
                o = compensation_against_truth(run, r, workspace_joints(r, run.setup, 200))
                print(f"  {name:18s} {seed:4d}  {o['compensated_t_m'] * 1e3:.3f} / {o['compensated_r_rad'] * 1e3:.3f}"
                      f"  {o['predicted_t_m'] * 1e3:.3f} / {o['predicted_r_rad'] * 1e3:.3f}"
                      f"  {o['uncompensated_t_m'] * 1e3:.3f} / {o['uncompensated_r_rad'] * 1e3:.3f}"
                      f"   {o['vs_predicted_t']:.2f} / {o['vs_predicted_r']:.2f}"
                      f"   {o['ratio_t']:.3f} / {o['ratio_r']:.3f}")


if __name__ == "__main__":
    main()
