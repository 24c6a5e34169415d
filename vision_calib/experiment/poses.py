"""Measured poses without images (``vision-calib process-poses FILE.yaml --out DIR``): joint readings +
measured poses (or positions) from a file (:mod:`vision_calib.io.measured_poses`) -> identifiability
-> identification -> k-fold held-out validation -> report.json, calibrated_model.yaml, plots.

Held-out validation: the poses are split into k folds (seeded permutation); for each fold the SAME
base parameter set as the whole-data identification (its identifiability analysis) is identified on
the other folds, and the residuals (measured - model) of the held-out poses are compared under the
nominal parameters ("before") and the fold's identified ones ("after"). Residuals are those of the
setup's problem: errors of the chain's measured transform (eye-in-hand: T_target_cam; fixed camera:
T_cam_target) in its reference frame, so they include the measurement noise.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import ConfigError, DataError
from ..identify.identifiability import IdentifiabilityReport
from ..io.measured_poses import chain_direction, misreadings, read_measured_poses
from ..io.report import build_report, parameters_table, residual_stats, write_report
from ..rig import Measurements, Setup
from .checks import drop_inconsistent, duplicate_poses, motion_verdict
from .gross import gross_failure
from .steps import check_method, identify_measurements


def _stats(r: np.ndarray) -> dict:
    """n_poses and mean / RMS / max of the position [mm] (and rotation [deg] for 6-component) residual norms
    of r (N, m) SI, one norm per pose."""
    dp = np.linalg.norm(r[:, :3], axis=1) * 1e3
    out = {"n_poses": int(len(r)), "position_mean_mm": float(dp.mean()),
           "position_rms_mm": float(np.sqrt(np.mean(dp**2))), "position_max_mm": float(dp.max())}
    if r.shape[1] == 6:
        dr = np.degrees(np.linalg.norm(r[:, 3:], axis=1))
        out |= {"rotation_mean_deg": float(dr.mean()), "rotation_rms_deg": float(np.sqrt(np.mean(dr**2))),
                "rotation_max_deg": float(dr.max())}
    return out


def fold_indices(n: int, folds: int, seed: int) -> list[np.ndarray]:
    """k sorted index arrays partitioning range(n) (seeded permutation, sizes differing by at most 1)."""
    perm = np.random.default_rng(int(seed)).permutation(n)
    return [np.sort(p) for p in np.array_split(perm, folds)]


def kfold_validation(setup: Setup, meas: Measurements, method: str, residual: str,
                     analysis: IdentifiabilityReport | None, folds: int, seed: int,
                     outliers: Sequence[tuple[str, str]] = ()) -> dict:
    """Held-out residuals before (nominal) / after (identified on the other folds with the base parameter
    set of ``analysis``, the whole data's IdentifiabilityReport) of EVERY pose of ``meas``, per fold and
    overall. ``outliers``: labels of the poses the whole-data fit flagged; they are left out of every
    training set but still held out and predicted in their own fold, so ``overall`` counts all poses and
    ``without_outliers`` (None when there is none) the others.
    {folds, seed, residual_of, outliers: [label], per_fold: [{fold, n_train, n_test, n_outliers_held_out,
    converged, n_identified, before, after}], overall: {n_poses, before, after},
    without_outliers: {n_poses, excluded: [label], before, after} | None}; before/after: :func:`_stats`."""
    labels = list(meas.labels) or list(range(len(meas.T_cam_target)))
    flagged = set(outliers)
    unknown = flagged - set(labels)
    if unknown:
        raise ValueError(f"k-fold validation: outliers {sorted(map(str, unknown))} are not poses of the data")
    base = setup.params.mask(analysis.base_parameters)
    params = setup.params.only_free([nm for nm, b in zip(setup.params.names, base) if b])
    per_fold, rb_all, ra_all, test_all = [], [], [], []
    parts = fold_indices(len(labels), folds, seed)
    for k, test in enumerate(parts):
        train = np.array([i for j, p in enumerate(parts) if j != k for i in p if labels[i] not in flagged], int)
        train.sort()
        result = identify_measurements(setup, meas.subset(train), method, residual, analysis, robust=False,
                                       context=f"k-fold validation, fold {k + 1} of {folds}", cross_check=False).result
        held = setup.problem(meas.subset(test), residual, params=params)
        rb, ra = held.residual(params.nominal), held.residual(result.identified)
        rb_all.append(rb)
        ra_all.append(ra)
        test_all.append(test)
        per_fold.append({"fold": k + 1, "n_train": int(len(train)), "n_test": int(len(test)),
                         "n_outliers_held_out": int(sum(labels[i] in flagged for i in test)),
                         "converged": bool(result.converged),
                         "n_identified": int(np.sum(result.free)), "before": _stats(rb), "after": _stats(ra)})
    rb, ra, idx = np.concatenate(rb_all), np.concatenate(ra_all), np.concatenate(test_all)
    overall = {"n_poses": int(len(idx)), "before": _stats(rb), "after": _stats(ra)}
    clean = None
    if flagged:
        keep = np.array([labels[i] not in flagged for i in idx])
        clean = {"n_poses": int(keep.sum()), "excluded": [labels[i] for i in sorted(idx[~keep])],
                 "before": _stats(rb[keep]), "after": _stats(ra[keep])}
    return {"folds": int(folds), "seed": int(seed), "residual_of": chain_direction(setup),
            "outliers": [lab for lab in labels if lab in flagged], "per_fold": per_fold, "overall": overall,
            "without_outliers": clean}


def _fmt(b: dict, a: dict) -> str:
    """'position mean b -> a, RMS b -> a, max b -> a mm; rotation ... deg' (before -> after)."""

    def one(key, unit, nd):
        return (f"{key} mean {b[key + '_mean_' + unit]:.{nd}f} -> {a[key + '_mean_' + unit]:.{nd}f}, "
                f"RMS {b[key + '_rms_' + unit]:.{nd}f} -> {a[key + '_rms_' + unit]:.{nd}f}, "
                f"max {b[key + '_max_' + unit]:.{nd}f} -> {a[key + '_max_' + unit]:.{nd}f} {unit}")

    s = one("position", "mm", 3)
    return s + ("; " + one("rotation", "deg", 4) if "rotation_rms_deg" in b else "")


def kfold_lines(kf: dict) -> list[str]:
    """Summary lines of :func:`kfold_validation`: held-out mean / RMS / max before -> after over all poses,
    then without the flagged outliers (naming them), then per fold."""
    o, c, out = kf["overall"], kf.get("without_outliers"), kf.get("outliers") or []
    names = ", ".join(map(str, out[:10])) + (", ..." if len(out) > 10 else "")
    lines = [f"held-out {kf['folds']}-fold validation (seed {kf['seed']}, residuals of {kf['residual_of']}"
             + (f"; the {len(out)} flagged outlier poses are in no training set" if out else "") + "):",
             f"  all {o['n_poses']} poses" + (f" (the {len(out)} flagged outliers included)" if out else
                                              " (none flagged as an outlier)") + ": " + _fmt(o["before"], o["after"])]
    if c:
        lines.append(f"  without the {len(c['excluded'])} flagged outliers ({names}), {c['n_poses']} poses: "
                     + _fmt(c["before"], c["after"]))
    lines += [f"  fold {f['fold']} ({f['n_test']} poses held out"
              + (f", {f['n_outliers_held_out']} flagged outlier{'s' if f['n_outliers_held_out'] > 1 else ''}"
                 if f.get("n_outliers_held_out") else "")
              + "): " + _fmt(f["before"], f["after"]) + ("" if f["converged"] else " NOT CONVERGED")
              for f in kf["per_fold"]]
    return lines


#: what sets the length scale of a measured-pose file (named by the motion check's scale refusal)
SCALE_HINT = "the x,y,z columns of the CSV against the scene's robot lengths"


def screen_motions(setup, mp):
    """The motion-consistency check of ``process`` on a measured-pose file (``checks.motion_verdict``; full
    poses only: position rows carry no rotation). Never raises: a refusal goes to the gross-error diagnosis
    (``gross.gross_failure``), which also runs the check on each alternative reading of the file.
    Returns (measurements without the poses whose motion does not follow their joints, [(label, reason)] of
    those, the check's record (None for positions), the refusal or None, the check as
    ``f(Measurements) -> refusal | None`` (None for positions))."""
    meas = mp.measurements
    if mp.position_only:
        return meas, [], None, None, None

    def check(m):
        return motion_verdict(setup, m, "the motion-consistency check", SCALE_HINT)[1]

    motion, refusal = motion_verdict(setup, meas, "the motion-consistency check", SCALE_HINT)
    if refusal:
        return meas, [], {**motion, "refusal": refusal}, refusal, check
    try:
        kept, inconsistent = drop_inconsistent(meas, motion, "the motion-consistency check")
    except DataError as exc:  # too many poses inconsistent: the readings, not some poses, are wrong
        return meas, [], {**motion, "refusal": str(exc)}, str(exc), check
    return kept, inconsistent, motion, None, check


def process_poses(path: str | Path, out_dir: str | Path | None, method: str | None = None, folds: int | None = None,
                  plots: bool = True, fix_unidentifiable: bool = False) -> dict:
    """Identify a robot from a measured-pose file (YAML + CSV); writes DIR/report.json, summary.txt,
    calibrated_model.yaml (+ plots). folds: k of the held-out validation (default: the file's)."""
    t0 = time.perf_counter()
    mp = read_measured_poses(path)
    scene, setup, meas = mp.scene, mp.scene.setup, mp.measurements
    method = check_method(setup, method or scene.identification.method, "--method")
    folds = int(folds or mp.folds)
    if not 2 <= folds <= len(mp.ids):
        raise ConfigError(f"{mp.path}: folds: {folds} folds need 2 <= folds <= {len(mp.ids)} (the number of poses)")
    residual = setup.residual_for(method, mp.residual)
    where = str(mp.path)
    screened, inconsistent, motion, refusal, check = screen_motions(setup, mp)
    ident = identify_measurements(setup, screened, method, residual, where=where,
                                  fix_unidentifiable=fix_unidentifiable, rejected=inconsistent)
    result, problem, rep, setup = ident.result, ident.problem, ident.analysis, ident.setup
    t_id = time.perf_counter() - t0
    failure = gross_failure(setup, screened, ident, mp.residual, where, misreadings(mp),
                            untested=f"a wrong robot file or scene mounts ({scene.path}), joint columns in another "
                                     "order, joint or length units (checked up front only for gross factors)",
                            motion_refusal=refusal, motion_check=check)
    kf = None if failure else kfold_validation(setup, meas, method, mp.residual, rep, folds, mp.seed,
                                               outliers=[r[0] for r in ident.rejected])
    ps = setup.params
    n = len(mp.ids)
    report = build_report(
        "process_poses",
        source={"file": str(mp.path), "csv": str(mp.csv_path),
                "scene": {"name": scene.name, "path": str(scene.path), "robot_kind": setup.kind}},
        settings={"poses": n, "frames": None, "method": method, "residual": residual, "measured": mp.measured,
                  "residual_of": chain_direction(setup), "units": mp.units, "noise": mp.sigma_source,
                  "folds": folds, "fold_seed": mp.seed},
        measurements={"n_poses": n, "n_valid": n, "n_rejected": 0, "rejected": [], "measured": mp.measured,
                      "noise": mp.sigma_source, "pose_ids": list(mp.ids)},
        identifiability=rep, parameters=parameters_table(ps.names, ps.nominal, None, result, ps.kinds), result=result,
        identified=ident, warnings=duplicate_poses(meas), motion=motion,
        residuals=residual_stats(result.residuals, problem.residual_kind), extra={"kfold": kf},
        timings={"identify": t_id, "total": time.perf_counter() - t0}, failure=failure)
    report["summary_text"] += "\n" + ("\n".join(kfold_lines(kf)) if kf else
                                      "held-out validation skipped: the fit failed (see the verdict)")
    write_report(Path(out_dir), report, setup, result, problem, plots=plots)
    return report


__all__ = ["process_poses", "kfold_validation", "fold_indices", "kfold_lines"]
