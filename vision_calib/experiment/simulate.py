"""End-to-end simulated experiment: truth -> render + sensor effects -> measure ->
identifiability -> identify -> evaluate -> report (``vision-calib simulate`` / ``demo``).

Rendering and measurement run in worker processes (:mod:`.image_chain`); everything else in the
calling process. Per-pose seeds derive from the run seed, so the same seed gives the same report
whatever the number of workers.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from .. import frames as F
from ..errors import DataError
from ..io.atomic import write_json_atomic
from ..io.report import REPORT_VERSION, build_report, measurements_block, parameters_table, write_report
from ..rig import Measurements, Scene, SCENES_DIR, load_scene, scene_poses
from .image_chain import ImageChain, measure_poses, start_fork_server
from .checks import screen_measurements
from .steps import (check_method, identify_measurements, rejection_summary, rngs, run_analysis_and_truth,
                    shared_truth, unmodelled_truth)
from .synthetic import run_synthetic

DEFAULT_SCENE = SCENES_DIR / "h4_vision.yaml"
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
    """Measured poses vs ground truth (simulation only): RMS per component and predicted std."""
    err = F.pose_error(T_true, meas.T_cam_target)
    sd = np.sqrt(np.mean(np.diagonal(meas.cov, axis1=1, axis2=2), axis=0))
    return {
        "translation_rms_mm": [float(v) for v in np.sqrt(np.mean(err[:, :3] ** 2, axis=0)) * 1e3],
        "rotation_rms_deg": [float(v) for v in np.degrees(np.sqrt(np.mean(err[:, 3:] ** 2, axis=0)))],
        "predicted_translation_std_mm": [float(v) for v in sd[:3] * 1e3],
        "predicted_rotation_std_deg": [float(v) for v in np.degrees(sd[3:])],
    }, err


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
    timings["worker_peak_rss_mib"] = stage.pop("worker_peak_rss_mib", float("nan"))
    timings.update({f"{k}_cpu": v for k, v in stage.items()})
    timings["render_measure_wall"] = time.perf_counter() - t
    if export_recording is not None:
        from ..io.recording import write_recording

        write_recording(export_recording, scene, poses, q_true, frames)
    return pms


def _preload(plots: bool):
    """Import what the steps after the image chain need (scipy.stats for the adequacy test; matplotlib and
    its fonts for the plots) in a daemon thread while the image workers run and the main process only
    waits for them: ~1 s of CPU off the serial path of a run. Returns the thread."""
    import threading

    def work():
        try:
            import scipy.stats  # noqa: F401

            if plots:
                from ..io.plots import preload

                preload()
        except Exception:  # import or plotting problems surface where the modules are used, not here
            pass

    th = threading.Thread(target=work, name="preload", daemon=True)
    th.start()
    return th


def run_simulation(scene, out_dir=None, seed=None, n_poses=None, frames=None, method=None, export_recording=None,
                   workers=None, progress=False, overrides=None, plots=True, pool=None,
                   fix_unidentifiable=False) -> dict:
    """The whole simulated experiment; writes ``out_dir/report.json`` (+ plots, calibrated model)
    when out_dir is given and returns the report dict (with ``summary_text``). pool: an image worker
    pool to reuse (``image_chain``), else one is started for this run."""
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
    pms = _render_and_measure(scene, chain, T_true, q_true, poses, seed, frames, workers, export_recording, progress,
                              pool, timings)
    meas, ok = Measurements.from_pose_measurements(poses, q_true, pms)
    mblock = measurements_block(pms)
    if out_dir is not None:  # kept even if identification fails below
        write_json_atomic(Path(out_dir) / "measurements.json",
                          {"version": REPORT_VERSION, "scene": scene.name, "seed": seed, **mblock})
    t = time.perf_counter()
    meas_used, inconsistent, motion = screen_measurements(setup, meas, str(scene.path),
                                                          f"the target's square size ({scene.target_path})")
    ident = identify_measurements(setup, meas_used, method, residual, rep if not inconsistent else None,
                                  context=rejection_summary(pms), where=str(scene.path),
                                  fix_unidentifiable=fix_unidentifiable, rejected=inconsistent)
    result, problem, setup = ident.result, ident.problem, ident.setup  # setup: after Setup.prepare (H4 camera axis)
    timings["identify"] = time.perf_counter() - t

    t = time.perf_counter()
    meas_acc, err = _measurement_accuracy(T_true[ok], meas)
    st = float(np.sqrt(np.mean(err[:, :3] ** 2)))  # measured pose noise, as pose sigmas
    sr = float(np.sqrt(np.mean(err[:, 3:] ** 2)))
    meas_val = tsetup.synthetic_measurements(validation, x_true, rv, st, sr)
    # before: the nominal model; after: the identified one (with what prepare() determined); truth: tsetup
    evals = {"before": scene.setup.evaluate(scene.setup.params.nominal, x_true, validation, meas_val, truth=tsetup),
             "after": setup.evaluate(result.identified, x_true, validation, meas_val, truth=tsetup)}
    # reference: the same experiment with synthetic pose measurements of the same noise level
    ref = run_synthetic(scene, method=method, residual=residual, sigma_t_m=st, sigma_r_rad=sr, seed=seed,
                        poses=poses, validation=validation, base=setup.params.mask(rep.base_parameters),
                        x_true=x_true, truth=truth, prepare=True)
    timings["evaluate"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t_start

    ps = setup.params
    mblock["accuracy_vs_truth"] = meas_acc
    report = build_report(
        "simulation", seed=seed,
        source={"scene": {"name": scene.name, "path": str(scene.path), "robot_kind": setup.kind}},
        settings={"poses": int(len(poses)), "frames": int(frames), "method": method, "residual": residual,
                  "averaging": scene.measurement.averaging, "camera": setup.camera.to_dict(),
                  "effects": scene.effects.to_dict(), "validation_poses": int(len(validation))},
        measurements=mblock, identifiability=rep, parameters=parameters_table(
            ps.names, ps.nominal, shared_truth(setup, truth or scene.setup, x_true), result),
        result=result, identified=ident, motion=motion, accuracy=evals, timings=timings,
        extra={"synthetic_reference": {"sigma_mm": st * 1e3, "sigma_deg": float(np.degrees(sr)),
                                       "accuracy_after": ref.after.to_dict()}})
    if out_dir is not None:
        preloading.join()
        write_report(out_dir, report, setup, result, problem, evals, plots=plots)
    return report
