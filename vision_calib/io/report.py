"""Writing a run's outputs: report.json (versioned), plots, calibrated model. All atomic."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .. import frames as F
from .atomic import write_json_atomic, write_text_atomic
from .model_export import write_calibrated_model


def validation_errors_mm(setup, x, x_true, poses_val) -> tuple[np.ndarray, np.ndarray]:
    """(positions (N, 3) m, position errors (N,) mm) of parameters x on validation poses."""
    if setup.kind == "h4":
        X = np.asarray(poses_val, float)
        q = setup.robot.igm(X, x_true)
        Xh = setup.robot.fgm(q, x, X0=X)
        return X[:, :3], np.linalg.norm(Xh[:, :3] - X[:, :3], axis=1) * 1e3
    T_true = setup.chain.forward(poses_val, x_true)
    T = setup.chain.forward(poses_val, x)
    return T_true[:, :3, 3], np.linalg.norm(F.pose_error(T_true, T)[:, :3], axis=1) * 1e3


def write_report(out_dir, report: dict, setup, result, problem, x_true=None, validation=None) -> Path:
    """report.json + residuals.png + parameters.png (+ error_map.png with truth) + calibrated_model.yaml."""
    from .plots import plot_error_map, plot_parameters, plot_residuals

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {"report": "report.json", "model": "calibrated_model.yaml"}
    write_calibrated_model(out / files["model"], setup, result.identified, result.std, result.free)
    try:
        r0 = problem.residual(setup.params.nominal)
        plot_residuals(out / "residuals.png", r0, result.residuals, problem.residual_kind)
        files["residuals_plot"] = "residuals.png"
        free = result.free
        ps = setup.params
        plot_parameters(out / "parameters.png", [n for n, f in zip(ps.names, free) if f], ps.nominal[free],
                        result.identified[free], result.std[free], None if x_true is None else x_true[free],
                        [k for k, f in zip(ps.kinds, free) if f])
        files["parameters_plot"] = "parameters.png"
        if x_true is not None and validation is not None:
            pos, eb = validation_errors_mm(setup, ps.nominal, x_true, validation)
            _, ea = validation_errors_mm(setup, result.identified, x_true, validation)
            plot_error_map(out / "error_map.png", pos, eb, ea)
            files["error_map_plot"] = "error_map.png"
    except Exception as exc:  # a plot must never cost the report
        report.setdefault("warnings", []).append(f"plotting failed: {exc}")
    report["files"] = files
    write_text_atomic(out / "summary.txt", report.get("summary_text", "") + "\n")
    write_json_atomic(out / files["report"], report)
    return out / files["report"]
