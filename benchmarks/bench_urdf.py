"""Identifiability of the shipped UR5e URDF chain (per-joint placement model, 7 n + 12 = 54 parameters)
with base + tool mounts over 50 random joint sets: base-parameter count and condition number of the
base set (whitened by 1 mm / 1 mrad, columns scaled by 1 mm / 1 mrad, ``analyze(selection="order")``),
for full-pose and position-only residuals; the same for the UR5e in modified DH + Hayati (beta3,
beta4 for the parallel axes 2-3-4) as a cross-check of the counts; and the time of one pose
Jacobian over the 50 poses.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_urdf.py
"""

from __future__ import annotations

import time

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import numpy as np

from vision_calib.rig import SCENES_DIR
from vision_calib.frames import T_from_xyz_rpy
from vision_calib.identify import analyze
from vision_calib.identify.serial_problem import serial_problem
from vision_calib.kinematics.serial import SerialChain
from vision_calib.kinematics.urdf import load_urdf_robot

N_POSES = 50
SEED = 0


def _mounts():
    """A generic table-to-base and flange-to-camera placement (m, rad), not aligned with any axis."""
    return (T_from_xyz_rpy([0.4, -0.2, 0.05], [0.1, -0.05, 0.3]),
            T_from_xyz_rpy([0.03, 0.01, 0.08], [0.2, 0.1, -0.15]))


def _ur5e_mdh(TL, TR):
    """UR5e in modified DH (rows alpha, a, theta, d; from the published standard DH table)."""
    dh = [[0, 0, 0, 0.1625], [np.pi / 2, 0, 0, 0], [0, -0.425, 0, 0], [0, -0.3922, 0, 0.1333],
          [np.pi / 2, 0, 0, 0.0997], [-np.pi / 2, 0, 0, 0.0996]]
    return SerialChain.build("ur5e_mdh", dh, hayati=(3, 4), left="T_target_base", right="T_flange_cam",
                             T_left_base=TL, T_flange_right=TR)


def main():
    TL, TR = _mounts()
    urdf = load_urdf_robot(SCENES_DIR / "robots" / "ur5e.urdf", "base_link", "tool0", left="T_target_base",
                           right="T_flange_cam", T_left_base=TL, T_flange_right=TR)
    q = np.random.default_rng(SEED).uniform(-np.pi, np.pi, (N_POSES, 6))
    for label, ch in (("URDF per-joint model", urdf), ("MDH + Hayati model  ", _ur5e_mdh(TL, TR))):
        T = ch.forward(q)
        for res in ("pose", "position"):
            rep = analyze(serial_problem(ch, q, T, residual=res), selection="order")
            print(f"UR5e {label}, {N_POSES} random poses, {res:8s} residuals: {rep.n_params} parameters, "
                  f"{len(rep.base_parameters)} base parameters, condition number {rep.condition_number:.4g}")
    rep = analyze(serial_problem(urdf, q, urdf.forward(q)), selection="order")
    print("URDF model, full pose, dropped:", ", ".join(rep.non_identifiable))
    reps = 20
    t0 = time.perf_counter()
    for _ in range(reps):
        urdf.pose_jacobian(q)
    print(f"pose_jacobian of {N_POSES} poses x {len(urdf.params)} parameters: "
          f"{(time.perf_counter() - t0) / reps * 1e3:.2f} ms")


if __name__ == "__main__":
    main()
