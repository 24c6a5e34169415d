"""Offline processing of a recorded folder (``vision-calib process FOLDER --out DIR``):
measure every pose from its images -> identifiability -> identify -> report.

Real-world robustness: a pose whose images are missing, unreadable, of the wrong size, or where
the target is not detected is skipped with its reason in the report; the rest goes on. The
per-pose measurements are written (``measurements.json``) before identification, so they are
kept even when identification then fails (e.g. too few usable poses).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import ConfigError, DataError, IdentifiabilityError
from ..io.atomic import write_json_atomic
from ..io.recording import read_recording
from ..io.report import (REPORT_VERSION, build_report, measurements_block, parameters_table, residual_stats,
                         write_report)
from ..rig import Measurements, load_scene
from .checks import screen_measurements
from .steps import check_method, identify_measurements, rejection_summary


#: the report's intrinsics.propagated.how when the intrinsics' uncertainty is a term of the fit
IN_FIT = ("included in the fit: one nuisance coefficient (prior N(0, 1)) per eigen-direction of the intrinsics "
          "covariance, so the outlier test, the adequacy test, the variance factor and the std all use the "
          "measurement covariance of the poses plus that of the intrinsics' shared error")


def measure_recording(rec, progress=False, detections=None):
    """PoseMeasurement per pose id of a Recording (invalid ones carry a reason). detections: a dict to
    fill with {pose id: [Detection per frame]} (for the reprojection error of the calibrated chain)."""
    from ..measure import PoseMeasurement, measure_images

    out = []
    it = rec.pose_ids
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc="measure", unit="pose", leave=False)
    for pid in it:
        files = rec.images.get(pid)
        if not files:
            out.append(PoseMeasurement(pid, False, f"no images in images/{pid}/", np.full((4, 4), np.nan),
                                       np.full((6, 6), np.nan), 0, 0, float("nan")))
            continue
        pm, dets = measure_images([str(f) for f in files], rec.target, rec.camera, pose_id=pid,
                                  config=rec.measure_config())
        out.append(pm)
        if detections is not None:
            detections[pid] = dets
    return out


def _recording_setup(rec):
    """(scene, setup with the recording's camera) of a joint-pose recording, checked against it."""
    where = rec.folder / "recording.yaml"
    if rec.scene_path is None:
        raise ConfigError(f"{where}: scene: needed to know the robot model (joint poses)")
    scene = load_scene(rec.scene_path)
    setup = scene.setup
    if rec.camera_mount != setup.mount:
        raise ConfigError(f"{where}: camera_mount: {rec.camera_mount!r} but the scene {scene.path} has mount "
                          f"{setup.mount!r}")
    if setup.camera is not None and setup.camera.size != rec.camera.size:
        raise DataError(f"{rec.folder}: recording camera {rec.camera.size} differs from the scene's {setup.camera.size}")
    setup.check_joints(rec.poses, str(rec.folder / "poses.csv"), rec.pose_ids)
    return scene, setup.with_camera(rec.camera)


def process_folder(folder, out_dir, method=None, progress=False, plots=True, fix_unidentifiable=False,
                   allow_symlinks=False, refine_intrinsics=False, camera_file=None) -> dict:
    """Process a recorded folder; writes DIR/measurements.json, DIR/report.json (+ plots, model).
    refine_intrinsics: calibrate the camera from the recording's images even when recording.yaml gives
    intrinsics (always done when it gives none); camera_file: a camera.yaml (``calibrate-camera``) used
    instead of recording.yaml's intrinsics; the report's ``intrinsics`` block says which were used."""
    from .camera_step import intrinsics_response, recording_intrinsics

    t0 = time.perf_counter()
    rec = read_recording(folder, allow_symlinks=allow_symlinks)
    rec, intr = recording_intrinsics(rec, refine_intrinsics, progress, camera_file)
    out = Path(out_dir)
    scene, setup = _recording_setup(rec) if rec.pose_kind != "flange_pose" else (None, None)
    method = None if scene is None else check_method(setup, method or scene.identification.method, "--method")
    dets = {}
    pms = measure_recording(rec, progress, dets)
    mblock = measurements_block(pms, extra_files_ignored=list(rec.extra_files))
    write_json_atomic(out / "measurements.json", {"version": REPORT_VERSION, "folder": str(rec.folder), **mblock})
    t_meas = time.perf_counter() - t0
    if scene is None:
        return _process_handeye(rec, out, pms, mblock, t0, plots, intr, dets)

    meas, ok = Measurements.from_pose_measurements(rec.poses, rec.poses, pms)
    residual = setup.residual_for(method, scene.identification.residual)
    if len(ok) < 2:
        raise IdentifiabilityError(f"{rec.folder}: only {len(ok)} usable poses of {len(pms)} "
                                   f"({rejection_summary(pms)}); identification needs more")
    t1 = time.perf_counter()
    where = str(rec.folder)
    meas, inconsistent, motion = screen_measurements(
        setup, meas, where, "the recording's target.square_m (or marker/tag size), camera.fx/fy, and units.length "
        "of poses.csv")
    # intrinsics calibrated from these images: their error is shared by all poses, it goes into the fit
    ident = identify_measurements(setup, meas, method, residual, context=rejection_summary(pms), where=where,
                                  fix_unidentifiable=fix_unidentifiable, rejected=inconsistent,
                                  nuisance=intrinsics_response(dets, rec, intr))
    result, problem, rep, setup = ident.result, ident.problem, ident.analysis, ident.setup
    if ident.nuisance is not None:
        intr = {**intr, "propagated": {**ident.nuisance, "in_fit": True, "how": IN_FIT}}
    t_id = time.perf_counter() - t1
    ps = setup.params
    report = build_report(
        "process", source={"folder": str(rec.folder), "scene": {"name": scene.name, "path": str(scene.path),
                                                               "robot_kind": setup.kind}},
        settings={"poses": len(pms), "frames": rec.frames_per_pose, "method": method, "residual": residual,
                  "camera": rec.camera.to_dict()},
        measurements=mblock, warnings=[*rec.notes, *intr["warnings"]], identifiability=rep,
        parameters=parameters_table(ps.names, ps.nominal, None, result), result=result, identified=ident,
        motion=motion,
        residuals=residual_stats(result.residuals, problem.residual_kind),
        extra={"intrinsics": intr, "reprojection": _chain_reprojection(setup, meas, problem, result, dets, rec)},
        timings={"measure": t_meas, "identify": t_id, "total": time.perf_counter() - t0})
    write_report(out, report, setup, result, problem, plots=plots)
    return report


def _chain_reprojection(setup, meas, problem, result, dets, rec) -> dict:
    """Reprojection RMS px of the identified robot chain over the poses the fit kept."""
    from ..measure.reprojection import chain_reprojection

    kept = set(problem.labels)
    idx = [k for k, lab in enumerate(meas.labels) if lab in kept]
    T = setup.predict_from_joints(meas.joints[idx], result.identified)
    return chain_reprojection(T, dets, [meas.labels[k] for k in idx], rec.target, rec.camera)


def _process_handeye(rec, out, pms, mblock, t0, plots, intr, dets=None) -> dict:
    """Flange poses known: identify the camera mount and the target mount only."""
    from ..identify.handeye_problem import handeye_report, solve_handeye, stack_measurements

    ok = [i for i, pm in enumerate(pms) if pm.valid]
    if len(ok) < 3:
        raise IdentifiabilityError(f"{rec.folder}: only {len(ok)} usable poses; hand-eye identification needs "
                                   "at least 3 (with rotations about two different axes)")
    # one image with few corners per pose: each pose's sigma_px is a poor estimate, pool it over the poses
    T, cov, labels, _ = stack_measurements([pms[i] for i in ok], pool_sigma=rec.frames_per_pose == 1)
    mount = "fixed" if rec.camera_mount in ("fixed", "base") else "eye_in_hand"
    # PnP covariances miss the robot's own pose error: scale the covariance by the a-posteriori
    # variance factor (whitened cost / degrees of freedom), reported as such
    result, A, B, problem = solve_handeye(rec.poses[ok], T, mount, pose_cov=cov, labels=labels,
                                          scale_cov_by_residual=True)
    result, A, B, prop = _handeye_intrinsics_uncertainty(result, problem, rec, pms, ok, dets, intr, mount)
    if prop is not None:
        intr = {**intr, "propagated": prop}
    he = handeye_report(result, A, B, problem, detections=dets, target=rec.target, intrinsics=rec.camera)
    report = build_report(
        "process_handeye", source={"folder": str(rec.folder)},
        settings={"poses": mblock["n_poses"], "mount": mount, "camera": rec.camera.to_dict(), "method": "lse"},
        measurements=mblock, warnings=[*rec.notes, *intr["warnings"]], result=result,
        residuals=residual_stats(result.residuals, "pose"),
        extra={"handeye": he, "intrinsics": intr, "reprojection": he["reprojection"]},
        timings={"total": time.perf_counter() - t0})
    write_report(out, report, plots=plots)
    return report


def _handeye_intrinsics_uncertainty(result, problem, rec, pms, ok, dets, intr, mount):
    """(result, A, B, propagated block or None): the hand-eye fit redone with the uncertainty of intrinsics
    calibrated from the recording as nuisance coefficients (one per eigen-direction of their covariance; the
    response U of every pose's residual from the poses re-measured from the detections, as in
    ``camera_step.intrinsics_response``), so its variance factor and covariance see the poses' covariance
    plus the intrinsics' shared error (``identify.nuisance.solve_nuisance_unknown_noise``: the poses'
    covariance scaled by its estimated factor, the intrinsics' not); the input result when the intrinsics
    were given."""
    from ..identify.handeye_problem import handeye_problem, transforms_from_x
    from ..identify.nuisance import solve_nuisance_unknown_noise, split_nuisance
    from .camera_step import intrinsics_directions, residual_response
    from .steps import NUISANCE_PREFIX

    A, B = transforms_from_x(problem, result.identified)
    dirs = intrinsics_directions(intr, rec.camera)
    if not dirs or result.covariance is None or not dets:
        return result, A, B, None
    x = np.asarray(result.identified, float)
    m = problem.meta
    U = residual_response(dirs, dets, [str(pms[i].pose_id) for i in ok], rec, x,
                          np.asarray(problem.residual(x), float),
                          lambda T: handeye_problem(m["T_base_flange"], T, mount, m["A0"], m["B0"], problem.obs_cov,
                                                    labels=problem.labels))
    if U is None:
        return result, A, B, None
    # the PnP covariances miss the robot's own pose error (flange poses from a nominal model): their scale is
    # estimated (variance factor s2), the intrinsics' known
    full, s2 = solve_nuisance_unknown_noise(problem, U, x, NUISANCE_PREFIX)
    res, nz = split_nuisance(full, len(problem.params))
    free = np.asarray(res.free, bool)
    ratio = res.std / result.std  # both as reported (each with its own variance factor)
    prop = {"n_directions": int(U.shape[2]), "coefficients": nz["values"], "coefficients_std": nz["std"],
            "std_inflation": {n: float(v) for n, v, f in zip(res.names, ratio, free) if f and np.isfinite(v)},
            "pose_variance_factor": float(s2), "in_fit": True, "how": IN_FIT}
    A, B = transforms_from_x(problem, res.identified)
    return res, A, B, prop


__all__ = ["process_folder", "measure_recording"]
