"""``process`` of a recorded folder against its detection floor (issue 35: measure once).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_process_once.py [--poses 16] [--frames 2] [--fx-error 0.05]
                                                                   [--image-size W H] [--folder DIR ...] [--repeat 3]
                                                                   [--folders-only] [--target T.yaml]

Folders: a simulated RX-90 eye-in-hand recording (``--poses`` x ``--frames``, rendered here, not timed) whose
recording.yaml gives fx, fy ``--fx-error`` off, so that ``process`` runs the cause test (both hypotheses on the
intrinsics, :mod:`vision_calib.experiment.cause`), the same folder with the true intrinsics, the same images with
flange poses instead of joints (the true flange poses with a 0.2 mm / 0.02 deg robot pose error, its std not
given: the hand-eye path that ``import-rosi`` / ``import-visp`` folders take, with the robot's pose error
estimated; true intrinsics and fx off), and any ``--folder`` given (a recorded folder, e.g. one ``import-rosi`` /
``import-visp`` wrote; ``--folders-only``: those alone, nothing simulated).

``--target T.yaml``: the simulated folders show this target instead of the scene's (e.g. targets/apriltag_grid.yaml;
the hand-eye folders only, as with ``--image-size``).

``--image-size W H``: the scene's camera rescaled to W x H px with the same field of view (focal lengths and
principal point times W / its width): e.g. 1600 1200, the AVT Mako of the ROS-I ``test_set_charuco`` set (16
images at fx 1352 px), whose decoding and detection cost more per image than the scene's 1024 x 768.

Per folder, measured in this run: the floor, every pose's images decoded, detected and solved by PnP once
(``measure.measure_images`` per pose, the recording's intrinsics), and ``process`` (``process_folder``, no plots),
each the best of ``--repeat`` runs (the two interleaved); the ratio process / floor, and the images read and
detections made during ``process`` (counted, each once is the target).
"""

from __future__ import annotations

import vision_calib.cli  # noqa: F401  (single-threaded BLAS, as the CLI runs)

import argparse
import importlib
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import yaml

from vision_calib.experiment.process import process_folder
from vision_calib.experiment.simulate import run_simulation
from vision_calib.io.recording import read_recording
from vision_calib.measure import measure_images

REPO = Path(__file__).resolve().parents[1]
SCENE = REPO / "scenes" / "rx90_eye_in_hand.yaml"
D = importlib.import_module("vision_calib.measure.detect")


def floor_s(folder: Path) -> float:
    """Seconds to decode, detect and solve PnP once per image of a recorded folder (its intrinsics)."""
    rec = read_recording(folder)
    t0 = time.perf_counter()
    for pid in rec.pose_ids:
        if rec.images.get(pid):
            measure_images([str(f) for f in rec.images[pid]], rec.target, rec.camera, pose_id=pid,
                           config=rec.measure_config())
    return time.perf_counter() - t0


def process_s(folder: Path, out: Path) -> tuple[float, dict, int, int]:
    """(seconds, report, images decoded, corner detections run) of one ``process_folder``."""
    loads, finds, load, find = [0], [0], D.load_gray, D._find_corners

    def counted_load(*a, **k):
        loads[0] += 1
        return load(*a, **k)

    def counted_find(*a, **k):
        finds[0] += 1
        return find(*a, **k)

    D.load_gray, D._find_corners = counted_load, counted_find
    try:
        t0 = time.perf_counter()
        rep = process_folder(folder, out, plots=False)
        return time.perf_counter() - t0, rep, loads[0], finds[0]
    finally:
        D.load_gray, D._find_corners = load, find


def scene_at(size, target=None):
    """The RX-90 scene, its camera rescaled to size (W, H) px with the same field of view (None: as it is), its
    target file replaced by ``target`` (a path; None: the scene's)."""
    from dataclasses import replace

    from vision_calib.rig.scene import load_scene

    scene = load_scene(SCENE)
    if target is not None:
        scene = replace(scene, target_path=Path(target).resolve())
    if size is None:
        return scene
    c = scene.setup.camera
    k = size[0] / c.width
    cam = replace(c, width=int(size[0]), height=int(size[1]), fx=c.fx * k, fy=c.fy * k, cx=c.cx * k, cy=c.cy * k)
    return replace(scene, setup=replace(scene.setup, camera=cam))


