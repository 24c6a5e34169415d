"""Writing a run's outputs into its folder: report.json (the per-pose measurements once, :func:`on_disk`),
summary.txt, report.html, the plots and the calibrated model files (:func:`write_report`). All writes atomic; an
output that cannot be written is an error naming the file, never a warning."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..io.model_export import write_calibrated_model
from ..io.portable import relative_source
from ..serialize import write_json_atomic, write_text_atomic
from .summary import parameter_table_text


def _add_joint_offsets(report: dict, model_path: Path) -> None:
    """The report's ``joint_offsets`` (the calibrated model file's: the joint-offset form a controller takes) and
    its summary line, where the robot has one; the joint offsets the identifiability reduction folded into other
    parameters are named as such (the offsets carry them)."""
    from ..io.model_export import OFFSET_CONVENTION, read_calibrated_model

    cm = read_calibrated_model(model_path)
    if not cm.joint_offsets:
        return
    report["joint_offsets"] = {"convention": OFFSET_CONVENTION, "offsets": cm.joint_offsets,
                               "folded": [f["parameter"] for f in cm.folded if f["parameter"].startswith(("q0_", "theta"))]}
    vals = ", ".join(f"{q} {o['offset'] * (180 / np.pi if o['unit'] == 'rad' else 1e3):+.4f} "
                     f"{'deg' if o['unit'] == 'rad' else 'mm'}" for q, o in cm.joint_offsets.items())
    folded = report["joint_offsets"]["folded"]
    report["summary_text"] = report.get("summary_text", "") + (
        f"\njoint offsets for the controller (model joint = reading + offset; the same predictions as the identified "
        f"parameters): {vals}" + (f" (these carry {', '.join(folded)}, which the identifiability reduction folded "
                                  "into other parameters)" if folded else ""))


def write_report(out_dir, report: dict, setup=None, result=None, problem=None, evaluations=None,
                 plots: bool = True, overlays=None) -> Path:
    """report.json + summary.txt + report.html (+ calibrated_model.yaml with a setup; + residuals.png,
    parameters.png, and error_map.png with ``evaluations`` = {"before": Evaluation, "after": Evaluation}).
    overlays: an ``report.overlay.OverlaySource`` (the images of the run's poses): report.html then shows what the
    detector found on the rejected and the worst poses. A plot, overlay or page that fails to be *drawn* costs a
    warning (in report.json and the printed summary), never the report. An output that cannot be *written* (an
    OSError: a full disk, a read-only folder) is an error, never a warning: the calibrated model files of this run
    are removed (no model without its report), report.json is still written when it can be (with the failure
    among its warnings), and an OSError naming the file that could not be written is raised (exit 2)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report["source"] = relative_source(report["source"], out)  # paths relative to report.json (io.portable)
    files = {"report": "report.json"}
    models: list[Path] = []
    try:
        if setup is not None and report["verdict"].get("usable", report["verdict"]["ok"]):  # never from a failed fit
            files["model"] = "calibrated_model.yaml"
            models.append(out / files["model"])
            write_calibrated_model(out / files["model"], setup, result.identified, result.std, result.free,
                                   result, problem, report.get("identifiability"))
            exported = setup.export_model_files(out, result.identified)
            models += [out / name for name in exported.values()]
            files.update(exported)
            _add_joint_offsets(report, out / files["model"])
        else:  # a calibrated model left by an earlier run into the same folder must not pass for this run's
            for stale in out.glob("calibrated_model.*"):
                stale.unlink()
        if plots and setup is not None:
            try:
                files.update(_write_plots(out, report, setup, result, problem, evaluations))
            except OSError:
                raise
            except Exception as exc:  # a plot that cannot be drawn must never cost the report
                _late_warning(report, f"plotting failed: {exc}")
        shown = None
        if overlays is not None:
            try:
                from .overlay import build_overlays

                shown = build_overlays(report, overlays)
            except OSError:
                raise
            except Exception as exc:  # an overlay must never cost the report
                _late_warning(report, f"overlay images failed: {exc}")
        files["html"] = "report.html"
        report["files"] = files
        table = parameter_table_text(report.get("parameters") or [])
        write_text_atomic(out / "summary.txt", report.get("summary_text", "") + "\n" + (f"\n{table}\n" if table else ""))
        try:
            from .html import write_report_html

            write_report_html(out, report, shown, pictures=plots)
        except OSError:
            raise
        except Exception as exc:  # a page that cannot be built must never cost report.json
            files.pop("html")
            (out / "report.html").unlink(missing_ok=True)  # not an earlier run's page
            _late_warning(report, f"report.html failed: {exc}")
        write_json_atomic(out / files["report"], on_disk(report, out))
    except OSError as exc:
        _abandon(out, report, files, models, exc)
    return out / files["report"]


def _late_warning(report: dict, text: str) -> None:
    """A warning found while writing the outputs: in report.json and in the printed summary (not hidden)."""
    report.setdefault("warnings", []).append(text)
    if "summary_text" in report:
        report["summary_text"] += f"\nwarning: {text}"


def _abandon(out: Path, report: dict, files: dict, models: list, exc: OSError):
    """An output could not be written: remove this run's calibrated model files and report.html (it shows them; or
    it is an earlier run's), keep report.json when it can still be written (the failure in its warnings,
    ``files`` without them), and raise the OSError naming the file."""
    for m in models:
        m.unlink(missing_ok=True)
    for key in [k for k, v in files.items() if k not in ("report", "html") and (out / v) in models]:
        files.pop(key)
    files.pop("html", None)  # this run's page (when written) shows a model that is not kept; an earlier run's is stale
    (out / "report.html").unlink(missing_ok=True)
    path = exc.filename or "an output file"
    why = exc.strerror or str(exc)
    report["files"] = files
    report.setdefault("warnings", []).append(f"{path}: could not be written ({why}): the outputs are incomplete, no "
                                             "calibrated model kept")
    if Path(str(path)).name != files.get("report"):
        try:
            write_json_atomic(out / files["report"], on_disk(report, out))
        except OSError:
            pass
    raise OSError(exc.errno, f"{why} (the outputs in {out} are incomplete: no calibrated model kept; free some space "
                             "or choose another --out, and run again)", str(path)) from exc


#: file beside report.json holding the per-pose measurements (written before identification)
MEASUREMENTS_FILE = "measurements.json"


def on_disk(report: dict, out: Path) -> dict:
    """The report as written: per-pose measurements once. When ``out`` holds :data:`MEASUREMENTS_FILE` with the
    same poses, the ``measurements`` block keeps its counts and names the file (``poses_file``) instead of
    repeating the per-pose list (the in-memory report keeps it)."""
    m = report.get("measurements")
    path = out / MEASUREMENTS_FILE
    if not isinstance(m, dict) or "poses" not in m or not path.is_file():
        return report
    try:
        on_file = json.loads(path.read_text()).get("poses")
    except (OSError, ValueError):
        return report
    if not isinstance(on_file, list) or [p.get("pose_id") for p in on_file] != [p.get("pose_id") for p in m["poses"]]:
        return report
    return {**report, "measurements": {**{k: v for k, v in m.items() if k != "poses"}, "poses_file": MEASUREMENTS_FILE}}


def _named(plot):
    """``plot(path, ...)`` whose OSError (e.g. ENOSPC from savefig's write, which names no file) names ``path``."""
    def run(path, *args):
        try:
            return plot(path, *args)
        except OSError as exc:
            if exc.filename is None:
                raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
            raise
    return run


def _write_plots(out: Path, report: dict, setup, result, problem, evaluations) -> dict:
    from .plots import draw_all, plot_error_map, plot_parameters, plot_residuals

    plot_error_map, plot_parameters, plot_residuals = map(_named, (plot_error_map, plot_parameters, plot_residuals))

    jobs, files = [], {}
    jobs.append((plot_residuals, (out / "residuals.png", problem.residual(setup.params.nominal), result.residuals,
                                  problem.residual_kind)))
    files["residuals_plot"] = "residuals.png"
    free, ps = result.free, setup.params
    true = {p["name"]: p["true"] for p in report.get("parameters", [])}
    x_true = np.array([np.nan if true.get(n) is None else true[n] for n in ps.names])
    jobs.append((plot_parameters, (out / "parameters.png", [n for n, f in zip(ps.names, free) if f],
                                   ps.nominal[free], result.identified[free], result.std[free],
                                   None if not np.isfinite(x_true[free]).any() else x_true[free],
                                   [k for k, f in zip(ps.kinds, free) if f])))
    files["parameters_plot"] = "parameters.png"
    if evaluations:
        b, a = evaluations["before"], evaluations["after"]
        jobs.append((plot_error_map, (out / "error_map.png", b.positions_m, b.position_errors_mm,
                                      a.position_errors_mm)))
        files["error_map_plot"] = "error_map.png"
    draw_all(jobs)
    return files
