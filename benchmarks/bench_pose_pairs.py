"""Pose pairs without images (issue 27, deliverable 3): our hand-eye fit of a pose-pair file (the measured poses'
std per axis estimated, the robot's pose error in the weights: ``process-poses`` on a ``flange_poses`` file)
against a plain least-squares refinement of the best OpenCV closed form, on simulated AR-tag pairs
(``experiment.handeye_sim.simulate_pose_pairs``: a tag on the arm tip, a fixed camera, tag noise 0.5 / 0.5 / 3 mm
and 1 / 1 / 0.1 deg per axis of the tag frame, robot 0.1 mm / 0.01 deg per axis).

Consistency: the loop residual |T_base_ee X - Z T_cam_marker| per pair (X = T_flange_target, Z = T_base_cam),
translation norm [mm] and rotation angle [deg], RMS over the pairs: in-sample (the 42 fitted pairs: what a plain
least squares minimises) and on 500 fresh pairs of the same cell (held out); and the error of X and Z against the
truth. Plain LS: ``identify.handeye_problem.solve_handeye`` with equal weights, started from the OpenCV closed form
of least cost under the same weights; two weightings: 1 m : 1 rad and 1 mm : 0.1 deg. Mean over the seeds.

    PYTHONPATH=. python benchmarks/bench_pose_pairs.py [--seeds 1-20] [--pairs 42] [--mount fixed]
    PYTHONPATH=. python benchmarks/bench_pose_pairs.py --scale 200 2000

``--scale N1 N2 ..`` (issue 35: pose pairs in O(N)): a pose-pair file of N simulated pairs through
``vision-calib process-poses --no-plots``, each in a fresh interpreter, with the noise estimated (the robust
chi-square outlier test), then given (sigma columns: the deletion test of every pose, ``handeye_step.deletion_test``): wall and CPU seconds, peak memory (max RSS),
the seconds and memory per pair against the smallest N's in this run (a ratio near 1: linear). Targets: 2,000 pairs
in <= 30 s and <= 1 GB. Then ``import-pairs``: a TransformPairs file of the largest N x 100 pairs read streamed
(``io.transform_pairs.read_transform_pairs``) against the YAML composer on its first 5,000 pairs, in this run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from vision_calib import frames
from vision_calib.experiment.handeye_sim import simulate_pose_pairs
from vision_calib.experiment.handeye_step import identify_handeye
from vision_calib.identify.handeye_problem import mount_G, solve_handeye
from vision_calib.measure.handeye import closed_forms


def seeds(text: str) -> list[int]:
    a, _, b = text.partition("-")
    return list(range(int(a), int(b) + 1)) if b else [int(v) for v in text.split(",")]


def consistency(A, B, F, M, mount) -> tuple[float, float]:
    """(RMS translation [mm], RMS rotation [deg]) of the loop residual over the pairs (norms are frame-free)."""
    r = frames.pose_error(A @ mount_G(F, mount) @ B, M)
    return (1e3 * float(np.sqrt(np.mean(np.sum(r[:, :3] ** 2, axis=1)))),
            float(np.degrees(np.sqrt(np.mean(np.sum(r[:, 3:] ** 2, axis=1))))))


def plain_ls(F, M, mount, wt, wr):
    """(A, B, start method): equal-weight least squares from the closed form of least cost under those weights."""
    cf = {k: v for k, v in closed_forms(F, M, mount).items() if not isinstance(v, str)}

    def cost(v):
        r = frames.pose_error(v[0] @ mount_G(F, mount) @ v[1], M)
        return float(np.sum((r[:, :3] / wt) ** 2) + np.sum((r[:, 3:] / wr) ** 2))

    best = min(cf, key=lambda m: cost(cf[m]))
    _, A, B, _ = solve_handeye(F, M, mount, sigma_t_m=wt, sigma_rot_rad=wr, A0=cf[best][0], B0=cf[best][1])
    return A, B, best


#: a child interpreter running the CLI with its arguments, then printing its own peak memory (kB) to stderr
_CHILD = ("import resource, sys\nfrom vision_calib.cli import main\ntry:\n    main(sys.argv[1:])\nfinally:\n"
          "    print('MAXRSS', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)")


def scale(sizes, mount: str) -> None:
    """The ``--scale`` figures (module docstring)."""
    import os
    import resource
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    from vision_calib.io.measured_poses_writer import write_pose_pairs

    print(f"process-poses --no-plots, mount {mount}; load average {os.getloadavg()[0]:.2f} "
          "(2 cores shared: wall moves with it, CPU less)")
    print(f"{'noise':>10}{'pairs':>7}{'wall s':>9}{'CPU s':>8}{'max RSS MB':>12}{'CPU ms/pair':>13}{'x smallest':>11}"
          f"{'RSS ratio':>10}")
    with tempfile.TemporaryDirectory() as tmp:
        # estimated: the robust chi-square outlier test; given (sigma columns): the deletion test of each pose
        for noise in ("estimated", "given"):
            first = None
            for n in sizes:
                d = simulate_pose_pairs(n, 4, mount)
                sig = np.sqrt(np.einsum("nii->ni", d.pose_cov)) if noise == "given" else None
                path = write_pose_pairs(Path(tmp) / f"pairs{n}{noise}.yaml", d.labels, d.T_base_flange, d.T_cam_target,
                                        d.mount, sigmas=sig)
                before = resource.getrusage(resource.RUSAGE_CHILDREN)
                t0 = time.perf_counter()
                run = subprocess.run([sys.executable, "-c", _CHILD, "process-poses", str(path), "--out",
                                      str(Path(tmp) / f"out{n}{noise}"), "--no-plots"], check=True, capture_output=True,
                                     text=True)
                wall = time.perf_counter() - t0
                after = resource.getrusage(resource.RUSAGE_CHILDREN)
                cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
                rss = int(run.stderr.rsplit("MAXRSS", 1)[1].split()[0]) / 1024  # this child's peak, kB -> MB (Linux)
                first = first or (cpu / n, rss)
                print(f"{noise:>10}{n:>7}{wall:>9.2f}{cpu:>8.2f}{rss:>12.0f}{1e3 * cpu / n:>13.2f}"
                      f"{cpu / n / first[0]:>10.2f}x{rss / first[1]:>9.2f}x")
        import vision_calib.io.transform_pairs as TP

        big, small = 100 * max(sizes), 5000
        rng = np.random.default_rng(0)
        T = frames.T_from_xyz_rotvec(rng.normal(size=(big, 6)))
        for n in (small, big):
            TP.write_transform_pairs(Path(tmp) / f"tp{n}.yml", T[:n], T[::-1][:n])
        t0 = time.perf_counter()
        TP.read_transform_pairs(Path(tmp) / f"tp{big}.yml")
        t_big = time.perf_counter() - t0
        t0 = time.perf_counter()
        TP.read_transform_pairs(Path(tmp) / f"tp{small}.yml")
        t_fast = time.perf_counter() - t0
        streamed, TP._streamed_pairs = TP._streamed_pairs, lambda *a, **k: None
        try:
            t0 = time.perf_counter()
            TP.read_transform_pairs(Path(tmp) / f"tp{small}.yml")
            t_yaml = time.perf_counter() - t0
        finally:
            TP._streamed_pairs = streamed
        print(f"TransformPairs read: {big} pairs streamed {t_big:.2f} s; {small} pairs streamed {t_fast:.2f} s vs "
              f"YAML composer {t_yaml:.2f} s ({t_yaml / t_fast:.1f}x)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1-20")
    ap.add_argument("--pairs", type=int, default=42)
    ap.add_argument("--mount", default="fixed", choices=("fixed", "eye_in_hand"))
    ap.add_argument("--scale", type=int, nargs="*", help="pose-pair counts through process-poses (time, memory)")
    args = ap.parse_args()
    if args.scale:
        scale(args.scale, args.mount)
        return
    names = ("ours", "LS 1 m : 1 rad", "LS 1 mm : 0.1 deg")
    rows, t_ours = {k: [] for k in names}, []
    for seed in seeds(args.seeds):
        d = simulate_pose_pairs(args.pairs, seed, args.mount)
        test = simulate_pose_pairs(500, 10_000 + seed, args.mount)  # the same cell (mounts), fresh pairs
        t = time.perf_counter()
        ident = identify_handeye(d.T_base_flange, d.T_cam_target, args.mount, None, d.labels, noise_frame="target")
        t_ours.append(time.perf_counter() - t)
        fits = {"ours": (ident.A, ident.B), "LS 1 m : 1 rad": plain_ls(d.T_base_flange, d.T_cam_target, args.mount,
                                                                        1.0, 1.0)[:2],
                "LS 1 mm : 0.1 deg": plain_ls(d.T_base_flange, d.T_cam_target, args.mount, 1e-3, np.radians(0.1))[:2]}
        for k, (A, B) in fits.items():
            eA, eB = frames.pose_error(d.A_true, A), frames.pose_error(d.B_true, B)
            rows[k].append([*consistency(A, B, d.T_base_flange, d.T_cam_target, args.mount),
                            *consistency(A, B, test.T_base_flange, test.T_cam_target, args.mount),
                            1e3 * np.linalg.norm(eA[:3]), np.degrees(np.linalg.norm(eA[3:])),
                            1e3 * np.linalg.norm(eB[:3]), np.degrees(np.linalg.norm(eB[3:]))])
    n = len(seeds(args.seeds))
    a_name, b_name = ("T_cam_base", "T_flange_target") if args.mount == "fixed" else ("T_cam_flange", "T_base_target")
    print(f"{args.pairs} pose pairs, mount {args.mount}, {n} seeds (means); ours {np.mean(t_ours):.2f} s per fit")
    print(f"{'':20s} {'in-sample mm':>12s} {'deg':>7s} {'held-out mm':>12s} {'deg':>7s}   "
          f"{'err ' + a_name + ' mm':>20s} {'deg':>7s} {'err ' + b_name + ' mm':>24s} {'deg':>7s}")
    for k in names:
        m = np.mean(rows[k], axis=0)
        print(f"{k:20s} {m[0]:12.4f} {m[1]:7.4f} {m[2]:12.4f} {m[3]:7.4f}   {m[4]:20.4f} {m[5]:7.4f} {m[6]:24.4f} "
              f"{m[7]:7.4f}")
    ours = np.array(rows["ours"])
    for k in names[1:]:
        o = np.array(rows[k])
        print(f"ours no worse than {k}: in-sample translation on {np.sum(ours[:, 0] <= o[:, 0])}/{n} seeds, rotation "
              f"{np.sum(ours[:, 1] <= o[:, 1])}/{n}; held-out translation {np.sum(ours[:, 2] <= o[:, 2])}/{n}, "
              "rotation "
              f"{np.sum(ours[:, 3] <= o[:, 3])}/{n}")


if __name__ == "__main__":
    main()
