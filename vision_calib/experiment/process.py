"""Offline processing of a recorded folder (``vision-calib process FOLDER --out DIR``):
measure every pose from its images -> identifiability -> identify -> report.

Real-world robustness: a pose whose images are missing, unreadable, of the wrong size, or where
the target is not detected is skipped with its reason in the report; the rest goes on. The
per-pose measurements are written (``measurements.json``) before identification, so they are
kept even when identification then fails (e.g. too few usable poses).
"""

from __future__ import annotations

import functools
import time
from pathlib import Path
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..errors import ConfigError, DataError, IdentifiabilityError
from ..serialize import write_json_atomic
from ..io.portable import relative_ref
from ..io.recording import Recording, read_recording
from ..report.build import (REPORT_VERSION, build_report, measurements_block, parameters_table, residual_stats,
                            result_is_finite)
from ..report.write import write_report
from ..rig import Measurements, load_scene
from .checks import drop_copies, duplicate_poses, screen_measurements
from .gross import gross_failure
from .holdout import flagged_labels, holdout_failure, holdout_folds, holdout_lines, with_holdout_warning
from .reprojection_check import (label_points, points_line, reprojection_noise_check, robot_corner_variance,
                                 used_corners)
from .steps import check_method, identify_measurements, inconsistency_failure, rejection_summary

if TYPE_CHECKING:  # the measure package is imported where poses are measured
    from ..measure import PoseMeasurement


#: the report's intrinsics.propagated.how when the intrinsics' uncertainty is a term of the fit
IN_FIT = ("included in the fit: one nuisance coefficient (prior N(0, 1)) per eigen-direction of the intrinsics "
          "covariance, so the outlier test, the adequacy test, the variance factor and the std all use the "
          "measurement covariance of the poses plus that of the intrinsics' shared error")


def measure_recording(rec: Recording, progress: bool = False, detections: dict | None = None,
                      detected: dict | None = None) -> list[PoseMeasurement]:
    """PoseMeasurement per pose id of a Recording (invalid ones carry a reason). detections: a dict to
    fill with {pose id: [Detection per frame]} (for the reprojection error of the calibrated chain). detected: those
    of the same images made before (``measure.batch.reusable_detections``): measured with ``rec.camera`` from them
    (undistortion + PnP), nothing decoded or detected."""
    from ..measure import PoseMeasurement, measure_images, measure_pose

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
        if detected is not None:
            dets = detected[pid]
            pm = measure_pose(dets, rec.target, rec.camera, pose_id=pid, config=rec.measure_config())
        else:
            pm, dets = measure_images([str(f) for f in files], rec.target, rec.camera, pose_id=pid,
                                      config=rec.measure_config())
        out.append(pm)
        if detections is not None:
            detections[pid] = dets
    return out


@dataclass
class Measured:
    """A recorded folder measured under one hypothesis on the intrinsics: the Recording with the camera used
    (``rec.camera``), the report's ``intrinsics`` block, a PoseMeasurement per pose id, the detections {pose id:
    [Detection per frame]}, and the seconds it took (reading the intrinsics, detection, PnP)."""

    rec: Recording
    intr: dict
    pms: list
    dets: dict
    seconds: float


