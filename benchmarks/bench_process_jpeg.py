"""Time to process a recorded folder of JPEG images: 100 poses x 1 frame of the RX-90 eye-in-hand scene.

    .venv/bin/python benchmarks/bench_process_jpeg.py [--poses 100] [--quality 95]

Exports a simulated recording (``simulate --export-recording``), rewrites its PNG frames as JPEG
(quality ``--quality``), and runs ``process`` on both folders in this run (the PNG folder is the baseline).
Prints wall seconds total and per pose, split into read + detect + PnP (report timing "measure") and
identification ("identify"), the JPEG/PNG ratio, and the largest difference of the identified parameters.
"""

from __future__ import annotations

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import cv2

from vision_calib.experiment.process import process_folder
from vision_calib.experiment.simulate import run_simulation

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "rx90_eye_in_hand.yaml"


def _to_jpeg(src: Path, dst: Path, quality: int) -> None:
    shutil.copytree(src, dst)
    for f in sorted((dst / "images").rglob("*.png")):
        cv2.imwrite(str(f.with_suffix(".jpg")), cv2.imread(str(f), cv2.IMREAD_UNCHANGED),
                    [cv2.IMWRITE_JPEG_QUALITY, quality])
        f.unlink()


def _process(folder: Path, out: Path) -> tuple[dict, float]:
    t0 = time.perf_counter()
    rep = process_folder(folder, out, plots=False)
    return rep, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--poses", type=int, default=100)
    ap.add_argument("--quality", type=int, default=95)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        t0 = time.perf_counter()
        run_simulation(SCENE, out_dir=d / "sim", seed=7, n_poses=a.poses, frames=1, export_recording=d / "png",
                       workers=a.workers, progress=False, plots=False)
        print(f"simulate + export {a.poses} poses x 1 frame: {time.perf_counter() - t0:.1f} s (not timed below)")
        _to_jpeg(d / "png", d / "jpg", a.quality)
        mb = {k: sum(f.stat().st_size for f in (d / k / "images").rglob("*.*")) / 1e6 for k in ("png", "jpg")}
        rows = {}
        for k in ("png", "jpg"):
            rep, wall = _process(d / k, d / f"out_{k}")
            t = rep["timings_s"]
            rows[k] = (rep, wall, t)
            n = rep["measurements"]["n_poses"]
            print(f"{k.upper()} ({mb[k]:.1f} MB): total {wall:.2f} s = {wall / n * 1e3:.1f} ms/pose; "
                  f"read+detect+PnP {t['measure']:.2f} s ({t['measure'] / n * 1e3:.1f} ms/pose), "
                  f"identify {t['identify']:.2f} s; valid poses {rep['measurements']['n_valid']}/{n}")
        print(f"JPEG/PNG wall-time ratio: {rows['jpg'][1] / rows['png'][1]:.2f}")
        p = {k: {q['name']: (q['identified'], q['std']) for q in rows[k][0]['parameters'] if q['free']} for k in rows}
        dz = max(abs(p['jpg'][n][0] - p['png'][n][0]) / p['png'][n][1] for n in p['png'])
        print(f"identified parameters, JPEG q{a.quality} vs PNG: max |difference| = {dz:.3f} x their std")


if __name__ == "__main__":
    main()
