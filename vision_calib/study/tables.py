"""Study tables: results.csv/.parquet (one row per run), summary.csv (per cell and metric), the
per-parameter table (parameters.csv), parameter spread, and the summary text."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np

from ..errors import VisionCalibError
from ..serialize import write_bytes_atomic, write_text_atomic
from .cells import cell_poses, scene_for
from .spec import MAIN_FIGURES, StudySpec, format_value, row_value, run_seed, study_cells

PARAMETER_COLUMNS = ("parameter", "kind", "true_deviation", "identifiable", "noise_free", "identified_mean", "mc_std",
                     "predicted_std", "mc_rms_error", "n", "note", "thesis_reported")


def _cell_reference(spec: StudySpec, cell: dict):
    """(scene, x_true (n,), identifiability report, noise-free identified vector (n,) or None) of a
    cell, on the poses of repetition 0."""
    from ..experiment.steps import analyze_setup, scene_truth
    from ..experiment.synthetic import run_synthetic

    s = {**spec.settings, **cell}
    scene = scene_for(str(spec.scene_path), s.get("variant"), s.get("model"), spec.hash, s.get("trial"))
    residual = s.get("residual") or scene.identification.residual
    seed = run_seed(spec.seed, 0)
    poses = cell_poses(spec, scene, s, seed, residual)
    rep, _ = analyze_setup(scene.setup, poses, residual)
    x_true = scene_truth(scene)
    try:  # least squares (the kind's first non-EKF method) on exact measurements
        method = next(m for m in scene.setup.methods if m != "ekf")
        ref = run_synthetic(scene, method=method, residual=residual, poses=poses, validation=poses[:1], seed=seed,
                            base=scene.setup.params.mask(rep.base_parameters), x_true=x_true, sigma_t_m=0.0,
                            sigma_r_rad=0.0)
        x_ref = ref.result.identified
    except (VisionCalibError, np.linalg.LinAlgError):
        x_ref = None
    return scene, x_true, rep, x_ref


def parameter_table(spec: StudySpec, table: list[dict]) -> list[dict]:
    """Per (cell, parameter) rows of ``parameters.csv`` (see the module docstring); SI units.
    Empty unless mode synthetic, ``truth: scene``, no ``truth_variant`` and ``parameters`` output."""
    if spec.mode != "synthetic" or spec.truth != "scene" or spec.truth_variant is not None \
            or "parameters" not in spec.outputs:
        return []
    groups = _group(spec, table)
    out = []
    for cell in study_cells(spec):
        rows = [r for r in groups.get(tuple(cell[a] for a in spec.axes), []) if not r.get("error")]
        scene, x_true, rep, x_ref = _cell_reference(spec, cell)
        ps = scene.setup.params
        dev = x_true - ps.nominal
        trial = scene.truth.trial
        reported = (scene.setup.trials().get(trial, {}).get("reported", {}) or {}) if trial else {}
        couplings = {c["parameter"]: c for c in rep.couplings}
        names = [n for i, n in enumerate(ps.names) if ps.free[i] or abs(dev[i]) > 0 or n in reported]
        if spec.parameters is not None:
            names = [n for n in names if n in spec.parameters]
        for n in names:
            i = ps.index(n)
            err = np.array([row_value(r, f"err:{n}") for r in rows])
            std = np.array([row_value(r, f"std:{n}") for r in rows])
            err, std = err[np.isfinite(err)], std[np.isfinite(std)]
            ident = n in rep.base_parameters
            if n in couplings:
                comb = couplings[n]["combination_si"]
                note = ("no effect on the measurements" if not comb else
                        f"not identifiable: {n} acts as " + " ".join(f"{v:+.3g}*{k}" for k, v in comb.items()))
            elif not ps.free[i]:
                note = scene.setup.fixed_note(n)
            else:
                note = ""
            out.append({
                **cell, "parameter": n, "kind": ps.kinds[i], "true_deviation": float(dev[i]),
                "identifiable": "yes" if ident else "no",
                "noise_free": float(x_ref[i] - ps.nominal[i]) if x_ref is not None else float("nan"),
                "identified_mean": float(dev[i] + err.mean()) if err.size else float("nan"),
                "mc_std": float(err.std(ddof=1)) if err.size > 1 else float("nan"),
                "predicted_std": float(std.mean()) if std.size else float("nan"),
                "mc_rms_error": float(np.sqrt(np.mean(err**2))) if err.size else float("nan"),
                "n": int(err.size), "note": note,
                "thesis_reported": float(reported[n]) if n in reported else float("nan"),
            })
    return out


def write_parameter_table(spec: StudySpec, prows: list[dict], out: Path) -> str:
    """``parameters.csv`` (SI units; empty cells for NaN)."""
    cols = [*spec.axes, *PARAMETER_COLUMNS]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in prows:
        w.writerow(["" if isinstance(r[c], float) and math.isnan(r[c]) else repr(r[c]) if isinstance(r[c], float)
                    else r[c] for c in cols])
    return str(write_text_atomic(out / "parameters.csv", buf.getvalue()))


def parameter_text(spec: StudySpec, prows: list[dict]) -> list[str]:
    """Compact per-parameter lines: one block per value of the axes other than ``method``, one
    line per parameter (lengths in mm, angles in mrad), one column per method."""
    if not prows:
        return []
    axes = [a for a in spec.axes if a != "method"]
    methods = []
    for r in prows:
        m = r.get("method", "")
        if m not in methods:
            methods.append(m)
    blocks: dict = {}
    for r in prows:
        blocks.setdefault(tuple(r[a] for a in axes), {}).setdefault(r["parameter"], {})[r.get("method", "")] = r
    has_thesis = any(math.isfinite(r["thesis_reported"]) for r in prows)

    def f(v):
        return "-" if not math.isfinite(v) else f"{v * 1e3:.4g}"

    lines = ["parameters: deviation from nominal, mm / mrad (true, noise-free = the value the identifiable "
             "parameters take with exact data, identified mean ± Monte Carlo std)"]
    for key, params in blocks.items():
        title = " ".join(f"{a}={format_value(v)}" for a, v in zip(axes, key)) or "all cells"
        head = ["param", "true", "ident", "noise-free"] + [f"{m or 'identified'} mean ± std" for m in methods]
        head += ["thesis"] if has_thesis else []
        head += ["note"]
        body = []
        for n, by_m in params.items():
            r0 = next(iter(by_m.values()))
            row = [n, f(r0["true_deviation"]), r0["identifiable"], f(r0["noise_free"])]
            for m in methods:
                r = by_m.get(m)
                if r is None or not math.isfinite(r["identified_mean"]):
                    row.append("-")
                else:
                    sd = f" ± {r['mc_std'] * 1e3:.2g}" if math.isfinite(r["mc_std"]) else ""
                    row.append(f"{r['identified_mean'] * 1e3:.4g}{sd}")
            if has_thesis:
                row.append(f(r0["thesis_reported"]))
            row.append(r0["note"].split(" (")[0])
            body.append(row)
        widths = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(head)]
        lines.append(f"[{title}]")
        lines.append("  " + "  ".join(h.rjust(w) if i < len(head) - 1 else h for i, (h, w) in enumerate(zip(head, widths))))
        lines.extend("  " + "  ".join(c.rjust(w) if i < len(head) - 1 else c for i, (c, w) in enumerate(zip(b, widths)))
                     for b in body)
    return lines


def parameter_spread(spec: StudySpec, table: list[dict]) -> list[dict]:
    """Per cell: geometric mean, over the parameters identified in every run of every cell (so the
    cells compare like with like), of the predicted std and of the Monte Carlo RMS error (SI), and
    the ratio of the predicted std to the first cell's."""
    rows_ok = [r for r in table if not r.get("error")]
    if not rows_ok:
        return []
    names = sorted(k[4:] for k in rows_ok[0] if k.startswith("std:"))
    names = [n for n in names
             if all(r.get(f"std:{n}") is not None and math.isfinite(r[f"std:{n}"]) and r[f"std:{n}"] > 0 for r in rows_ok)]
    if not names:
        return []
    groups: dict = {}
    for r in rows_ok:
        groups.setdefault(tuple(r[a] for a in spec.axes), []).append(r)
    out = []
    for key, rows in groups.items():
        pred = np.array([[r[f"std:{n}"] for n in names] for r in rows]).mean(axis=0)
        mc = np.sqrt(np.array([[r[f"err:{n}"] ** 2 for n in names] for r in rows]).mean(axis=0))
        out.append({**dict(zip(spec.axes, key)), "n_params": len(names),
                    "predicted_std_geomean": float(np.exp(np.mean(np.log(pred)))),
                    "mc_rms_error_geomean": float(np.exp(np.mean(np.log(np.maximum(mc, 1e-300)))))})
    for o in out:
        o["predicted_std_vs_first"] = o["predicted_std_geomean"] / out[0]["predicted_std_geomean"]
    return out