def measure_folder(rec: Recording, refine_intrinsics: bool = False, progress: bool = False, camera_file=None,
                   reuse: Measured | None = None) -> Measured:
    """Measure ``rec`` (:func:`measure_recording`) with the intrinsics ``camera_step.recording_intrinsics`` gives.
    reuse: the same folder measured with other intrinsics: each image is decoded and detected once per run, its
    detections serve the camera calibration and, where detection reads no intrinsics
    (``measure.batch.reusable_detections``), the measurement (undistortion + PnP only); AprilTag grids' corners
    (edge fits in undistorted pixels) are fitted again to their edge samples under these intrinsics
    (``measure.batch.refit_detection``), no image read."""
    from ..measure.batch import refit_detection, refittable, reusable_detections
    from ..measure.detect import DetectConfig
    from .camera_step import recording_intrinsics

    t0 = time.perf_counter()
    rec, intr = recording_intrinsics(rec, refine_intrinsics, progress, camera_file,
                                     detections=None if reuse is None else reuse.dets)
    same = reuse is not None and reuse.rec.camera is not None and reuse.rec.camera.size == rec.camera.size
    detected = None
    if same and reusable_detections(rec.target):
        detected = reuse.dets
    elif same and refittable(d for ds in reuse.dets.values() for d in ds):  # AprilTag grids: edges refitted
        n_min = DetectConfig().min_corners  # (measure_images' detection settings)
        detected = {pid: [refit_detection(d, rec.camera, n_min) or d for d in ds] for pid, ds in reuse.dets.items()}
    dets = {}
    pms = measure_recording(rec, progress, dets, detected=detected)
    return Measured(rec, intr, pms, dets, time.perf_counter() - t0)


@dataclass
class _Fitted:
    """One hypothesis fitted, nothing written yet. view: what the cause test reads of its report
    (:func:`.cause.cause_test_applies`, :func:`.cause.compare`: the blocks ``verdict`` (converged, finite),
    ``reprojection``, ``parameters``, ``intrinsics`` with the report's values); holdout() -> the report's
    ``holdout`` block as far as the cause test reads it (residual_of, overall), or None: the k-fold fits, made
    on the first call (the cause test asks for them only when the likelihood favours the refined intrinsics
    decisively, :func:`.cause.compare`; the report's build asks for its own);
    build() -> (report, tail: the summary lines that follow the cause message): the work only the written report
    needs (the held-out mounts-only baseline, prediction and decision, the intrinsics sensitivity) is done there,
    so not for a hypothesis the cause test does not choose. :meth:`finish` builds the report, adds the :mod:`.cause`
    block (when the cause was tested) and writes it."""

    view: dict
    build: Callable[[], tuple[dict, str]]
    write: Callable[[dict], None]
    holdout: Callable[[], dict | None]
    scene: object = None  #: the recording's scene (a joint-pose recording), for the other hypothesis
    _built: tuple | None = field(default=None, init=False, repr=False)

    def full_view(self) -> dict:
        """``view`` with its ``holdout`` block (the k-fold fits made if not yet): the report's figures."""
        return {**self.view, "holdout": self.holdout()}

    def built(self) -> tuple[dict, str]:
        """(report, tail) of ``build`` (built once)."""
        if self._built is None:
            self._built = self.build()
        return self._built

    def finish(self, cause: dict | None = None) -> dict:
        report, tail = self.built()
        if cause:
            report["cause"] = cause
            report["summary_text"] += "\n" + cause["message"]
        report["summary_text"] += tail
        self.write(report)
        return report


def _recording_setup(rec, scene=None):
    """(scene, setup with the recording's camera) of a joint-pose recording, checked against it. scene: the
    recording's scene when already loaded (the cause test's second hypothesis)."""
    where = rec.folder / "recording.yaml"
    if rec.scene_path is None:
        raise ConfigError(f"{where}: scene: needed to know the robot model (joint poses)")
    scene = load_scene(rec.scene_path) if scene is None else scene
    setup = scene.setup
    if rec.camera_mount != setup.mount:
        raise ConfigError(f"{where}: camera_mount: {rec.camera_mount!r} but the scene {scene.path} has mount "
                          f"{setup.mount!r}")
    if setup.camera is not None and setup.camera.size != rec.camera.size:
        raise DataError(f"{rec.folder}: recording camera {rec.camera.size} differs from the scene's {setup.camera.size}")
    setup.check_joints(rec.poses, str(rec.folder / "poses.csv"), rec.pose_ids)
    return scene, setup.with_camera(rec.camera)


