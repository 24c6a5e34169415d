"""Detect once per pose vs per frame (issue 11): measure-stage speed and accuracy, side by side.

    .venv/bin/python benchmarks/bench_detect.py [--poses 6] [--seeds 4] [--frames 10] [--seed 0]
                                                [--targets charuco,apriltag_grid] [--read-noise 1.0]
    .venv/bin/python benchmarks/bench_detect.py --targets chessboard,circles_asymmetric --poses 8 --seeds 2 --frames 5

For each target (bench_measure's ChArUco 7 x 10 and AprilTag grid 4 x 5, 1024 x 768 with distortion,
SensorEffects() defaults unless --read-noise): P random poses (TargetRenderer, supersample 2), S noise
seeds of N frames each. Both DetectConfig.batch modes run on the same frames, interleaved:
- time per frame of the measure stage (detect_batch + measure_pose, one thread) beside a floor measured
  in the same loop: raw OpenCV detection (ChArUco detectBoard / AprilTag detectMarkers without
  refinement) + cv2.solvePnP on one frame;
- systematic error: per pose, the mean over seeds of the pose error vs the rendered truth, RMS over
  poses; random error: per pose the std over seeds, RMS over poses (pose components, mm and deg);
- corners: per-corner bias (mean over frames and seeds of the error vs the projected truth, RMS over
  corners) and scatter (std over frames, pooled), px;
- the largest |seeded - per_frame| pose difference.

Target kinds chessboard / circles_asymmetric (targets/chessboard_a4.yaml, targets/circles_asymmetric_a4.yaml)
run at the H4 viewing geometry (1024 x 768, f = 1013 px, no distortion, 0.6-0.76 m, tilt <= 35 deg), default
DetectConfig, polygon renderer; every other pose is seen with the camera rolled 180 degrees. Printed: corner
bias / scatter (as above), pose error systematic / random (as above) and the total RMS pose error.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from bench_measure import APRILGRID, CHARUCO, INTR  # noqa: E402
from vision_calib import frames  # noqa: E402
from vision_calib.measure import DetectConfig, detect_batch, measure_pose  # noqa: E402
from vision_calib.measure.accuracy import pose_seeds, random_view_pose  # noqa: E402
from vision_calib.measure.pnp import target_lookup  # noqa: E402
from vision_calib.sensor import SensorEffects, apply_effects  # noqa: E402

MODES = {"per_frame": DetectConfig(batch="per_frame"), "seeded": DetectConfig(batch="seeded")}
SCALE = np.array([1e3, 1e3, 1e3, *(3 * [np.degrees(1.0)])])  # -> mm, deg


def _floor_s(target, img) -> float:
    """Raw OpenCV detection + solvePnP on one frame [s]."""
    _, P = target.corner_points()
    t0 = time.perf_counter()
    if target.kind == "charuco":
        cc, ci, _, _ = _FLOOR[target.name].detectBoard(img)
        if ci is not None and len(ci) >= 4:
            cv2.solvePnP(P[ci.ravel()], cc, INTR.K, INTR.dist_array)
    else:
        corners, mids, _ = _FLOOR[target.name].detectMarkers(img)
        if mids is not None:
            pos = {int(i): k for k, i in enumerate(target.corner_points()[0])}
            ids = (4 * mids.reshape(-1, 1) + np.arange(4)).ravel()
            keep = [k for k, i in enumerate(ids) if int(i) in pos]
            uv = np.concatenate(corners).reshape(-1, 2)[keep]
            cv2.solvePnP(P[[pos[int(ids[k])] for k in keep]], uv, INTR.K, INTR.dist_array)
    return time.perf_counter() - t0


_FLOOR = {}


def _corner_errors(dets, T, lookup, acc: dict):
    """Append each corner's error vs the projected truth to acc[id] (list of (2,) px)."""
    for d in dets:
        if not d.valid:
            continue
        p = np.array([lookup[int(i)] for i in d.ids])
        e = d.uv_px - INTR.project(frames.transform_points(T, p))
        for i, ee in zip(d.ids, e):
            acc.setdefault(int(i), []).append(ee)


