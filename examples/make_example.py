"""Regenerate the shipped example recording ``examples/rx90_eye_in_hand/`` with the project's own simulator.

    PYTHONPATH=. python examples/make_example.py [--out examples/rx90_eye_in_hand]

What it makes: the shipped scene ``scenes/rx90_eye_in_hand.yaml`` (Staubli RX-90, camera on the flange, A5
ChArUco board on the table, the scene's true robot: 0.5 mm / 0.05 deg deviations drawn with its truth seed)
seen by a 640 x 480 camera with the same field of view, 12 poses x 1 frame, rendered and exported by
``simulate --export-recording``, the frames re-encoded as JPEG (quality 75) to keep the folder small. Beside the
recording, ``truth.yaml`` holds the true parameters the images were rendered with (SI: m, rad), so the result
of ``vision-calib process examples/rx90_eye_in_hand --out out/example`` can be checked against them
(``tests/test_example.py``). Deterministic: same seed, same scene, same images (OpenCV's JPEG encoder is pinned
with opencv-contrib-python-headless).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NAME = "rx90_eye_in_hand"
SEED = 0
N_POSES = 12
FRAMES = 1
JPEG_QUALITY = 75
#: 640 x 480 with the shipped scene's field of view (1024 x 768 at fx = 1100 px, scaled by 0.625)
CAMERA = {"width": 640, "height": 480, "fx": 687.5, "fy": 687.5, "cx": 321.9, "cy": 237.4,
          "dist": [-0.05, 0.02, 0.0, 0.0, 0.0]}


def make_example(out: Path, workers: int = 1) -> dict:
    """Write the example recording into ``out`` (replaced); returns the simulation's report dict."""
    import cv2
    import yaml

    from vision_calib.experiment.simulate import run_simulation
    from vision_calib.rig import SCENES_DIR

    raw = yaml.safe_load((SCENES_DIR / f"{NAME}.yaml").read_text())
    raw.update(name=NAME, camera=CAMERA,  # the shipped robot and target, by absolute path (shipped files)
               robot=str((SCENES_DIR / raw["robot"]).resolve()), target=str((SCENES_DIR / raw["target"]).resolve()))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / f"{NAME}.yaml").write_text(yaml.safe_dump(raw, sort_keys=False))
        report = run_simulation(tmp / f"{NAME}.yaml", out_dir=None, seed=SEED, n_poses=N_POSES, frames=FRAMES,
                                export_recording=tmp / "rec", workers=workers, plots=False, reference=False)
        for png in sorted((tmp / "rec" / "images").rglob("*.png")):
            img = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
            ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY, cv2.IMWRITE_JPEG_OPTIMIZE, 1])
            if not ok:
                raise RuntimeError(f"JPEG encoding failed for {png}")
            png.with_suffix(".jpg").write_bytes(buf.tobytes())
            png.unlink()
        truth = {p["name"]: float(p["true"]) for p in report["parameters"] if p.get("true") is not None}
        (tmp / "rec" / "truth.yaml").write_text(
            "# The true parameters the images were rendered with (SI: m, rad), written by examples/make_example.py:\n"
            f"# scene scenes/{NAME}.yaml (its truth seed) with a {CAMERA['width']} x {CAMERA['height']} camera, "
            f"simulate seed {SEED}, {N_POSES} poses x {FRAMES} frame, JPEG quality {JPEG_QUALITY}.\n"
            + yaml.safe_dump({"seed": SEED, "parameters": truth}, sort_keys=False))
        if out.exists():
            shutil.rmtree(out)
        shutil.copytree(tmp / "rec", out)
    return report


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "examples" / NAME, help="folder to write (replaced)")
    ap.add_argument("--workers", type=int, default=1, help="image workers (the images do not depend on it)")
    args = ap.parse_args(argv)
    report = make_example(args.out, args.workers)
    size = sum(p.stat().st_size for p in args.out.rglob("*") if p.is_file())
    print(f"{args.out}: {N_POSES} poses x {FRAMES} frame, {size / 1024:.0f} KiB")
    print(report["summary_text"].splitlines()[0])
    return 0


if __name__ == "__main__":
    sys.exit(main())