def _columns(spec: StudySpec, table: list[dict]) -> list[str]:
    fixed = ["study", *spec.axes, "repetition", "seed", "error", "converged", "iterations", "seconds", "n_free"]
    rest = []
    for row in table:
        for k in row:
            if k not in fixed and k not in rest:
                rest.append(k)
    pre = [k for k in rest if ":" not in k]
    par = sorted((k for k in rest if ":" in k), key=lambda k: (k.split(":", 1)[1], k))
    return fixed + pre + par


def _metric_columns(spec, cols):
    skip = {"study", "repetition", "seed", "error", *spec.axes}
    return [c for c in cols if c not in skip]


def write_outputs(spec: StudySpec, table: list[dict], out: Path, plots: bool = True) -> dict:
    """results.csv/.parquet, summary.csv and plots from the run rows; returns {kind: path}."""
    cols = _columns(spec, table)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for row in table:
        w.writerow(["" if row.get(c) is None or (isinstance(row.get(c), float) and math.isnan(row[c])) else
                    repr(row[c]) if isinstance(row.get(c), float) else row[c] for c in cols])
    files = {"results_csv": str(write_text_atomic(out / "results.csv", buf.getvalue()))}
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq

        numeric = set(_metric_columns(spec, cols)) - {"converged", "iterations", "n_free"}
        data = {}
        for c in cols:
            vals = [row.get(c) for row in table]
            if c in numeric:
                data[c] = pa.array([row_value(row, c) for row in table], pa.float64())
            else:
                data[c] = pa.array(vals)
        sink = io.BytesIO()
        pq.write_table(pa.table(data), sink)
        files["results_parquet"] = str(write_bytes_atomic(out / "results.parquet", sink.getvalue()))
    except ImportError:  # pragma: no cover
        pass
    srows = summary_rows(spec, table, cols)
    buf = io.StringIO()
    scols = [*spec.axes, "metric", "n", "mean", "std", "rms", "p05", "p50", "p95"]
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(scols)
    for r in srows:
        w.writerow([repr(r[c]) if isinstance(r[c], float) else r[c] for c in scols])
    files["summary_csv"] = str(write_text_atomic(out / "summary.csv", buf.getvalue()))
    if plots:
        from .plots import write_plots

        files["plots"] = write_plots(spec, table, cols, out)
    else:
        files["plots"] = []
    return files


