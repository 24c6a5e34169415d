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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1-20")
    ap.add_argument("--pairs", type=int, default=42)
    ap.add_argument("--mount", default="fixed", choices=("fixed", "eye_in_hand"))
    args = ap.parse_args()
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