def process_folder(folder: str | Path, out_dir: str | Path | None, method: str | None = None, progress: bool = False,
                   plots: bool = True, fix_unidentifiable: bool = False, allow_symlinks: bool = False,
                   refine_intrinsics: bool = False, camera_file: str | Path | None = None, folds: int | None = None,
                   tcp=None) -> dict:
    """Process a recorded folder (:func:`process_once`); with intrinsics given and a reprojection far above its
    noise model, the cause tested (:mod:`.cause`): the intrinsics refined from the same detections, the fit redone,
    the two hypotheses compared on what both predict (``_Fitted.view``), the chosen one's report built and written
    (kept, not recomputed), both in its ``cause`` block. Each image is decoded and detected once
    (:func:`measure_folder`)."""
    from ..errors import VisionCalibError
    from .cause import cause_test_applies, compare

    kw = dict(method=method, progress=progress, fix_unidentifiable=fix_unidentifiable, folds=folds, tcp=tcp,
              plots=plots)
    t0 = time.perf_counter()
    rec = read_recording(folder, allow_symlinks=allow_symlinks)
    given_m = measure_folder(rec, refine_intrinsics, progress, camera_file)
    given = fit_measured(given_m, out_dir, t0=t0, **kw)
    if refine_intrinsics or camera_file is not None or not cause_test_applies(given.view):
        return given.finish()
    try:
        refined, why = fit_measured(measure_folder(rec, True, progress, reuse=given_m), out_dir, t0=t0,
                                    early_measurements=False, scene=given.scene, **kw), None
    except VisionCalibError as exc:
        refined, why = None, str(exc)
    try:  # the held-out folds of both, only when the likelihood favours the refined intrinsics decisively
        block = compare(given.view, None if refined is None else refined.view, why,
                        holdout=None if refined is None else lambda: (given.holdout(), refined.holdout()))
    except VisionCalibError as exc:  # the refined hypothesis' folds (the given one's say it again when built)
        block = compare(given.view, None, str(exc))
    if block["chosen"] == "refined":
        try:  # its report's work, done for the chosen hypothesis only: an error there is one of the refined fit
            refined.built()
        except VisionCalibError as exc:
            block = compare(given.view, None, str(exc))
    return (refined if block["chosen"] == "refined" else given).finish(block)


def process_once(folder: str | Path, out_dir: str | Path | None, method: str | None = None, progress: bool = False,
                 plots: bool = True, fix_unidentifiable: bool = False, allow_symlinks: bool = False,
                 refine_intrinsics: bool = False, camera_file: str | Path | None = None, folds: int | None = None,
                 tcp=None, cause: dict | None = None) -> dict:
    """Process a recorded folder under one hypothesis on the intrinsics (:func:`measure_folder`,
    :func:`fit_measured`); writes DIR/measurements.json, DIR/report.json (+ plots, model). cause: the :mod:`.cause`
    block, reported as is."""
    t0 = time.perf_counter()
    rec = read_recording(folder, allow_symlinks=allow_symlinks)
    return fit_measured(measure_folder(rec, refine_intrinsics, progress, camera_file), out_dir, method, progress,
                        plots, fix_unidentifiable, folds, tcp, t0=t0).finish(cause)


