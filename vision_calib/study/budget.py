"""The acquisition budget of a study with a ``target``: per sensor condition (the values of every swept axis but
``frames`` and ``n_poses``), the cheapest acquisition -- fewest images = poses x frames, then fewest poses --
whose 95th percentile of the after-calibration figure meets the target (``budget.csv``, summary lines).

A run that failed counts as missing the target (its figure is +inf): the percentile (numpy's linear interpolation,
as in ``summary.csv`` when no run failed) is +inf when it interpolates toward a failed run."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np

from ..serialize import write_text_atomic
from .spec import StudySpec, format_value, run_seed

#: axes that set the cost of an acquisition; every other axis is a condition the budget is given for
COST_AXES = ("n_poses", "frames")
BUDGET_COLUMNS = ("metric", "target", "reached", "n_poses", "frames", "images", "p50", "p95", "n_runs", "n_failed")


def _defaults(spec: StudySpec) -> dict:
    """n_poses and frames of a run that does not set them: the scene's pose count and frames per pose."""
    from ..experiment.steps import rngs
    from ..rig import scene_poses
    from .cells import scene_for

    s = spec.settings
    scene = scene_for(str(spec.scene_path), s.get("variant"), s.get("model"), spec.hash, s.get("trial"))
    return {"n_poses": len(scene_poses(scene, rngs(run_seed(spec.seed, 0))[0])),
            "frames": int(scene.measurement.frames)}


def percentile_with_failures(v: np.ndarray, q: float) -> float:
    """q-th percentile of ``v`` (numpy's default linear interpolation) where +inf stands for failed runs: +inf when
    it interpolates toward one (the exact order statistic otherwise; numpy itself gives nan there)."""
    v = np.sort(np.asarray(v, float))
    if v.size == 0:
        return math.inf
    pos = q / 100 * (v.size - 1)
    i = int(np.floor(pos))
    t = pos - i
    if t == 0 or i + 1 >= v.size:
        return float(v[i])
    return float(v[i] + (v[i + 1] - v[i]) * t) if np.isfinite(v[i + 1]) else math.inf


def _percentiles(rows: list[dict], column: str) -> tuple[float, float, int]:
    """(p50, p95, failed runs) of ``column`` over ``rows``, a failed / missing / non-finite figure as +inf."""
    v = np.array([float(r[column]) if r.get(column) is not None and not r.get("error") else np.inf for r in rows])
    v[~np.isfinite(v)] = np.inf
    return percentile_with_failures(v, 50), percentile_with_failures(v, 95), int(np.sum(~np.isfinite(v)))


def budget_table(spec: StudySpec, table: list[dict]) -> list[dict]:
    """Rows of ``budget.csv``: per condition and target figure, the cheapest cell meeting the target
    (``reached`` "yes"), else the cell with the lowest 95th percentile (``reached`` "no"). Figures in the units
    their names carry (mm, deg, rad, m). Empty without a ``target``."""
    if not spec.target or not table:
        return []
    defaults = _defaults(spec)
    conds = [a for a in spec.axes if a not in COST_AXES]
    groups: dict = {}
    for r in table:
        cost = {**defaults, **{k: v for k, v in spec.settings.items() if k in COST_AXES},
                **{k: r[k] for k in COST_AXES if k in r}}
        key = (tuple(r[a] for a in conds), int(cost["n_poses"]), int(cost["frames"]))
        groups.setdefault(key, []).append(r)
    by_cond: dict = {}
    for (cond, n_poses, frames), rows in groups.items():
        by_cond.setdefault(cond, []).append((n_poses * frames, n_poses, frames, rows))
    out = []
    for cond, cells in by_cond.items():
        cells.sort(key=lambda c: c[:3])
        for metric, limit in spec.target.items():
            col = f"after_{metric}"
            stats = [(c, *_percentiles(c[3], col)) for c in cells]
            met = [s for s in stats if s[2] <= limit]
            (images, n_poses, frames, rows), p50, p95, failed = met[0] if met else min(stats, key=lambda s: s[2])
            out.append({**dict(zip(conds, cond)), "metric": metric, "target": float(limit),
                        "reached": "yes" if met else "no", "n_poses": n_poses, "frames": frames, "images": images,
                        "p50": p50, "p95": p95, "n_runs": len(rows), "n_failed": failed})
    return out


