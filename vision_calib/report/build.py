"""The ONE builder of ``report.json``: its blocks, the verdict, and :func:`build_report` (its summary text from
:mod:`.summary`; writing a run's outputs: :mod:`.write`).

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

from pathlib import Path
from typing import Protocol

import numpy as np

from .summary import summary_text

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