def fit_measured(m: Measured, out_dir: str | Path | None, method: str | None = None, progress: bool = False,
                 plots: bool = True, fix_unidentifiable: bool = False, folds: int | None = None, tcp=None,
                 t0: float | None = None, early_measurements: bool = True, scene=None) -> _Fitted:
    """Identify and report a measured folder; the report is written by the returned object's ``finish``:
    DIR/measurements.json (written now when ``early_measurements``, so the measurements are kept when
    identification then fails), DIR/report.json (+ plots, model). The intrinsics used are those of ``m`` (the
    report's ``intrinsics`` block says which: ``process --refine-intrinsics`` calibrates them from the recording's
    images even when recording.yaml gives intrinsics, always done when it gives none; ``--camera FILE`` replaces
    recording.yaml's). folds / tcp: the held-out validation's k and tool point (x, y, z in the flange frame, m),
    :mod:`.holdout`: its decision can fail the verdict (no calibrated model). t0: the run's start (timings).
    scene: the recording's scene when the caller has it loaded (``_Fitted.scene`` of the other hypothesis: one
    model for both, whose generic-pose rank is then computed once)."""
    from .camera_step import SOURCE_CAMERA_FILE, fitted_camera, intrinsics_response, intrinsics_sensitivity, remeasure

    t0 = time.perf_counter() - m.seconds if t0 is None else t0
    rec, intr, pms, dets = m.rec, m.intr, m.pms, m.dets
    out = Path(out_dir)
    if rec.camera_file is not None and intr["source"] == f"{SOURCE_CAMERA_FILE} {rec.camera_file}":
        intr = {**intr, "source": f"{SOURCE_CAMERA_FILE} {relative_ref(rec.camera_file, out)}"}  # relative to report.json
    scene, setup = _recording_setup(rec, scene) if rec.pose_kind != "flange_pose" else (None, None)
    nominal = setup
    method = None if scene is None else check_method(setup, method or scene.identification.method, "--method")
    mblock = measurements_block(pms, extra_files_ignored=list(rec.extra_files))

    def write_measurements():  # the folder relative to this file (io.portable)
        out.mkdir(parents=True, exist_ok=True)
        write_json_atomic(out / "measurements.json",
                          {"version": REPORT_VERSION, "folder": relative_ref(rec.folder, out), **mblock})

    if early_measurements:
        write_measurements()
    t_meas = m.seconds
    if scene is None:
        return _process_handeye(rec, out, pms, mblock, t0, plots, intr, dets, folds,
                                None if early_measurements else write_measurements)

    meas, ok = Measurements.from_pose_measurements(rec.poses, rec.poses, pms)
    residual = setup.residual_for(method, scene.identification.residual)
    if len(ok) < 2:
        raise IdentifiabilityError(f"{rec.folder}: only {len(ok)} usable poses of {len(pms)} "
                                   f"({rejection_summary(pms)}); identification needs more")
    t1 = time.perf_counter()
    where = str(rec.folder)
    meas, copies = drop_copies(meas)  # one measurement under two pose ids (a copied image folder): counted once
    meas, inconsistent, motion = screen_measurements(
        setup, meas, where, "the recording's target.square_m (or marker/tag size), camera.fx/fy, and units.length "
        "of poses.csv")
    # intrinsics calibrated from these images: their error is shared by all poses, it goes into the fit
    used = []  # the intrinsics directions of the fit's nuisance coefficients
    by_id = {str(pm.pose_id): pm for pm in pms}  # the corner selection each re-measurement keeps
    ident = identify_measurements(setup, meas, method, residual, context=rejection_summary(pms), where=where,
                                  fix_unidentifiable=fix_unidentifiable, rejected=inconsistent,
                                  nuisance=intrinsics_response(dets, rec, intr, used=used, original=by_id))
    result, problem, rep, setup = ident.result, ident.problem, ident.analysis, ident.setup
    failure = gross_failure(setup, meas, ident, residual, where,
                            untested=f"a wrong robot file or scene mounts ({scene.path}), joint columns in another "
                                     "order, the target's or camera's description in recording.yaml")
    folds_of = functools.cache(lambda: None if failure else holdout_folds(
        nominal, meas, method, residual, rep, folds, 0, outliers=flagged_labels(meas, ident.rejected), tcp=tcp,
        result=result, fitted_setup=setup))  # the k-fold fits, when first asked for (``_Fitted.holdout``)
    cam_fit = None
    if ident.nuisance is not None:
        cam_fit = fitted_camera(rec.camera, used, ident.nuisance["coefficients"])
        intr = {**intr, "propagated": {**ident.nuisance, "in_fit": True, "how": IN_FIT,
                                       "fitted_values": _camera_values(cam_fit)}}
    t_id = time.perf_counter() - t1
    kept = {str(lab) for lab in problem.labels}
    used, counts = used_corners(dets, pms, rec.target)
    reproj = label_points(_chain_reprojection(setup, meas, problem, result, used, rec, cam_fit), counts)
    rcheck, rwarn = reprojection_noise_check(reproj, [pm for pm in pms if str(pm.pose_id) in kept], intr)
    if rcheck is not None:
        reproj = {**reproj, "noise_check": rcheck}
    ps = setup.params
    view = {"verdict": {"converged": bool(result.converged), "finite": result_is_finite(result)},
            "reprojection": reproj, "parameters": parameters_table(ps.names, ps.nominal, None, result, ps.kinds),
            "intrinsics": intr}
    final = {}  # the result with the held-out decision's warning, for write()

    def build():
        t2 = time.perf_counter()
        held = folds_of()
        hold = None if held is None else held.block()
        failed = failure or inconsistency_failure(ident) or holdout_failure(hold)
        final["result"] = res = with_holdout_warning(result, hold)
        prepared = {}  # each pose's corners gathered once for the shifted cameras
        sens = intrinsics_sensitivity(ident, meas, rec.camera, lambda cam, labels: remeasure(
            dets, labels, rec.target, cam, rec.measure_config(), by_id, prepared), given_std=intr.get("std") is not None)
        report = build_report(
            "process", source={"folder": str(rec.folder), "scene": {"name": scene.name, "path": str(scene.path),
                                                                   "robot_kind": setup.kind}},
            settings={"poses": len(pms), "frames": rec.frames_per_pose, "method": method, "residual": residual,
                      "camera": rec.camera.to_dict()},
            measurements=mblock, warnings=[*rec.notes, *intr["warnings"], *([sens["warning"]] if sens["warning"]
                                                                            else []),
                                           *duplicate_poses(meas, copies), *([rwarn] if rwarn else [])],
            identifiability=rep,
            parameters=parameters_table(ps.names, ps.nominal, None, res, ps.kinds), result=res, identified=ident,
            motion=motion,
            residuals=residual_stats(res.residuals, problem.residual_kind),
            extra={"intrinsics": intr, "intrinsics_sensitivity": sens,
                   "reprojection": reproj, "holdout": hold, "cause": None},
            timings={"measure": t_meas, "identify": t_id + time.perf_counter() - t2, "total": time.perf_counter() - t0},
            failure=failed)
        report["summary_text"] += points_line(report.get("reprojection")) + "\n" + "\n".join(holdout_lines(hold))
        return report, ""

    def write(report):
        from .accuracy_map import add_accuracy_map  # the map of the calibrated tool over the workspace: only for the

        result = final["result"]
        add_accuracy_map(report, setup, result, meas.select(problem.labels).joints, tcp=tcp,  # hypothesis written
                         sigma_q_rad=scene.measurement.sigma_q_rad)
        if not early_measurements:
            write_measurements()
        write_report(out, report, setup, result, problem, plots=plots,
                     overlays=_overlay_source(rec, dets, setup if report["verdict"].get("usable") else None,
                                              result) if plots else None)

    return _Fitted(view, build, write, lambda: None if folds_of() is None else folds_of().figures(), scene)


