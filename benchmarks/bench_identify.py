"""Identification speed: analytic Jacobian vs scipy least_squares with 2-point finite
differences on the same residuals, measured in the same run; and 100 Monte Carlo
identifications of the H4 model.

    .venv/bin/python benchmarks/bench_identify.py [--repeats 20]

Prints one table; targets: >= 5x faster than the finite-difference baseline, 100 H4 Monte Carlo
identifications in < 2 s on a 2-core machine.
"""

from __future__ import annotations

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import argparse
import time

import numpy as np

from vision_calib.rig import load_scene, scene_poses
from vision_calib.experiment.steps import analyze_setup, rngs, scene_truth
from vision_calib.identify import solve_lse, solve_lse_fd


def _problem(scene_path, n_poses, seed=0):
    scene = load_scene(scene_path)
    setup = scene.setup
    rp, rn, _ = rngs(seed)
    poses = scene_poses(scene, rp, n_poses)
    rep, _ = analyze_setup(scene.setup, poses)
    x_true = scene_truth(scene)
    params = setup.params.only_free(rep.base_parameters)
    meas = setup.synthetic_measurements(poses, x_true, rn, scene.measurement.sigma_t_m, scene.measurement.sigma_r_rad)
    return scene, setup.problem(meas, params=params), poses, x_true, params


def _time(fn, repeats):
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts)), res


def bench_analytic_vs_fd(scene_path, n_poses, repeats):
    scene, problem, *_ = _problem(scene_path, n_poses)
    t_an, r_an = _time(lambda: solve_lse(problem, fix_unidentifiable=False), repeats)
    t_fd, r_fd = _time(lambda: solve_lse_fd(problem, fix_unidentifiable=False), max(3, repeats // 4))
    free = r_an.free
    dx = np.max(np.abs(r_an.identified[free] - r_fd.identified[free]) / r_an.std[free])
    return {"scene": scene.name, "poses": n_poses, "params": int(free.sum()), "analytic_ms": t_an * 1e3,
            "fd_ms": t_fd * 1e3, "speedup": t_fd / t_an, "max_diff_in_std": float(dx),
            "iters_analytic": r_an.iterations, "iters_fd": r_fd.iterations}


def bench_monte_carlo(scene_path, n_poses=71, runs=100):
    scene, _, poses, x_true, params = _problem(scene_path, n_poses)
    setup = scene.setup
    rng = np.random.default_rng(123)
    st, sr = scene.measurement.sigma_t_m, scene.measurement.sigma_r_rad
    t0 = time.perf_counter()
    n_conv = 0
    for _ in range(runs):
        meas = setup.synthetic_measurements(poses, x_true, rng, st, sr)
        res = solve_lse(setup.problem(meas, params=params), fix_unidentifiable=False)
        n_conv += bool(res.converged)
    total = time.perf_counter() - t0
    return {"scene": scene.name, "runs": runs, "poses": n_poses, "total_s": total, "per_run_ms": total / runs * 1e3,
            "converged": n_conv}


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=20)
    args = ap.parse_args(argv)
    rows = [bench_analytic_vs_fd("scenes/h4_vision.yaml", 71, args.repeats),
            bench_analytic_vs_fd("scenes/rx90_eye_in_hand.yaml", 50, args.repeats)]
    print("identification time, analytic Jacobian vs 2-point finite differences (median, same run)")
    print(f"{'scene':<22}{'poses':>6}{'params':>7}{'analytic ms':>13}{'FD ms':>10}{'speed-up':>10}{'max |diff|/std':>16}")
    for r in rows:
        print(f"{r['scene']:<22}{r['poses']:>6}{r['params']:>7}{r['analytic_ms']:>13.2f}{r['fd_ms']:>10.2f}"
              f"{r['speedup']:>9.1f}x{r['max_diff_in_std']:>16.2e}")
    mc = bench_monte_carlo("scenes/h4_vision.yaml")
    print(f"\nMonte Carlo: {mc['runs']} identifications of {mc['scene']} (model 12, {mc['poses']} poses, new noise each): "
          f"{mc['total_s']:.3f} s total, {mc['per_run_ms']:.2f} ms each, {mc['converged']}/{mc['runs']} converged "
          f"(target < 2 s)")


if __name__ == "__main__":
    main()
