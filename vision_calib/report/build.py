"""The ONE builder of ``report.json`` (and its summary text), plus writing a run's outputs: report,
plots, calibrated model. All writes atomic.

report.json, version 2 (each value once)::

    version: "2.0"
    kind: simulation | process | process_handeye | process_poses | process_pose_pairs
    verdict: {ok, status, usable, converged, adequacy, lack_of_fit, message, n_rejected_poses, warnings: n,
              failure: kind}                                     # read first; failure only when one was found
    failure: {kind, chi2_dof, moves, tests: [{candidate, chi2_dof, fits}], message}  # experiment/gross.py
    lack_of_fit: identify.lack_of_fit dict                       # measured-data fits (simulate, process)
    intrinsics_sensitivity: {...}                                # process, simulate (experiment/camera_step.py)
    source: {scene: {name, path, robot_kind}} or {folder: ...}    # paths relative to report.json's folder
    seed: int                                                    # simulation only
    settings: {...}                                              # poses, frames, method, residual, camera, ...
    measurements: {n_poses, n_valid, n_rejected, rejected: [{pose_id, reason}], poses: [...], ...}
    identifiability: IdentifiabilityReport.to_dict()             # absent for hand-eye
    parameters: [{name, nominal, true, identified, std, free}]   # SI units; true = null on real data
    identification: {method, converged, iterations, cost_initial, cost_final, seconds, residual_kind,
                     correlation_warnings, warnings}             # no parameter values (they are above)
    accuracy: {before: {...}, after: {...}}                      # validation poses, simulation only
    residuals: {...}                                             # RMS per component (process)
    pose_residuals: {kind, how, poses: [{pose_id, chi2, p_value, translation_mm, rotation_deg | joint_deg}]}
                                                                 # every kept pose's final residual, worst first
    method_check: {methods: [ran, other], verdict, chi2, dof, p_value, max_abs_z, parameters: [{name,
                   difference, std, z}], ...}                    # H4 igm / lse: the other method, same poses
    intrinsics: {source: "recording.yaml" | "calibrated from the recording", values, std, rms_px,
                 coverage, warnings, propagated: {n_directions, in_fit, std_inflation, ...}, ...}
                                                                 # process (experiment/camera_step.py)
    outliers: [{pose_id, reason}], adequacy: {...}, variance_factor  # measured data (process, process_handeye)
    handeye: {transforms, residuals, reprojection, robot_pose_std: {source, translation_mm, rotation_deg, ...},
              closed_form_comparison: {ours, start, methods: {name: {cost, cost_minus_ours, distance}}}, ...}
                                                                 # process_handeye (experiment/handeye_step.py)
    warnings: [str]
    timings_s: {...}
    files: {report, model, residuals_plot, html, ...}           # html: report.html (report/html.py)

The machine-readable contract is the JSON Schema shipped beside this module (:data:`SCHEMA_PATH`,
``schema.json``): the keys every kind always writes, their types, open blocks allowed to grow.

Changes from version 1: the parameter table is only in ``parameters`` (``identification.parameters``
is gone); ``scene`` / ``folder`` moved under ``source``; ``verdict`` added.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Protocol

import numpy as np

from ..serialize import write_json_atomic, write_text_atomic
from ..io.model_export import write_calibrated_model
from ..io.portable import relative_source
from .text import (KIND_UNITS, figure_label, fmt_sig, handeye_values, lack_of_fit_line,
                          method_check_line)

REPORT_VERSION = "2.0"
#: JSON Schema (draft 2020-12) of report.json, shipped as package data
SCHEMA_PATH = Path(__file__).with_name("schema.json")


class IdentifiedFit(Protocol):
    """What the report reads of a measured-data fit (``experiment.steps.Identified``,
    ``experiment.handeye_step.HandeyeIdentified``): rejected [(label, reason)], adequacy
    (``identify.model_adequacy``), variance_factor, prepared, lack_of_fit and method_check (dicts or None)."""

    rejected: tuple
    adequacy: dict
    variance_factor: float
    prepared: dict | None
    lack_of_fit: dict | None
    method_check: dict | None


def parameters_table(names, nominal, x_true, result, kinds=None) -> list[dict]:
    """Per-parameter rows: name, unit (SI: "m", "rad" or "" from ``kinds``, the parameter set's kinds, when given),
    nominal, true (None on real data), identified, std, free (values in SI)."""
    out = []
    for i, n in enumerate(names):
        std = result.std[i]
        true = None if x_true is None or not np.isfinite(x_true[i]) else float(x_true[i])
        row = {"name": n, "nominal": float(nominal[i]), "true": true, "identified": float(result.identified[i]),
               "std": float(std) if np.isfinite(std) else None, "free": bool(result.free[i])}
        if kinds is not None:
            row["unit"] = {"length": "m", "angle": "rad"}.get(kinds[i], "")
        out.append(row)
    return out


def parameter_table_text(rows: list[dict]) -> str:
    """The summary's parameter table of the identified (free) rows of :func:`parameters_table`: name, unit,
    nominal, identified +- std (:func:`.text.fmt_sig`: 2 significant digits), and in simulation the true
    value and z = (identified - true) / std; lengths in mm, angles in deg (rows without a unit: SI). Empty when
    nothing was identified."""
    free = [r for r in rows if r.get("free")]
    if not free:
        return ""
    sim = any(r.get("true") is not None for r in free)
    head = f"{'parameter':<18} {'unit':>4} {'nominal':>12} {'identified':>12} {'+- std':>10}"
    head += f" {'true':>12} {'z':>6}" if sim else ""
    lines = ["identified parameters (" + ("simulation: true values and z = (identified - true) / std" if sim
                                         else "measured data") + "):", head]
    for r in free:
        unit = r.get("unit")
        kind = {"m": "length", "rad": "angle"}.get(unit)
        shown, f, fmt = KIND_UNITS.get(kind, (unit or "SI", 1.0, "12.6g"))
        std = r.get("std")
        line = (f"{r['name']:<18} {shown:>4} {r['nominal'] * f:{fmt}} {r['identified'] * f:{fmt}} "
                f"{fmt_sig(None if std is None else std * f):>10}")
        if sim:
            t = r.get("true")
            z = (r["identified"] - t) / std if t is not None and std else None
            line += f" {'n/a' if t is None else format(t * f, fmt):>12} {'n/a' if z is None else format(z, '+.2f'):>6}"
        lines.append(line)
    return "\n".join(lines)


def identification_block(result) -> dict:
    """The result's summary without its parameter values (they are in ``parameters``)."""
    d = result.to_dict()
    d.pop("parameters", None)
    return d


def residual_stats(r, kind) -> dict:
    """RMS per component of final residuals r (N, m) SI: mm / deg for pose residuals, deg for joints."""
    if kind in ("pose", "position"):
        d = {"translation_rms_mm": [float(v) for v in np.sqrt(np.mean(r[:, :3] ** 2, axis=0)) * 1e3]}
        if r.shape[1] == 6:
            d["rotation_rms_deg"] = [float(v) for v in np.degrees(np.sqrt(np.mean(r[:, 3:] ** 2, axis=0)))]
        return d
    return {"joint_rms_deg": [float(v) for v in np.degrees(np.sqrt(np.mean(r**2, axis=0)))]}


def residuals_line(res: dict) -> str:
    """One summary line of a :func:`residual_stats` block, each figure with what it is and its unit
    (:func:`.text.figure_label`)."""
    def part(k, vals):
        label, unit, f = figure_label(k)
        axes = "joints 1..n" if k.startswith("joint") else "x, y, z"
        return f"{label} {axes} " + ", ".join(f"{x * f:.4g}" for x in vals) + (f" {unit}" if unit else "")

    parts = [part(k, vals) for k, vals in res.items()]
    where = ("" if set(res) == {"joint_rms_deg"} else
             ", per axis of the measured transform's left frame")
    return f"residual RMS after the fit (measured - model{where}): " + "; ".join(parts)


#: per-pose residual columns of report.json's ``pose_residuals`` per residual kind: (key, columns, factor from SI)
POSE_RESIDUAL_COLUMNS = {
    "pose": (("translation_mm", slice(0, 3), 1e3), ("rotation_deg", slice(3, 6), float(np.degrees(1.0)))),
    "position": (("translation_mm", slice(0, 3), 1e3),),
    "joint": (("joint_deg", slice(None), float(np.degrees(1.0))),),
}


def pose_residuals_block(result) -> dict:
    """Final residual of every pose the fit kept, worst first (JSON-ready): {kind, how, poses: [{pose_id, chi2
    (squared norm of the whitened residual; null when the fit gave none), p_value (upper tail of chi2(m), m the
    residual components per pose), translation_mm / rotation_deg (pose kinds: norm of that part) or joint_deg}]};
    sorted by chi2 (else by the first norm), largest first."""
    from scipy.stats import chi2 as chi2_dist

    r = np.atleast_2d(np.asarray(result.residuals, float))
    kind = result.residual_kind
    cols = [c for c in POSE_RESIDUAL_COLUMNS.get(kind, POSE_RESIDUAL_COLUMNS["joint"])
            if c[1].stop is None or r.shape[1] >= c[1].stop]
    pc = None if result.pose_chi2 is None else np.asarray(result.pose_chi2, float)
    labels = list(result.labels) if result.labels else [f"#{k}" for k in range(len(r))]
    rows = []
    for k, lab in enumerate(labels[:len(r)]):
        c2 = None if pc is None or not np.isfinite(pc[k]) else float(pc[k])
        row = {"pose_id": str(lab), "chi2": c2,
               "p_value": None if c2 is None else float(chi2_dist.sf(c2, r.shape[1]))}
        row.update({key: float(np.linalg.norm(r[k, sl]) * f) for key, sl, f in cols})
        rows.append(row)
    first = cols[0][0] if cols else None
    rows.sort(key=lambda e: -(e["chi2"] if e["chi2"] is not None else (e.get(first) or 0.0)))
    return {"kind": kind, "how": "final residual (measured - model) per pose; chi2: squared norm of the pose's "
            "whitened residual (its measurement covariance), expected about m = " + str(r.shape[1]) +
            " for a right model", "poses": rows}


def measurements_block(pms, **extra) -> dict:
    """Per-pose measurement summary of a list of measure.PoseMeasurement."""
    rejected = [{"pose_id": pm.pose_id, "reason": pm.reason} for pm in pms if not pm.valid]
    # corners the per-view rule dropped (measure/view_checks.py) from views it kept
    dropped = [{"pose_id": pm.pose_id, "frame_index": f["frame_index"], "corners": f["dropped_corners"]}
               for pm in pms for f in pm.frames if f.get("dropped_corners")]
    return {"n_poses": len(pms), "n_valid": len(pms) - len(rejected), "n_rejected": len(rejected),
            "rejected": rejected, "dropped_corners": dropped, **extra, "poses": [pm.to_dict() for pm in pms]}


def result_is_finite(result) -> bool:
    """Whether the identified values, their std (where free) and the final cost are finite."""
    free = np.asarray(result.free, bool)
    return bool(np.all(np.isfinite(result.identified)) and np.all(np.isfinite(np.asarray(result.std)[free]))
                and np.isfinite(result.cost_final))


#: more rejected poses (measurement failures, detection included, plus outliers) than this fraction: a "warning"
MAX_REJECTED_FRACTION = 0.3


def verdict(result, measurements: dict | None = None, identified: IdentifiedFit | None = None, warnings=(), adequacy: dict | None = None,
            lack_of_fit: dict | None = None, failure: dict | None = None) -> dict:
    """What to read first. status: "failed" (not converged or not finite: no calibrated model is written),
    "warning" (the chi-square model-adequacy test says the model does not explain the data: chi2/dof above
    its expected interval; the calibrated model is written, but it may be worse than the nominal one), else
    "ok"; ok = (status == "ok"); usable = converged with finite values (a calibrated model is written). Also
    the poses rejected (measurement + outliers), the adequacy verdict, a note ("too small": the noise is
    overestimated, not a failure) and the warning count. adequacy: ``identify.model_adequacy`` dict
    (default: ``identified.adequacy``). lack_of_fit: ``identify.lack_of_fit`` dict (default:
    ``identified.lack_of_fit``): a significant term (the residuals depend on a joint or on the image position)
    also makes the status "warning", its message naming the term. failure: a gross input error found after the
    fit (``experiment.gross.gross_failure``: {kind, message, ...}): status "failed", not usable (no model written)."""
    finite = result_is_finite(result)
    n_out = len(identified.rejected) if identified is not None else 0
    if adequacy is None and identified is not None:
        adequacy = identified.adequacy
    if lack_of_fit is None and identified is not None:
        lack_of_fit = identified.lack_of_fit
    usable = bool(result.converged and finite) and failure is None
    adq = (adequacy or {}).get("verdict")
    lof = bool((lack_of_fit or {}).get("significant"))
    tail = ((adequacy or {}).get("pose_tail") or {}) if adq == "consistent" else {}
    n_all = (measurements or {}).get("n_poses", 0)
    n_rej = (measurements or {}).get("n_rejected", 0) + n_out
    many = bool(n_all) and n_rej > MAX_REJECTED_FRACTION * n_all  # detection failures count as rejected views
    status = "failed" if not usable else ("warning" if adq == "too large" or lof or many else "ok")
    why = ([misfit_message(adequacy)] if adq == "too large" else []) + ([lack_of_fit["message"]] if lof else [])
    why += [f"{n_rej} of {n_all} poses rejected (more than {MAX_REJECTED_FRACTION:.0%}; measurement and outliers): "
            "the result rests on the views that were easy to measure"] if many else []
    message = getattr(result, "message", "") if not usable else "; ".join(why)
    if failure is not None:
        message = failure["message"]
    out = {"ok": status == "ok", "status": status, "usable": usable, "converged": bool(result.converged),
           "finite": finite, "n_rejected_poses": (measurements or {}).get("n_rejected", 0) + n_out,
           "n_outliers": n_out, "adequacy": adq, "lack_of_fit": None if lack_of_fit is None else lof,
           "message": message,
           "warnings": len(set(warnings) | set(result.warnings))}  # a warning given by both: counted once
    if failure is not None:
        out["failure"] = failure["kind"]
    if tail.get("significant"):  # named, not a verdict: measured on clean H4 scenes it fires on most seeds (the
        # image-measured poses' covariance misses some views' error), which a warning would teach users to ignore
        out["note"] = tail["message"]
    if adq == "too small":
        lo, hi = adequacy.get("expected_chi2_dof") or (float("nan"), float("nan"))
        out["note"] = (f"chi2/dof {adequacy['chi2_dof']:.3g} below its expected {lo:.2f}-{hi:.2f} (two-sided p "
                       f"{adequacy['p_value']:.2g}): the residuals are smaller than the measurement covariance "
                       "predicts; the std are not reduced for it (they may be pessimistic)")
    return out


def misfit_message(adequacy: dict) -> str:
    """'model does not explain the data (chi2/dof X, expected lo-hi, p Y); largest residual poses: a, b, c'
    for a "too large" ``identify.model_adequacy`` dict."""
    lo, hi = adequacy.get("expected_chi2_dof") or (float("nan"), float("nan"))
    worst = ", ".join(str(w["label"]) for w in adequacy.get("worst_poses", [])[:5]) or "n/a"
    return (f"model does not explain the data (chi2/dof {adequacy['chi2_dof']:.3g}, expected {lo:.2f}-{hi:.2f}, "
            f"two-sided p {adequacy['p_value']:.2g}); largest residual poses: {worst}")


def build_report(kind: str, *, source: dict, settings: dict, result, measurements: dict | None = None,
                 identifiability=None, parameters: list | None = None, accuracy: dict | None = None,
                 residuals: dict | None = None, warnings=(), extra: dict | None = None, timings: dict | None = None,
                 seed: int | None = None, identified: IdentifiedFit | None = None, motion: dict | None = None,
                 failure: dict | None = None) -> dict:
    """report.json content (see the module docstring) with its ``summary_text``. identifiability: an
    IdentifiabilityReport (or None); accuracy: {"before": Evaluation, "after": Evaluation}; identified:
    the :class:`IdentifiedFit` of a measured-data fit (outliers, adequacy, variance factor);
    motion: the motion-consistency check (``experiment.checks``); failure: a gross input error
    (``experiment.gross``), kept as ``failure`` and read by the verdict."""
    warnings = list(dict.fromkeys(warnings))  # each once, in order
    report = {
        "version": REPORT_VERSION,
        "kind": kind,
        "verdict": verdict(result, measurements, identified, warnings, failure=failure),
        "source": source,
    }
    if failure is not None:
        report["failure"] = failure
    if seed is not None:
        report["seed"] = int(seed)
    report["settings"] = settings
    if measurements is not None:
        report["measurements"] = measurements
    if identifiability is not None:
        report["identifiability"] = identifiability.to_dict()
    if parameters is not None:
        report["parameters"] = parameters
    report["identification"] = identification_block(result)
    if identified is not None:
        report["outliers"] = [{"pose_id": lab, "reason": why} for lab, why in identified.rejected]
        report["adequacy"] = identified.adequacy
        report["variance_factor"] = identified.variance_factor
        if identified.lack_of_fit is not None:
            report["lack_of_fit"] = identified.lack_of_fit
        if identified.prepared:
            report["prepared"] = identified.prepared
        if identified.method_check:
            report["method_check"] = identified.method_check
    if motion:
        report["motion_check"] = motion
    if accuracy is not None:
        report["accuracy"] = {k: v.to_dict() for k, v in accuracy.items()}
    if residuals is not None:
        report["residuals"] = residuals
    if np.ndim(getattr(result, "residuals", None)) == 2 and len(result.residuals):
        report["pose_residuals"] = pose_residuals_block(result)
    report.update(extra or {})
    report["warnings"] = warnings
    if timings is not None:
        report["timings_s"] = timings
    report["summary_text"] = summary_text(report)
    return report


def _what(report) -> str:
    src = report["source"]
    if "scene" in src:
        s = report["settings"]
        return (f"scene {src['scene']['name']}" + (f"  seed {report['seed']}" if "seed" in report else "")
                + f"  poses {s.get('poses')}" + (f"  frames {s['frames']}" if s.get("frames") else "")
                + f"  method {s.get('method')}")
    if "flange_csv" in src:  # a pose-pair file (process-poses, hand-eye)
        s = report["settings"]
        return (f"pose pairs {Path(str(src['file'])).name}  poses {s.get('poses')}  mount {s.get('mount')}  "
                f"noise {s.get('noise')}")
    return f"recording {Path(str(src.get('folder'))).name}"  # the folder's name: no absolute path in summary.txt


def verdict_line(v: dict) -> str:
    """First line of a summary: 'verdict: ok; ...', 'verdict: WARNING: model does not explain the data (...)'
    or 'verdict: NOT CONVERGED; ... -- why' (v: the report's ``verdict`` block)."""
    status = v.get("status", "ok" if v["ok"] else "failed")
    if status == "failed":
        state = (f"FAILED ({v['failure']})" if v.get("failure") else
                 "NOT FINITE" if not v.get("finite", True) else "NOT CONVERGED")
    else:
        state = "WARNING: " + v["message"] if status == "warning" else "ok"
    adequacy = f"; model adequacy: {v['adequacy']}" if v.get("adequacy") else ""
    note = f" (note: {v['note']})" if v.get("note") else ""
    if v.get("adequacy") == "consistent" and v.get("note"):  # which holds: the whole set; the note: some poses
        adequacy, note = "; model adequacy: consistent over all poses (chi2/dof in its band)", f"; but {v['note']}"
    return (f"verdict: {state}; {v['n_rejected_poses']} poses rejected ({v.get('n_outliers', 0)} as outliers)"
            f"{adequacy}{note}; {v['warnings']} warnings" + (f" -- {v['message']}" if status == "failed" and
                                                             v.get("message") else ""))


def summary_text(report: dict) -> str:
    """One screen: the verdict first, then what was run, measured, identified and how accurate."""
    v, ident = report["verdict"], report["identification"]
    lines = [verdict_line(v), _what(report)]
    m = report.get("measurements")
    if m:
        # no second rejected count: the verdict line gives it (measurement failures + outliers)
        lines.append(f"measurement: {m['n_valid']} of {m['n_poses']} poses measured"
                     + (f" ({m['n_rejected']} failed, below; counted in the verdict's rejected poses)"
                        if m["n_rejected"] else ""))
        lines += [f"  pose {rj['pose_id']}: {rj['reason']}" for rj in m["rejected"][:10]]
        if m.get("dropped_corners"):
            dc = m["dropped_corners"]
            lines.append(f"  {sum(len(d['corners']) for d in dc)} corners off the target-plane homography dropped "
                         f"in {len(dc)} views (first: pose {dc[0]['pose_id']} frame {dc[0]['frame_index']}, "
                         f"ids {[c['id'] for c in dc[0]['corners']]})")
        acc = m.get("accuracy_vs_truth")
        if acc:
            lines.append("  measured target pose vs truth, RMS per axis of the camera frame (x, y, z): t = "
                         + ", ".join(f"{x:.3f}" for x in acc["translation_rms_mm"]) + " mm; r = "
                         + ", ".join(f"{x:.4f}" for x in acc["rotation_rms_deg"]) + " deg")
    if "intrinsics" in report:
        lines.append(_intrinsics_line(report["intrinsics"]))
    lines += [f"warning: {w}" for w in report.get("warnings", [])]
    idf = report.get("identifiability")
    if idf:
        pri = idf.get("prior_parameters") or []
        lines.append(f"identifiability: {idf['n_params']} parameters"
                     + (f" ({len(pri)} with a prior: {', '.join(pri)})" if pri else "")
                     + f", rank {idf['rank']}"
                     + (f"; not identifiable: {', '.join(idf['non_identifiable'])}" if idf["non_identifiable"] else ""))
        lines.append(f"  condition number {idf['condition_number']:.3g}"
                     + (f" (of the {idf['condition_number_of']})" if idf.get("condition_number_of") else ""))
    lines.append(f"identification ({ident['method']}): converged={ident['converged']} iterations={ident['iterations']} "
                 f"cost {ident['cost_initial']:.4g} at the start -> {ident['cost_final']:.4g} (half the sum of squared "
                 "whitened residuals, no unit; about half the residual dof when the model fits)")
    check = method_check_line(report["method_check"]) if "method_check" in report else None
    given = set(report.get("warnings", []))  # printed above: once
    lines += [f"warning: {w}" for w in ident.get("warnings", []) if w != check and w not in given]  # check: below
    if check:
        lines.append(check)
    if report.get("lack_of_fit"):
        lines.append(lack_of_fit_line(report["lack_of_fit"]))
    largest = (report.get("intrinsics_sensitivity") or {}).get("largest")
    if largest:
        lines.append("intrinsics sensitivity (largest shift per px, in std): " + ", ".join(
            f"{k} -> {v['parameter']} {v['std_per_px']:+.3g}" for k, v in largest.items()))
    if "residuals" in report:
        lines.append(residuals_line(report["residuals"]))
    if "reprojection" in report:
        from ..measure.reprojection import reprojection_line

        lines.append(reprojection_line(report["reprojection"]))
    if "accuracy" in report:
        b, a = report["accuracy"]["before"], report["accuracy"]["after"]
        lines.append(f"validation ({b['n_poses']} poses, nominal -> identified): "
                     + ", ".join(_before_after(k, b, a, {"mm": ".3f", "deg": ".4f"}.get(figure_label(k)[1], ".4g"))
                                 for k in ("position_rms_mm", "position_max_mm", "rotation_rms_deg") if k in a))
        crit = [k for k in a if k not in _ACCURACY_SHOWN and k in b]  # the kind's criteria (H4: V1, V2, V3)
        if crit:
            vm = report.get("validation_measurements")
            kind = ((report.get("source") or {}).get("scene") or {}).get("robot_kind")
            how = [f"robot kind {kind}"] * bool(kind) + [f"V1/V2 from {vm['n_valid']} of {vm['n_poses']} validation "
                                                          "poses measured from images"] * bool(vm)
            parts = [_before_after(k, b, a, ".3g") + (f" ({100 * (1 - a[k] / b[k]):.1f} % better)"
                                                      if k == "V2_rad" and b[k] > 0 else "") for k in crit]
            lines.append("criteria" + (f" ({'; '.join(how)})" if how else "") + ": " + ", ".join(parts))
    if "synthetic_reference" in report:
        lines += _reference_lines(report)
    if "handeye" in report:
        lines += _handeye_lines(report)
    if "timings_s" in report and "total" in report["timings_s"]:
        lines.append(f"time: {report['timings_s']['total']:.1f} s")
    return "\n".join(lines)


#: accuracy keys of the summary's validation line (the rest of the block: the kind's criteria, their own line)
_ACCURACY_SHOWN = ("position_rms_mm", "position_max_mm", "rotation_rms_deg", "rotation_max_deg", "n_poses",
                   "position_rms_registered_mm")  # the last in report.json only (the audit reads it)


def _before_after(key: str, b: dict, a: dict, fmt: str) -> str:
    """'label b -> a unit' of one figure key of two dicts, in its display unit (:func:`.text.figure_label`)."""
    label, unit, f = figure_label(key)
    return f"{label} {b[key] * f:{fmt}} -> {a[key] * f:{fmt}}" + (f" {unit}" if unit else "")


def _reference_lines(report: dict) -> list[str]:
    """Summary lines of the ``synthetic_reference`` block (experiment.simulate): how it was drawn, the median
    and range over its draws of the validation position RMS (and V2 when the kind has it)."""
    r = report["synthetic_reference"]
    if "sigma_mm" in r:  # version-2.0 reports before the per-pose covariance draws: one draw, pooled sigma
        return [f"synthetic reference (no images, sigma {r['sigma_mm']:.3f} mm / {r['sigma_deg']:.4f} deg): "
                f"position RMS {r['accuracy_after']['position_rms_mm']:.3f} mm"]
    a, rg = r["accuracy_after"], r["range"]
    out = (f"synthetic reference (no images; noise drawn from each measured pose's covariance, {r['draws']} draws): "
           f"position RMS median {a['position_rms_mm']:.3f} mm (range {rg['position_rms_mm'][0]:.3f}-"
           f"{rg['position_rms_mm'][1]:.3f})")
    if "V2_rad" in a:
        label, unit, f = figure_label("V2_rad")
        out += (f", {label.split(':')[0]} median {a['V2_rad'] * f:.3g} {unit} (range {rg['V2_rad'][0] * f:.3g}-"
                f"{rg['V2_rad'][1] * f:.3g})")
    return [out]


def _intrinsics_line(block: dict) -> str:
    """One summary line of the ``intrinsics`` block (process: where the camera intrinsics came from)."""
    v, s = block["values"], block.get("std")
    names = list(v)
    if s is None:
        return (f"intrinsics ({block['source']}): " + ", ".join(f"{k} {v[k]:.2f}" for k in names[:4]) + " px; dist "
                + ", ".join(f"{v[k]:.4g}" for k in names[4:]))
    prop = block.get("propagated") or {}
    how = (f"; their uncertainty {'is included in the fit' if prop.get('in_fit') else 'is added to the std'} "
           f"({prop['n_directions']} directions)") if prop else ""
    views = (f", {block['n_views_used']} views, RMS {block['rms_px']:.3f} px"
             if block.get("n_views_used") is not None and block.get("rms_px") is not None else "")
    return (f"intrinsics ({block['source']}{views}): "
            + ", ".join(f"{k} {v[k]:.2f} ± {fmt_sig(s[k])}" for k in names[:4]) + " px; dist "
            + ", ".join(f"{k} {v[k]:.4g} ± {fmt_sig(s[k])}" for k in names[4:]) + how)


def _handeye_lines(report: dict) -> list[str]:
    he = report["handeye"]
    names = (he["A"], he["B"]) if report["settings"]["mount"] == "eye_in_hand" else ("T_base_cam", "T_flange_target")
    lines = []
    for name in names:
        t = he["transforms"][name]
        xyz, rpy = handeye_values(t)
        lines.append(f"{name}: xyz = " + ", ".join(x for x, _ in xyz) + " mm (std " + ", ".join(s for _, s in xyz)
                     + "); rpy = " + ", ".join(x for x, _ in rpy) + " deg (std " + ", ".join(s for _, s in rpy) + ")")
    rob = he.get("robot_pose_std")
    if rob:
        est = (f" ± {fmt_sig(rob['std_translation_mm'])}" if rob.get("std_translation_mm") is not None else "",
               f" ± {fmt_sig(rob['std_rotation_deg'])}" if rob.get("std_rotation_deg") is not None else "")
        tr = (f"{rob['translation_mm']:.3f}{est[0]} mm" if rob.get("translation_mm") is not None
              else "translation in the measured poses' std (not separable)")
        lines.append(f"robot pose error ({rob['source']}): {tr}, {rob['rotation_deg']:.4f}{est[1]} deg per axis "
                     "(in the weights)")
    mn = he.get("measured_noise")
    if mn:
        lines.append(f"measured poses' noise ({mn['source']}, std per axis of the {mn['frame']} frame): translation "
                     + ", ".join(f"{v:.3g} ± {fmt_sig(s)}" for v, s in
                                 zip(mn["translation_mm"], mn["std_translation_mm"]))
                     + " mm; rotation " + ", ".join(f"{v:.3g} ± {fmt_sig(s)}" for v, s in
                                                    zip(mn["rotation_deg"], mn["std_rotation_deg"])) + " deg")
    cf = he.get("closed_form_comparison")
    if cf:
        ok = {m: v for m, v in cf["methods"].items() if "cost" in v}
        if ok:
            best = min(ok, key=lambda m: ok[m]["cost"])
            lines.append(f"closed forms (OpenCV): started from {cf['start']}; cheapest {best}, cost "
                         f"{ok[best]['cost']:.4g} vs ours {cf['ours']:.4g}")
    return lines


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

            write_report_html(out, report, shown)
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