def _overlay_source(rec, dets, setup=None, result=None):
    """report.html's overlay images of a recorded folder: its files and detections; the calibrated model's
    reprojection from the pose's joint readings when a usable ``setup`` is given (through the recording's
    intrinsics, as the measured poses)."""
    from ..report.overlay import OverlaySource, recording_frames

    index = {str(p): i for i, p in enumerate(rec.pose_ids)}

    def model_pose(pid):
        i = index.get(str(pid))
        return None if i is None or setup is None else setup.predict_from_joints(rec.poses[i:i + 1],
                                                                                 result.identified)[0]

    return OverlaySource(recording_frames(rec.images, dets), rec.target, rec.camera, model_pose)


def _camera_values(cam) -> dict:
    """{fx, fy, cx, cy, k1, k2, p1, p2, k3} of a CameraIntrinsics (the intrinsics block's ``values`` layout)."""
    from ..measure.intrinsics import PARAM_NAMES

    return dict(zip(PARAM_NAMES, (float(v) for v in (cam.fx, cam.fy, cam.cx, cam.cy, *cam.dist))))


def _chain_reprojection(setup, meas, problem, result, dets, rec, fitted=None) -> dict:
    """Reprojection RMS px of the identified robot chain over the poses the fit kept, with the intrinsics the fit
    used (``measure.reprojection.reprojection_with``): ``fitted`` (the calibrated ones moved by the fitted
    nuisance coefficients) when the intrinsics' error was a term of the fit, else the recording's camera."""
    from ..measure.reprojection import reprojection_with

    kept = set(problem.labels)
    idx = [k for k, lab in enumerate(meas.labels) if lab in kept]
    T = setup.predict_from_joints(meas.joints[idx], result.identified)
    return reprojection_with(T, dets, [meas.labels[k] for k in idx], rec.target, rec.camera, fitted)


