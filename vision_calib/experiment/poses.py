"""Measured poses without images (``vision-calib process-poses FILE.yaml --out DIR``): joint readings +
measured poses (or positions) from a file (:mod:`vision_calib.io.measured_poses`) -> identifiability
-> identification -> k-fold held-out validation -> report.json, calibrated_model.yaml, plots.

Held-out validation and the decision that can fail the verdict: :mod:`vision_calib.experiment.holdout`.
"""

from __future__ import annotations

import time
from pathlib import Path

from ..errors import ConfigError, DataError
from ..io.measured_poses import chain_direction, misreadings, read_measured_poses
from ..io.report import build_report, parameters_table, residual_stats, write_report
from .checks import drop_copies, drop_inconsistent, duplicate_poses, motion_verdict
from .gross import gross_failure
from .holdout import flagged_labels, holdout_failure, holdout_lines, holdout_validation
from .steps import check_method, identify_measurements


#: what sets the length scale of a measured-pose file (named by the motion check's scale refusal)
SCALE_HINT = "the x,y,z columns of the CSV against the scene's robot lengths"


def screen_motions(setup, mp, meas=None):
    """The motion-consistency check of ``process`` on a measured-pose file (``checks.motion_verdict``; full
    poses only: position rows carry no rotation). Never raises: a refusal goes to the gross-error diagnosis
    (``gross.gross_failure``), which also runs the check on each alternative reading of the file.
    Returns (measurements without the poses whose motion does not follow their joints, [(label, reason)] of
    those, the check's record (None for positions), the refusal or None, the check as
    ``f(Measurements) -> refusal | None`` (None for positions)). meas: the file's measurements to check (default
    all of them)."""
    meas = mp.measurements if meas is None else meas
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
                  plots: bool = True, fix_unidentifiable: bool = False, tcp=None) -> dict:
    """Identify a robot from a measured-pose file (YAML + CSV); writes DIR/report.json, summary.txt,
    calibrated_model.yaml (+ plots). folds: k of the held-out validation (default: the file's); tcp: a tool
    point (x, y, z) in the flange frame [m] where the held-out and predicted accuracy are also given
    (:mod:`vision_calib.experiment.holdout`, whose decision can fail the verdict: no calibrated model)."""
    t0 = time.perf_counter()
    mp = read_measured_poses(path)
    scene, setup, meas = mp.scene, mp.scene.setup, mp.measurements
    method = check_method(setup, method or scene.identification.method, "--method")
    folds = int(folds or mp.folds)
    if not 2 <= folds <= len(mp.ids):
        raise ConfigError(f"{mp.path}: folds: {folds} folds need 2 <= folds <= {len(mp.ids)} (the number of poses)")
    residual = setup.residual_for(method, mp.residual)
    where = str(mp.path)
    meas, copies = drop_copies(meas)  # one measurement under two pose ids (a copied row): counted once
    screened, inconsistent, motion, refusal, check = screen_motions(setup, mp, meas)
    ident = identify_measurements(setup, screened, method, residual, where=where,
                                  fix_unidentifiable=fix_unidentifiable, rejected=inconsistent)
    result, problem, rep, setup = ident.result, ident.problem, ident.analysis, ident.setup
    t_id = time.perf_counter() - t0
    failure = gross_failure(setup, screened, ident, mp.residual, where, misreadings(mp),
                            untested=f"a wrong robot file or scene mounts ({scene.path}), joint columns in another "
                                     "order, joint or length units (checked up front only for gross factors)",
                            motion_refusal=refusal, motion_check=check)
    hold = None if failure else holdout_validation(
        mp.scene.setup, meas, method, residual, rep, folds, mp.seed, outliers=flagged_labels(meas, ident.rejected),
        tcp=tcp, result=result, fitted_setup=setup)
    failure = failure or holdout_failure(hold)
    ps = setup.params
    n = len(mp.ids)
    report = build_report(
        "process_poses",
        source={"file": str(mp.path), "csv": str(mp.csv_path),
                "scene": {"name": scene.name, "path": str(scene.path), "robot_kind": setup.kind}},
        settings={"poses": n, "frames": None, "method": method, "residual": residual, "measured": mp.measured,
                  "residual_of": chain_direction(setup), "units": mp.units, "noise": mp.sigma_source,
                  "folds": folds, "fold_seed": mp.seed},
        measurements={"n_poses": n, "n_valid": n - len(copies), "n_rejected": len(copies),
                      "rejected": [{"pose_id": lab, "reason": why} for lab, why in copies], "measured": mp.measured,
                      "noise": mp.sigma_source, "pose_ids": list(mp.ids)},
        identifiability=rep, parameters=parameters_table(ps.names, ps.nominal, None, result, ps.kinds), result=result,
        identified=ident, warnings=duplicate_poses(meas, copies), motion=motion,
        residuals=residual_stats(result.residuals, problem.residual_kind), extra={"holdout": hold},
        timings={"identify": t_id, "total": time.perf_counter() - t0}, failure=failure)
    report["summary_text"] += "\n" + "\n".join(holdout_lines(hold))
    write_report(Path(out_dir), report, setup, result, problem, plots=plots)
    return report


__all__ = ["process_poses"]
