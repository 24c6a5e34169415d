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
from ..io.atomic import write_json_atomic, write_text_atomic
from ..io.recording import read_recording
from .setup import Measurements
from .simulate import REPORT_VERSION, identify_measurements, rejection_summary, summary_text


def measure_recording(rec, progress=False):
    """PoseMeasurement per pose id of a Recording (invalid ones carry a reason)."""
    from ..measure import MeasureConfig, PoseMeasurement, measure_images

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
        pm, _ = measure_images([str(f) for f in files], rec.target, rec.camera, pose_id=pid,
                               config=MeasureConfig(mode=rec.averaging))
        out.append(pm)
    return out


def process_folder(folder, out_dir, method=None, progress=False) -> dict:
    """Process a recorded folder; writes DIR/measurements.json, DIR/report.json (+ plots, model)."""
    from ..io.report import write_report

    t0 = time.perf_counter()
    rec = read_recording(folder)
    out = Path(out_dir)
    pms = measure_recording(rec, progress)
    ok = [i for i, pm in enumerate(pms) if pm.valid]
    rejected = [{"pose_id": pm.pose_id, "reason": pm.reason} for pm in pms if not pm.valid]
    meas_block = {"n_poses": len(pms), "n_valid": len(ok), "n_rejected": len(rejected), "rejected": rejected,
                  "extra_files_ignored": list(rec.extra_files), "poses": [pm.to_dict() for pm in pms]}
    write_json_atomic(out / "measurements.json", {"version": REPORT_VERSION, "folder": str(rec.folder), **meas_block})
    t_meas = time.perf_counter() - t0

    T = np.array([pms[i].T_cam_target for i in ok]).reshape(-1, 4, 4)
    cov = np.array([pms[i].cov for i in ok]).reshape(-1, 6, 6)
    labels = tuple(str(pms[i].pose_id) for i in ok)
    if rec.pose_kind == "flange_pose":
        return _process_handeye(rec, out, [pms[i] for i in ok], ok, meas_block, t0)

    if rec.scene_path is None:
        raise ConfigError(f"{rec.folder / 'recording.yaml'}: scene: needed to know the robot model (joint poses)")
    from .scene import load_scene

    scene = load_scene(rec.scene_path)
    setup = scene.setup
    if rec.camera_mount != setup.mount:
        raise ConfigError(f"{rec.folder / 'recording.yaml'}: camera_mount: {rec.camera_mount!r} but the scene "
                          f"{scene.path} has mount {setup.mount!r}")
    if setup.camera is not None and setup.camera.size != rec.camera.size:
        raise DataError(f"{rec.folder}: recording camera {rec.camera.size} differs from the scene's {setup.camera.size}")
    from dataclasses import replace

    setup = replace(setup, camera=rec.camera)
    scene = replace(scene, setup=setup)
    q = rec.poses[ok]
    n_joints = setup.chain.n_joints if setup.kind == "serial" else 4
    if rec.poses.shape[1] != n_joints:
        raise DataError(f"{rec.folder / 'poses.csv'}: {rec.poses.shape[1]} joint columns, the robot has {n_joints}")
    if setup.kind == "serial" and setup.chain.joint_limits is not None:
        lim = setup.chain.joint_limits
        bad = np.argwhere((rec.poses < lim[:, 0]) | (rec.poses > lim[:, 1]))
        if bad.size:
            k, j = (int(v) for v in bad[0])
            raise DataError(
                f"{rec.folder / 'poses.csv'}: pose {rec.pose_ids[k]!r} joint q{j + 1} = {np.degrees(rec.poses[k, j]):.4g} deg "
                f"is outside the robot's limits [{np.degrees(lim[j, 0]):.4g}, {np.degrees(lim[j, 1]):.4g}] deg "
                f"(wrong angle unit in recording.yaml 'units'?)")
    meas = Measurements(q, q, T, cov, labels)
    method = method or scene.identification["method"]
    residual = scene.identification["residual"]
    if len(ok) < 2:
        raise IdentifiabilityError(f"{rec.folder}: only {len(ok)} usable poses of {len(pms)} "
                                   f"({rejection_summary(pms)}); identification needs more")
    t1 = time.perf_counter()
    result, problem, params, rep = identify_measurements(scene, meas, method, residual, context=rejection_summary(pms))
    t_id = time.perf_counter() - t1
    from .synthetic import parameters_table, report_to_json

    r = result.residuals
    res_stats = _residual_stats(r, problem.residual_kind)
    ps = setup.params
    report = {
        "version": REPORT_VERSION,
        "kind": "process",
        "folder": str(rec.folder),
        "scene": {"name": scene.name, "path": str(scene.path), "robot_kind": setup.kind},
        "settings": {"poses": len(pms), "frames": rec.frames_per_pose, "method": method, "residual": residual,
                     "camera": rec.camera.to_dict()},
        "measurements": meas_block,
        "warnings": list(rec.notes),
        "identifiability": report_to_json(rep),
        "parameters": parameters_table(ps.names, ps.nominal, None, result),
        "identification": result.to_dict(),
        "residuals": res_stats,
        "timings_s": {"measure": t_meas, "identify": t_id, "total": time.perf_counter() - t0},
    }
    report["summary_text"] = _summary(report)
    write_report(out, report, setup, result, problem)
    return report


