"""Detect once per pose vs per frame (issue 11): measure-stage speed and accuracy, side by side.

    .venv/bin/python benchmarks/bench_detect.py [--poses 6] [--seeds 4] [--frames 10] [--seed 0]
                                                [--targets charuco,apriltag_grid] [--read-noise 1.0]
    .venv/bin/python benchmarks/bench_detect.py --targets chessboard,circles_asymmetric --poses 8 --seeds 2 --frames 5

For each target (bench_measure's ChArUco 7 x 10 and AprilTag grid 4 x 5, 1024 x 768 with distortion,
SensorEffects() defaults unless --read-noise): P random poses (TargetRenderer, supersample 2, lens
distortion drawn geometrically as in the image chain), S noise
seeds of N frames each. Both DetectConfig.batch modes run on the same frames, interleaved:
- time per frame of the measure stage (detect_batch + measure_pose, one thread) beside a floor measured
  in the same loop: raw OpenCV detection (ChArUco detectBoard / AprilTag detectMarkers without
  refinement) + cv2.solvePnP on one frame;
- systematic error: per pose, the mean over seeds of the pose error vs the rendered truth, RMS over
  poses; random error: per pose the std over seeds, RMS over poses (pose components, mm and deg);
- corners: per-corner bias (mean over frames and seeds of the error vs the projected truth, RMS over
  corners) and scatter (std over frames, pooled), px;
- the largest |seeded - per_frame| pose difference.

Target kinds chessboard / circles_asymmetric / modified_circle_grid (targets/<kind>_a4.yaml)
run at the H4 viewing geometry (1024 x 768, f = 1013 px, no distortion, 0.6-0.76 m, tilt <= 35 deg), default
DetectConfig, polygon renderer; every other pose is seen with the camera rolled 180 degrees. Printed per path:
time per frame of detect_batch, corner bias (per corner the mean error over all frames of the pose, RMS over
corners and poses) / scatter (std over the frames of one seed, pooled), pose error systematic / random (as
above) and the total RMS pose error, and the corner scatter the image model predicts (measure/covariance.py).
Chessboard paths, on the same frames: "SB ACCURACY" (findChessboardCornersSB with CALIB_CB_ACCURACY on every
frame, the detector before the saddle fit), "saddle per_frame" and "saddle seeded" (targets/kinds/chessboard.py).
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
from vision_calib.sim.accuracy import pose_seeds, random_view_pose  # noqa: E402
from vision_calib.measure.pnp import target_lookup  # noqa: E402
from vision_calib.sensor import SensorEffects, apply_effects, effects_for_render  # noqa: E402

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
    r = TargetRenderer(target, INTR, supersample=2, distort=True)  # as the image chain renders
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
                imgs = apply_effects(ideal, effects_for_render(r, effects), n_frames, seeds[k * n_seeds + s], INTR)
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


class _AccuracyChessboard:
    """The chessboard kind as it was before the saddle fit: findChessboardCornersSB(CALIB_CB_ACCURACY) on
    every frame (no seeded mode), same orientation logic."""

    def __init__(self, kind):
        self.kind = kind

    def __getattr__(self, name):
        return getattr(self.kind, name)

    def find_corners(self, spec, det, img, config, diag, intrinsics=None):
        nr, nc = spec.rows - 1, spec.cols - 1
        ok, corners = cv2.findChessboardCornersSB(img, (nc, nr), flags=cv2.CALIB_CB_ACCURACY)
        if not ok or corners is None:
            return None, "not found"
        G, why = self.kind.orient(spec, img, corners.reshape(nr, nc, 2).astype(np.float64))
        return (None, why) if G is None else (np.arange(nr * nc), G.reshape(-1, 2))

    def seeded_mode(self, config):
        return None


def _variants(target):
    """[(label, kind implementation or None (the registered one), DetectConfig)] compared for a target."""
    if target.kind == "chessboard":
        old = _AccuracyChessboard(target.kind_impl)
        return [("SB ACCURACY", old, MODES["per_frame"]), ("saddle per_frame", None, MODES["per_frame"]),
                ("saddle seeded", None, MODES["seeded"])]
    return [("default", None, DetectConfig())]


def _with_kind(target, impl, fn):
    """fn() with the target's kind implementation replaced by impl (None: as registered)."""
    from vision_calib.targets import spec as spec_mod

    if impl is None:
        return fn()
    reg = spec_mod._REGISTRY
    keep = reg[target.kind]
    reg[target.kind] = impl
    try:
        return fn()
    finally:
        reg[target.kind] = keep


