"""`vision-calib noise` against known truth: simulated folders of repeated frames (the project's renderer and
sensor stage) -> the fitted settings' z = (fit - truth) / reported se, RMS and mean over seeds.

    .venv/bin/python benchmarks/bench_noise.py [--seeds 24] [--frames 10] [--target targets/charuco_a5.yaml]
                                               [--distance 0.35] [--no-diameter]

Camera 640 x 480, f = 600 px, k1 = -0.1, k2 = 0.05; target at --distance m tilted (0.3, -0.2, 0.1) rad; truth
SensorEffects(blur 1.3 px, read noise 3 grey, full well 5000 e-, exposure 0.6, black level 30). Each seed writes
--frames PNGs and runs experiment.noise.measure_noise (plain folder with --target/--camera; with --no-diameter a
ROS-I cal_data.yaml whose finder has no dot diameter, the diameter fitted). Printed per figure: z RMS, z mean;
"read/fw (pixels)" from the photon-transfer fit, "read/fw (matched)" the noise that reproduces the corner
scatter, "reproduced" the log ratio measured / re-simulated corner noise over its reported se; and seconds per run.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import yaml

from vision_calib.camera import CameraIntrinsics
from vision_calib.experiment.noise import measure_noise
from vision_calib.experiment.noise_sim import simulate_frames
from vision_calib.render import look_at_target
from vision_calib.sensor import SensorEffects
from vision_calib.targets import load_target

CAM = CameraIntrinsics(640, 480, 600, 600, 319.5, 239.5, (-0.1, 0.05, 0.0, 0.0, 0.0))
TRUTH = dict(blur_sigma_px=1.3, read_noise_grey=3.0, full_well_e=5000.0, exposure=0.6, black_level_grey=30.0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=24)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--target", default="targets/charuco_a5.yaml")
    ap.add_argument("--distance", type=float, default=0.35)
    ap.add_argument("--no-diameter", action="store_true")
    a = ap.parse_args()
    t = load_target(a.target)
    T = look_at_target(t, a.distance, (0.3, -0.2, 0.1))
    Z, secs = {}, []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cam = tmp / "camera.yaml"
        cam.write_text(yaml.safe_dump({"format": "vision_calib.camera/1", **CAM.to_dict()}))
        for seed in range(a.seeds):
            d = tmp / f"s{seed}"
            (d / "images").mkdir(parents=True)
            for i, im in enumerate(simulate_frames(t, CAM, T, SensorEffects(**TRUTH), a.frames, 1000 + seed)):
                cv2.imwrite(str(d / "images" / f"{i}.png"), im)
            t0 = time.perf_counter()
            if a.no_diameter:
                doc = {"data": [{"image": f"images/{i}.png"} for i in range(a.frames)], "distortion": list(CAM.dist),
                       "intrinsics": {k: getattr(CAM, k) for k in ("fx", "fy", "cx", "cy")},
                       "target_finder": {"type": "ModifiedCircleGridTargetFinder", "rows": t.rows, "cols": t.cols,
                                         "spacing": t.spacing_m}}
                (d / "cal_data.yaml").write_text(yaml.safe_dump(doc))
                r = measure_noise(d, d / "out", seed=seed)
            else:
                r = measure_noise(d / "images", d / "out", target=a.target, camera=cam, seed=seed)
            secs.append(time.perf_counter() - t0)
            pn, fb = r["pixel_noise"], r["image_fit"]
            st = r["simulator"]["settings"]["value_and_se"]
            rep = r["simulator"]["reproduced"]["measured_over_simulated"]
            z = {"blur": (fb["blur_sigma_px"] - 1.3) / fb["blur_se_px"],
                 "black level": (fb["black_level_grey"] - 30) / fb["black_se"],
                 "exposure": (fb["exposure"] - 0.6) / fb["exposure_se"],
                 "read (pixels)": (pn["read_noise_grey"] - 3) / pn["read_noise_se"],
                 "full well (pixels)": (pn["full_well_e"] - 5000) / pn["full_well_se"],
                 "read (matched)": (st["read_noise_grey"][0] - 3) / st["read_noise_grey"][1],
                 "full well (matched)": (st["full_well_e"][0] - 5000) / st["full_well_e"][1],
                 "reproduced corner noise": np.log(rep["ratio"]) / rep["rel_se"]}
            if "dot_diameter" in fb:
                dd = fb["dot_diameter"]
                z["dot diameter"] = (dd["diameter_m"] - t.diameter_m) / dd["diameter_se_m"]
            for k, v in z.items():
                Z.setdefault(k, []).append(v)
    print(f"{a.target} at {a.distance} m, {a.frames} frames, {a.seeds} seeds: z = (fit - truth) / se")
    for k, v in Z.items():
        print(f"  {k:26s} z RMS {np.sqrt(np.mean(np.square(v))):5.2f}  mean {np.mean(v):+5.2f}  max |z| {np.max(np.abs(v)):5.2f}")
    print(f"  seconds per run: median {np.median(secs):.2f}")


if __name__ == "__main__":
    main()
