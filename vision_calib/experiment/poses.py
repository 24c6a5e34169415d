"""Measured poses without images (``vision-calib process-poses FILE.yaml --out DIR``): joint readings +
measured poses (or positions) from a file (:mod:`vision_calib.io.measured_poses`) -> identifiability
-> identification -> k-fold held-out validation -> report.json, calibrated_model.yaml, plots.

Held-out validation and the decision that can fail the verdict: :mod:`vision_calib.experiment.holdout`.

Pose pairs (a file naming ``flange_poses``: flange poses + measured target poses, no robot model):
:func:`process_pose_pairs`, the hand-eye route of ``process`` (``experiment.handeye_step``: closed-form start,
the robot's pose error in the weights, outlier test, adequacy, variance factor) with the measured poses' std per
axis estimated when the file gives none, and a k-fold held-out validation of its own (:func:`pair_holdout`).
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import ConfigError, DataError, VisionCalibError
from ..io.measured_poses import PosePairs, chain_direction, misreadings, read_measured_poses
from ..report.build import build_report, parameters_table, residual_stats
from ..report.write import write_report
from .checks import (copies_warning, drop_copies, drop_inconsistent, duplicate_poses, handeye_motions, motion_verdict,
                     pair_copies)
from .gross import gross_failure
from .holdout import flagged_labels, holdout_failure, holdout_lines, holdout_validation, with_holdout_warning
from .steps import check_method, identify_measurements, inconsistency_failure


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
    if isinstance(mp, PosePairs):
        if method not in (None, "lse") or fix_unidentifiable or tcp is not None:
            raise ConfigError(f"{mp.path}: a pose-pair file (flange_poses) is a hand-eye fit: --method, "
                              "--fix-unidentifiable and --tcp do not apply")
        return process_pose_pairs(mp, out_dir, folds=folds, plots=plots, t0=t0)
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
    failure = failure or inconsistency_failure(ident) or holdout_failure(hold)
    result = with_holdout_warning(result, hold)
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
    from .accuracy_map import add_accuracy_map  # the map of the calibrated tool over the workspace

    add_accuracy_map(report, setup, result, screened.select(problem.labels).joints, tcp=tcp,
                     sigma_q_rad=scene.measurement.sigma_q_rad)
    write_report(Path(out_dir), report, setup, result, problem, plots=plots)
    return report


# ------------------------------------------------------------------------------------------- pose pairs
def _pair_errors(A, B, F, M, mount: str) -> np.ndarray:
    """(N, 6) frames.pose_error of the measured T_cam_target M against the model A G B [m, rad] (camera frame)."""
    from ..frames import pose_error
    from ..identify.handeye_problem import mount_G

    return pose_error(A @ mount_G(F, mount) @ B, M)


def _folds_from_fit(pp, trains: list, fit) -> dict:
    """{fold index: (A, B, closed-form start name, (A, B) of that closed form)}: the folds' training sets fitted
    together from the whole-data fit ``fit`` (a ``HandeyeFit``; ``identify.handeye_loo.subset_fits``: the iteration
    of ``fit_handeye`` from that fit instead of a closed form), with the start each fold's own fit would take (the
    closed form of least weighted cost, weights at each one) for the "before" figures. A fold is left out (the
    caller fits it alone, ``identify_handeye``) when its motions are degenerate, no closed form solves it, its
    iteration does not settle, or one of its closed forms is below it under its final weights (another minimum)."""
    from ..errors import VisionCalibError
    from ..identify.handeye_fit import candidate_costs
    from ..identify.handeye_loo import subset_fits, subset_weights
    from ..identify.handeye_problem import robot_pose_cov, transforms_from_x, x_from_transforms
    from ..measure.handeye import closed_forms_many
    from .checks import handeye_motions
    from .handeye_step import all_poses_problem

    if pp.cov is None or not np.all(fit.result.free):
        return {}
    F, M, n = pp.T_base_flange, pp.T_cam_target, len(pp.ids)
    allp = all_poses_problem(F, M, pp.mount, pp.cov, fit.A, fit.B)
    estimate = pp.robot_std is None
    theta = fit.robot_variances if estimate else np.square(np.asarray(pp.robot_std, float))
    start_cov = robot_pose_cov(*np.sqrt(np.zeros(2) if estimate else theta))  # fit_handeye's, choosing its start
    moving = []  # the folds whose training motions are not degenerate
    for f, train in enumerate(trains):
        try:
            handeye_motions(F[train], pp.mount, [str(pp.ids[i]) for i in train], "")
        except VisionCalibError:
            continue
        moving.append(f)
    cands = {}
    for f, cf in zip(moving, closed_forms_many([(F[trains[f]], M[trains[f]]) for f in moving], pp.mount)):
        ok = {m: v for m, v in cf.items() if not isinstance(v, str)}
        if ok:
            AB = np.array(list(ok.values()))  # (k, 2, 4, 4)
            cands[f] = (list(ok), x_from_transforms(allp, AB[:, 0], AB[:, 1]), ok)
    if not cands:
        return {}
    fs = list(cands)
    mask = np.zeros((len(fs), n), bool)
    for j, f in enumerate(fs):
        mask[j, trains[f]] = True
    X, _, th, settled = subset_fits(allp, x_from_transforms(allp, fit.A, fit.B), theta, estimate, mask)
    out = {}
    for j, f in enumerate(fs):
        if not settled[j]:
            continue
        names, Xc, ok = cands[f]
        start = names[int(np.argmin(candidate_costs(allp, Xc, start_cov, mask=mask[j:j + 1])))]
        c = candidate_costs(allp, np.vstack([X[j:j + 1], Xc]), mask=mask[j:j + 1],
                            W=subset_weights(allp, X[j:j + 1], th[j:j + 1]))
        if np.min(c[1:]) < c[0] * (1 - 1e-9):
            continue
        out[f] = (*transforms_from_x(allp, X[j]), start, ok[start])
    return out


def pair_holdout(pp: PosePairs, folds: int, seed: int, outliers=(), theta_start=None, fit=None) -> dict:
    """k-fold held-out validation of a pose-pair fit (``pp``: a PosePairs, or any object with its ids,
    T_base_flange, T_cam_target, cov, noise_frame, mount, robot_std and path): the poses split by
    ``holdout.fold_indices``; each fold's
    model identified on the other folds (the whole-data outliers in no training set; the fit of
    ``handeye_step.identify_handeye`` without its outlier test) predicts the held-out poses ("after"), beside the
    OpenCV closed form a fit of that fold's training poses starts from ("before": the one of least weighted cost).
    Errors of T_cam_target, position [mm] and rotation [deg] norms (``holdout.error_stats``), overall and without
    the flagged outliers; the paired-bootstrap interval of the RMS change. Decision not ok (the verdict fails): a fold that cannot be identified, or our model
    predicting held-out poses significantly worse than the closed form. theta_start: the robot's variances of the
    fit of all the poses: each fold's REML search starts there (``identify_handeye``). fit: that fit (a
    ``HandeyeFit`` of the poses not flagged): the folds are then fitted together from it (:func:`_folds_from_fit`;
    the same minimum as from their closed forms, to the iteration's tolerance), a fold it cannot settle alone."""
    from .handeye_step import identify_handeye
    from .holdout import error_stats, fold_indices, rms_change_interval

    labels = [str(i) for i in pp.ids]
    n, flagged = len(labels), {str(o) for o in outliers}
    F, M, C = pp.T_base_flange, pp.T_cam_target, pp.cov
    frame = pp.noise_frame if C is None else None
    per_fold, fails, rb, ra, idx_all = [], [], [], [], []
    parts = fold_indices(n, folds, seed)
    trains = [np.array(sorted(i for j, q in enumerate(parts) if j != f for i in q if labels[i] not in flagged), int)
              for f in range(len(parts))]
    near = {} if fit is None else _folds_from_fit(pp, trains, fit)
    for f, test in enumerate(parts):
        train = trains[f]
        rec = {"fold": f + 1, "n_train": int(len(train)), "n_test": int(len(test)),
               "n_outliers_held_out": int(sum(labels[i] in flagged for i in test))}
        if f in near:
            A_f, B_f, start, (Acf, Bcf) = near[f]
            converged = True
        else:
            try:
                fi = identify_handeye(F[train], M[train], pp.mount, None if C is None else C[train],
                                      [labels[i] for i in train], pp.robot_std, robust=False, noise_frame=frame,
                                      where=f"{pp.path}: held-out validation, fold {f + 1} of {folds}",
                                      theta_start=theta_start, compare=False)
            except VisionCalibError as exc:
                fails.append(f"fold {f + 1} ({len(train)} training poses): {exc}")
                per_fold.append({**rec, "converged": False, "error": str(exc)})
                continue
            start, (A_f, B_f), converged = fi.fit.closed_forms["start"], (fi.A, fi.B), bool(fi.result.converged)
            Acf, Bcf = fi.fit.candidates[start]
            if not converged:
                fails.append(f"fold {f + 1} ({len(train)} training poses): the fit did not converge "
                             f"({fi.result.message})")
        before, after = _pair_errors(Acf, Bcf, F[test], M[test], pp.mount), _pair_errors(A_f, B_f, F[test], M[test],
                                                                                         pp.mount)
        rb.append(before)
        ra.append(after)
        idx_all.append(test)
        per_fold.append({**rec, "converged": converged, "closed_form": start,
                         "before": error_stats(*_norms(before)), "after": error_stats(*_norms(after))})
    out = {"folds": int(folds), "seed": int(seed), "residual_kind": "pose", "residual_of": "T_cam_target",
           "before_is": "the OpenCV closed form of least weighted cost on each fold's training poses, the start a "
                        "fit of them alone takes (measure.handeye.closed_forms)",
           "after_is": "the hand-eye fit of the fold's training poses",
           "outliers": [lab for lab in labels if lab in flagged], "per_fold": per_fold, "tcp_m": None}
    if not idx_all:
        out["decision"] = {"ok": False, "reason": "no fold could be identified: " + "; ".join(fails)}
        return out
    idx = np.concatenate(idx_all)
    rb, ra = np.concatenate(rb), np.concatenate(ra)
    keep = np.array([labels[i] not in flagged for i in idx])
    (bp, br), (ap, ar) = _norms(rb), _norms(ra)
    out["overall"] = {"n_poses": int(len(idx)), "before": error_stats(bp, br), "after": error_stats(ap, ar)}
    out["without_outliers"] = None if keep.all() else {
        "n_poses": int(keep.sum()), "excluded": [labels[i] for i in sorted(idx[~keep])],
        "before": error_stats(bp[keep], br[keep]), "after": error_stats(ap[keep], ar[keep])}
    rng = np.random.default_rng([int(seed), 27])
    inter = {"level": 0.95, "over": int(keep.sum()),
             "position_rms_change_mm": rms_change_interval(bp[keep], ap[keep], rng),
             "rotation_rms_change_deg": rms_change_interval(br[keep], ar[keep], rng)}
    out["interval"] = inter
    worse = [q for q, key in (("position", "position_rms_change_mm"), ("rotation", "rotation_rms_change_deg"))
             if inter[key][0] > 0]
    o = out["overall"]
    figs = (f"position RMS {o['before']['position_rms_mm']:.4g} -> {o['after']['position_rms_mm']:.4g} mm "
            f"(change {inter['position_rms_change_mm'][0]:+.3g}..{inter['position_rms_change_mm'][1]:+.3g}), rotation "
            f"RMS {o['before']['rotation_rms_deg']:.4g} -> {o['after']['rotation_rms_deg']:.4g} deg (change "
            f"{inter['rotation_rms_change_deg'][0]:+.3g}..{inter['rotation_rms_change_deg'][1]:+.3g}), "
            "closed form -> ours")
    if fails:
        out["decision"] = {"ok": False, "reason": "the k-fold training sets cannot be fitted: " + "; ".join(fails[:3])}
    elif worse:
        out["decision"] = {"ok": False, "reason": f"our model predicts held-out poses significantly worse than the "
                                                  f"closed form in {' and '.join(worse)}: {figs}"}
    else:
        out["decision"] = {"ok": True, "reason": figs}
    return out


def _norms(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position error norms [mm], rotation error norms [deg]) of pose errors r (N, 6) [m, rad]."""
    return np.linalg.norm(r[:, :3], axis=1) * 1e3, np.degrees(np.linalg.norm(r[:, 3:], axis=1))


def pair_holdout_lines(h: dict) -> list[str]:
    """Summary lines of :func:`pair_holdout`."""
    def fmt(b, a):
        return (f"position mean {b['position_mean_mm']:.3f} -> {a['position_mean_mm']:.3f}, RMS "
                f"{b['position_rms_mm']:.3f} -> {a['position_rms_mm']:.3f}, max {b['position_max_mm']:.3f} -> "
                f"{a['position_max_mm']:.3f} mm; rotation RMS {b['rotation_rms_deg']:.4f} -> "
                f"{a['rotation_rms_deg']:.4f}"
                f", max {b['rotation_max_deg']:.4f} -> {a['rotation_max_deg']:.4f} deg")

    out = h.get("outliers") or []
    lines = [f"held-out {h['folds']}-fold validation (seed {h['seed']}, errors of T_cam_target, the OpenCV closed form "
             "-> our fit, both from the same training poses"
             + (f"; the {len(out)} flagged outlier poses are in no training set" if out else "") + "):"]
    if "overall" in h:
        o = h["overall"]
        lines.append(f"  all {o['n_poses']} poses: " + fmt(o["before"], o["after"]))
        c = h.get("without_outliers")
        if c:
            lines.append(f"  without the {len(c['excluded'])} flagged outliers, {c['n_poses']} poses: "
                         + fmt(c["before"], c["after"]))
    for f in h["per_fold"]:
        if "error" in f:
            lines.append(f"  fold {f['fold']}: {f['error']}")
    lines.append(("  decision: ok, " if h["decision"]["ok"] else "  decision: FAILED, ") + h["decision"]["reason"])
    return lines


def process_pose_pairs(pp: PosePairs, out_dir, folds: int | None = None, plots: bool = True,
                       t0: float | None = None) -> dict:
    """Hand-eye identification of a pose-pair file (module docstring); writes DIR/report.json (kind
    ``process_pose_pairs``: the ``handeye`` block with the measured poses' estimated noise, ``holdout``),
    summary.txt, report.html. folds: k of the held-out validation (default the file's)."""
    from ..report.handeye import handeye_report
    from .handeye_gross import alternative_readings, handeye_gross_failure
    from .handeye_step import handeye_blocks, identify_handeye
    from .holdout import holdout_failure

    t0 = time.perf_counter() if t0 is None else t0
    n = len(pp.ids)
    folds = int(folds or pp.folds)
    if not 2 <= folds <= n:
        raise ConfigError(f"{pp.path}: folds: {folds} folds need 2 <= folds <= {n} (the number of pose pairs)")
    handeye_motions(pp.T_base_flange, pp.mount, pp.ids, str(pp.path))  # degenerate motion named with its copies
    keep, copies = pair_copies(pp.T_base_flange, pp.T_cam_target, pp.cov, pp.ids)  # a pair written twice: once
    if copies:
        pp = replace(pp, ids=tuple(pp.ids[k] for k in keep), T_base_flange=pp.T_base_flange[keep],
                     T_meas=pp.T_meas[keep], T_cam_target=pp.T_cam_target[keep],
                     cov=None if pp.cov is None else pp.cov[keep])
        folds = min(folds, len(keep))  # as the flange-recording route: at most one pose per fold
    frame = pp.noise_frame if pp.cov is None else None
    ident = identify_handeye(pp.T_base_flange, pp.T_cam_target, pp.mount, pp.cov, list(pp.ids), pp.robot_std,
                             where=str(pp.path), noise_frame=frame)
    result, A, B, problem = ident.result, ident.A, ident.B, ident.problem
    he = handeye_report(result, A, B, problem)
    he.update(handeye_blocks(ident))
    t_id = time.perf_counter() - t0
    hold = pair_holdout(pp, folds, pp.seed, outliers=[lab for lab, _ in ident.rejected], fit=ident.fit)
    failure = handeye_gross_failure(pp.T_base_flange, pp.T_cam_target, pp.mount, ident, str(pp.path),
                                    alternatives=alternative_readings(pp.T_base_flange, pp.T_cam_target, pp.mount,
                                                                      "the pose-pair file", "measured poses"))
    report = build_report(
        "process_pose_pairs",
        source={"file": str(pp.path), "csv": str(pp.csv_path), "flange_csv": str(pp.flange_path)},
        settings={"poses": n, "mount": pp.mount, "method": "lse", "measured": pp.measured, "units": pp.units,
                  "noise": pp.sigma_source, "folds": folds, "fold_seed": pp.seed},
        measurements={"n_poses": len(pp.ids), "n_valid": len(pp.ids), "n_rejected": 0, "rejected": [],
                      "copies": [{"pose_id": lab, "reason": why} for lab, why in copies],  # not a rejected view
                      "measured": pp.measured, "noise": pp.sigma_source, "pose_ids": list(pp.ids)},
        warnings=copies_warning(copies, "flange pose"),
        result=result, identified=ident, residuals=residual_stats(result.residuals, "pose"),
        extra={"handeye": he, "holdout": hold},
        timings={"identify": t_id, "total": time.perf_counter() - t0},
        failure=failure or holdout_failure(hold))
    report["summary_text"] += "\n" + "\n".join(pair_holdout_lines(hold))
    write_report(Path(out_dir), report, plots=plots)
    return report


__all__ = ["process_poses", "process_pose_pairs", "pair_holdout"]
