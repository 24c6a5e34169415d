"""Report plots (matplotlib, Agg backend, PNG): residuals before/after, parameter deviations with
error bars, per-pose validation error map."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .atomic import write_bytes_atomic


def _fig():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path) -> Path:
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
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
    x = np.arange(len(nb))
    ax[0].bar(x - 0.2, nb, 0.4, label="nominal")
    ax[0].bar(x + 0.2, na, 0.4, label="identified")
    ax[0].set_xlabel("pose")
    ax[0].set_ylabel(f"residual norm [{unit}]")
    ax[0].set_yscale("log")
    ax[0].legend()
    ax[0].set_title("identification residuals per pose")
    ax[1].hist([nb, na], bins=20, label=["nominal", "identified"])
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
    fig, ax = plt.subplots(figsize=(max(6, 0.35 * len(names)), 4))
    x = np.arange(len(names))
    ax.errorbar(x, dev, yerr=err, fmt="o", capsize=3, label="identified - nominal (±2σ)")
    if true is not None:
        ax.plot(x, (np.asarray(true) - np.asarray(nominal)) * f, "rx", label="true - nominal")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xticks(x, [f"{n} [{'mm' if k == 'length' else 'mrad'}]" for n, k in zip(names, kinds)], rotation=90, fontsize=7)
    ax.set_ylabel("deviation [mm | mrad]")
    ax.legend()
    ax.set_title("identified parameter deviations")
    return _save(fig, path)


def plot_error_map(path, positions_m, err_before_mm, err_after_mm) -> Path:
    """Validation position error per pose (x-y map of pose positions, colour = error)."""
    plt = _fig()
    p = np.asarray(positions_m) * 1e3
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    vmax = max(float(np.max(err_before_mm)), 1e-9)
    for a, e, title in ((ax[0], err_before_mm, "nominal"), (ax[1], err_after_mm, "identified")):
        sc = a.scatter(p[:, 0], p[:, 1], c=e, cmap="viridis", vmin=0, vmax=vmax if title == "nominal" else None, s=30)
        a.set_title(f"validation position error, {title} [mm]")
        a.set_xlabel("x [mm]")
        a.set_ylabel("y [mm]")
        fig.colorbar(sc, ax=a)
    return _save(fig, path)
