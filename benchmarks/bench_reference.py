"""Is the simulation's synthetic reference like for like? Demo scene (H4, 81 poses x 10 frames), seeds 0-9:
the image run's validation position RMS and V2 (V1/V2 from the validation poses measured from their own
images) against the synthetic reference (noise drawn from each image-measured pose's covariance, 5 draws:
median and range), and, as the baseline in the same run, the former reference (one draw, one pooled sigma
per block from the measured pose errors vs truth, for identification and validation measurements alike).

    .venv/bin/python benchmarks/bench_reference.py [--seeds 0 1 ... 9] [--workers 2]

Goal (issue 16): the reference's median within 2x of the image run's validation position RMS.
"""

from __future__ import annotations

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import argparse
import time

import numpy as np

from vision_calib.experiment.image_chain import ImagePool
from vision_calib.experiment.simulate import DEFAULT_SCENE, image_chain_of, run_simulation
from vision_calib.experiment.steps import rngs, run_analysis_and_truth, unmodelled_truth
from vision_calib.experiment.synthetic import run_synthetic
from vision_calib.rig import load_scene, scene_poses


def pooled_reference(scene, seed: int, acc: dict):
    """The former reference of a run: one draw with one sigma per block (the RMS over the components of the
    measured pose errors vs truth, ``accuracy_vs_truth``), identification and validation measurements alike."""
    st = float(np.sqrt(np.mean(np.square(acc["translation_rms_mm"])))) * 1e-3
    sr = float(np.radians(np.sqrt(np.mean(np.square(acc["rotation_rms_deg"])))))
    rp, _, rv = rngs(seed)
    poses = scene_poses(scene, rp)
    validation = scene_poses(scene, rv, which="validation")
    rep, x_true = run_analysis_and_truth(scene, poses, scene.identification.residual)
    truth, x_truth = unmodelled_truth(scene)
    out = run_synthetic(scene, sigma_t_m=st, sigma_r_rad=sr, seed=seed, poses=poses, validation=validation,
                        x_true=x_truth if truth is not None else x_true, truth=truth, prepare=True)
    return out.after.to_dict(), st, sr


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    scene = load_scene(DEFAULT_SCENE)
    print(f"scene {scene.name}; position RMS [mm] and V2 [rad] after calibration on the validation poses")
    print(f"{'seed':>4} | {'image':>6} {'ref med':>7} {'ref range':>13} {'ratio':>5} | {'pooled':>6} {'ratio':>5} | "
          f"{'V2 image':>9} {'V2 ref med':>10} {'ratio':>5} | {'V2 pooled':>9} | {'t s':>4}")
    rows = []
    with ImagePool(image_chain_of(scene), a.workers) as pool:
        for seed in a.seeds:
            t0 = time.perf_counter()
            rep = run_simulation(scene, seed=seed, plots=False, pool=pool)
            t = time.perf_counter() - t0
            img, ref = rep["accuracy"]["after"], rep["synthetic_reference"]
            med, rg = ref["accuracy_after"], ref["range"]
            old, _, _ = pooled_reference(scene, seed, rep["measurements"]["accuracy_vs_truth"])
            r_pos, r_v2 = med["position_rms_mm"] / img["position_rms_mm"], img["V2_rad"] / med["V2_rad"]
            rows.append((img["position_rms_mm"], med["position_rms_mm"], old["position_rms_mm"], r_v2))
            print(f"{seed:>4} | {img['position_rms_mm']:6.3f} {med['position_rms_mm']:7.3f} "
                  f"{rg['position_rms_mm'][0]:6.3f}-{rg['position_rms_mm'][1]:6.3f} {r_pos:5.2f} | "
                  f"{old['position_rms_mm']:6.3f} {old['position_rms_mm'] / img['position_rms_mm']:5.2f} | "
                  f"{img['V2_rad']:9.3g} {med['V2_rad']:10.3g} {r_v2:5.2f} | {old['V2_rad']:9.3g} | {t:4.1f}")
    r = np.array(rows)
    ratio = r[:, 1] / r[:, 0]
    within = np.sum((ratio >= 0.5) & (ratio <= 2.0))
    print(f"reference median / image position RMS: median {np.median(ratio):.2f}, range {ratio.min():.2f}-"
          f"{ratio.max():.2f}; within 2x in {within} of {len(r)} seeds (pooled reference: median "
          f"{np.median(r[:, 2] / r[:, 0]):.2f}, range {np.min(r[:, 2] / r[:, 0]):.2f}-{np.max(r[:, 2] / r[:, 0]):.2f})")
    print(f"image V2 / reference median V2: median {np.median(r[:, 3]):.2f}, range {r[:, 3].min():.2f}-"
          f"{r[:, 3].max():.2f}")


if __name__ == "__main__":
    main()
