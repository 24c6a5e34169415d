"""Compensate at scale (issue 33): the shipped example recording (RX-90, camera over a board under the base axis:
every pose near the q1 / q6 singularity) processed, then its 12 joint sets jittered (+-20 deg, seed 0) into N rows
and compensated row by row (``CalibratedRobot.compensate_rows``: damped Gauss-Newton with the geometric joint
Jacobian, chunks of ``deploy.robot.CHUNK_ROWS`` rows). Prints the time and the process's peak resident memory
(an upper bound of what compensate holds) for N rows, the statuses, the largest correction of a corrected row, and
the baseline measured in the same run: the previous compensate (exact Levenberg-Marquardt with central-difference
Jacobians on the whole table at once) on the first ``--baseline-rows`` rows, its time per row and the ratio.
Then inverse (``CalibratedRobot.inverse_rows``, no start: from the nominal model's solution; ``deploy.kinematics.
BatchedArm``) of the calibrated tool poses of ``--inverse-rows`` of those joint sets (clipped into the joint limits;
near-singular ones included): time, peak RSS, how many are reached and how many come back as the joint sets they were
made from; and the baseline measured in the same run on the first ``--inverse-baseline-rows`` of them: the same
inverse with the chain's own forward kinematics per call (``kinematics.serial``: link constants rebuilt on every
call) and the joint Jacobian from a second pass over its frames, as before BatchedArm.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_deploy_scale.py [--rows 100000] [--baseline-rows 10000]
        [--inverse-rows 100000] [--inverse-baseline-rows 5000]
"""

from __future__ import annotations

import argparse
import dataclasses
import resource
import tempfile
import time
from pathlib import Path

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import numpy as np

from vision_calib.deploy import CalibratedRobot
from vision_calib.deploy.kinematics import ChainKinematics
from vision_calib.deploy.solve import levenberg_marquardt
from vision_calib.experiment.process import process_folder
from vision_calib.io.recording import read_recording
from vision_calib.shipped import examples_dir


def _peak_rss_mb() -> float:
    """The process's peak resident memory so far [MB] (Linux: ru_maxrss in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


class PreviousKinematics(ChainKinematics):
    """ChainKinematics as before BatchedArm (modified-DH arms): the chain's own forward kinematics per call, the
    geometric joint Jacobian from a second pass over the chain's frames (``forward_all``)."""

    def _arms(self, x):
        return super()._arms(x)[0], None

    def joint_jacobian(self, q, x) -> np.ndarray:
        fr = self.arm_at(x).forward_all(q)  # every joint turns about its frame's z axis
        w, lever = fr[:, 1:-1, :3, 2], fr[:, -1, None, :3, 3] - fr[:, 1:-1, :3, 3]
        return np.concatenate([np.swapaxes(np.cross(w, lever), 1, 2), np.swapaxes(w, 1, 2)], axis=1)


