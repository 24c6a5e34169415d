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

import numpy as np

from ..errors import ConfigError
from ..io.measured_poses import chain_direction, misreadings, read_measured_poses
from ..io.report import build_report, parameters_table, residual_stats, write_report
from .checks import duplicate_poses
from .gross import gross_failure
from .steps import check_method, identify_measurements


def _rms(r: np.ndarray) -> dict:
    """RMS / max of the position [mm] (and rotation [deg] for 6-component) residual norms of r (N, m) SI."""
    dp = np.linalg.norm(r[:, :3], axis=1) * 1e3
    out = {"position_rms_mm": float(np.sqrt(np.mean(dp**2))), "position_max_mm": float(dp.max())}
    if r.shape[1] == 6:
        dr = np.degrees(np.linalg.norm(r[:, 3:], axis=1))
        out |= {"rotation_rms_deg": float(np.sqrt(np.mean(dr**2))), "rotation_max_deg": float(dr.max())}
    return out


def fold_indices(n: int, folds: int, seed: int) -> list[np.ndarray]:
    """k sorted index arrays partitioning range(n) (seeded permutation, sizes differing by at most 1)."""
    perm = np.random.default_rng(int(seed)).permutation(n)
    return [np.sort(p) for p in np.array_split(perm, folds)]


def kfold_validation(setup, meas, method: str, residual: str, analysis, folds: int, seed: int) -> dict:
    """Held-out residuals before (nominal) / after (identified on the other folds with the base parameter
    set of ``analysis``, the whole data's IdentifiabilityReport) per fold and overall:
    {folds, seed, per_fold: [...], overall: {before, after}}."""
    base = setup.params.mask(analysis.base_parameters)
    params = setup.params.only_free([nm for nm, b in zip(setup.params.names, base) if b])
    per_fold, rb_all, ra_all = [], [], []
    parts = fold_indices(len(meas.T_cam_target), folds, seed)
    for k, test in enumerate(parts):
        train = np.sort(np.concatenate([p for j, p in enumerate(parts) if j != k]))
        result = identify_measurements(setup, meas.subset(train), method, residual, analysis, robust=False,
                                       context=f"k-fold validation, fold {k + 1} of {folds}", cross_check=False).result
        held = setup.problem(meas.subset(test), residual, params=params)
        rb, ra = held.residual(params.nominal), held.residual(result.identified)
        rb_all.append(rb)
        ra_all.append(ra)
        per_fold.append({"fold": k + 1, "n_train": int(len(train)), "n_test": int(len(test)),
                         "converged": bool(result.converged),
                         "n_identified": int(np.sum(result.free)), "before": _rms(rb), "after": _rms(ra)})
    overall = {"before": _rms(np.concatenate(rb_all)), "after": _rms(np.concatenate(ra_all))}
    return {"folds": int(folds), "seed": int(seed), "residual_of": chain_direction(setup), "per_fold": per_fold,
            "overall": overall}


def kfold_lines(kf: dict) -> list[str]:
    """Summary lines of :func:`kfold_validation` (held-out RMS before -> after, per fold and overall)."""

    def fmt(b, a):
        s = f"position RMS {b['position_rms_mm']:.3f} -> {a['position_rms_mm']:.3f} mm"
        if "rotation_rms_deg" in b:
            s += f", rotation RMS {b['rotation_rms_deg']:.4f} -> {a['rotation_rms_deg']:.4f} deg"
        return s

    o = kf["overall"]
    lines = [f"held-out {kf['folds']}-fold validation (seed {kf['seed']}, residuals of {kf['residual_of']}): "
             + fmt(o["before"], o["after"])]
    lines += [f"  fold {f['fold']} ({f['n_test']} poses held out): " + fmt(f["before"], f["after"])
              + ("" if f["converged"] else " NOT CONVERGED") for f in kf["per_fold"]]
    return lines


def process_poses(path, out_dir, method=None, folds=None, plots=True, fix_unidentifiable=False) -> dict:
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
    ident = identify_measurements(setup, meas, method, residual, where=str(mp.path),
                                  fix_unidentifiable=fix_unidentifiable)
    result, problem, rep, setup = ident.result, ident.problem, ident.analysis, ident.setup
    t_id = time.perf_counter() - t0
    kept = [k for k, lab in enumerate(meas.labels) if lab not in {r[0] for r in ident.rejected}]
    failure = gross_failure(setup, meas, ident, mp.residual, str(mp.path), misreadings(mp),
                            untested=f"a wrong robot file or scene mounts ({scene.path}), joint columns in another "
                                     "order, joint or length units (checked up front only for gross factors)")
    kf = None if failure else kfold_validation(setup, meas.subset(kept), method, mp.residual, rep, folds, mp.seed)
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
        identifiability=rep, parameters=parameters_table(ps.names, ps.nominal, None, result), result=result,
        identified=ident, warnings=duplicate_poses(meas),
        residuals=residual_stats(result.residuals, problem.residual_kind), extra={"kfold": kf},
        timings={"identify": t_id, "total": time.perf_counter() - t0}, failure=failure)
    report["summary_text"] += "\n" + ("\n".join(kfold_lines(kf)) if kf else
                                      "held-out validation skipped: the fit failed (see the verdict)")
    write_report(Path(out_dir), report, setup, result, problem, plots=plots)
    return report


__all__ = ["process_poses", "kfold_validation", "fold_indices", "kfold_lines"]
