"""End-to-end simulated experiment: truth -> render + sensor effects -> measure ->
identifiability -> identify -> evaluate -> report (``vision-calib simulate`` / ``demo``).

Rendering and measurement run in worker processes (one OpenGL context and one torch thread
each); everything else in the calling process. Per-pose seeds derive from the run seed, so the
same seed gives the same report whatever the number of workers.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import DataError
from .scene import SCENES_DIR, Scene, load_scene, scene_poses
from .setup import Measurements
from .synthetic import identifiability_report, identify, parameters_table, report_to_json, rngs, scene_truth

DEFAULT_SCENE = SCENES_DIR / "h4_vision.yaml"
REPORT_VERSION = "1.0"


def effects_from_scene(scene: Scene):
    """SensorEffects from the scene's ``effects`` mapping (short names noise_grey / blur_px accepted)."""
    from ..sensor import SensorEffects

    d = dict(scene.effects)
    alias = {"noise_grey": "read_noise_grey", "blur_px": "blur_sigma_px"}
    d = {alias.get(k, k): v for k, v in d.items()}
    return SensorEffects.from_dict(d, where=f"{scene.path}: effects")

def rejection_summary(pms) -> str:
    """'k of n poses rejected: reason (count); ...' for a list of PoseMeasurement."""
    from collections import Counter

    bad = [pm.reason for pm in pms if not pm.valid]
    if not bad:
        return f"0 of {len(pms)} poses rejected"
    top = "; ".join(f"{r} ({c})" for r, c in Counter(bad).most_common(3))
    return f"{len(bad)} of {len(pms)} poses rejected: {top}"


def _to_measurements(setup, poses, pms, x_true_joints) -> tuple[Measurements, list[int]]:
    ok = [i for i, pm in enumerate(pms) if pm.valid]
    T = np.array([pms[i].T_cam_target for i in ok]).reshape(-1, 4, 4)
    cov = np.array([pms[i].cov for i in ok]).reshape(-1, 6, 6)
    labels = tuple(str(pms[i].pose_id) for i in ok)
    return Measurements(np.asarray(poses)[ok], np.asarray(x_true_joints)[ok], T, cov, labels), ok