def run_target(target, n_poses, n_seeds, n_frames, seed, effects):
    from vision_calib.render import TargetRenderer

    lookup = target_lookup(target)
    rng = np.random.default_rng(seed)
    Ts = [random_view_pose(rng, target, INTR) for _ in range(n_poses)]
    seeds = pose_seeds(seed + 1, n_poses * n_seeds)
    r = TargetRenderer(target, INTR.without_distortion(), supersample=2)
    t = {m: 0.0 for m in MODES}
    t_floor, n_img = 0.0, 0
    err = {m: np.full((n_poses, n_seeds, 6), np.nan) for m in MODES}
    corners = {m: [] for m in MODES}
    n_fallback = 0
    try:
        for k, T in enumerate(Ts):
            ideal = r.render(T)
            per_pose = {m: {} for m in MODES}
            for s in range(n_seeds):
                imgs = apply_effects(ideal, effects, n_frames, seeds[k * n_seeds + s], INTR)
                order = list(MODES) if (k + s) % 2 == 0 else list(MODES)[::-1]  # alternate who goes first
                for m in order:
                    t0 = time.perf_counter()
                    dets = detect_batch(imgs, target, INTR, MODES[m])
                    pm = measure_pose(dets, target, INTR, k)
                    t[m] += time.perf_counter() - t0
                    if pm.valid:
                        err[m][k, s] = frames.pose_error(T, pm.T_cam_target)
                    _corner_errors(dets, T, lookup, per_pose[m])
                    if m == "seeded":
                        n_fallback += sum(1 for d in dets if "fallback" in d.diagnostics)
                t_floor += _floor_s(target, imgs[0])
                n_img += n_frames
            for m in MODES:
                corners[m] += [np.array(v) for v in per_pose[m].values() if len(v) > 1]
    finally:
        r.close()
    floor = t_floor / (n_img / n_frames)
    print(f"  measure stage per frame (detect_batch + measure_pose), {n_img} frames per mode; floor = raw "
          f"OpenCV detection + solvePnP on one frame: {floor * 1e3:.2f} ms")
    for m in MODES:
        per = t[m] / n_img
        print(f"    {m:9s} {per * 1e3:8.2f} ms/frame   / floor {per / floor:6.2f}")
    print(f"    per_frame / seeded = {t['per_frame'] / t['seeded']:.2f}x; seeded frames that fell back to a full "
          f"detection: {n_fallback}")
    print(f"  accuracy over {n_poses} poses x {n_seeds} seeds x {n_frames} frames (mm, deg; px):")
    print(f"    {'mode':9s} | {'systematic t':>12} {'r':>7} | {'random t':>9} {'r':>7} | "
          f"{'corner bias':>11} {'scatter':>8} | valid")
    for m in MODES:
        e = err[m] * SCALE
        sysm = np.nanmean(e, axis=1)
        rnd = np.nanstd(e, axis=1, ddof=1)
        cb = np.sqrt(np.mean([np.sum(c.mean(0) ** 2) / 2 for c in corners[m]]))
        sc = np.sqrt(np.mean([c.var(0, ddof=1).mean() for c in corners[m]]))
        print(f"    {m:9s} | {np.sqrt(np.mean(sysm[:, :3] ** 2)):12.5f} {np.sqrt(np.mean(sysm[:, 3:] ** 2)):7.5f} | "
              f"{np.sqrt(np.mean(rnd[:, :3] ** 2)):9.5f} {np.sqrt(np.mean(rnd[:, 3:] ** 2)):7.5f} | "
              f"{cb:11.4f} {sc:8.4f} | {int(np.isfinite(e[..., 0]).sum())}/{e.shape[0] * e.shape[1]}")
    d = np.abs(err["seeded"] - err["per_frame"]) * SCALE
    print(f"    max |seeded - per_frame| pose difference: {np.nanmax(d[..., :3]):.5f} mm, {np.nanmax(d[..., 3:]):.5f} deg")