def run_new_kind(name, n_poses, n_seeds, n_frames, seed, effects):
    """Accuracy and speed of a chessboard / circle-grid target at the H4 geometry (module docstring); for the
    chessboard, the SB ACCURACY detector (the old path) beside the saddle fit, per frame and seeded, on the
    same frames, plus the corner scatter the image model predicts (measure/covariance.py corner_info)."""
    from vision_calib.camera import CameraIntrinsics
    from vision_calib.measure.covariance import corner_info
    from vision_calib.render import TargetRenderer
    from vision_calib.targets import load_target

    target = load_target(Path(__file__).resolve().parents[1] / "targets" / f"{name}_a4.yaml")
    intr = CameraIntrinsics(1024, 768, 1013.0, 1013.0, 511.5, 383.5)
    lookup = target_lookup(target)
    ids_all, P_all = target.corner_points()
    rng = np.random.default_rng(seed)
    roll = frames.make_T(np.diag([-1.0, -1.0, 1.0]), np.zeros(3))
    Ts = [(roll if k % 2 else np.eye(4)) @ random_view_pose(rng, target, intr, dist_range=(0.6, 0.76))
          for k in range(n_poses)]
    seeds = pose_seeds(seed + 1, n_poses * n_seeds)
    r = TargetRenderer(target, intr, backend="polygon")
    variants = _variants(target)
    err = {v[0]: np.full((n_poses, n_seeds, 6), np.nan) for v in variants}
    corners = {v[0]: [] for v in variants}
    t_det = {v[0]: 0.0 for v in variants}
    pred_var, n_img = [], 0
    for k, T in enumerate(Ts):
        ideal = r.render(T)
        acc = {v[0]: {} for v in variants}
        F = corner_info(target, T, P_all, intr, effects)
        pred_var.append(np.trace(np.linalg.inv(F), axis1=1, axis2=2) / 2)
        for s in range(n_seeds):
            imgs = apply_effects(ideal, effects, n_frames, seeds[k * n_seeds + s], intr)
            n_img += n_frames
            order = variants if (k + s) % 2 == 0 else variants[::-1]  # alternate who goes first
            for label, impl, cfg in order:
                t0 = time.perf_counter()
                dets = _with_kind(target, impl, lambda: detect_batch(imgs, target, intr, cfg))
                t_det[label] += time.perf_counter() - t0
                pm = measure_pose(dets, target, intr, k)
                if pm.valid:
                    err[label][k, s] = frames.pose_error(T, pm.T_cam_target)
                for d in dets:
                    if d.valid:
                        p = np.array([lookup[int(i)] for i in d.ids])
                        e = d.uv_px - intr.project(frames.transform_points(T, p))
                        for i, ee in zip(d.ids, e):
                            acc[label].setdefault((s, int(i)), []).append(ee)
        for label in acc:  # bias per corner over all frames of the pose; scatter per (seed, corner) over frames
            per_id = {}
            for (s, i), v in acc[label].items():
                per_id.setdefault(i, []).append(np.array(v))
            corners[label] += [(np.concatenate(v), v) for v in per_id.values()]
    n_frames_mode = n_img // max(1, n_poses * n_seeds) * n_poses * n_seeds
    print(f"  {target.name}: {target.n_corners} points, {n_poses} poses (every other rolled 180 deg) x {n_seeds} "
          f"seeds x {n_frames} frames ({n_frames_mode} frames per row), read noise {effects.read_noise_grey} grey")
    print(f"    {'path':17s} | {'ms/frame':>8} | {'corner bias':>11} {'scatter':>8} | {'systematic t':>12} {'r':>7} | "
          f"{'random t':>8} {'r':>7} | {'total t':>7} {'r':>7} | valid  (px, mm, deg)")
    for label, _, _ in variants:
        e = err[label] * SCALE
        sysm, rnd = np.nanmean(e, axis=1), np.nanstd(e, axis=1, ddof=1)
        cb = np.sqrt(np.mean([np.sum(c.mean(0) ** 2) / 2 for c, _ in corners[label]]))
        sc = np.sqrt(np.mean([x.var(0, ddof=1).mean() for _, xs in corners[label] for x in xs if len(x) > 1]))
        print(f"    {label:17s} | {t_det[label] / n_img * 1e3:8.1f} | {cb:11.4f} {sc:8.4f} | "
              f"{np.sqrt(np.mean(sysm[:, :3] ** 2)):12.4f} {np.sqrt(np.mean(sysm[:, 3:] ** 2)):7.4f} | "
              f"{np.sqrt(np.mean(rnd[:, :3] ** 2)):8.4f} {np.sqrt(np.mean(rnd[:, 3:] ** 2)):7.4f} | "
              f"{np.sqrt(np.nanmean(e[..., :3] ** 2)):7.4f} {np.sqrt(np.nanmean(e[..., 3:] ** 2)):7.4f} | "
              f"{int(np.isfinite(e[..., 0]).sum())}/{e.shape[0] * e.shape[1]}")
    print(f"    image-model corner scatter (corner_info of kind {target.kind!r}): "
          f"{np.sqrt(np.mean(np.concatenate(pred_var))):.4f} px per coordinate")
    if len(variants) > 1:
        base = variants[0][0]
        for label, _, _ in variants[1:]:
            print(f"    {base} / {label} time per frame: {t_det[base] / t_det[label]:.1f}x")


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
    for name in ("chessboard", "circles_asymmetric", "modified_circle_grid"):
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
