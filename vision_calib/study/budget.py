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