def write_budget(spec: StudySpec, rows: list[dict], out: Path) -> str:
    """``budget.csv`` (condition axes, then BUDGET_COLUMNS); returns its path."""
    cols = [a for a in spec.axes if a not in COST_AXES] + list(BUDGET_COLUMNS)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([repr(r[c]) if isinstance(r[c], float) and math.isfinite(r[c]) else
                    "" if isinstance(r[c], float) else r[c] for c in cols])
    return str(write_text_atomic(Path(out) / "budget.csv", buf.getvalue()))


def budget_text(spec: StudySpec, rows: list[dict]) -> list[str]:
    """Summary lines of the budget table."""
    if not rows:
        return []
    conds = [a for a in spec.axes if a not in COST_AXES]
    lines = ["budget: cheapest acquisition whose 95th percentile after calibration meets the target "
             "(images = poses x frames per pose; failed runs count as missing it):"]
    for r in rows:
        cond = " ".join(f"{a}={format_value(r[a])}" for a in conds) or "all runs"
        what = f"{r['n_poses']} poses x {r['frames']} frame{'s' if r['frames'] != 1 else ''} ({r['images']} images)"
        p95 = "-" if not math.isfinite(r["p95"]) else f"{r['p95']:.3g}"
        p50 = "-" if not math.isfinite(r["p50"]) else f"{r['p50']:.3g}"
        if r["reached"] == "yes":
            lines.append(f"  {cond}: {r['metric']} <= {r['target']:g}: {what}, p95 {p95} (median {p50}, "
                         f"{r['n_runs']} runs)")
        else:
            lines.append(f"  {cond}: {r['metric']} <= {r['target']:g}: not reached (best p95 {p95} with {what}, "
                         f"{r['n_runs']} runs)")
    return lines