def _process_handeye(rec, out, pms, mblock, t0, plots, intr, dets=None, folds=None, write_first=None) -> _Fitted:
    """Flange poses known: identify the camera mount and the target mount only (``handeye_step``: the robot's
    pose error in the weights, given by recording.yaml ``robot_pose_std`` or estimated; closed-form start;
    outlier test, adequacy test and variance factor as the robot-chain path); k-fold held-out prediction of the
    measured poses (``poses.pair_holdout``, ``folds``: default ``holdout.DEFAULT_FOLDS``). write_first: called
    before the report is written (the measurements when they were not written before the fit)."""
    from ..identify.handeye_problem import handeye_problem, stack_measurements
    from ..report.handeye import handeye_report
    from .camera_step import fitted_camera, intrinsics_directions, residual_response
    from .checks import copies_warning, handeye_motions, pair_copies
    from .handeye_gross import alternative_readings, handeye_gross_failure
    from .handeye_step import handeye_blocks, identify_handeye

    ok = [i for i, pm in enumerate(pms) if pm.valid]
    if len(ok) < 3:
        raise IdentifiabilityError(f"{rec.folder}: only {len(ok)} usable poses; hand-eye identification needs "
                                   "at least 3 (with rotations about two different axes)")
    # one image with few corners per pose: each pose's sigma_px is a poor estimate, pool it over the poses
    T, cov, labels, _ = stack_measurements([pms[i] for i in ok], pool_sigma=rec.frames_per_pose == 1)
    mount = "fixed" if rec.camera_mount in ("fixed", "base") else "eye_in_hand"
    handeye_motions(rec.poses[ok], mount, labels, str(rec.folder))  # degenerate motion named before any fit
    keep, copies = pair_copies(rec.poses[ok], T, cov, labels)  # a copied pose folder: counted once
    ok, T, cov, labels = [ok[k] for k in keep], T[keep], cov[keep], [labels[k] for k in keep]
    if copies:
        mblock = {**mblock, "copies": [{"pose_id": lab, "reason": why} for lab, why in copies]}
    dirs = intrinsics_directions(intr, rec.camera) if dets else []
    used = []  # the cameras of the nuisance columns (refilled by residual_response)
    by_id = {str(pm.pose_id): pm for pm in pms}  # the corner selection each re-measurement keeps

    def nuisance(pb, x):  # intrinsics calibrated from these images: their error is shared by all poses
        m = pb.meta
        return residual_response(dirs, dets, [str(lab) for lab in pb.labels], rec, x, np.asarray(pb.residual(x), float),
                                 lambda Tm: handeye_problem(m["T_base_flange"], Tm, mount, m["A0"], m["B0"], pb.obs_cov,
                                                            labels=pb.labels), used, by_id)

    from ..identify.adequacy import IMAGE_COV_SCALE

    ident = identify_handeye(rec.poses[ok], T, mount, cov, labels, rec.robot_pose_std,
                             nuisance=nuisance if dirs else None, where=str(rec.folder), cov_scale=IMAGE_COV_SCALE)
    result, A, B, problem = ident.result, ident.A, ident.B, ident.problem
    failure = handeye_gross_failure(rec.poses[ok], T, mount, ident, str(rec.folder), alternatives=alternative_readings(
        rec.poses[ok], T, mount, "recording.yaml camera_mount"))

    def pairs_holdout():  # the k-fold fits, when first asked for (``_Fitted.holdout``)
        if failure is not None:
            return None
        from types import SimpleNamespace

        from .holdout import DEFAULT_FOLDS
        from .poses import pair_holdout

        pairs = SimpleNamespace(ids=tuple(str(lab) for lab in labels), T_base_flange=rec.poses[ok], T_cam_target=T,
                                cov=cov, noise_frame=None, mount=mount, robot_std=rec.robot_pose_std, path=rec.folder)
        # the folds' REML starts from the full fit's robot variances
        start = tuple(ident.fit.robot_variances) if ident.fit.robot.get("source") == "estimated" else None
        return pair_holdout(pairs, int(min(folds or DEFAULT_FOLDS, len(ok))), 0,
                            outliers=[lab for lab, _ in ident.rejected], theta_start=start, fit=ident.fit)

    hold_of = functools.cache(pairs_holdout)
    cam_fit = None
    if ident.nuisance is not None:
        cam_fit = fitted_camera(rec.camera, used, ident.nuisance["coefficients"])
        intr = {**intr, "propagated": {**ident.nuisance, "in_fit": True, "how": IN_FIT,
                                       "fitted_values": _camera_values(cam_fit)}}
    # reprojection with the intrinsics the fit ended at, the calibrated ones' figure beside it
    # reprojection over the points the measurement used, with the intrinsics the fit ended at (calibrated beside)
    used, counts = used_corners(dets or {}, pms, rec.target)
    he = handeye_report(result, A, B, problem, detections=used, target=rec.target, intrinsics=cam_fit or rec.camera)
    if cam_fit is not None and he["reprojection"] is not None:
        from ..measure.reprojection import with_calibrated_figure

        cal = handeye_report(result, A, B, problem, detections=used, target=rec.target, intrinsics=rec.camera)
        he["reprojection"] = with_calibrated_figure(he["reprojection"], cal["reprojection"])
    he.update(handeye_blocks(ident))
    he["reprojection"] = label_points(he["reprojection"], counts)
    kept = {str(lab) for lab in problem.labels}
    rwarn = None
    if he["reprojection"] is not None:
        T_model = A @ problem.meta["G"] @ B
        px2 = robot_corner_variance(problem, result.identified, T_model, used, rec.target, cam_fit or rec.camera)
        rcheck, rwarn = reprojection_noise_check(he["reprojection"], [pm for pm in pms if str(pm.pose_id) in kept],
                                                 intr, px2, he.get("robot_pose_std"))
        if rcheck is not None:
            he["reprojection"] = {**he["reprojection"], "noise_check": rcheck}
    def report_with(hold):
        """(report, tail) with the held-out block ``hold`` (None: none; its decision can fail the verdict)."""
        report = build_report(
            "process_handeye", source={"folder": str(rec.folder)},
            settings={"poses": mblock["n_poses"], "mount": mount, "camera": rec.camera.to_dict(), "method": "lse"},
            measurements=mblock, warnings=[*rec.notes, *intr["warnings"], *copies_warning(copies, "flange pose"),
                                           *([rwarn] if rwarn else [])], result=result,
            identified=ident,
            residuals=residual_stats(result.residuals, "pose"),
            extra={"handeye": he, "intrinsics": intr, "reprojection": he["reprojection"], "cause": None,
                   **({"holdout": hold} if hold is not None else {})},
            timings={"total": time.perf_counter() - t0}, failure=failure or holdout_failure(hold))
        report["summary_text"] += points_line(report.get("reprojection"))
        tail = ""
        if hold is not None:
            from .poses import pair_holdout_lines

            tail = "\n" + "\n".join(pair_holdout_lines(hold))
        return report, tail

    def write(report):
        if write_first is not None:
            write_first()
        write_report(out, report, plots=plots, overlays=_overlay_source(rec, dets) if plots else None)

    view, _ = report_with(None)  # what the cause test reads: the report but its held-out block
    return _Fitted(view, lambda: report_with(hold_of()), write, hold_of)


__all__ = ["process_folder", "process_once", "fit_measured", "measure_folder", "Measured", "measure_recording"]
