"""Study plots (PNG, matplotlib Agg): main figures vs each swept axis, Monte Carlo parameter std."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..serialize import write_bytes_atomic
from .spec import MAIN_FIGURES, StudySpec, format_value, row_value

def _save_fig(fig, path: Path) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return str(write_bytes_atomic(path, buf.getvalue()))


def write_plots(spec: StudySpec, table: list[dict], cols, out: Path) -> list[str]:
    """PNG plots: for each swept axis, the main figures (median, 5-95 % band; one line per value
    of the other axes) and the Monte Carlo std of each identified parameter."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    ok = [r for r in table if not r.get("error")]
    if not ok:
        return paths
    for names, _ in spec.sweep:
        axis = names[0]  # linked axes (one group) are plotted against the group's first axis
        values = []
        for r in ok:
            if r[axis] not in values:
                values.append(r[axis])
        numeric = all(isinstance(v, (int, float)) for v in values)
        if numeric:
            values = sorted(values)
        xs = np.array(values, float) if numeric else np.arange(len(values), dtype=float)
        others = [a for a in spec.axes if a not in names]
        series = {}
        for r in ok:
            series.setdefault(tuple(r[a] for a in others), []).append(r)
        for c, lab, f in MAIN_FIGURES:
            if c not in cols:
                continue
            fig, ax = plt.subplots(figsize=(6, 4))
            for skey, rows in series.items():
                med, lo, hi = [], [], []
                for v in values:
                    vals = np.array([row_value(r, c) for r in rows if r[axis] == v]) * f
                    vals = vals[np.isfinite(vals)]
                    p = np.percentile(vals, [5, 50, 95]) if vals.size else [np.nan] * 3
                    lo.append(p[0]), med.append(p[1]), hi.append(p[2])
                label = ", ".join(f"{a}={format_value(v)}" for a, v in zip(others, skey)) or "median"
                line, = ax.plot(xs, med, "o-", label=label)
                ax.fill_between(xs, lo, hi, color=line.get_color(), alpha=0.2)
            limit = (spec.target or {}).get(c[len("after_"):]) if c.startswith("after_") else None
            if limit is not None:  # the spec's target (budget table): the 95 % band's top must be below it
                ax.axhline(limit * f, color="k", ls="--", lw=1, label=f"target {limit * f:g}")
            ax.set_xlabel(axis)
            ax.set_ylabel(lab)
            if not numeric:
                ax.set_xticks(xs, [str(v) for v in values])
            if c == "cond":
                ax.set_yscale("log")
            ax.set_title(f"{spec.name}: {lab} (median, 5-95 %)")
            ax.legend(fontsize=7)
            ax.grid(alpha=0.3)
            paths.append(_save_fig(fig, out / f"{c}_vs_{axis}.png"))
        errs = [c for c in cols if c.startswith("err:")]
        if errs and len(series) == 1:
            fig, axs = plt.subplots(1, 2, figsize=(10, 4))
            rows = next(iter(series.values()))
            for c in errs:
                sd = []
                for v in values:
                    vals = np.array([row_value(r, c) for r in rows if r[axis] == v])
                    vals = vals[np.isfinite(vals)]
                    sd.append(vals.std(ddof=1) * 1e3 if vals.size > 1 else np.nan)
                if not np.any(np.isfinite(sd)):
                    continue
                name = c[4:]
                is_angle = any(t in name.split(".")[-1] for t in ("alpha", "psi", "beta", "theta")) or name.startswith("q0")
                axs[1 if is_angle else 0].plot(xs, sd, "o-", label=name)
            for a, lab in zip(axs, ("length parameters: std [mm]", "angle parameters: std [mrad]")):
                a.set_xlabel(axis)
                a.set_ylabel(lab)
                a.set_yscale("log")
                if not numeric:
                    a.set_xticks(xs, [str(v) for v in values])
                if a.lines:
                    a.legend(fontsize=6, ncol=2)
                a.grid(alpha=0.3)
            fig.suptitle(f"{spec.name}: Monte Carlo std of identified parameters")
            paths.append(_save_fig(fig, out / f"param_std_vs_{axis}.png"))
        else:
            plt.close("all")
    return paths