def with_fx_error(src: Path, dst: Path, error: float) -> Path:
    """A copy of the recorded folder src at dst whose recording.yaml gives fx and fy ``error`` (relative) off."""
    shutil.copytree(src, dst)
    doc = yaml.safe_load((dst / "recording.yaml").read_text())
    doc["camera"] = {**doc["camera"], "fx": doc["camera"]["fx"] * (1 + error), "fy": doc["camera"]["fy"] * (1 + error)}
    (dst / "recording.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return dst


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--poses", type=int, default=16)
    ap.add_argument("--frames", type=int, default=2)
    ap.add_argument("--fx-error", type=float, default=0.05)
    ap.add_argument("--image-size", nargs=2, type=int, default=None, metavar=("W", "H"))
    ap.add_argument("--folder", nargs="*", default=[])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--folders-only", action="store_true", help="the --folder ones only, nothing simulated")
    ap.add_argument("--target", default=None, help="a target file for the simulated folders (default: the scene's)")
    a = ap.parse_args()
    if a.folders_only and not a.folder:
        ap.error("--folders-only needs --folder DIR ...")
    print(f"load average {os.getloadavg()[0]:.2f} (2 cores shared: wall times move with it)")
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        if a.folders_only:
            return run_folders([(str(f), Path(f)) for f in a.folder], a.repeat, d / "out")
        run_simulation(scene_at(a.image_size, a.target), out_dir=d / "sim", seed=7, n_poses=a.poses, frames=a.frames,
                       export_recording=d / "rec", workers=1, progress=False, plots=False)
        sys.path.insert(0, str(REPO / "tests"))
        from flange_folder import flange_pose_folder  # the test suite's writer of flange-pose folders

        flange_pose_folder(d / "rec", d / "flange", robot_std_mm=0.2, robot_std_deg=0.02)
        bad, flange_bad = with_fx_error(d / "rec", d / "rec_fx", a.fx_error), with_fx_error(d / "flange",
                                                                                            d / "flange_fx", a.fx_error)
        size = f"{a.poses} poses x {a.frames} frame(s)"
        px = ("" if a.image_size is None else f", {a.image_size[0]} x {a.image_size[1]} px") + \
            ("" if a.target is None else f", target {a.target}")
        joints = [(f"simulated RX-90, {size}, fx {a.fx_error:+.0%}", bad),
                  (f"simulated RX-90, {size}, true intrinsics", d / "rec")]
        alone = a.image_size is not None or a.target is not None
        if alone:  # the joint folders name the scene, whose camera and target are not these
            print("--image-size, --target: the hand-eye folders only (a joint folder names its scene, whose camera and "
                  "target these replace)")
        folders = [*(joints if not alone else []),
                   (f"simulated RX-90 images{px}, flange poses (hand-eye), {size}, fx {a.fx_error:+.0%}", flange_bad),
                   (f"the same images{px}, flange poses (hand-eye), true intrinsics", d / "flange"),
                   *((str(f), Path(f)) for f in a.folder)]
        run_folders(folders, a.repeat, d / "out")


def run_folders(folders, repeat: int, out: Path) -> None:
    """Print each (name, folder)'s floor, process time (the best of ``repeat``, interleaved) and their ratio."""
    for name, folder in folders:
        n_img = sum(len(v) for v in read_recording(folder).images.values())
        fls, runs = [], []
        for _ in range(repeat):  # interleaved: a slow spell of the machine hits both
            fls.append(floor_s(folder))
            runs.append(process_s(folder, out))
        fl = min(fls)
        wall, rep, n_load, n_find = min(runs, key=lambda r: r[0])
        cause = (rep.get("cause") or {}).get("chosen")
        print(f"{name}: {n_img} images; floor (decode + detect + PnP once each) {fl:.3f} s; process "
              f"{wall:.3f} s = {wall / fl:.2f} x the floor; during process {n_load} decodes, {n_find} detections"
              f" ({n_load / n_img:.2f}, {n_find / n_img:.2f} per image); cause test: "
              f"{'not run' if cause is None else 'chosen ' + cause}")


if __name__ == "__main__":
    main()
