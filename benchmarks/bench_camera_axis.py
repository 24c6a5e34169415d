"""H4 camera-axis step (identify/camera_axis.py, paper §4.1) on many random poses: time and peak memory.

1. ``estimate_camera_axis`` on N random H4 workspace poses (truth with a 0.5 deg camera tilt and a 0.3 deg
   target tilt, pose noise 0.2 mm / 0.03 deg, rotation noise estimated from the residuals as in
   ``H4Setup.prepare``): best-of-repeats wall time, and the tracemalloc peak of a separate call (numpy array
   allocations; LAPACK's own workspace is not counted).
2. Baseline in the same run: the dense Gauss-Newton it replaces (one unknown per pose, lstsq on the
   whitened (3N, 4 + N) system; the reference kept in tests/identify/test_camera_axis.py) on the first
   --dense-n poses of the same data, with the largest difference of the results.
3. The whole synthetic H4 identification (``run_synthetic``, scenes/h4_vision.yaml with random poses,
   prepare included: camera axis, tilt parameters, IGM fit), and the axis step's share of it.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=. .venv/bin/python benchmarks/bench_camera_axis.py \
        [--sizes 1000 2000 5000 20000] [--dense-n 1000] [--pipeline-n 2000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
import tracemalloc
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from vision_calib.frames import perturb_pose, so3_exp  # noqa: E402
from vision_calib.identify.camera_axis import estimate_camera_axis  # noqa: E402
from vision_calib.kinematics.h4 import random_workspace_poses  # noqa: E402
from vision_calib.kinematics.h4_io import load_h4_robot  # noqa: E402

SIG_T, SIG_R = 2e-4, np.deg2rad(0.03)
TILT_CAM_DEG = [0.4, -0.3]  # truth camera tilt (tilt_cam_rad's convention: R_BC0 = R_BC0_nominal so3_exp(w))


def _dense_reference():
    spec = importlib.util.spec_from_file_location("_ref", ROOT / "tests" / "identify" / "test_camera_axis.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.dense_camera_axis


def measured_poses(robot, n, seed=0):
    """n noisy measured T_cam_target (n, 4, 4) of a truth with tilted camera and target mounts, drawn in
    blocks of 1000 poses (one seeded stream per block): the first m poses are the same for any n >= m."""
    truth = replace(robot, R_BC0=robot.R_BC0 @ so3_exp(np.deg2rad(TILT_CAM_DEG + [0.0])),
                    R_ME0=so3_exp(np.deg2rad([0.18, 0.24, 0.0])) @ robot.R_ME0)
    out = []
    for i in range(0, n, 1000):
        m, rng = min(1000, n - i), np.random.default_rng([seed, i])
        T = truth.camera_measurement(random_workspace_poses(m, rng))
        out.append(perturb_pose(T, np.concatenate([rng.normal(0, SIG_T, (m, 3)), rng.normal(0, SIG_R, (m, 3))], 1)))
    return np.concatenate(out)


def timed(fn, repeats):
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return out, best, peak / 2**20


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 2000, 5000, 20000])
    ap.add_argument("--dense-n", type=int, default=1000, help="poses for the dense baseline (0: skip)")
    ap.add_argument("--pipeline-n", type=int, default=2000, help="poses for the whole identification (0: skip)")
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    robot = load_h4_robot(ROOT / "scenes" / "robots" / "h4.yaml")
    T_all = measured_poses(robot, max(a.sizes + [a.dense_n, 2]))

    def axis(T):
        return lambda: estimate_camera_axis(T, R_BC0=robot.R_BC0, R_ME0=robot.R_ME0)

    print("estimate_camera_axis (Schur complement, rotation noise estimated), best of", a.repeats)
    print(f"{'N':>7} {'time s':>9} {'peak MiB':>9} {'us/pose':>8}   camera tilt (deg) +- std (truth {TILT_CAM_DEG})")
    times = {}
    for n in a.sizes:
        est, t, mb = timed(axis(T_all[:n]), a.repeats)
        times[n] = t
        print(f"{n:7d} {t:9.4f} {mb:9.1f} {1e6 * t / n:8.1f}   {np.rad2deg(est.tilt_cam_rad).round(4)} "
              f"+- {np.rad2deg(est.tilt_cam_std_rad).round(4)}")

    if a.dense_n:
        n = a.dense_n
        dense = _dense_reference()
        T = T_all[:n]
        ref, t_d, mb_d = timed(lambda: dense(T, None, robot.R_BC0, robot.R_ME0), 1)
        est, t_s, mb_s = timed(axis(T), a.repeats)
        d = max(np.abs(est.z_B_cam - ref["z_B_cam"]).max(), np.abs(est.n_target - ref["n_target"]).max(),
                np.abs(est.theta_rad - ref["theta_rad"]).max())
        dc = max(np.abs(getattr(est, k) - ref[k]).max() / np.abs(ref[k]).max() for k in ("cov_tilt_cam", "cov_tilt_target"))
        print(f"\ndense reference, N = {n}: {t_d:.3f} s, tracemalloc peak {mb_d:.1f} MiB; Schur {t_s:.4f} s, "
              f"{mb_s:.1f} MiB: {t_d / t_s:.0f} x faster; largest difference: axes/theta {d:.1e} rad, "
              f"tilt covariances {dc:.1e} (relative)")

    if a.pipeline_n:
        from vision_calib.experiment.synthetic import run_synthetic
        from vision_calib.kinematics.h4_variants import without_tilt_params
        from vision_calib.rig import load_scene

        sc = load_scene(ROOT / "scenes" / "h4_vision.yaml")
        sc = replace(sc, poses=replace(sc.poses, kind="random"))
        run_synthetic(sc, n_poses=81, seed=0)  # warm-up: first-use imports (scipy.stats, ...) not timed
        t0 = time.perf_counter()
        run = run_synthetic(sc, n_poses=a.pipeline_n, seed=0)
        t_all = time.perf_counter() - t0
        base = without_tilt_params(run.setup.robot)  # the robot H4Setup.prepare gives the axis step
        _, t_ax, _ = timed(lambda: estimate_camera_axis(run.measurements.T_cam_target, R_BC0=base.R_BC0,
                                                        R_ME0=base.R_ME0), a.repeats)
        print(f"\nrun_synthetic h4_vision, {a.pipeline_n} random poses (prepare included): {t_all:.2f} s; "
              f"the axis step on its measurements {t_ax:.4f} s ({100 * t_ax / t_all:.1f} %); "
              f"validation position RMS {1e3 * np.sqrt(np.mean(np.sum(run.after.errors[:, :3] ** 2, 1))):.3f} mm")


if __name__ == "__main__":
    main()