def _residual_stats(r, kind) -> dict:
    if kind in ("pose", "position"):
        d = {"translation_rms_mm": [float(v) for v in np.sqrt(np.mean(r[:, :3] ** 2, axis=0)) * 1e3]}
        if r.shape[1] == 6:
            d["rotation_rms_deg"] = [float(v) for v in np.degrees(np.sqrt(np.mean(r[:, 3:] ** 2, axis=0)))]
        return d
    return {"joint_rms_deg": [float(v) for v in np.degrees(np.sqrt(np.mean(r**2, axis=0)))]}


def _summary(report) -> str:
    m = report["measurements"]
    ident = report["identification"]
    lines = [f"{report['folder']}: {m['n_valid']} of {m['n_poses']} poses usable, {m['n_rejected']} rejected"]
    lines += [f"warning: {w}" for w in report.get("warnings", [])]
    for rj in m["rejected"][:10]:
        lines.append(f"  pose {rj['pose_id']}: {rj['reason']}")
    idf = report.get("identifiability")
    if idf:
        lines.append(f"identifiability: {idf['n_params']} parameters, rank {idf['rank']}, cond {idf['condition_number']:.3g}"
                     + (f"; not identifiable: {', '.join(idf['non_identifiable'])}" if idf["non_identifiable"] else ""))
    lines.append(f"identification ({ident['method']}): converged={ident['converged']} iterations={ident['iterations']} "
                 f"cost {ident['cost_initial']:.4g} -> {ident['cost_final']:.4g}")
    lines += [f"warning: {w}" for w in ident.get("warnings", [])]
    lines.append("residual RMS: " + "; ".join(f"{k} " + ", ".join(f"{v:.4g}" for v in vals)
                                              for k, vals in report["residuals"].items()))
    return "\n".join(lines)


def _process_handeye(rec, out, pms_ok, ok, meas_block, t0) -> dict:
    """Flange poses known: identify the camera mount and the target mount only."""
    from ..identify.handeye_problem import handeye_report, solve_handeye, stack_measurements

    if len(ok) < 3:
        raise IdentifiabilityError(f"{rec.folder}: only {len(ok)} usable poses; hand-eye identification needs "
                                   "at least 3 (with rotations about two different axes)")
    # one image with few corners per pose: each pose's sigma_px is a poor estimate, pool it over the poses
    T, cov, labels, _ = stack_measurements(pms_ok, pool_sigma=rec.frames_per_pose == 1)
    G = rec.poses[ok]
    mount = "fixed" if rec.camera_mount in ("fixed", "base") else "eye_in_hand"
    # PnP covariances miss the robot's own pose error: scale the covariance by the a-posteriori
    # variance factor (whitened cost / degrees of freedom), reported as such
    result, A, B, problem = solve_handeye(G, T, mount, pose_cov=cov, labels=labels, scale_cov_by_residual=True)
    he = handeye_report(result, A, B, problem)
    report = {
        "version": REPORT_VERSION,
        "kind": "process_handeye",
        "folder": str(rec.folder),
        "settings": {"poses": meas_block["n_poses"], "mount": mount, "camera": rec.camera.to_dict()},
        "measurements": meas_block,
        "handeye": he,
        "identification": result.to_dict(),
        "residuals": _residual_stats(result.residuals, "pose"),
        "timings_s": {"total": time.perf_counter() - t0},
    }
    lines = []
    for name in (he["A"], he["B"]) if mount == "eye_in_hand" else ("T_base_cam", "T_flange_target"):
        t = he["transforms"][name]
        lines.append(f"{name}: xyz = " + ", ".join(f"{v * 1e3:.1f}" for v in t["xyz_m"]) + " mm (std "
                     + ", ".join(f"{v * 1e3:.2f}" for v in t["std_xyz_m"]) + "); rpy = "
                     + ", ".join(f"{v:.2f}" for v in t["rpy_deg"]) + " deg (std "
                     + ", ".join(f"{v:.2f}" for v in t["std_rot_deg"]) + ")")
    report["summary_text"] = _summary(report) + "\n" + "\n".join(lines)
    write_text_atomic(out / "summary.txt", report["summary_text"] + "\n")
    write_json_atomic(out / "report.json", report)
    return report


__all__ = ["process_folder", "measure_recording", "summary_text"]