def run_new_kind(name, n_poses, n_seeds, n_frames, seed, effects):
    """Accuracy of a chessboard / circle-grid target at the H4 geometry (module docstring)."""
    from vision_calib.camera import CameraIntrinsics
    from vision_calib.render import TargetRenderer
    from vision_calib.targets import load_target

    target = load_target(Path(__file__).resolve().parents[1] / "targets" / f"{name}_a4.yaml")
    intr = CameraIntrinsics(1024, 768, 1013.0, 1013.0, 511.5, 383.5)
    lookup = target_lookup(target)
    rng = np.random.default_rng(seed)
    roll = frames.make_T(np.diag([-1.0, -1.0, 1.0]), np.zeros(3))
    Ts = [(roll if k % 2 else np.eye(4)) @ random_view_pose(rng, target, intr, dist_range=(0.6, 0.76))
          for k in range(n_poses)]
    seeds = pose_seeds(seed + 1, n_poses * n_seeds)
    r = TargetRenderer(target, intr, backend="polygon")
    err = np.full((n_poses, n_seeds, 6), np.nan)
    corners, t_det, n_img = [], 0.0, 0
    for k, T in enumerate(Ts):
        ideal = r.render(T)
        acc = {}
        for s in range(n_seeds):
            imgs = apply_effects(ideal, effects, n_frames, seeds[k * n_seeds + s], intr)
            t0 = time.perf_counter()
            dets = detect_batch(imgs, target, intr)
            t_det += time.perf_counter() - t0
            n_img += n_frames
            pm = measure_pose(dets, target, intr, k)
            if pm.valid:
                err[k, s] = frames.pose_error(T, pm.T_cam_target)
            for d in dets:
                if d.valid:
                    e = d.uv_px - intr.project(frames.transform_points(T, np.array([lookup[int(i)] for i in d.ids])))
                    for i, ee in zip(d.ids, e):
                        acc.setdefault(int(i), []).append(ee)
        corners += [np.array(v) for v in acc.values() if len(v) > 1]
    e = err * SCALE
    sysm, rnd = np.nanmean(e, axis=1), np.nanstd(e, axis=1, ddof=1)
    cb = np.sqrt(np.mean([np.sum(c.mean(0) ** 2) / 2 for c in corners]))
    sc = np.sqrt(np.mean([c.var(0, ddof=1).mean() for c in corners]))
    print(f"  {target.name}: {target.n_corners} points, {n_poses} poses (every other rolled 180 deg) x {n_seeds} "
          f"seeds x {n_frames} frames, detect {t_det / n_img * 1e3:.0f} ms/frame")
    print(f"    corner bias {cb:.4f} px, scatter {sc:.4f} px (per coordinate)")
    print(f"    pose error systematic t {np.sqrt(np.mean(sysm[:, :3] ** 2)):.4f} mm, r {np.sqrt(np.mean(sysm[:, 3:] ** 2)):.4f} deg;"
          f" random t {np.sqrt(np.mean(rnd[:, :3] ** 2)):.4f} mm, r {np.sqrt(np.mean(rnd[:, 3:] ** 2)):.4f} deg;"
          f" total RMS t {np.sqrt(np.nanmean(e[..., :3] ** 2)):.4f} mm, r {np.sqrt(np.nanmean(e[..., 3:] ** 2)):.4f} deg;"
          f" valid {int(np.isfinite(e[..., 0]).sum())}/{e.shape[0] * e.shape[1]}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--poses", type=int, default=6)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--targets", default="charuco,apriltag_grid")
    ap.add_argument("--read-noise", type=float, default=None, help="SensorEffects.read_noise_grey (default: its default)")
    a = ap.parse_args(argv)
    cv2.setNumThreads(1)
    effects = SensorEffects() if a.read_noise is None else SensorEffects(read_noise_grey=a.read_noise)
    _FLOOR[CHARUCO.name] = cv2.aruco.CharucoDetector(CHARUCO.cv_board())
    _FLOOR[APRILGRID.name] = cv2.aruco.ArucoDetector(APRILGRID.cv_dictionary(), cv2.aruco.DetectorParameters())
    for name in ("chessboard", "circles_asymmetric"):
        if name in a.targets.split(","):
            print(f"\n=== {name} at the H4 geometry, read noise {effects.read_noise_grey} grey, seed {a.seed} ===",
                  flush=True)
            run_new_kind(name, a.poses, a.seeds, a.frames, a.seed, effects)
    for target in (CHARUCO, APRILGRID):
        if target.kind not in a.targets.split(","):
            continue
        print(f"\n=== {target.name}: {INTR.width}x{INTR.height}, read noise {effects.read_noise_grey} grey, "
              f"seed {a.seed} ===", flush=True)
        detect_batch(np.zeros((1, INTR.height, INTR.width), np.uint8), target, INTR)  # detector caches
        run_target(target, a.poses, a.seeds, a.frames, a.seed, effects)


if __name__ == "__main__":
    main()