def _inverse(r, T) -> tuple:
    """(q, why, wall seconds, CPU seconds of this process, peak RSS MB after) of r.inverse_rows(T)."""
    t0, c0 = time.perf_counter(), time.process_time()
    q, why = r.inverse_rows(T)
    return q, why, time.perf_counter() - t0, time.process_time() - c0, _peak_rss_mb()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", type=int, default=100_000)
    ap.add_argument("--baseline-rows", type=int, default=10_000)
    ap.add_argument("--inverse-rows", type=int, default=100_000)
    ap.add_argument("--inverse-baseline-rows", type=int, default=5_000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = examples_dir() / "rx90_eye_in_hand"
        process_folder(folder, Path(tmp) / "run")
        r = CalibratedRobot.load(Path(tmp) / "run")
        q0 = read_recording(folder).poses
        rng = np.random.default_rng(0)
        q = np.repeat(q0, -(-args.rows // len(q0)), axis=0)[: args.rows]
        q = q + rng.uniform(-1, 1, q.shape) * np.radians(20.0)

        rss0 = _peak_rss_mb()
        t0, c0 = time.perf_counter(), time.process_time()
        c = r.compensate_rows(q)
        t_new, cpu_new = time.perf_counter() - t0, time.process_time() - c0
        rss = _peak_rss_mb()
        st, n = np.unique(c.status, return_counts=True)
        ok = c.corrected
        dq = np.degrees(np.abs(c.q_corrected[ok] - q[ok]).max(axis=1))
        print(f"compensate {args.rows} rows: {t_new:.1f} s wall, {cpu_new:.1f} s CPU ({t_new / args.rows * 1e6:.0f} "
              f"us/row wall); process peak RSS {rss:.0f} MB after it ({rss0:.0f} MB before: the processing of the "
              "example)")
        print("  statuses: " + ", ".join(f"{s} {k}" for s, k in zip(st, n)))
        print(f"  largest correction of a corrected row {dq.max():.3f} deg; near a singularity: median amplification "
              f"{np.median(c.amplification[c.status == 'near_singularity']):.2f} deg/mm")

        nb = min(args.baseline_rows, args.rows)
        inside = np.flatnonzero(c.status != "outside_limits")[:nb]
        T = r.kin.tool(q[inside], r.x_nominal)
        t0 = time.perf_counter()  # the previous compensate: kin.inverse from q, i.e. this (central differences)
        arm = r.kin.arm_at(r.x)  # the chain's own forward kinematics, as the previous compensate used
        _, _, ok = levenberg_marquardt(arm.forward, T, q[inside], r.kin.joint_limits)
        base_note = "" if ok.all() else f" ({int((~ok).sum())} rows not reached: it failed the whole table)"
        t_old = time.perf_counter() - t0
        print(f"baseline: previous exact compensate of {len(inside)} rows (inside the limits): {t_old:.1f} s "
              f"({t_old / len(inside) * 1e6:.0f} us/row){base_note}; per-row ratio previous / new "
              f"{(t_old / len(inside)) / (t_new / args.rows):.2f}")

        lim = r.kin.joint_limits
        qi = np.repeat(q0, -(-args.inverse_rows // len(q0)), axis=0)[: args.inverse_rows]
        qi = np.clip(qi + rng.uniform(-1, 1, qi.shape) * np.radians(20.0), lim[:, 0], lim[:, 1])
        T = r.kin.tool(qi, r.x)  # the calibrated tool poses (without the covariance of forward())
        rss0 = _peak_rss_mb()
        q_inv, why, t_inv, cpu_inv, rss = _inverse(r, T)
        ok = why == ""
        same = ok & (np.abs(np.angle(np.exp(1j * (np.where(ok[:, None], q_inv, 0.0) - qi)))).max(axis=1) < 1e-6)
        print(f"inverse {len(T)} rows: {t_inv:.1f} s wall, {cpu_inv:.1f} s CPU ({t_inv / len(T) * 1e6:.0f} us/row "
              f"wall); process peak RSS {rss:.0f} MB after it ({rss0:.0f} MB before); {int(ok.sum())} reached, "
              f"{int((~ok).sum())} not reached (named); "
              f"{int(same.sum())} returned the joint set they were made from (the others another branch; --near "
              "keeps it)")
        nb = min(args.inverse_baseline_rows, len(T))
        prev = dataclasses.replace(r, kin=PreviousKinematics(r.model.robot, r.tcp))
        qb, why_b, t_b, c_b, _ = _inverse(prev, T[:nb])
        _, _, t_n, c_n, _ = _inverse(r, T[:nb])
        agree = (why_b == "") & ok[:nb] & (np.abs(qb - q_inv[:nb]).max(axis=1) < 1e-9)
        print(f"baseline: inverse as before BatchedArm (the chain's own forward kinematics per call) of the first {nb} "
              f"rows: {t_b:.1f} s wall, {c_b:.1f} s CPU ({c_b / nb * 1e6:.0f} us/row CPU); BatchedArm on the same rows "
              f"{t_n:.1f} s wall, {c_n:.1f} s CPU ({c_n / nb * 1e6:.0f} us/row CPU): ratio (CPU) {c_b / c_n:.2f}; "
              "the same joints (1e-9) on "
              f"{int(agree.sum())} of {nb} rows ({int((why_b != '').sum())} not reached by the baseline, "
              f"{int((~ok[:nb]).sum())} by BatchedArm)")


if __name__ == "__main__":
    main()
