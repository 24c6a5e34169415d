"""Compensate at scale (issue 33): the shipped example recording (RX-90, camera over a board under the base axis:
every pose near the q1 / q6 singularity) processed, then its 12 joint sets jittered (+-20 deg, seed 0) into N rows
and compensated row by row (``CalibratedRobot.compensate_rows``: damped Gauss-Newton with the geometric joint
Jacobian, chunks of ``deploy.robot.CHUNK_ROWS`` rows). Prints the time and the process's peak resident memory
(an upper bound of what compensate holds) for N rows, the statuses, the largest correction of a corrected row, and
the baseline measured in the same run: the previous compensate (exact Levenberg-Marquardt with central-difference
Jacobians on the whole table at once) on the first ``--baseline-rows`` rows, its time per row and the ratio.
Then inverse (no start: from the nominal model's solution) of the tool poses of ``--inverse-rows`` of those joint
sets (of status ``corrected``: away from the singularities): time, peak RSS, and how many come back as the joint
sets they were made from.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_deploy_scale.py [--rows 100000] [--baseline-rows 10000]
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import numpy as np

from vision_calib.deploy import CalibratedRobot
from vision_calib.deploy.solve import levenberg_marquardt
from vision_calib.experiment.process import process_folder
from vision_calib.io.recording import read_recording
from vision_calib.shipped import examples_dir


def _peak_rss_mb() -> float:
    """The process's peak resident memory so far [MB] (Linux: ru_maxrss in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", type=int, default=100_000)
    ap.add_argument("--baseline-rows", type=int, default=10_000)
    ap.add_argument("--inverse-rows", type=int, default=20_000)
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
        t0 = time.perf_counter()
        c = r.compensate_rows(q)
        t_new = time.perf_counter() - t0
        rss = _peak_rss_mb()
        st, n = np.unique(c.status, return_counts=True)
        ok = c.corrected
        dq = np.degrees(np.abs(c.q_corrected[ok] - q[ok]).max(axis=1))
        print(f"compensate {args.rows} rows: {t_new:.1f} s ({t_new / args.rows * 1e6:.0f} us/row); process peak RSS "
              f"{rss:.0f} MB after it ({rss0:.0f} MB before: the processing of the example)")
        print("  statuses: " + ", ".join(f"{s} {k}" for s, k in zip(st, n)))
        print(f"  largest correction of a corrected row {dq.max():.3f} deg; near a singularity: median amplification "
              f"{np.median(c.amplification[c.status == 'near_singularity']):.2f} deg/mm")

        nb = min(args.baseline_rows, args.rows)
        inside = np.flatnonzero(c.status != "outside_limits")[:nb]
        T = r.kin.tool(q[inside], r.x_nominal)
        t0 = time.perf_counter()  # the previous compensate: kin.inverse from q, i.e. this (central differences)
        _, _, ok = levenberg_marquardt(lambda qq: r.kin.tool(qq, r.x), T, q[inside], r.kin.joint_limits)
        base_note = "" if ok.all() else f" ({int((~ok).sum())} rows not reached: it failed the whole table)"
        t_old = time.perf_counter() - t0
        print(f"baseline: previous exact compensate of {len(inside)} rows (inside the limits): {t_old:.1f} s "
              f"({t_old / len(inside) * 1e6:.0f} us/row){base_note}; per-row ratio previous / new "
              f"{(t_old / len(inside)) / (t_new / args.rows):.2f}")

        well = np.flatnonzero(c.status == "corrected")  # away from the singularities (where Newton may stall)
        ni = min(args.inverse_rows, well.size)
        qi = q[well[:ni]]
        T = r.forward(qi)[0]
        t0 = time.perf_counter()
        q_inv = r.inverse(T)
        t_inv = time.perf_counter() - t0
        same = np.abs(np.angle(np.exp(1j * (q_inv - qi)))).max(axis=1) < 1e-6
        print(f"inverse {ni} rows: {t_inv:.1f} s ({t_inv / ni * 1e6:.0f} us/row); process peak RSS "
              f"{_peak_rss_mb():.0f} MB after it; {int(same.sum())} rows returned the joint set they were made from "
              "(the others another branch; --near keeps it)")


if __name__ == "__main__":
    main()
