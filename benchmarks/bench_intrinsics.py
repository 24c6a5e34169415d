"""Camera calibration benchmark (measure.intrinsics): recovered vs true intrinsics, std and z per seed,
RMS, time; the spread over seeds vs the mean reported std; a white-noise check of the std.

    .venv/bin/python benchmarks/bench_intrinsics.py [--seeds 0,1,2,3,4] [--views 20] [--resampled] [--apriltag]

Setting: 1024 x 768, fx = fy = 1100 px, distortion (-0.1, 0.05, 5e-4, -5e-4, 0), ChArUco 7 x 10 (30 mm),
views from ``sim.intrinsics_views.calibration_poses`` (tilt 20-45 deg, 0.4-0.65 m), distortion drawn
geometrically (``render_views``; --resampled: the sensor stage's bilinear resampling instead, for comparison)
+ SensorEffects() defaults (blur 0.6 px, ~2 grey levels noise), one frame per view.

--apriltag: the same camera and effects, the AprilTag grid targets/apriltag_grid.yaml (4 x 6 tags of 30 mm) at
0.25-0.45 m, the images written to files and calibrated by ``calibrate_from_images`` (tag-edge corners, refitted
once in the undistorted pixels of a first calibration: ``TAG_EDGE_REFIT``), against the same without the refit
(edges in raw pixels), with two refits, and OpenCV's AprilTag marker refinement (``detect`` per frame, refine "apriltag"): RMS and
mean z, RMS error, detection time per image.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from vision_calib.camera import CameraIntrinsics  # noqa: E402
from vision_calib.measure.detect import Detection, DetectConfig, detect  # noqa: E402
from vision_calib.measure.intrinsics import PARAM_NAMES, calibrate_intrinsics, distortion_displacement  # noqa: E402
from vision_calib.sim.intrinsics_views import calibration_poses, render_views  # noqa: E402
from vision_calib.targets.spec import TargetSpec  # noqa: E402

INTR = CameraIntrinsics(1024, 768, 1100.0, 1100.0, 515.3, 380.7, (-0.1, 0.05, 0.0005, -0.0005, 0.0))
CHARUCO = TargetSpec(kind="charuco", name="bench_charuco_7x10", rows=7, cols=10, dictionary="DICT_5X5_100",
                     square_m=0.03, marker_m=0.022)
TRUE = np.array([INTR.fx, INTR.fy, INTR.cx, INTR.cy, *INTR.dist])


def rendered(seeds, n_views, exact=True):
    print(f"=== rendered views: {n_views} per seed, distortion {'drawn exactly' if exact else 'resampled'} ===")
    print("per seed: value ± std (z = (value - true) / std)")
    est, std, zd = [], [], []
    for seed in seeds:
        t0 = time.perf_counter()
        imgs = render_views(CHARUCO, INTR, calibration_poses(CHARUCO, INTR, n_views, seed), seed,
                            exact_distortion=exact)
        dets = [detect(im, CHARUCO, None, config=DetectConfig(batch="per_frame")) for im in imgs]
        t1 = time.perf_counter()
        res = calibrate_intrinsics(dets, list(range(len(dets))), CHARUCO)
        t2 = time.perf_counter()
        v, s = np.array(list(res.values().values())), np.array(list(res.std.values()))
        est.append(v)
        std.append(s)
        print(f"seed {seed}: RMS {res.rms_px:.4f} px, {res.n_used} views used, render+detect {t1 - t0:.2f} s, "
              f"calibrate {t2 - t1:.3f} s")
        print("   " + "  ".join(f"{n} {x:.6g}±{e:.2g} (z {(x - t) / e:+.1f})" for n, x, e, t in
                                zip(PARAM_NAMES, v, s, TRUE)))
        d = res.distortion
        err = np.linalg.norm(distortion_displacement(res.camera, d["corners_xy"])
                             - distortion_displacement(INTR, d["corners_xy"]), axis=1)
        zd.append(err / d["std_corners_px"])
        print("   distortion at the image corners TL TR BL BR: error " + " ".join(f"{e:.3f}" for e in err)
              + " px, std " + " ".join(f"{e:.3f}" for e in d["std_corners_px"]) + " px")
        for w in res.warnings:
            print(f"      warning: {w}")
    est, std = np.array(est), np.array(std)
    z = (est - TRUE) / std
    print("true: " + "  ".join(f"{n} {t:.6g}" for n, t in zip(PARAM_NAMES, TRUE)))
    print("RMS z over seeds:           " + "  ".join(f"{n} {x:.2f}" for n, x in zip(PARAM_NAMES, np.sqrt(np.mean(z**2, 0)))))
    print("max |z| over seeds:         " + "  ".join(f"{n} {x:.2f}" for n, x in zip(PARAM_NAMES, np.abs(z).max(0))))
    zd = np.array(zd)
    print(f"distortion at the image corners, |error| / std: RMS {np.sqrt(np.mean(zd**2)):.2f}, max {zd.max():.2f}")
    if len(seeds) > 1:
        print("spread over seeds / mean std: " + "  ".join(f"{n} {x:.2f}" for n, x in
                                                    zip(PARAM_NAMES, est.std(0, ddof=1) / std.mean(0))))


def white_noise(trials=100, sigma=0.1):
    """Exact projections of the corners + N(0, sigma) px: reported std vs the spread of the estimates."""
    print(f"\n=== white-noise check: {trials} trials, 12 views, sigma {sigma} px per coordinate ===")
    rng = np.random.default_rng(0)
    poses = calibration_poses(CHARUCO, INTR, 12, 2)
    ids, p = CHARUCO.corner_points()
    clean = [INTR.project(p @ T[:3, :3].T + T[:3, 3]) for T in poses]
    est, std = [], []
    t0 = time.perf_counter()
    for _ in range(trials):
        dets = []
        for uv in clean:
            uv = uv + rng.normal(0, sigma, uv.shape)
            ok = (uv[:, 0] > 0) & (uv[:, 0] < 1023) & (uv[:, 1] > 0) & (uv[:, 1] < 767)
            dets.append(Detection(True, "", ids[ok], uv[ok], INTR.size))
        res = calibrate_intrinsics(dets, list(range(12)), CHARUCO)
        est.append(list(res.values().values()))
        std.append(list(res.std.values()))
    dt = (time.perf_counter() - t0) / trials
    ratio = np.mean(std, 0) / np.std(est, 0, ddof=1)
    print("mean reported std / spread: " + "  ".join(f"{n} {x:.2f}" for n, x in zip(PARAM_NAMES, ratio)))
    print(f"calibration time per trial: {dt * 1e3:.0f} ms")


def apriltag(seeds, n_views):
    """The --apriltag comparison (module docstring)."""
    import tempfile

    import cv2

    import vision_calib.measure.intrinsics as I
    from vision_calib.targets.spec import load_target

    tag = load_target(Path(__file__).resolve().parents[1] / "targets" / "apriltag_grid.yaml")
    print(f"\n=== AprilTag grid {tag.rows} x {tag.cols}: {n_views} views per seed, seeds {list(seeds)} ===")
    out = {"tag edges, refitted (calibrate_from_images)": [], "tag edges in raw pixels (no refit)": [],
           "tag edges, refitted twice": [], "OpenCV AprilTag refinement, per frame": []}
    secs = dict.fromkeys(out, 0.0)
    for seed in seeds:
        imgs = render_views(tag, INTR, calibration_poses(tag, INTR, n_views, seed, dist_range=(0.25, 0.45)), seed)
        with tempfile.TemporaryDirectory() as tmp:
            files = [str(Path(tmp) / f"{k:02d}.png") for k in range(len(imgs))]
            for f, im in zip(files, imgs):
                cv2.imwrite(f, im)
            for name, refit in list(zip(out, (1, 0, 2))):
                I.TAG_EDGE_REFIT, keep = refit, I.TAG_EDGE_REFIT
                try:
                    t0 = time.perf_counter()
                    res = I.calibrate_from_images(files, tag, INTR.size)
                    secs[name] += time.perf_counter() - t0
                finally:
                    I.TAG_EDGE_REFIT = keep
                out[name].append(res)
            name = list(out)[3]
            t0 = time.perf_counter()
            dets = [detect(f, tag, None, config=DetectConfig(batch="per_frame")) for f in files]
            out[name].append(calibrate_intrinsics(dets, files, tag))
            secs[name] += time.perf_counter() - t0
    for name, rs in out.items():
        v = np.array([list(r.values().values()) for r in rs])
        z = (v - TRUE) / np.array([list(r.std.values()) for r in rs])
        print(f"{name}: {secs[name] / len(rs) / n_views * 1e3:.0f} ms per image (decode, detect, calibrate), "
              f"reprojection RMS {np.mean([r.rms_px for r in rs]):.3f} px")
        print("   RMS z     " + "  ".join(f"{n} {x:.2f}" for n, x in zip(PARAM_NAMES, np.sqrt(np.mean(z**2, 0)))))
        print("   mean z    " + "  ".join(f"{n} {x:+.2f}" for n, x in zip(PARAM_NAMES, z.mean(0))))
        print("   RMS error " + "  ".join(f"{n} {x:.2g}" for n, x in zip(PARAM_NAMES, np.sqrt(np.mean((v - TRUE)**2, 0)))))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="0,1,2,3,4")
    ap.add_argument("--views", type=int, default=20)
    ap.add_argument("--resampled", action="store_true", help="also run with the sensor stage's resampled distortion")
    ap.add_argument("--apriltag", action="store_true", help="the AprilTag grid comparison only (module docstring)")
    a = ap.parse_args()
    if a.apriltag:
        return apriltag([int(s) for s in a.seeds.split(",")], a.views)
    rendered([int(s) for s in a.seeds.split(",")], a.views)
    if a.resampled:
        rendered([int(s) for s in a.seeds.split(",")], a.views, exact=False)
    white_noise()


if __name__ == "__main__":
    main()
