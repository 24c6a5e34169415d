"""Report plots (matplotlib, Agg backend, PNG): residuals before/after (translation and rotation, per pose and
histograms), parameter deviations with error bars (one axis per unit; z-scores against the truth in simulation),
per-pose validation error map (each panel its own labelled colour scale).

Drawn cheaply (issue 11: the three plots took ~1.85 s of CPU besides the matplotlib import, now ~0.8 s; CPU
time of the three functions on random data of the demo's sizes):
one artist per data series (``vlines`` and step histograms instead of one bar patch per pose) and fixed
margins instead of ``bbox_inches="tight"``, which draws every figure twice. :func:`preload` imports
matplotlib and loads its fonts ahead of time (a background thread while the image workers run)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..serialize import write_bytes_atomic


def _fig():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def preload() -> None:
    """Import matplotlib (Agg) and draw one tiny figure (font cache, text layout), so that the first report
    plot does not pay for them; safe to call from a background thread, any number of times."""
    import io

    plt = _fig()
    fig = plt.figure(figsize=(1, 1))
    fig.text(0.5, 0.5, "x")
    fig.savefig(io.BytesIO(), format="png", dpi=10)
    plt.close(fig)


def draw_all(jobs) -> None:
    """Run the plot jobs [(function, args)]: on Linux with more than one core, the first half in a forked child
    process while this process draws the rest (each plot is ~0.2 s of single-threaded Agg drawing; the data
    are already in memory, matplotlib already imported), else one after the other. A job that fails in the
    child is drawn again here, so its exception surfaces to the caller as it would serially."""
    import os

    jobs = list(jobs)
    k = len(jobs) // 2
    pid = -1
    if k and hasattr(os, "fork") and (os.cpu_count() or 1) > 1:
        import warnings

        with warnings.catch_warnings():  # Python >= 3.12 warns on fork() with threads; the child only draws
            warnings.simplefilter("ignore", DeprecationWarning)
            try:
                pid = os.fork()
            except OSError:
                pid = -1
        if pid == 0:  # child: draw, then leave without running the parent's exit handlers
            code = 0
            try:
                for f, args in jobs[:k]:
                    f(*args)
            except BaseException:
                code = 1
            finally:
                os._exit(code)
    for f, args in jobs[k if pid > 0 else 0:]:
        f(*args)
    if pid > 0:
        _, status = os.waitpid(pid, 0)
        if os.waitstatus_to_exitcode(status) != 0:
            for f, args in jobs[:k]:
                f(*args)


def _save(fig, path) -> Path:
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    _fig().close(fig)
    return write_bytes_atomic(path, buf.getvalue())


#: per-pose norm of a residual block: (columns, display factor from SI, unit, what) per residual kind
_RESIDUAL_BLOCKS = {
    "pose": [(slice(0, 3), 1e3, "mm", "translation"), (slice(3, 6), float(np.degrees(1.0)), "deg", "rotation")],
    "position": [(slice(0, 3), 1e3, "mm", "translation")],
    "joint": [(slice(None), float(np.degrees(1.0)), "deg", "joint")],
}


def _plain_log_ticks(axis) -> None:
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    axis.set_major_formatter(FormatStrFormatter("%g"))  # plain text: mathtext "10^k" labels cost ~0.2 s
    axis.set_minor_formatter(NullFormatter())


def plot_residuals(path, r_before, r_after, kind: str, labels=None) -> Path:
    """Per-pose residual norms before (nominal parameters) and after identification, one row per residual block:
    translation [mm] and, for 6-component pose residuals, rotation [deg] (or the joint residual [deg]); left the
    norm per pose (log scale), right its histogram (log-spaced bins: before and after differ by orders of
    magnitude). r_*: (N, m) SI (m, rad); labels: (N,) pose ids (tick labels when few poses)."""
    plt = _fig()
    rb, ra = np.atleast_2d(np.asarray(r_before, float)), np.atleast_2d(np.asarray(r_after, float))
    blocks = [b for b in _RESIDUAL_BLOCKS.get(kind, _RESIDUAL_BLOCKS["joint"])
              if b[0].start is None or rb.shape[1] >= b[0].stop]
    n = len(blocks)
    fig, axes = plt.subplots(n, 2, figsize=(11, 3.4 * n + 0.4), squeeze=False,
                             gridspec_kw={"width_ratios": [1.6, 1]})
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.12 / n, top=1 - 0.08 / n, wspace=0.22, hspace=0.42)
    x = np.arange(len(rb))
    lw = float(np.clip(140.0 / max(len(rb), 1), 0.3, 6.0))  # ~0.4 pose wide bars [pt], one artist per series
    for row, (cols, f, unit, what) in zip(axes, blocks):
        nb = np.linalg.norm(rb[:, cols], axis=1) * f
        na = np.linalg.norm(ra[:, cols], axis=1) * f
        both = np.concatenate([nb, na])
        pos = both[np.isfinite(both) & (both > 0)]
        floor = max(float(pos.min()) / 2 if pos.size else 1e-6, 1e-12)
        top = max(float(pos.max()) * 1.5 if pos.size else 1.0, floor * 10)
        a = row[0]
        a.vlines(x - 0.2, floor, np.maximum(nb, floor), lw=lw, color="C0", label="nominal")
        a.vlines(x + 0.2, floor, np.maximum(na, floor), lw=lw, color="C1", label="identified")
        a.set_yscale("log")
        a.set_ylim(floor, top)
        _plain_log_ticks(a.yaxis)
        a.set_xlabel("pose (fit order)" if labels is None or len(x) > 30 else "pose")
        if labels is not None and len(x) <= 30:
            a.set_xticks(x, [str(v) for v in labels], rotation=90, fontsize=7)
        a.set_ylabel(f"{what} residual [{unit}]")
        a.set_title(f"{what} residual norm per pose")
        a.legend(fontsize=8)
        h = row[1]
        bins = np.geomspace(floor, top, 25)
        h.hist([np.clip(nb, floor, top), np.clip(na, floor, top)], bins=bins, label=["nominal", "identified"],
               histtype="step", lw=1.5, color=["C0", "C1"])
        h.set_xscale("log")
        _plain_log_ticks(h.xaxis)
        h.set_xlabel(f"{what} residual norm per pose [{unit}]")
        h.set_ylabel("number of poses")
        h.set_title(f"{what} residuals: histogram")
        h.legend(fontsize=8)
    return _save(fig, path)


#: display unit of a parameter kind: (unit, factor from SI); the units of the report's tables (lengths mm, angles deg)
_PARAM_UNITS = {"length": ("mm", 1e3), "angle": ("deg", float(np.degrees(1.0))), "coefficient": ("1", 1.0)}


def plot_parameters(path, names, nominal, identified, std, true=None, kinds=None) -> Path:
    """Identified - nominal with ±2 std error bars, one axis per unit (lengths in mm, angles in deg,
    coefficients dimensionless), true - nominal as markers; with ``true`` (simulation) a second row:
    z = (identified - true) / std per parameter, the ±2 band shaded. Arrays (n,) SI; kinds (n,) parameter kinds."""
    plt = _fig()
    names = list(names)
    kinds = list(kinds or ["length"] * len(names))
    nominal, identified = np.asarray(nominal, float), np.asarray(identified, float)
    std = np.asarray(std, float)
    groups = [k for k in _PARAM_UNITS if k in kinds] + sorted({k for k in kinds if k not in _PARAM_UNITS})
    idx = {k: [i for i, kk in enumerate(kinds) if kk == k] for k in groups}
    rows = 2 if true is not None else 1
    longest = max((len(t) for t in names), default=0)
    w = max(6.0, 0.32 * len(names) + 1.0 * len(groups))
    h = 3.0 * rows + 0.07 * longest + 0.9
    fig, axes = plt.subplots(rows, max(1, len(groups)), figsize=(w, h), squeeze=False,
                             gridspec_kw={"width_ratios": [max(1, len(idx[k])) for k in groups] or [1]})
    # fixed margins: the rotated tick labels (fontsize 7, ~0.07 in a character) below the last row
    fig.subplots_adjust(left=0.8 / w, right=1 - 0.15 / w, top=1 - 0.75 / h, bottom=(0.07 * longest + 0.2) / h,
                        wspace=0.9 / w * max(1, len(groups)), hspace=0.25)
    for j, k in enumerate(groups):
        unit, f = _PARAM_UNITS.get(k, ("SI", 1.0))
        ii = idx[k]
        x = np.arange(len(ii))
        a = axes[0, j]
        a.errorbar(x, (identified[ii] - nominal[ii]) * f, yerr=2 * np.nan_to_num(std[ii]) * f, fmt="o", ms=4,
                   capsize=3, label="identified - nominal (±2σ)")
        if true is not None:
            a.plot(x, (np.asarray(true, float)[ii] - nominal[ii]) * f, "rx", label="true - nominal")
        a.axhline(0, color="k", lw=0.5)
        a.set_ylabel(f"{k} deviation [{unit}]")
        a.set_xlim(-0.7, len(ii) - 0.3)
        a.set_title(f"{k}s [{unit}]", fontsize=10)
        if j == 0:
            a.legend(fontsize=7)
        if rows == 1:
            a.set_xticks(x, [names[i] for i in ii], rotation=90, fontsize=7)
        else:
            a.set_xticks(x, [""] * len(ii))
            z = (identified[ii] - np.asarray(true, float)[ii]) / np.where(std[ii] > 0, std[ii], np.nan)
            b = axes[1, j]
            b.axhspan(-2, 2, color="0.9", zorder=0)
            b.plot(x, z, "o", ms=4, color="C2")
            b.axhline(0, color="k", lw=0.5)
            b.set_xlim(-0.7, len(ii) - 0.3)
            zmax = float(np.nanmax(np.abs(z))) if np.isfinite(z).any() else 3.0
            b.set_ylim(-max(3.0, 1.1 * zmax), max(3.0, 1.1 * zmax))
            b.set_ylabel("z = (identified - true) / std")
            b.set_xticks(x, [names[i] for i in ii], rotation=90, fontsize=7)
    fig.suptitle("identified parameter deviations from nominal" + (" and z-scores against the truth (band: ±2)"
                                                                  if rows == 2 else ""), fontsize=11)
    return _save(fig, path)


def plot_error_map(path, positions_m, err_before_mm, err_after_mm) -> Path:
    """Validation position error per pose: x-y map of the validation poses' positions (N, 3) m, colour = error
    (N,) mm, nominal and identified. Each panel has its own colour scale (the identified errors are often
    orders of magnitude below the nominal ones: on a shared scale that panel would be one flat colour), from its
    own minimum to maximum, with a labelled colour bar; the titles give RMS and max."""
    plt = _fig()
    p = np.asarray(positions_m) * 1e3
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.4))
    fig.subplots_adjust(left=0.07, right=0.97, bottom=0.12, top=0.86, wspace=0.28)
    for a, e, title in ((ax[0], err_before_mm, "nominal"), (ax[1], err_after_mm, "identified")):
        e = np.asarray(e, float)
        fin = e[np.isfinite(e)]
        lo, hi = (float(fin.min()), float(fin.max())) if fin.size else (0.0, 1.0)
        if hi - lo <= 1e-12 * max(abs(hi), 1.0):
            lo, hi = lo - 0.5 * max(abs(lo), 1e-9), hi + 0.5 * max(abs(hi), 1e-9)
        sc = a.scatter(p[:, 0], p[:, 1], c=e, cmap="viridis", vmin=lo, vmax=hi, s=30)
        rms = float(np.sqrt(np.mean(fin ** 2))) if fin.size else float("nan")
        a.set_title(f"{title} model: position error\nRMS {rms:.3g} mm, max {hi if fin.size else float('nan'):.3g} mm"
                    " (own colour scale)", fontsize=10)
        a.set_xlabel("x [mm]")
        a.set_ylabel("y [mm]")
        a.set_aspect("equal", adjustable="datalim")
        fig.colorbar(sc, ax=a, label=f"position error, {title} [mm]")
    fig.suptitle("validation poses (never used in the fit) at the x-y position of the evaluated point "
                 "(serial: chain end; H4: nacelle point in the base frame)", fontsize=10)
    return _save(fig, path)