# ----------------------------------------------------------------------------- what a run will cost (issue 28)
# A pose count or a study is checked against the machine before anything runs: when its estimated wall time exceeds
# CONFIRM_HOURS (or a study's own ``max_hours``), or its memory / run files exceed this machine's
# (MEMORY_SHARE of the physical memory, os.sysconf; the free disk space of the output folder), the command stops
# with exit 2 and the estimate unless ``--yes`` is given.
#
# Cost model: measured once on the development machine (2 cores shared with other jobs; Python 3.11, numpy 2,
# OpenBLAS 1 thread) and written down here, never timed in tests:
#   identify-synthetic rx90_eye_in_hand --poses 5000 / 20000 (/ 40000): 15.8 / 64.1 (/ 113) s, peak RSS 293 / 698
#     (/ 1208) MB -> slope 3.2 ms and 27 kB per pose (SYNTH_*, rounded up);
#   identifiability rx90_eye_in_hand --poses 5000 / 20000: 4.4 / 24.4 s, 201 / 367 MB -> 1.3 ms, 11 kB per pose;
#   study runs (study.cells.run_cell after one warm-up run, mean of 3): synthetic rx90 12 / 100 / 400 poses 0.135 /
#     0.179 / 0.530 s, h4_vision 15 / 71 poses 0.082 / 0.099 s -> 0.15 s + 1.2 ms per pose (STUDY_*); images
#     h4_vision 20 x 1 / 40 x 1 / 20 x 10 poses x frames 8.6 / 9.2 / 8.2 s -> 8 s + 0.03 s per pose (rendered) +
#     2 ms per frame (the resolution of the measurement: 180 more frames changed a run by < 0.4 s) (IMAGES_RUN_S,
#     POSE_RENDER_S, FRAME_S); the shipped h4_image_noise study (540 runs) took 28 min on 2 workers, this model
#     says 44;
#   runs/<key>.json: 2.9-3.6 kB.
#   (How: ``python -c`` over identify_synthetic_json / identifiability_json / run_cell, time.perf_counter and
#   resource.getrusage(RUSAGE_SELF).ru_maxrss, each in a fresh process.)
SYNTH_S_PER_POSE = 3.5e-3
SYNTH_BYTES_PER_POSE = 28e3
IDENT_S_PER_POSE = 1.4e-3
IDENT_BYTES_PER_POSE = 12e3
STUDY_RUN_S = 0.15
STUDY_S_PER_POSE = 1.2e-3
IMAGES_RUN_S = 8.0
POSE_RENDER_S = 0.03
FRAME_S = 2e-3
#: one run's file (runs/<key>.json), and its row kept in memory until the tables are written (a dict of ~60 floats)
RUN_FILE_BYTES = 4e3
RUN_ROW_BYTES = 8e3
#: a process's own memory before any pose (interpreter, numpy, scipy, OpenCV)
BASE_BYTES = 250e6
#: an estimate above this wall time asks for --yes
CONFIRM_HOURS = 1.0
#: an estimate above this share of the machine's physical memory asks for --yes
MEMORY_SHARE = 0.5
#: pose counts per command: (seconds, bytes) per pose (simulate: the render, frames come on top: FRAME_S each)
POSE_COSTS = {"identify-synthetic": (SYNTH_S_PER_POSE, SYNTH_BYTES_PER_POSE),
              "identifiability": (IDENT_S_PER_POSE, IDENT_BYTES_PER_POSE),
              "simulate": (POSE_RENDER_S, SYNTH_BYTES_PER_POSE)}


def _gb(b: float) -> str:
    return f"{b / 1e9:.3g} GB"


def _hours(s: float) -> str:
    return f"{s / 3600:.3g} h"


def _over(seconds: float, memory: float, disk: float | None, max_hours: float | None, out_dir=None) -> list[str]:
    """What the estimate exceeds: ["more than 1 h", "more than half of this machine's 16 GB of memory", ...]."""
    from ..config import machine_memory_bytes

    over = []
    limit_h = CONFIRM_HOURS if max_hours is None else max_hours
    if seconds > limit_h * 3600:
        over.append(f"more than the study file's max_hours: {max_hours:g}" if max_hours is not None
                    else f"more than {CONFIRM_HOURS:g} h")
    have = machine_memory_bytes()
    if have and memory > MEMORY_SHARE * have:
        over.append(f"more than {MEMORY_SHARE:.0%} of this machine's {_gb(have)} of memory")
    if disk is not None and out_dir is not None:
        import shutil

        probe = Path(out_dir).resolve()
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        try:
            free = shutil.disk_usage(probe).free
        except OSError:
            free = None
        if free is not None and disk > free:
            over.append(f"more than the {_gb(free)} free on the disk of {out_dir}")
    return over


