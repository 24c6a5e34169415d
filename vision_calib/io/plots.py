"""Report plots (matplotlib, Agg backend, PNG): residuals before/after, parameter deviations with
error bars, per-pose validation error map.

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


def plot_residuals(path, r_before, r_after, kind: str, labels=None) -> Path:
    """Per-pose residual norms before (nominal) and after identification. r_*: (N, m) SI."""
    plt = _fig()
    f = 1e3 if kind in ("pose", "position") else np.degrees(1.0)
    unit = "mm" if kind in ("pose", "position") else "deg (joint)"
    cols = slice(0, 3) if kind in ("pose", "position") else slice(None)
    nb = np.linalg.norm(r_before[:, cols], axis=1) * f
    na = np.linalg.norm(r_after[:, cols], axis=1) * f
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.8))
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.14, top=0.92, wspace=0.18)
    x = np.arange(len(nb))
    floor = max(float(np.min(np.concatenate([nb, na])[np.concatenate([nb, na]) > 0], initial=1.0)), 1e-12) / 2
    lw = float(np.clip(140.0 / max(len(nb), 1), 0.3, 6.0))  # ~0.4 pose wide bars [pt], one artist per series
    ax[0].vlines(x - 0.2, floor, np.maximum(nb, floor), lw=lw, color="C0", label="nominal")
    ax[0].vlines(x + 0.2, floor, np.maximum(na, floor), lw=lw, color="C1", label="identified")
    ax[0].set_xlabel("pose")
    ax[0].set_ylabel(f"residual norm [{unit}]")
    ax[0].set_yscale("log")
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    ax[0].yaxis.set_major_formatter(FormatStrFormatter("%g"))  # plain text: mathtext "10^k" labels cost ~0.2 s
    ax[0].yaxis.set_minor_formatter(NullFormatter())
    ax[0].legend()
    ax[0].set_title("identification residuals per pose")
    ax[1].hist([nb, na], bins=20, label=["nominal", "identified"], histtype="step", lw=1.5)
    ax[1].set_xlabel(f"residual norm [{unit}]")
    ax[1].legend()
    return _save(fig, path)


def plot_parameters(path, names, nominal, identified, std, true=None, kinds=None) -> Path:
    """Identified - nominal (mm or mrad) with ±2 std error bars; truth - nominal as markers."""
    plt = _fig()
    names = list(names)
    kinds = kinds or ["length"] * len(names)
    f = np.array([1e3] * len(names))  # m -> mm, rad -> mrad
    dev = (np.asarray(identified) - np.asarray(nominal)) * f
    err = 2 * np.nan_to_num(np.asarray(std, float)) * f
    labels = [f"{n} [{'mm' if k == 'length' else 'mrad'}]" for n, k in zip(names, kinds)]
    w, h = max(6, 0.35 * len(names)), 4 + 0.055 * max((len(t) for t in labels), default=0)
    fig, ax = plt.subplots(figsize=(w, h))
    # fixed margins: the rotated tick labels (fontsize 7, ~0.055 in a character) below a 3.3 in tall axes
    fig.subplots_adjust(left=0.7 / w, right=1 - 0.2 / w, top=1 - 0.35 / h, bottom=(h - 3.3 - 0.35) / h)
    x = np.arange(len(names))
    ax.errorbar(x, dev, yerr=err, fmt="o", capsize=3, label="identified - nominal (±2σ)")
    if true is not None:
        ax.plot(x, (np.asarray(true) - np.asarray(nominal)) * f, "rx", label="true - nominal")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xticks(x, labels, rotation=90, fontsize=7)
    ax.set_ylabel("deviation [mm | mrad]")
    ax.legend()
    ax.set_title("identified parameter deviations")
    return _save(fig, path)


def plot_error_map(path, positions_m, err_before_mm, err_after_mm) -> Path:
    """Validation position error per pose (x-y map of pose positions, colour = error)."""
    plt = _fig()
    p = np.asarray(positions_m) * 1e3
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.12, top=0.92, wspace=0.25)
    vmax = max(float(np.max(err_before_mm)), 1e-9)
    for a, e, title in ((ax[0], err_before_mm, "nominal"), (ax[1], err_after_mm, "identified")):
        sc = a.scatter(p[:, 0], p[:, 1], c=e, cmap="viridis", vmin=0, vmax=vmax if title == "nominal" else None, s=30)
        a.set_title(f"validation position error, {title} [mm]")
        a.set_xlabel("x [mm]")
        a.set_ylabel("y [mm]")
        fig.colorbar(sc, ax=a)
    return _save(fig, path)
