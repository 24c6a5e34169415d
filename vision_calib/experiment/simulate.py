"""End-to-end simulated experiment: truth -> render + sensor effects -> measure ->
identifiability -> identify -> evaluate -> report (``vision-calib simulate`` / ``demo``).

Rendering and measurement run in worker processes (:mod:`.image_chain`); everything else in the
calling process. Per-pose seeds derive from the run seed, so the same seed gives the same report
whatever the number of workers. Kinds whose criteria need validation measurements (H4 V1/V2:
``Setup.measured_criteria``) get them from the validation poses rendered and measured the same way (own
noise stream), while the identification runs. The report's ``synthetic_reference`` is the same
identification with synthetic pose measurements drawn from each measured pose's covariance (like for like).
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

from .. import frames as F
from ..errors import DataError
from ..serialize import write_json_atomic
from ..report.build import REPORT_VERSION, build_report, measurements_block, parameters_table
from ..report.write import write_report
from ..rig import Measurements, Scene, SCENES_DIR, load_scene, scene_poses
from .image_chain import ImageChain, ImagePool, InlineImagePool, measure_poses, start_fork_server
from .checks import screen_measurements
from .holdout import flagged_labels, holdout_failure, holdout_lines, holdout_validation, with_holdout_warning
from .steps import (check_method, identify_measurements, inconsistency_failure, rejection_summary, rngs,
                    run_analysis_and_truth, shared_truth, unmodelled_truth)
from .synthetic import run_synthetic

DEFAULT_SCENE = SCENES_DIR / "h4_vision.yaml"
#: random streams of a run seed beside experiment.steps' (1-4) and the identification images' (5): the
#: validation poses' images, and the synthetic reference's noise (draw k: [seed, 7, k, 0] for the
#: identification poses, [seed, 7, k, 1] for the validation measurements)
STREAM_VALIDATION_IMAGES, STREAM_REFERENCE = 6, 7
#: independent noise draws of the synthetic reference (its report gives the median and the range)
REFERENCE_DRAWS = 5
#: what the synthetic reference's noise is, for its report block
REFERENCE_NOISE = ("Gaussian, drawn from each image-measured pose's own covariance (the measurement's cov, 6x6: "
                   "translation m and rotation vector rad in the camera frame, applied as frames.perturb_pose), "
                   "for the identification poses and the validation measurements alike; joint readings exact "
                   "as in the image run")
#: settings an images-mode run may override (studies): sensor effects and frames per pose
OVERRIDES = ("noise_grey", "blur_px", "frames", "averaging")


def apply_overrides(scene: Scene, overrides: dict) -> Scene:
    """Scene with image settings replaced: noise_grey, blur_px (sensor effects), frames, averaging.
    DataError naming the key for anything else (e.g. the synthetic pose noise sigma_mm, which an
    image run never reads: it measures its noise)."""
    from .. rig.scene import EFFECT_ALIASES

    eff, meas = {}, {}
    for k, v in overrides.items():
        if k in ("noise_grey", "blur_px"):
            eff[EFFECT_ALIASES[k]] = float(v)
        elif k in ("frames", "averaging"):
            meas[k] = int(v) if k == "frames" else str(v)
        else:
            raise DataError(f"override {k!r} does not apply to an image run (known: {', '.join(OVERRIDES)})")
    return replace(scene, effects=replace(scene.effects, **eff), measurement=replace(scene.measurement, **meas))


def image_chain_of(scene: Scene) -> ImageChain:
    """The image-chain settings of a scene (target file, camera, sensor effects, supersampling, averaging)."""
    if scene.target_path is None or scene.setup.camera is None:
        raise DataError(f"{scene.path}: image simulation needs a target and a camera in the scene")
    return ImageChain(str(scene.target_path), scene.setup.camera, scene.effects, scene.supersample,
                      scene.measurement.averaging)


def _measurement_accuracy(T_true, meas: Measurements) -> dict:
    """Measured poses vs ground truth T_true (N, 4, 4) (simulation only): RMS per component, the std the
    covariances predict, and ``normalised_error_rms`` = sqrt(mean_k e_k^T cov_k^-1 e_k / 6) (1 when each
    pose's covariance describes its error; the synthetic reference draws its noise from these covariances)."""
    err = F.pose_error(T_true, meas.T_cam_target)
    sd = np.sqrt(np.mean(np.diagonal(meas.cov, axis1=1, axis2=2), axis=0))
    m2 = np.einsum("ki,ki->k", err, np.linalg.solve(meas.cov, err[..., None])[..., 0]) if len(err) else np.zeros(0)
    return {
        "translation_rms_mm": [float(v) for v in np.sqrt(np.mean(err[:, :3] ** 2, axis=0)) * 1e3],
        "rotation_rms_deg": [float(v) for v in np.degrees(np.sqrt(np.mean(err[:, 3:] ** 2, axis=0)))],
        "predicted_translation_std_mm": [float(v) for v in sd[:3] * 1e3],
        "predicted_rotation_std_deg": [float(v) for v in np.degrees(sd[3:])],
        "normalised_error_rms": float(np.sqrt(np.mean(m2) / 6)) if len(m2) else float("nan"),
    }


def _check_outputs(out_dir, export_recording) -> None:
    if out_dir is not None:
        Path(out_dir).mkdir(parents=True, exist_ok=True)  # fail now, not after rendering
    if export_recording is not None:
        ex = Path(export_recording)
        if ex.exists() and (not ex.is_dir() or any(ex.iterdir())):
            raise DataError(f"{ex}: --export-recording needs a new or empty folder (frames of another run would mix in)")


def _render_and_measure(scene, chain, T_true, q_true, poses, seed, frames, workers, export_recording, progress, pool,
                        timings: dict) -> list:
    """PoseMeasurement per pose of the image chain (+ the recorded folder when exporting); stage timings added."""
    t = time.perf_counter()
    labels = [f"{i:03d}" for i in range(len(poses))]
    image_dir = None if export_recording is None else Path(export_recording) / "images"
    pms, stage = measure_poses(chain, T_true, labels, seed, frames, workers, image_dir, progress, pool=pool)
    _add_stage_timings(timings, stage)
    timings["render_measure_wall"] = time.perf_counter() - t
    if export_recording is not None:
        from ..io.recording import write_recording

        write_recording(export_recording, scene, poses, q_true, frames)
    return pms


def _add_stage_timings(timings: dict, stage: dict) -> None:
    """Add measure_poses' worker CPU seconds per stage (and the peak worker RSS) into ``timings``."""
    rss = stage.pop("worker_peak_rss_mib", float("nan"))
    timings["worker_peak_rss_mib"] = max(timings.get("worker_peak_rss_mib", float("-inf")), rss)
    for k, v in stage.items():
        timings[f"{k}_cpu"] = timings.get(f"{k}_cpu", 0.0) + v


def validation_labels(n: int) -> list[str]:
    """Pose ids of the n validation poses' measurements ("v000", ...; identification poses are "000", ...)."""
    return [f"v{i:03d}" for i in range(n)]


def _measure_validation(chain, tsetup, validation, x_true, seed, frames, pool, progress, timings):
    """(Measurements of the validation poses measured from their own rendered images, indices of those poses
    in ``validation`` (M,), their PoseMeasurement list): the same image chain as the identification poses,
    noise stream STREAM_VALIDATION_IMAGES, labels :func:`validation_labels`; exact joint readings."""
    t = time.perf_counter()
    T = tsetup.T_cam_target(validation, x_true)
    pms, stage = measure_poses(chain, T, validation_labels(len(validation)), seed, frames, pool=pool,
                               progress=progress, stream=STREAM_VALIDATION_IMAGES, desc="validation poses")
    _add_stage_timings(timings, stage)
    meas, ok = Measurements.from_pose_measurements(validation, tsetup.joints(validation, x_true), pms)
    timings["validation_render_measure_wall"] = time.perf_counter() - t
    return meas, np.asarray(ok, int), pms, T


def _reference(scene, method, residual, seed, poses, meas, validation, val_meas, val_idx, base, x_true, truth,
               draws: int = REFERENCE_DRAWS) -> dict:
    """The report's ``synthetic_reference``: the same identification and evaluation with synthetic pose
    measurements whose noise is drawn from each image-measured pose's own covariance (``meas.cov``; validation
    measurements from ``val_meas.cov``, of the validation poses ``val_idx``), ``draws`` independent draws
    (streams [seed, STREAM_REFERENCE, k, 0 | 1]); every figure of the accuracy after calibration as the median
    over the draws (``accuracy_after``), its [min, max] (``range``) and the draws (``per_draw``)."""
    per = []
    for k in range(draws):
        ref = run_synthetic(scene, method=method, residual=residual, seed=seed, poses=poses, validation=validation,
                            base=base, x_true=x_true, truth=truth, prepare=True, pose_cov=meas.cov,
                            validation_cov=None if val_meas is None else val_meas.cov,
                            validation_measured=val_idx, sigma_q_rad=0.0,
                            noise_rngs=(np.random.default_rng([seed, STREAM_REFERENCE, k, 0]),
                                        np.random.default_rng([seed, STREAM_REFERENCE, k, 1])))
        per.append(ref.after.to_dict())
    keys = [k for k in per[0] if k != "n_poses"]
    return {"noise": REFERENCE_NOISE, "draws": draws,
            "streams": f"numpy default_rng([seed, {STREAM_REFERENCE}, k, 0]) for the identification poses' noise, "
                       f"[seed, {STREAM_REFERENCE}, k, 1] for the validation measurements', k = 0..{draws - 1}",
            "n_poses": int(len(poses)), "identification_poses": list(meas.labels),
            "validation_measured": [] if val_meas is None else list(val_meas.labels),
            "accuracy_after": {**{k: float(np.median([p[k] for p in per])) for k in keys},
                               "n_poses": per[0]["n_poses"]},
            "range": {k: [float(min(p[k] for p in per)), float(max(p[k] for p in per))] for k in keys},
            "per_draw": per}


def _preload(plots: bool):
    """Import what the steps after the image chain need (scipy.stats for the adequacy test; matplotlib and
    its fonts for the plots) in a daemon thread while the image workers run and the main process only
    waits for them: ~1 s of CPU off the serial path of a run. Returns the thread."""
    import threading

    def work():
        try:
            import scipy.stats  # noqa: F401

            if plots:
                from ..report.plots import preload

                preload()
        except Exception:  # import or plotting problems surface where the modules are used, not here
            pass

    th = threading.Thread(target=work, name="preload", daemon=True)
    th.start()
    return th


def _intrinsics_sensitivity(scene, ident, meas) -> dict:
    """``camera_step.intrinsics_sensitivity`` of a simulated run (exact intrinsics: no warning), the poses
    re-measured from the target's corners projected at the measured poses (``projected_remeasure``)."""
    from ..targets import load_target
    from .camera_step import intrinsics_sensitivity, projected_remeasure

    cam = ident.setup.camera
    again = projected_remeasure(load_target(scene.target_path), cam, dict(zip(meas.labels, meas.T_cam_target)))
    return intrinsics_sensitivity(ident, meas, cam, again, given_std=None)


def truth_failure(evals: dict) -> dict | None:
    """The report's ``failure`` when the calibrated model is worse than the nominal one against the truth on the
    validation poses (position or rotation RMS; simulation only: the truth is known), else None."""
    b, a = evals["before"].to_dict(), evals["after"].to_dict()
    worse = [f"{q} RMS {b[k]:.4g} -> {a[k]:.4g} {u}" for q, k, u in (("position", "position_rms_mm", "mm"),
                                                                       ("rotation", "rotation_rms_deg", "deg"))
             if k in b and k in a and np.isfinite(a[k]) and a[k] > b[k]]
    if not worse:
        return None
    return {"kind": "validation against the truth",
            "message": "no calibrated model written: on the validation poses the calibrated model is further from "
                       "the true robot than the nominal one (" + "; ".join(worse) + ")"}


def run_simulation(scene: Scene | str | Path, out_dir: str | Path | None = None, seed: int | None = None,
                   n_poses: int | None = None, frames: int | None = None, method: str | None = None,
                   export_recording: str | Path | None = None, workers: int | None = None, progress: bool = False,
                   overrides: dict | None = None, plots: bool = True, pool: ImagePool | InlineImagePool | None = None,
                   fix_unidentifiable: bool = False, reference: bool = True, folds: int | None = None,
                   tcp=None, accuracy_map: bool = True) -> dict:
    """The whole simulated experiment; writes ``out_dir/report.json`` (+ plots, calibrated model)
    when out_dir is given and returns the report dict (with ``summary_text``). pool: an image pool to reuse
    (``image_chain.ImagePool``, or ``InlineImagePool``: the chain in this thread, the validation poses measured
    after the identification instead of beside it; same numbers), else one is started for this run (and shared by
    the identification and validation poses). reference: add the report's ``synthetic_reference`` (5 more
    identifications; a study, which does not record it, leaves it out). accuracy_map: add the report's
    ``accuracy_map`` (:mod:`.accuracy_map`; a study leaves it out too). folds / tcp: the held-out validation
    (:mod:`.holdout`; its decision, and a validation against the truth worse than the nominal model, fail the
    verdict: no calibrated model)."""
    t_start = time.perf_counter()
    if pool is None:
        start_fork_server()  # its imports overlap with the preparation below (no-op if started already)
    scene = scene if isinstance(scene, Scene) else load_scene(scene)
    _check_outputs(out_dir, export_recording)
    if overrides:
        scene = apply_overrides(scene, overrides)
    chain = image_chain_of(scene)  # fails now (no target/camera), not after rendering
    setup = scene.setup
    seed = 0 if seed is None else int(seed)
    frames = frames or scene.measurement.frames
    method = check_method(setup, method or scene.identification.method, "method")
    residual = setup.residual_for(method, scene.identification.residual)
    timings = {}
    rp, _, rv = rngs(seed)

    t = time.perf_counter()
    poses = scene_poses(scene, rp, n_poses)
    validation = scene_poses(scene, rv, which="validation")
    rep, x_true = run_analysis_and_truth(scene, poses, residual)  # the run's one identifiability analysis
    truth, x_truth = unmodelled_truth(scene)  # a true robot the model does not share, if the scene asks
    if truth is not None:
        x_true = x_truth
    tsetup = truth or setup
    T_true = tsetup.T_cam_target(poses, x_true)
    q_true = tsetup.joints(poses, x_true)
    timings["setup"] = time.perf_counter() - t
    preloading = _preload(out_dir is not None and plots)
    measured_validation = bool(setup.measured_criteria)  # H4: V1/V2 from image-measured validation poses
    own = pool is None
    if own:
        pool = ImagePool(chain, max(1, min(workers or os.cpu_count() or 1, len(poses))))
    inline = getattr(pool, "inline", False)  # the chain runs in this thread: no second thread may use it
    background = None if inline else ThreadPoolExecutor(1, thread_name_prefix="validation-images")
    try:
        pms = _render_and_measure(scene, chain, T_true, q_true, poses, seed, frames, workers, export_recording,
                                  progress, pool, timings)
        # the validation poses' images are rendered and measured by the workers while this process identifies
        val_job = None
        if measured_validation and not inline:
            val_job = background.submit(_measure_validation, chain, tsetup, validation, x_true, seed, frames, pool,
                                        False, timings)
        meas, ok = Measurements.from_pose_measurements(poses, q_true, pms)
        mblock = measurements_block(pms)
        if out_dir is not None:  # kept even if identification fails below
            write_json_atomic(Path(out_dir) / "measurements.json",
                              {"version": REPORT_VERSION, "scene": scene.name, "seed": seed, **mblock})
        t = time.perf_counter()
        meas_used, inconsistent, motion = screen_measurements(setup, meas, str(scene.path),
                                                              f"the target's square size ({scene.target_path})")
        # analysed again on the measured poses, whitened by their measured covariances, as `process` does (the
        # planning analysis `rep` has no noise model: 1 mm and 1 mrad weigh alike, another condition number)
        ident = identify_measurements(setup, meas_used, method, residual, None,
                                      context=rejection_summary(pms), where=str(scene.path),
                                      fix_unidentifiable=fix_unidentifiable, rejected=inconsistent)
        result, problem, setup = ident.result, ident.problem, ident.setup  # setup: after prepare_setup (H4 axis)
        sens = _intrinsics_sensitivity(scene, ident, meas_used)
        timings["identify"] = time.perf_counter() - t
        t = time.perf_counter()
        hold = holdout_validation(scene.setup, meas_used, method, residual, ident.analysis, folds, seed,
                                  outliers=flagged_labels(meas_used, ident.rejected), tcp=tcp, result=result, fitted_setup=setup)
        result = with_holdout_warning(result, hold)
        timings["holdout"] = time.perf_counter() - t
        if val_job is not None:
            val_meas, val_idx, val_pms, T_val = val_job.result()
        elif measured_validation:  # inline pool: the same measurements, after the identification
            val_meas, val_idx, val_pms, T_val = _measure_validation(chain, tsetup, validation, x_true, seed, frames,
                                                                    pool, False, timings)
        else:
            val_meas, val_idx, val_pms, T_val = None, [], None, None
    except BaseException:  # an error or Ctrl-C: the queued poses are dropped, not measured
        if own:
            pool.close(cancel=True)
        raise
    finally:
        if background is not None:
            background.shutdown()  # waits for the validation images (also when the identification failed)
        if own:
            pool.close()

    t = time.perf_counter()
    meas_acc = _measurement_accuracy(T_true[ok], meas)
    # before: the nominal model; after: the identified one (with what prepare_setup determined); truth: tsetup.
    # V1/V2 (H4) from the image-measured validation poses, never used in the identification
    if val_meas is not None and not len(val_idx):  # no validation pose measurable: criteria left out, not NaN
        val_meas = None
    evals = {"before": scene.setup.evaluate(scene.setup.params.nominal, x_true, validation, val_meas, truth=tsetup),
             "after": setup.evaluate(result.identified, x_true, validation, val_meas, truth=tsetup)}
    # reference: the same experiment with synthetic pose measurements drawn from the measured covariances
    ref = None if not reference else _reference(scene, method, residual, seed, poses[ok], meas, validation, val_meas,
                                                val_idx, setup.params.mask(rep.base_parameters), x_true, truth)
    timings["evaluate"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t_start

    ps = setup.params
    mblock["accuracy_vs_truth"] = meas_acc
    extra = {"intrinsics_sensitivity": sens} if ref is None else {"synthetic_reference": ref, "intrinsics_sensitivity": sens}
    if val_pms is not None:
        vb = measurements_block(val_pms)
        extra["validation_measurements"] = {
            "source": "images: the validation poses rendered and measured through the identification poses' image "
                      f"chain (own noise stream [seed, {STREAM_VALIDATION_IMAGES}, i]); never used in the "
                      "identification",
            "criteria": list(setup.measured_criteria), "labels": [pm.pose_id for pm in val_pms if pm.valid],
            "n_poses": vb["n_poses"], "n_valid": vb["n_valid"], "rejected": vb["rejected"],
            "accuracy_vs_truth": None if val_meas is None else _measurement_accuracy(T_val[val_idx], val_meas)}
    report = build_report(
        "simulation", seed=seed,
        source={"scene": {"name": scene.name, "path": str(scene.path), "robot_kind": setup.kind}},
        settings={"poses": int(len(poses)), "frames": int(frames), "method": method, "residual": residual,
                  "averaging": scene.measurement.averaging, "camera": setup.camera.to_dict(),
                  "effects": scene.effects.to_dict(), "validation_poses": int(len(validation))},
        measurements=mblock, identifiability=ident.analysis, parameters=parameters_table(
            ps.names, ps.nominal, shared_truth(setup, truth or scene.setup, x_true), result, ps.kinds),
        result=result, identified=ident, motion=motion, accuracy=evals, timings=timings,
        extra={**extra, "holdout": hold}, failure=inconsistency_failure(ident) or holdout_failure(hold) or truth_failure(evals))
    report["summary_text"] += "\n" + "\n".join(holdout_lines(hold))
    if accuracy_map:  # the map of the calibrated tool over the workspace
        from .accuracy_map import add_accuracy_map, map_rng

        add_accuracy_map(report, setup, result, meas_used.select(problem.labels).joints, tcp=tcp,
                         sigma_q_rad=scene.measurement.sigma_q_rad, truth_setup=tsetup, x_true=x_true,
                         rng=map_rng(seed))
    if out_dir is not None:
        preloading.join()
        write_report(out_dir, report, setup, result, problem, evals, plots=plots,
                     overlays=_overlay_source(scene, chain, setup, result, report, T_true, q_true, seed, frames)
                     if plots else None)
    return report


def _overlay_source(scene, chain, setup, result, report, T_true, q_true, seed, frames):
    """report.html's overlay images of a simulated run: the few poses shown rendered again (the frames of the run
    are not kept), the model's reprojection from the joint readings q_true through the identified parameters."""
    from ..report.overlay import OverlaySource
    from ..targets import load_target
    from .image_chain import overlay_frames

    labels = [f"{i:03d}" for i in range(len(T_true))]  # as _render_and_measure
    usable = report["verdict"].get("usable")

    def model_pose(pid):
        i = labels.index(pid) if pid in labels else None
        return None if i is None or not usable else setup.predict_from_joints(q_true[i:i + 1], result.identified)[0]

    return OverlaySource(lambda ids: overlay_frames(chain, T_true, labels, seed, frames, ids),
                         load_target(scene.target_path), chain.camera, model_pose)