def check_pose_count(command: str, n_poses: int | None, frames: int | None = 1, workers: int = 1, yes: bool = False,
                     scene=None) -> dict:
    """The estimate {seconds, bytes} of ``command`` (:data:`POSE_COSTS`) with ``n_poses`` (x ``frames`` images for
    simulate, default: the ``scene`` file's frames per pose; on ``workers`` processes); ConfigError (exit 2) with
    the estimate when it exceeds the machine (:data:`CONFIRM_HOURS`, :data:`MEMORY_SHARE`) and ``yes`` is not
    given. None poses: nothing to check."""
    from ..errors import ConfigError

    if n_poses is None or command not in POSE_COSTS:
        return {}
    if frames is None:
        from ..rig import load_scene

        frames = int(load_scene(scene).measurement.frames) if scene is not None else 1
    s_per, b_per = POSE_COSTS[command]
    if command == "simulate":  # rendered and measured on the workers
        s_per = s_per + frames * FRAME_S
        seconds = n_poses * s_per / max(workers, 1)
    else:
        seconds = n_poses * s_per
    memory = BASE_BYTES + n_poses * b_per
    est = {"seconds": seconds, "bytes": memory}
    over = _over(seconds, memory, None, None)
    if over and not yes:
        per = (f"{b_per / 1e3:.3g} kB and {s_per * 1e3:.3g} ms per pose"
               + (f" of {frames} frame{'s' if frames > 1 else ''} on {max(workers, 1)} workers"
                  if command == "simulate" else ""))
        raise ConfigError(f"{command} --poses {n_poses}: estimated {_gb(memory)} of memory and {_hours(seconds)} "
                          f"({per}, measured: vision_calib/study/budget.py), {' and '.join(over)}: give --yes to "
                          "run it anyway, or fewer poses")
    return est


def study_estimate(spec: StudySpec, n_runs: int, workers: int, n_rows: int | None = None) -> dict:
    """{seconds (wall, on ``workers``), cpu_seconds, bytes (memory), disk_bytes (run files)} of ``n_runs`` runs of
    ``spec`` still to compute (each cell's n_poses and frames; the scene's when the spec does not set them), with
    ``n_rows`` rows (default n_runs: those reused too) held in memory until the tables are written."""
    from .spec import study_cells

    cells = study_cells(spec)
    defaults = None
    cpu, peak = 0.0, 0.0
    for c in cells:
        s = {**spec.settings, **c}
        if "n_poses" not in s or (spec.mode == "images" and "frames" not in s):
            defaults = defaults or _defaults(spec)
        n = int(s.get("n_poses") or defaults["n_poses"])
        if spec.mode == "images":
            f = int(s.get("frames") or defaults["frames"])
            cpu += IMAGES_RUN_S + n * (POSE_RENDER_S + f * FRAME_S)
        else:
            cpu += STUDY_RUN_S + STUDY_S_PER_POSE * n
        peak = max(peak, n * SYNTH_BYTES_PER_POSE)
    per_run = cpu / max(len(cells), 1)
    w = max(int(workers), 1)
    return {"cpu_seconds": per_run * n_runs, "seconds": per_run * n_runs / w,
            "bytes": (BASE_BYTES + peak) * w + RUN_ROW_BYTES * (n_runs if n_rows is None else n_rows),
            "disk_bytes": RUN_FILE_BYTES * n_runs, "workers": w}


def check_study(spec: StudySpec, n_runs: int, workers: int, out_dir, yes: bool = False, where: str = "",
                n_rows: int | None = None) -> dict:
    """:func:`study_estimate`; ConfigError (exit 2) naming the spec with the estimate when it exceeds the machine or
    the spec's ``max_hours`` and ``yes`` is not given. where: said after the worker count (e.g. " of the Dask
    cluster")."""
    from ..errors import ConfigError

    est = study_estimate(spec, n_runs, workers, n_rows)
    max_hours = getattr(spec, "max_hours", None)
    over = _over(est["seconds"], est["bytes"], est["disk_bytes"], max_hours, out_dir)
    if over and not yes:
        raise ConfigError(
            f"{spec.path}: {n_runs} runs: estimated {_hours(est['seconds'])} on {est['workers']} worker"
            f"{'s' if est['workers'] > 1 else ''}{where} ({_hours(est['cpu_seconds'])} of CPU), {_gb(est['bytes'])} of "
            f"memory and {_gb(est['disk_bytes'])} of run files (cost model: vision_calib/study/budget.py), "
            f"{' and '.join(over)}: give --yes to run it anyway, bound it in the study file (max_hours: H), or use "
            "fewer repetitions or cells")
    return est