def _group(spec, table):
    groups = {}
    for row in table:
        groups.setdefault(tuple(row.get(a) for a in spec.axes), []).append(row)
    return groups


def _stats(v: np.ndarray) -> dict:
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {"n": 0, "mean": float("nan"), "std": float("nan"), "rms": float("nan"), "p05": float("nan"),
                "p50": float("nan"), "p95": float("nan")}
    p = np.percentile(v, [5, 50, 95])
    return {"n": int(v.size), "mean": float(v.mean()), "std": float(v.std(ddof=1)) if v.size > 1 else float("nan"),
            "rms": float(np.sqrt(np.mean(v**2))), "p05": float(p[0]), "p50": float(p[1]), "p95": float(p[2])}


def summary_rows(spec: StudySpec, table: list[dict], cols=None) -> list[dict]:
    """Long summary: one dict per (cell, metric) with n, mean, std, rms, p05, p50, p95."""
    cols = cols or _columns(spec, table)
    out = []
    for key, rows in _group(spec, table).items():
        for c in _metric_columns(spec, cols):
            st = _stats(np.array([row_value(r, c) for r in rows]))
            out.append({**dict(zip(spec.axes, key)), "metric": c, **st})
    return out


def cell_summary(spec: StudySpec, table: list[dict]) -> list[dict]:
    """Per cell: the axes, n_runs, n_failed, converged fraction and {figure: {mean, std, p05, p95}}
    of the main figures and of the mean predicted / Monte Carlo parameter std."""
    out = []
    for key, rows in _group(spec, table).items():
        d = {**dict(zip(spec.axes, key)), "n_runs": len(rows), "n_failed": sum(1 for r in rows if r.get("error")),
             "converged": float(np.mean([bool(r.get("converged")) for r in rows]))}
        figs = {}
        for c, _, _ in MAIN_FIGURES:
            if any(c in r for r in rows):
                st = _stats(np.array([row_value(r, c) for r in rows]))
                figs[c] = {k: st[k] for k in ("mean", "std", "p05", "p95")}
        d["figures"] = figs
        out.append(d)
    return out


