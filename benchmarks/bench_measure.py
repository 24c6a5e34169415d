"""Measurement-chain benchmark: accuracy vs ground truth, the image-model bound and the pose covariance
(z-scores), noise sweep, speed per stage.

    .venv/bin/python benchmarks/bench_measure.py [--poses 50] [--sweep-poses 12] [--speed-poses 12]
                                                 [--workers 2] [--seed 0] [--skip accuracy,scenes,sweep,speed]
                                                 [--scene-poses 20] [--scene-seeds 1,2,3,4,5]
                                                 [--detector-terms N] [--phase-terms N]

Default setting: 1024 x 768, fx = fy = 1100 px, mild Brown–Conrady distortion, ChArUco 7 x 10
(30 mm squares, DICT_5X5_100) at 0.4-0.8 m, tilt up to 35 deg, SensorEffects() defaults (blur
0.6 px, full well 10000 e-, read noise 1 grey level -> ~2 grey levels total at mid-grey), 10 frames.
All numbers are measured here from a seed; nothing is hard-coded.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
import tracemalloc
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from vision_calib import frames  # noqa: E402
from vision_calib.camera import CameraIntrinsics  # noqa: E402
from vision_calib.measure import DetectConfig, MeasureConfig, detect_batch, measure_pose  # noqa: E402
from vision_calib.sim.accuracy import (accuracy_study, format_study, pose_seeds,  # noqa: E402
                                           random_view_pose)
from vision_calib.sensor import SensorEffects, apply_effects, effects_for_render  # noqa: E402
from vision_calib.targets.spec import TargetSpec  # noqa: E402

INTR = CameraIntrinsics(1024, 768, 1100.0, 1100.0, 515.3, 380.7, (-0.1, 0.05, 0.0005, -0.0005, 0.0))
CHARUCO = TargetSpec(kind="charuco", name="bench_charuco_7x10", rows=7, cols=10, dictionary="DICT_5X5_100",
                     square_m=0.03, marker_m=0.022)
APRILGRID = TargetSpec(kind="apriltag_grid", name="bench_aprilgrid_4x5", rows=4, cols=5,
                       dictionary="DICT_APRILTAG_36h11", tag_m=0.04, spacing_m=0.012)
SCALE = np.array([1e3, 1e3, 1e3, *(3 * [np.degrees(1.0)])])


def section(title):
    print(f"\n=== {title} ===", flush=True)


def run_accuracy(n_poses, seed, supersample=2, targets=(CHARUCO, APRILGRID)):
    for target in targets:
        section(f"accuracy: {target.name}, {n_poses} random poses, 10 frames, default effects, "
                f"render supersample {supersample}")
        t0 = time.perf_counter()
        res = accuracy_study(target, INTR, SensorEffects(), n_poses=n_poses, n_frames=10, seed=seed,
                             supersample=supersample)
        print(format_study(res))
        for mode in ("corners", "poses"):
            s = res[mode]
            tot_t = np.max(s["rms"][:3]) * 1e3
            tot_r = np.degrees(np.max(s["rms"][3:]))
            print(f"  {mode}: max component total RMS {tot_t:.4f} mm (target < 0.2), {tot_r:.4f} deg (target < 0.03); "
                  f"random/bound {np.min(s['random_over_bound']):.2f}-{np.max(s['random_over_bound']):.2f}; "
                  f"bias/random {np.min(s['bias_over_random']):.1f}-{np.max(s['bias_over_random']):.1f}; "
                  f"z RMS new {np.min(s['z_new_rms']):.2f}-{np.max(s['z_new_rms']):.2f} (max |z| "
                  f"{np.max(s['z_new_max']):.1f}), old {np.min(s['z_old_rms']):.1f}-{np.max(s['z_old_rms']):.1f} "
                  f"(max |z| {np.max(s['z_old_max']):.1f})")
        print(f"  ({time.perf_counter() - t0:.1f} s)")


def run_detector_terms(n_poses, seed):
    """Corner errors common to a pose (pose covariance model, measure/covariance.py): per pose, a least-squares
    fit to the true corner error (noise-free frame) of a common shift, tag growth (AprilTag) and the smooth
    field terms; mean / RMS over poses and the leak of the independent part into the same fit (RMS)."""
    from vision_calib.targets.kinds.image_model import field_directions
    from vision_calib.render import TargetRenderer

    clean = SensorEffects(full_well_e=0.0, read_noise_grey=0.0)
    cases = ((APRILGRID, "seeded edges", DetectConfig()), (APRILGRID, "per-frame OpenCV", DetectConfig(batch="per_frame")),
             (CHARUCO, "ChArUco", DetectConfig()))
    section(f"detector terms: {n_poses} random poses, noise-free; columns shift u, v, growth, strain u, v, "
            "keystone u, v [px; field terms at the pattern's edge]")
    for target, name, cfg in cases:
        lut = dict(zip(*[list(a) for a in target.corner_points()]))
        rng = np.random.default_rng(seed)
        coef, leak = [], []
        with TargetRenderer(target, INTR, 2, distort=True) as r:  # as the image chain renders
            for k in range(n_poses):
                T = random_view_pose(rng, target, INTR)
                d = detect_batch(apply_effects(r.render(T), effects_for_render(r, clean), 1, 0, INTR), target, INTR,
                                 cfg)[0]
                if not d.valid:
                    continue
                uv = INTR.project(frames.transform_points(T, np.array([lut[int(i)] for i in d.ids])))
                e = (d.uv_px - uv).ravel()
                n = np.zeros_like(uv)
                if target.kind == "apriltag_grid":
                    tag = d.ids // 4
                    c = np.array([uv[tag == t].mean(axis=0) for t in tag])
                    n = (uv - c) / np.maximum(np.linalg.norm(uv - c, axis=1), 1e-9)[:, None]
                A = np.column_stack([np.tile(np.eye(2), (len(uv), 1)), n.ravel(), field_directions(uv)])
                x, *_ = np.linalg.lstsq(A, e, rcond=None)
                res = e - A @ x
                coef.append(x)
                leak.append(res @ res / (len(e) - 7) * np.diag(np.linalg.pinv(A.T @ A)))
        coef, leak = np.array(coef), np.array(leak)
        print(f"  {name:<17} mean " + " ".join(f"{v:+.4f}" for v in coef.mean(0)))
        print(f"  {'':<17} RMS  " + " ".join(f"{v:.4f}" for v in np.sqrt((coef**2).mean(0))))
        print(f"  {'':<17} leak " + " ".join(f"{v:.4f}" for v in np.sqrt(leak.mean(0))))


def phase_split(e_px, uv_px):
    """Least-squares (a, b) of the pixel-phase-locked corner error (measure/covariance.py) from the pairs of one or
    more poses: e_px, uv_px lists of (K, 2) true corner errors and positions (distorted px); each pose's products
    e_k e_l^T (k != l) over its mean square error fit uu = a c(du) + b c(dv), vv = b c(du) + a c(dv) with
    c(x) = cos(2 pi x)."""
    B, Y = [], []
    for e, uv in zip(e_px, uv_px):
        s2 = float(np.mean(e**2))
        ph = 2 * np.pi * (uv[:, None, :] - uv[None, :, :])
        m = ~np.eye(len(e), dtype=bool)
        cu, cv = np.cos(ph[..., 0])[m], np.cos(ph[..., 1])[m]
        B += [np.column_stack([cu, cv]), np.column_stack([cv, cu])]
        Y += [(e[:, None, 0] * e[None, :, 0])[m] / s2, (e[:, None, 1] * e[None, :, 1])[m] / s2]
    return np.linalg.lstsq(np.concatenate(B), np.concatenate(Y), rcond=None)[0]


def run_phase_terms(n_poses, seed, step_deg=3.0, blur_px=None):
    """Pixel-phase-locked corner error of the ChArUco corners (cv2.cornerSubPix; measure/covariance.py
    TargetKind.phase_locked_share): random views with the board rolled uniformly about its normal, noise-free frames; per
    band of the board's edge angle to the pixel axes (folded to 0-45 deg) the split (a, b) of the error's
    covariance between corners into cos 2 pi du / cos 2 pi dv terms (:func:`phase_split`) and their sum, the
    phase-locked share. blur_px: the sensor's Gaussian blur (None: SensorEffects' default)."""
    from vision_calib.render import TargetRenderer

    clean = SensorEffects(full_well_e=0.0, read_noise_grey=0.0)
    if blur_px is not None:
        clean = SensorEffects(full_well_e=0.0, read_noise_grey=0.0, blur_sigma_px=blur_px)
    target = CHARUCO
    lut = dict(zip(*[list(a) for a in target.corner_points()]))
    x0, y0, x1, y1 = target.texture_extent_m()
    c = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    rng = np.random.default_rng(seed)
    bands = np.arange(0.0, 45.0 + 1e-9, step_deg)
    E, U, TH = [], [], []
    with TargetRenderer(target, INTR, 2, distort=True) as r:  # as the image chain renders
        for _ in range(n_poses):
            roll = frames.make_T(frames.T_from_xyz_rotvec(np.r_[0, 0, 0, 0, 0, rng.uniform(0, 2 * np.pi)])[:3, :3],
                                 np.zeros(3))
            T = random_view_pose(rng, target, INTR, dist_range=(0.6, 0.8), tilt_deg=25.0, min_visible=0.7)
            T = T @ frames.make_T(np.eye(3), c) @ roll @ frames.make_T(np.eye(3), -c)
            d = detect_batch(apply_effects(r.render(T), effects_for_render(r, clean), 1, 0, INTR), target, INTR)[0]
            if not d.valid or len(d.ids) < 12:
                continue
            uv = INTR.project(frames.transform_points(T, np.array([lut[int(i)] for i in d.ids])))
            E.append(d.uv_px - uv)
            U.append(uv)
            R = T[:3, :3]
            TH.append(abs((np.degrees(np.arctan2(R[1, 0], R[0, 0])) + 45) % 90 - 45))
    TH = np.array(TH)
    section(f"phase-locked ChArUco corner error: {len(TH)} views (of {n_poses}), noise-free, blur "
            f"{clean.blur_sigma_px} px; a, b per band of the board's edge angle (measure/covariance.py)")
    shares = []
    for lo, hi in zip(bands[:-1], bands[1:]):
        k = np.flatnonzero((TH >= lo) & (TH < hi))
        if len(k) >= 5:
            a, b = phase_split([E[i] for i in k], [U[i] for i in k])
            shares.append(a + b)
            print(f"  edge angle {lo:4.1f}-{hi:4.1f} deg ({len(k):3d} views): a {a:.2f}, b {b:.2f}, "
                  f"phase-locked share a + b {a + b:.2f}")
    print(f"  phase-locked share over the bands: mean {np.mean(shares):.2f}, range {np.min(shares):.2f}-"
          f"{np.max(shares):.2f} (TargetKind.phase_locked_share)")


def run_scene_z(scenes, n_poses, seeds):
    from vision_calib.sim.accuracy import scene_z_study

    for path in scenes:
        section(f"pose covariance z-scores: {path}, {n_poses} scene poses x noise seeds {seeds}, 10 frames")
        t0 = time.perf_counter()
        res = scene_z_study(ROOT / path, n_poses, seeds)
        print(f"  {'':14}" + "".join(f"{c:>8}" for c in ("tx", "ty", "tz", "rx", "ry", "rz")))
        for key in ("z_new_rms", "z_new_max", "z_old_rms", "z_old_max"):
            print(f"  {key:14}" + "".join(f"{x:8.2f}" for x in res[key]))
        print(f"  ({res['n']} measurements, {time.perf_counter() - t0:.1f} s)")


def _sweep_pose(ideal, target, read_noise, n_frames, seed, renderer):
    eff = effects_for_render(renderer, SensorEffects(read_noise_grey=read_noise))
    imgs = apply_effects(ideal, eff, n_frames, seed, INTR)
    dets = detect_batch(imgs, target, INTR)
    return [measure_pose(dets, target, INTR, 0, MeasureConfig(mode=m)) for m in ("corners", "poses")]


def run_sweep(n_poses, seed):
    from vision_calib.render import TargetRenderer

    section(f"noise sweep: {CHARUCO.name}, {n_poses} poses; pose error RMS over poses and components "
            "(translation: RMS of tx,ty,tz in mm; rotation: RMS of rx,ry,rz in deg)")
    noise_levels = (1.0, 4.0, 8.0, 16.0)
    frame_counts = (1, 3, 10)
    rng = np.random.default_rng(seed)
    Ts = [random_view_pose(rng, CHARUCO, INTR) for _ in range(n_poses)]
    seeds = pose_seeds(seed + 1, n_poses)
    renderer = TargetRenderer(CHARUCO, INTR, 2, distort=True)  # as the image chain renders
    try:
        ideals = [renderer.render(T) for T in Ts]
        clean = SensorEffects(full_well_e=0.0, read_noise_grey=0.0)
        bias = {}
        for mode in ("corners", "poses"):
            bias[mode] = [frames.pose_error(T, measure_pose(detect_batch(apply_effects(im, effects_for_render(renderer, clean), 1, 0, INTR), CHARUCO,
                                                                        INTR), CHARUCO, INTR, 0,
                                                           MeasureConfig(mode=mode)).T_cam_target)
                          for T, im in zip(Ts, ideals)]
        print("  total = pose error vs truth; random = total - error of the noise-free frame (bias)")
        print(f"  {'read noise':>10} {'frames':>6} | {'total t[mm]':>11} {'r[deg]':>7} | {'corners random t[mm]':>20} "
              f"{'r[deg]':>7} | {'poses random t[mm]':>18} {'r[deg]':>7} | {'sigma_px':>8} {'valid':>6}")
        for rn in noise_levels:
            for nf in frame_counts:
                tot, rnd = [], {"corners": [], "poses": []}
                sig = []
                for k, T in enumerate(Ts):
                    ms = _sweep_pose(ideals[k], CHARUCO, rn, nf, seeds[k], renderer)
                    for mode, m in zip(("corners", "poses"), ms):
                        if m.valid:
                            e = frames.pose_error(T, m.T_cam_target)
                            rnd[mode].append(e - bias[mode][k])
                            if mode == "corners":
                                tot.append(e)
                    if ms[0].valid and nf > 1:
                        sig.append(ms[0].sigma_px)

                def rms2(a):
                    a = np.array(a).reshape(-1, 6) * SCALE
                    return np.sqrt(np.mean(a[:, :3] ** 2)), np.sqrt(np.mean(a[:, 3:] ** 2))

                t0_, r0_ = rms2(tot)
                t1_, r1_ = rms2(rnd["corners"])
                t2_, r2_ = rms2(rnd["poses"])
                sig_s = f"{np.mean(sig):8.4f}" if sig else f"{'-':>8}"
                print(f"  {rn:10.1f} {nf:6d} | {t0_:11.4f} {r0_:7.4f} | {t1_:20.5f} {r1_:7.5f} | {t2_:18.5f} "
                      f"{r2_:7.5f} | {sig_s} {len(tot):3d}/{n_poses}", flush=True)
    finally:
        renderer.close()


# ----------------------------------------------------------------------------- speed
_W = {}


def _worker_init(gl_threads=None):
    if gl_threads is not None:  # Mesa llvmpipe: threads per GL context (must be set before the context)
        os.environ["LP_NUM_THREADS"] = str(gl_threads)
    import torch

    torch.set_num_threads(1)
    import cv2

    cv2.setNumThreads(1)
    from vision_calib.render import TargetRenderer

    _W["r"] = TargetRenderer(CHARUCO, INTR, 2, distort=True)  # as the image chain renders


def _chain(args):
    """Whole chain for one pose (render once, effects, detect, measure); returns stage times [s]."""
    k, T, seed, n_frames = args
    r = _W["r"]
    t0 = time.perf_counter()
    ideal = r.render(T)
    t1 = time.perf_counter()
    imgs = apply_effects(ideal, effects_for_render(r, SensorEffects()), n_frames, seed, INTR)
    t2 = time.perf_counter()
    dets = detect_batch(imgs, CHARUCO, INTR)
    t3 = time.perf_counter()
    m = measure_pose(dets, CHARUCO, INTR, k)
    t4 = time.perf_counter()
    return m.valid, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)


def run_speed(n_poses, workers, seed, n_frames=10):
    section(f"speed: {CHARUCO.name}, {INTR.width}x{INTR.height}, {n_frames} frames per pose, {n_poses} poses, "
            f"{os.cpu_count()} CPU(s)")
    rng = np.random.default_rng(seed)
    jobs = [(k, random_view_pose(rng, CHARUCO, INTR), s, n_frames) for k, s in enumerate(pose_seeds(seed, n_poses))]

    # serial, in this process, one thread each for a fair per-stage figure
    import cv2
    import torch

    tracemalloc.start()
    _worker_init()
    _chain(jobs[0])  # warm-up (distortion map, detectors)
    t0 = time.perf_counter()
    stats = [_chain(j) for j in jobs]
    serial = time.perf_counter() - t0
    _, peak_py = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    _W["r"].close()
    times = np.array([s[1] for s in stats]).sum(axis=0)
    n_img = n_poses * n_frames
    print(f"  render  (1 ideal image per pose, supersample 2): {n_poses / times[0]:7.1f} poses/s "
          f"({times[0] / n_poses * 1e3:.1f} ms each)")
    print(f"  effects (distortion+blur+noise+8 bit):           {n_img / times[1]:7.1f} frames/s")
    print(f"  detect  (ChArUco + extra cornerSubPix):          {n_img / times[2]:7.1f} frames/s")
    print(f"  PnP     (undistort, average, PnP, covariance):   {n_img / times[3]:7.1f} frames/s "
          f"({times[3] / n_poses * 1e3:.1f} ms per pose)")
    print(f"  whole chain, 1 process x 1 thread:               {n_img / serial:7.1f} frames/s "
          f"(valid {sum(s[0] for s in stats)}/{n_poses})")

    torch.set_num_threads(max(1, os.cpu_count() or 1))
    cv2.setNumThreads(-1)
    if workers > 1:
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_worker_init, initargs=(1,)) as ex:
            list(ex.map(_chain, jobs[:workers]))  # start + warm up the workers
            t0 = time.perf_counter()
            out = list(ex.map(_chain, jobs))
            par = time.perf_counter() - t0
        print(f"  whole chain, {workers} processes x 1 thread (LP_NUM_THREADS=1): {n_img / par:5.1f} frames/s "
              f"(valid {sum(o[0] for o in out)}/{n_poses}; target >= 25)")
    self_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    child_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"  peak memory: max RSS this process {self_mb:.0f} MiB, largest worker {child_mb:.0f} MiB; "
          f"python allocations (tracemalloc, serial run) {peak_py / 2**20:.0f} MiB")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--poses", type=int, default=50)
    ap.add_argument("--sweep-poses", type=int, default=12)
    ap.add_argument("--speed-poses", type=int, default=12)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--supersample", type=int, default=2, help="TargetRenderer supersampling for the accuracy study")
    ap.add_argument("--charuco-only", action="store_true", help="accuracy study on the ChArUco board only")
    ap.add_argument("--skip", default="", help="comma-separated: accuracy,scenes,sweep,speed")
    ap.add_argument("--detector-terms", type=int, default=0, metavar="N",
                    help="only: fit the per-pose common corner error terms on N poses (measure/covariance.py)")
    ap.add_argument("--phase-terms", type=int, default=0, metavar="N",
                    help="only: measure the pixel-phase-locked ChArUco corner error on N views (measure/covariance.py)")
    ap.add_argument("--blur", type=float, default=None,
                    help="--phase-terms: sensor blur [px] (default: SensorEffects')")
    ap.add_argument("--scene-poses", type=int, default=20)
    ap.add_argument("--scene-seeds", default="1,2,3,4,5")
    a = ap.parse_args(argv)
    skip = set(filter(None, a.skip.split(",")))
    if a.detector_terms:
        run_detector_terms(a.detector_terms, a.seed)
        return
    if a.phase_terms:
        run_phase_terms(a.phase_terms, a.seed, blur_px=a.blur)
        return
    if "speed" not in skip:
        run_speed(a.speed_poses, a.workers, a.seed)
    if "accuracy" not in skip:
        run_accuracy(a.poses, a.seed, a.supersample, (CHARUCO,) if a.charuco_only else (CHARUCO, APRILGRID))
    if "scenes" not in skip:
        run_scene_z(("scenes/h4_vision.yaml", "scenes/rx90_eye_in_hand.yaml"), a.scene_poses,
                    tuple(int(x) for x in a.scene_seeds.split(",")))
    if "sweep" not in skip:
        run_sweep(a.sweep_poses, a.seed)


if __name__ == "__main__":
    main()
