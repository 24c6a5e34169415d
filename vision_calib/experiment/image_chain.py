"""The simulated image chain of one run: render -> sensor effects -> (write PNGs) -> measure, per
pose, in worker processes.

This module is an *edge*: its worker initialiser is the one place (with ``cli.py``) that sets the
OpenGL platform and thread environment of a process. Workers hold one OpenGL context and one torch
thread each. Per-pose seeds derive from the run seed, so results do not depend on the worker count.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..camera import CameraIntrinsics

_W = {}  # per-process worker state


@dataclass(frozen=True)
class ImageChain:
    """What the chain needs, independent of scenes: the target file, the camera (intrinsics +
    distortion), the sensor effects (``sensor.SensorEffects``), the render supersampling factor and
    the frame averaging mode (``measure.MeasureConfig.mode``)."""

    target_path: str
    camera: CameraIntrinsics
    effects: object
    supersample: int = 2
    averaging: str = "corners"


def _worker_init(target_path, intrinsics, supersample):
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    os.environ.setdefault("EGL_PLATFORM", "surfaceless")
    # one Mesa llvmpipe thread per worker: several threaded workers oversubscribe the cores
    # (measured: 20 frames/s with Mesa's threads vs 47 frames/s with one, 2 workers, 2 cores)
    os.environ.setdefault("LP_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)
    from ..render import TargetRenderer
    from ..targets import load_target

    target = load_target(target_path)
    _W["target"] = target
    _W["intr"] = intrinsics
    _W["renderer"] = TargetRenderer(target, intrinsics.without_distortion(), supersample=supersample)


def _worker_pose(job):
    """Render, add effects, (optionally) write PNGs, measure one pose -> (index, PoseMeasurement, timings)."""
    from ..measure import MeasureConfig, measure_images
    from ..sensor import apply_effects

    i, pose_id, T_cam_target, effects, n_frames, seed, averaging, image_dir = job
    t0 = time.perf_counter()
    ideal = _W["renderer"].render(T_cam_target)
    t1 = time.perf_counter()
    frames = apply_effects(ideal, effects, n_frames, seed, _W["intr"])
    t2 = time.perf_counter()
    if image_dir is not None:
        import cv2

        d = Path(image_dir) / str(pose_id)
        d.mkdir(parents=True, exist_ok=True)
        for k, fr in enumerate(frames):
            ok, buf = cv2.imencode(".png", fr)
            (d / f"{k:02d}.png").write_bytes(buf.tobytes())
    t3 = time.perf_counter()
    pm, _ = measure_images(frames, _W["target"], _W["intr"], pose_id=pose_id, config=MeasureConfig(mode=averaging))
    t4 = time.perf_counter()
    import resource

    rss_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB
    return i, pm, {"render": t1 - t0, "effects": t2 - t1, "write": t3 - t2, "measure": t4 - t3, "rss_mib": rss_mib}


def measure_poses(chain: ImageChain, T_cam_targets, labels, seed: int, frames: int, workers: int | None = None,
                  image_dir=None, progress: bool = False):
    """Render + effects + measure every pose T_cam_targets (N, 4, 4) [m, OpenCV camera frame].
    Returns (list of PoseMeasurement in pose order, timings {stage: total seconds})."""
    from concurrent.futures import ProcessPoolExecutor
    import multiprocessing as mp

    cam = chain.camera
    jobs = [(i, labels[i], T_cam_targets[i], chain.effects, frames,
             int(np.random.default_rng([seed, 5, i]).integers(2**31 - 1)), chain.averaging, image_dir)
            for i in range(len(T_cam_targets))]
    workers = max(1, min(workers or os.cpu_count() or 1, len(jobs)))
    results = [None] * len(jobs)
    stage = {"render": 0.0, "effects": 0.0, "write": 0.0, "measure": 0.0}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), desc="render+measure", unit="pose", leave=False)
    init = (str(chain.target_path), cam, chain.supersample)
    # Rendering always runs in worker processes started by a fork server: the calling process may
    # hold an OpenGL context or library threads (a renderer of its own, torch), and a plain fork of
    # such a process can deadlock in the child. The server preloads our modules, so workers start fast.
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(["vision_calib.experiment.image_chain", "vision_calib.render", "vision_calib.sensor",
                                "vision_calib.measure"])
    ex = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_worker_init, initargs=init)
    it = ex.map(_worker_pose, jobs, chunksize=1)
    try:
        for i, pm, t in it:
            results[i] = pm
            stage["worker_peak_rss_mib"] = max(stage.get("worker_peak_rss_mib", 0.0), t.pop("rss_mib"))
            for k, v in t.items():
                stage[k] += v
            if bar is not None:
                bar.update(1)
    finally:
        ex.shutdown()
        if bar is not None:
            bar.close()
    return results, stage