def summary_table(spec: StudySpec, res: dict) -> tuple[list[str], list[list[str]]]:
    """(head, body) of the per-cell table: the axes, runs that did not fail, converged fraction, and the mean ±
    std of each main figure in its display unit (the text summary and the study page show it)."""
    figs = [(c, lab, f) for c, lab, f in MAIN_FIGURES if any(c in s["figures"] for s in res["summary"])]
    head = [*spec.axes, "runs", "conv"] + [lab for _, lab, _ in figs]
    body = []
    for s in res["summary"]:
        cells = [format_value(s[a]) for a in spec.axes] + [str(s["n_runs"] - s["n_failed"]), f"{s['converged']:.2f}"]
        for c, _, f in figs:
            v = s["figures"].get(c)
            if v is None or not math.isfinite(v["mean"]):
                cells.append("-")
            elif c == "cond":
                cells.append(f"{v['mean']:.3g}")
            else:
                sd = f" ± {v['std'] * f:.2g}" if math.isfinite(v["std"]) else ""
                cells.append(f"{v['mean'] * f:.3g}{sd}")
        body.append(cells)
    return head, body


def summary_text(spec: StudySpec, res: dict) -> str:
    """One screen: per cell mean ± std of the main figures."""
    head, body = summary_table(spec, res)
    lines = [f"study {spec.name}: {res['n_runs']} runs ({res['n_computed']} computed, {res['n_reused']} reused, "
             f"{res['n_failed']} failed) -> {res['out_dir']}"]
    widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h) for i, h in enumerate(head)]
    lines.append("  ".join(h.rjust(w) for h, w in zip(head, widths)))
    lines.extend("  ".join(c.rjust(w) for c, w in zip(b, widths)) for b in body)
    spread = res.get("parameter_spread") or []
    if spread:
        lines.append("parameter spread (geometric mean over the identified parameters; SI units):")
        for o in spread:
            cell = " ".join(f"{a}={format_value(o[a])}" for a in spec.axes)
            lines.append(f"  {cell}: predicted std {o['predicted_std_geomean']:.3g}, Monte Carlo RMS error "
                         f"{o['mc_rms_error_geomean']:.3g} ({o['n_params']} parameters); predicted std x"
                         f"{o['predicted_std_vs_first']:.3g} of the first cell")
    if res.get("parameters") and ("trial" in spec.axes or len(res["summary"]) <= 2):
        lines.extend(parameter_text(spec, res["parameters"]))
    return "\n".join(lines)