def run_simulation(scene, out_dir=None, seed=None, n_poses=None, frames=None, method=None, export_recording=None,
                   workers=None, progress=False, overrides=None) -> dict:
    """The whole simulated experiment; writes ``out_dir/report.json`` (+ plots, calibrated model)
    when out_dir is given and returns the report dict (with ``summary_text``)."""
    from ..io.report import write_report

    t_start = time.perf_counter()
    scene = scene if isinstance(scene, Scene) else load_scene(scene)
    if out_dir is not None:
        Path(out_dir).mkdir(parents=True, exist_ok=True)  # fail now, not after rendering
    if export_recording is not None:
        ex = Path(export_recording)
        if ex.exists() and (not ex.is_dir() or any(ex.iterdir())):
            raise DataError(f"{ex}: --export-recording needs a new or empty folder (frames of another run would mix in)")
    if overrides:
        scene = apply_overrides(scene, overrides)
    setup = scene.setup
    seed = 0 if seed is None else int(seed)
    frames = frames or scene.measurement["frames"]
    method = method or scene.identification["method"]
    residual = scene.identification["residual"]
    timings = {}
    rp, rn, rv = rngs(seed)

    t = time.perf_counter()
    poses = scene_poses(scene, rp, n_poses)
    validation = scene_poses(scene, rv, which="validation")
    rep, _ = identifiability_report(scene, poses, residual)
    base = setup.params.mask(rep.base_parameters)
    x_true = scene_truth(scene)
    T_true = setup.T_cam_target(poses, x_true)
    q_true = setup.joints(poses, x_true)
    labels = [f"{i:03d}" for i in range(len(poses))]
    timings["setup"] = time.perf_counter() - t

    image_dir = None
    if export_recording is not None:
        image_dir = Path(export_recording) / "images"
    if scene.target_path is None:
        raise DataError(f"{scene.path}: the scene has no target: image simulation needs one")
    from .image_chain import ImageChain, measure_poses

    chain = ImageChain(str(scene.target_path), setup.camera, effects_from_scene(scene), scene.render["supersample"],
                       scene.measurement["averaging"])
    pms, stage = measure_poses(chain, T_true, labels, seed, frames, workers, image_dir, progress)
    timings["worker_peak_rss_mib"] = stage.pop("worker_peak_rss_mib", float("nan"))
    timings.update({f"{k}_cpu": v for k, v in stage.items()})
    timings["render_measure_wall"] = time.perf_counter() - t - timings["setup"]
    if export_recording is not None:
        from ..io.recording import write_recording

        write_recording(export_recording, scene, poses, q_true, frames)

    meas, ok = _to_measurements(setup, poses, pms, q_true)
    rejected = [{"pose_id": pm.pose_id, "reason": pm.reason} for pm in pms if not pm.valid]
    if out_dir is not None:  # kept even if identification fails below
        from ..io.atomic import write_json_atomic

        write_json_atomic(Path(out_dir) / "measurements.json",
                          {"version": REPORT_VERSION, "scene": scene.name, "seed": seed, "n_poses": len(pms),
                           "n_valid": len(ok), "n_rejected": len(rejected), "rejected": rejected,
                           "poses": [pm.to_dict() for pm in pms]})
    t = time.perf_counter()
    result, problem, params, _ = identify_measurements(scene, meas, method, residual, base,
                                                       context=rejection_summary(pms))
    timings["identify"] = time.perf_counter() - t

    # measurement accuracy vs ground truth (only in simulation)
    from .. import frames as F

    err = F.pose_error(T_true[ok], meas.T_cam_target)
    meas_acc = {
        "translation_rms_mm": [float(v) for v in np.sqrt(np.mean(err[:, :3] ** 2, axis=0)) * 1e3],
        "rotation_rms_deg": [float(v) for v in np.degrees(np.sqrt(np.mean(err[:, 3:] ** 2, axis=0)))],
        "predicted_translation_std_mm": [float(v) for v in np.sqrt(np.mean(meas.cov[:, [0, 1, 2], [0, 1, 2]], axis=0)) * 1e3],
        "predicted_rotation_std_deg": [float(v) for v in np.degrees(np.sqrt(np.mean(meas.cov[:, [3, 4, 5], [3, 4, 5]], axis=0)))],
    }

    t = time.perf_counter()
    st = float(np.sqrt(np.mean(err[:, :3] ** 2)))  # measured pose noise, as pose sigmas
    sr = float(np.sqrt(np.mean(err[:, 3:] ** 2)))
    if setup.kind == "h4":
        meas_val = setup.synthetic_measurements(validation, x_true, rv, st, sr)
        before = setup.evaluate(setup.params.nominal, x_true, validation, meas_val)
        after = setup.evaluate(result.identified, x_true, validation, meas_val)
    else:
        before = setup.evaluate(setup.params.nominal, x_true, validation)
        after = setup.evaluate(result.identified, x_true, validation)
    # reference: the same experiment with synthetic pose measurements of the same noise level
    from .synthetic import run_synthetic

    ref = run_synthetic(scene, method=method, residual=residual, sigma_t_m=st, sigma_r_rad=sr, seed=seed,
                        poses=poses, validation=validation, base=base, x_true=x_true)
    timings["evaluate"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t_start

    ps = setup.params
    report = {
        "version": REPORT_VERSION,
        "kind": "simulation",
        "scene": {"name": scene.name, "path": str(scene.path), "robot_kind": setup.kind},
        "seed": seed,
        "settings": {"poses": int(len(poses)), "frames": int(frames), "method": method, "residual": residual,
                     "averaging": scene.measurement["averaging"], "camera": setup.camera.to_dict(),
                     "effects": effects_from_scene(scene).to_dict(), "validation_poses": int(len(validation))},
        "measurements": {"n_valid": len(ok), "n_rejected": len(rejected), "rejected": rejected,
                         "accuracy_vs_truth": meas_acc, "poses": [pm.to_dict() for pm in pms]},
        "identifiability": report_to_json(rep),
        "parameters": parameters_table(ps.names, ps.nominal, x_true, result),
        "identification": result.to_dict(),
        "accuracy": {"before": before, "after": after},
        "synthetic_reference": {"sigma_mm": st * 1e3, "sigma_deg": float(np.degrees(sr)),
                                "accuracy_after": ref["after"]},
        "timings_s": timings,
    }
    report["summary_text"] = summary_text(report)
    if out_dir is not None:
        write_report(out_dir, report, setup, result, problem, x_true, validation)
    return report


def identify_measurements(scene: Scene, meas: Measurements, method, residual, base=None, context: str = ""):
    """Identification of the scene's identifiable free parameters from measurements: (result, problem,
    params, identifiability report or None when ``base`` (n,) bool was given)."""
    from ..errors import IdentifiabilityError
    from ..identify import analyze

    from .synthetic import BASE_SELECTION, base_problem_of

    setup = scene.setup
    rep = None
    if base is None:
        if len(meas.T_cam_target) == 0:
            raise IdentifiabilityError(f"{scene.name}: no usable pose" + (f" ({context})" if context else ""))
        try:
            rep = analyze(setup.problem(meas, residual), selection=BASE_SELECTION)
        except IdentifiabilityError as exc:
            raise IdentifiabilityError(f"{scene.name}: {exc}" + (f" ({context})" if context else "")) from None
        base = setup.params.mask(rep.base_parameters)
    problem, params = base_problem_of(scene, meas, residual, base, context)
    result = identify(problem, method)
    from dataclasses import replace as _replace

    extra = tuple(plausibility_warnings(params, result))
    if extra:
        result = _replace(result, warnings=tuple(result.warnings) + extra)
    return result, problem, params, rep


def plausibility_warnings(params, result, rel: float = 0.2, length_floor_m: float = 0.05,
                          angle_limit_rad: float = 0.2) -> list[str]:
    """Warnings for identified deviations too large to be calibration corrections: a length moved
    by more than ``rel`` of max(|nominal|, length_floor_m), an angle by more than angle_limit_rad.
    Typical causes: wrong units in a file, a wrong target size, a wrong robot model."""
    out = []
    for i in np.flatnonzero(result.free):
        dev = result.identified[i] - params.nominal[i]
        name = params.names[i]
        if params.kinds[i] == "length":
            lim = rel * max(abs(params.nominal[i]), length_floor_m)
            if abs(dev) > lim:
                out.append(f"{name} moved by {dev * 1e3:+.1f} mm from its nominal {params.nominal[i] * 1e3:.1f} mm: "
                           "too large for a calibration correction (units, target size, robot model?)")
        elif abs(dev) > angle_limit_rad:
            out.append(f"{name} moved by {np.degrees(dev):+.2f} deg: too large for a calibration correction "
                       "(units, robot model?)")
    return out


def apply_overrides(scene: Scene, overrides: dict) -> Scene:
    """Scene with settings replaced: noise_grey, blur_px, frames, sigma_mm, sigma_deg, averaging."""
    from dataclasses import replace

    eff = dict(scene.effects)
    meas = dict(scene.measurement)
    for k, v in overrides.items():
        if k in ("noise_grey", "blur_px"):
            eff[k] = float(v)
        elif k == "frames":
            meas["frames"] = int(v)
        elif k == "sigma_mm":
            meas["sigma_t_m"] = float(v) * 1e-3
        elif k == "sigma_deg":
            meas["sigma_r_rad"] = float(np.radians(v))
        elif k == "averaging":
            meas["averaging"] = str(v)
        else:
            raise DataError(f"unknown scene override {k!r} (known: noise_grey, blur_px, frames, sigma_mm, sigma_deg, averaging)")
    return replace(scene, effects=eff, measurement=meas)


def summary_text(report: dict) -> str:
    """One screen: what was run, what was measured, what changed."""
    b, a = report["accuracy"]["before"], report["accuracy"]["after"]
    ident = report["identification"]
    idf = report["identifiability"]
    m = report["measurements"]
    lines = [
        f"scene {report['scene']['name']}  seed {report['seed']}  poses {report['settings']['poses']}  "
        f"frames {report['settings']['frames']}  method {report['settings']['method']}",
        f"measurement: {m['n_valid']} poses valid, {m['n_rejected']} rejected",
    ]
    if "accuracy_vs_truth" in m:
        acc = m["accuracy_vs_truth"]
        lines.append("  pose error vs truth, RMS per component: t = "
                     + ", ".join(f"{v:.3f}" for v in acc["translation_rms_mm"]) + " mm; r = "
                     + ", ".join(f"{v:.4f}" for v in acc["rotation_rms_deg"]) + " deg")
    lines.append(f"identifiability: {idf['n_params']} parameters, rank {idf['rank']}, cond {idf['condition_number']:.3g}"
                 + (f"; not identifiable: {', '.join(idf['non_identifiable'])}" if idf["non_identifiable"] else ""))
    lines.append(f"identification: converged={ident['converged']} iterations={ident['iterations']} "
                 f"cost {ident['cost_initial']:.4g} -> {ident['cost_final']:.4g}")
    lines += [f"warning: {w}" for w in ident.get("warnings", [])]
    lines.append(f"validation ({b['n_poses']} poses): position RMS {b['position_rms_mm']:.3f} -> {a['position_rms_mm']:.3f} mm, "
                 f"max {b['position_max_mm']:.3f} -> {a['position_max_mm']:.3f} mm, rotation RMS "
                 f"{b['rotation_rms_deg']:.4f} -> {a['rotation_rms_deg']:.4f} deg")
    if "V2_rad" in a:
        imp = 100 * (1 - a["V2_rad"] / b["V2_rad"]) if b["V2_rad"] > 0 else float("nan")
        lines.append(f"H4 criteria: V1 {b['V1_rad']:.3g} -> {a['V1_rad']:.3g} rad, V2 {b['V2_rad']:.3g} -> "
                     f"{a['V2_rad']:.3g} rad ({imp:.1f} % better), V3 {b['V3_m'] * 1e3:.4f} -> {a['V3_m'] * 1e3:.4f} mm")
    if "synthetic_reference" in report:
        r = report["synthetic_reference"]
        lines.append(f"synthetic reference (no images, sigma {r['sigma_mm']:.3f} mm / {r['sigma_deg']:.4f} deg): "
                     f"position RMS {r['accuracy_after']['position_rms_mm']:.3f} mm")
    if "timings_s" in report:
        lines.append(f"time: {report['timings_s'].get('total', float('nan')):.1f} s")
    return "\n".join(lines)
