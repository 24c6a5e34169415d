"""The simulated image chain of one run: render -> sensor effects -> (write PNGs) -> measure, per
pose, in worker processes.

This module is an *edge*: its worker initialiser is the one place (with ``cli/__init__.py``) that sets the
OpenGL platform and thread environment of a process. Workers hold one OpenGL context and one OpenCV
(and, if the torch effects are used, torch) thread each. Per-pose seeds derive from the run seed, so
results do not depend on the worker count. Neither the main process nor the workers import torch for the
CPU effects. :class:`ImagePool` starts the workers once (``with ImagePool(chain) as pool:
measure_poses(chain, ..., pool=pool)`` for many runs); workers die with their parent (Linux
``PR_SET_PDEATHSIG``), also after ``kill -9`` of the main process. It is what the single-run commands
(``simulate``, ``demo``) use. :class:`InlineImagePool` runs the same chain in the calling thread, no child process:
what a study run uses inside its study worker (whose parallelism is the study's; a daemonic Dask worker may not
have children). Both give the same numbers.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable, Iterator, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..camera import CameraIntrinsics

if TYPE_CHECKING:  # the sensor package is imported by the workers (PRELOAD), not by this module on load
    from ..measure import PoseMeasurement
    from ..sensor import SensorEffects

_W = {}  # per-process worker state
#: modules the fork server imports once; every worker is forked from it with them loaded
PRELOAD = ["vision_calib.experiment.image_chain", "vision_calib.render", "vision_calib.sensor", "vision_calib.measure"]


def start_fork_server() -> None:
    """Start the fork server of the image workers now, without waiting for it: its imports (OpenCV,
    scipy, our modules; ~0.9 s of CPU) then run on another core while the caller goes on importing and
    preparing, and the first :class:`ImagePool` forks ready workers from it. Idempotent; cheap to call
    again (the CLI calls it before importing the experiment modules, ``run_simulation`` on entry)."""
    import multiprocessing as mp
    from multiprocessing import forkserver

    if getattr(mp.current_process(), "_inheriting", False):  # a child re-importing the main module: no server
        return
    mp.get_context("forkserver").set_forkserver_preload(PRELOAD)
    forkserver.ensure_running()


@dataclass(frozen=True)
class ImageChain:
    """What the chain needs, independent of scenes: the target file, the camera (intrinsics +
    distortion), the sensor effects (``sensor.SensorEffects``), the render supersampling factor and
    the frame averaging mode (``measure.MeasureConfig.mode``)."""

    target_path: str
    camera: CameraIntrinsics
    effects: SensorEffects
    supersample: int = 2
    averaging: str = "corners"


def die_with_parent(main_pid: int) -> None:
    """Make this worker die with the main process ``main_pid``, also after ``kill -9`` of it.

    A worker's parent is the fork server, not the main process, and the fork server outlives the main
    process as long as any worker lives (each worker inherits the server's "alive" pipe end), so a plain
    ``PR_SET_PDEATHSIG`` never fires. Hence: a daemon thread polls the main process every 0.25 s and
    exits the worker when it is gone; ``PR_SET_PDEATHSIG`` (Linux) also kills it if the fork server dies."""
    import ctypes
    import signal
    import sys
    import threading

    if sys.platform.startswith("linux"):
        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)

    def main_alive() -> bool:
        try:
            os.kill(main_pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        try:  # a killed, not yet reaped main process is a zombie
            with open(f"/proc/{main_pid}/stat") as f:
                return f.read().rsplit(")", 1)[1].split()[0] != "Z"
        except OSError:
            return True

    def watch():
        while main_alive():
            time.sleep(0.25)
        os._exit(1)

    if not main_alive():
        os._exit(1)
    threading.Thread(target=watch, name="die-with-main", daemon=True).start()


def chain_state(target_path: str | Path, intrinsics: CameraIntrinsics, supersample: int) -> dict:
    """What the image chain of one camera/target/supersampling needs and only the setup determines, built once:
    {"target": TargetSpec, "intr": CameraIntrinsics, "renderer": render.TargetRenderer} (the renderer holds the
    target's geometry and the polygon backend's distortion tables)."""
    from ..render import TargetRenderer
    from ..targets import load_target

    target = load_target(target_path)
    # the lens distortion drawn geometrically by the polygon backend (exact pixel areas of the distorted
    # image, as a sensor integrates it): no resampling; a pose that falls back to pyrender gets the
    # distortion from the sensor stage (sensor.apply_effects)
    return {"target": target, "intr": intrinsics, "renderer": TargetRenderer(target, intrinsics, supersample,
                                                                             distort=True)}


def single_thread_libraries() -> None:
    """One OpenCV / Mesa llvmpipe (/ torch, if already imported) thread in this process: what each image worker
    and each study worker runs with (several threaded workers oversubscribe the cores; measured: 20 frames/s
    with Mesa's threads vs 47 frames/s with one, 2 workers, 2 cores)."""
    import sys

    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    os.environ.setdefault("EGL_PLATFORM", "surfaceless")
    os.environ.setdefault("LP_NUM_THREADS", "1")
    import cv2

    cv2.setNumThreads(1)
    if "torch" in sys.modules:  # only if something imported it already (torch effects import it lazily)
        sys.modules["torch"].set_num_threads(1)


#: glibc ``mallopt`` parameters and the values :func:`heap_for_images` sets: buffers up to 32 MiB (a 2x-supersampled
#: 1024x768 float32 render is 12 MiB) from the heap, and up to 128 MiB of free heap top kept
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
HEAP_MMAP_THRESHOLD_BYTES, HEAP_TRIM_THRESHOLD_BYTES = 32 << 20, 128 << 20


def heap_for_images() -> bool:
    """Keep image-sized buffers on the heap of this process (glibc; a no-op returning False elsewhere): without it,
    each such numpy array is mapped, zeroed by the kernel page by page and unmapped at every allocation. glibc
    adapts its thresholds by itself unless one is fixed in the environment, as a Dask nanny does for its workers
    (``MALLOC_TRIM_THRESHOLD_=65536``): measured, a demo-size images run cost 6.2-6.9 s of CPU in such a worker vs
    3.2-3.5 s with this (same machine and load). Returns whether both settings were applied."""
    import ctypes

    try:
        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(M_MMAP_THRESHOLD, HEAP_MMAP_THRESHOLD_BYTES)) & bool(mallopt(M_TRIM_THRESHOLD,
                                                                                  HEAP_TRIM_THRESHOLD_BYTES))


def study_worker_settings() -> None:
    """What a study worker (a local study process, a Dask worker) runs with: :func:`single_thread_libraries` and
    :func:`heap_for_images`. Idempotent."""
    single_thread_libraries()
    heap_for_images()


def _worker_init(target_path, intrinsics, supersample, main_pid=None):
    if main_pid is not None:
        die_with_parent(main_pid)
    single_thread_libraries()
    _W.update(chain_state(target_path, intrinsics, supersample))


def _worker_pose(job):
    """:func:`pose_job` with this worker process's state (set by its initialiser)."""
    return pose_job(_W, job)


def pose_job(state: dict, job: tuple) -> tuple[int, PoseMeasurement, dict]:
    """Render, add effects, (optionally) write PNGs, measure one pose with a :func:`chain_state` ->
    (index, PoseMeasurement, timings): only the small measurement goes back to the caller, never the frames;
    timings are CPU seconds of this thread."""
    from ..measure import MeasureConfig, measure_images
    from ..sensor import effects_for_render, pose_frames

    i, pose_id, T_cam_target, effects, n_frames, seed, averaging, image_dir = job
    clock = time.thread_time  # this thread's CPU time: not inflated by machine load (nor by other threads)
    t0 = clock()
    ideal = state["renderer"].render(T_cam_target)
    t1 = clock()
    # OpenCV on the CPU, no torch. Frames drawn on demand: the seeded measurement asks for noise only on the
    # pixels it reads in the frames after the first (sensor.cpu.PoseFrames); written frames are drawn in full
    frames = pose_frames(ideal, effects_for_render(state["renderer"], effects), n_frames, seed, state["intr"])
    t2 = clock()
    if image_dir is not None:
        import cv2

        frames = frames.stack()
        t2 = clock()
        d = Path(image_dir) / str(pose_id)
        d.mkdir(parents=True, exist_ok=True)
        for k, fr in enumerate(frames):
            ok, buf = cv2.imencode(".png", fr)
            f = d / f"{k:02d}.png"
            try:
                f.write_bytes(buf.tobytes())
            except OSError as exc:  # ENOSPC from write() names no file: name the frame that could not be written
                raise OSError(exc.errno, exc.strerror or str(exc), str(f)) from exc
    t3 = clock()
    pm, _ = measure_images(frames, state["target"], state["intr"], pose_id=pose_id, config=MeasureConfig(mode=averaging))
    t4 = clock()
    import resource

    rss_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB
    drawn = 0.0 if image_dir is not None else frames.draw_cpu_s  # frames drawn while measuring: effects
    return i, pm, {"render": t1 - t0, "effects": t2 - t1 + drawn, "write": t3 - t2, "measure": t4 - t3 - drawn,
                   "rss_mib": rss_mib}


def worker_pid(_: object = None) -> int:
    """This process's id: ``pool.map(worker_pid, ...)`` names the worker processes of an ImagePool (tests: workers
    die with the main process)."""
    return os.getpid()


class ImagePool:
    """Worker processes for the image chain of one camera/target/supersampling, started once and reused by
    every :func:`measure_poses` call given ``pool=`` (a study running many simulations). Context manager.

    chain: ImageChain (its target_path, camera and supersample fix the workers); workers: process count
    (default: CPU count)."""

    def __init__(self, chain: ImageChain, workers: int | None = None) -> None:
        from concurrent.futures import ProcessPoolExecutor
        import multiprocessing as mp

        self.key = (str(chain.target_path), chain.camera, int(chain.supersample))
        self.workers = max(1, int(workers or os.cpu_count() or 1))
        # Rendering always runs in worker processes started by a fork server: the calling process may
        # hold an OpenGL context or library threads (a renderer of its own, torch), and a plain fork of
        # such a process can deadlock in the child. The server preloads our modules (no torch, no OpenGL).
        ctx = mp.get_context("forkserver")
        start_fork_server()  # no-op when already started
        self._ex = ProcessPoolExecutor(self.workers, mp_context=ctx, initializer=_worker_init,
                                       initargs=self.key + (os.getpid(),))

    #: the chain runs in child processes (see :class:`InlineImagePool`)
    inline = False

    def map(self, fn: Callable, jobs: Iterable) -> Iterator:
        return self._ex.map(fn, jobs, chunksize=1)

    def run(self, jobs: Iterable[tuple]) -> Iterator[tuple[int, PoseMeasurement, dict]]:
        """(index, PoseMeasurement, timings) of each pose job, in order (:func:`pose_job` in the workers)."""
        if self._ex is None:
            raise RuntimeError("ImagePool: closed")
        return self._ex.map(_worker_pose, jobs, chunksize=1)

    def close(self, cancel: bool = False) -> None:
        """Stop the workers (idempotent): after the poses already handed to them; ``cancel``: the queued ones
        are dropped (an error or Ctrl-C in the caller)."""
        ex, self._ex = getattr(self, "_ex", None), None
        if ex is not None:
            ex.shutdown(wait=True, cancel_futures=cancel)

    def __enter__(self) -> "ImagePool":
        return self

    def __exit__(self, exc_type: type | None, *exc) -> None:
        self.close(cancel=exc_type is not None)


class InlineImagePool:
    """The image chain run in the calling thread, no child process: what a study run uses inside its worker
    (a local study process, a Dask worker -- daemonic or not, threads or processes --, or the main process with
    ``--workers 1``): its parallelism is the study's, one run per worker, and a daemonic process may not have
    children. Same interface and same numbers as :class:`ImagePool` (a pose's frames depend on its seed only);
    its :func:`chain_state` (target, renderer) is built once and reused by every run given this pool. Not
    thread-safe: one per thread (``study.cells`` keeps one per thread and chain). Nothing to release but the
    renderer's OpenGL context, if a pose fell back to pyrender (:meth:`close`)."""

    inline = True
    workers = 1

    def __init__(self, chain: ImageChain) -> None:
        self.key = (str(chain.target_path), chain.camera, int(chain.supersample))
        self._state = chain_state(*self.key)

    def run(self, jobs: Iterable[tuple]) -> Iterator[tuple[int, PoseMeasurement, dict]]:
        """(index, PoseMeasurement, timings) of each pose job, in order, computed here one after the other."""
        if self._state is None:
            raise RuntimeError("InlineImagePool: closed")
        state = self._state
        return (pose_job(state, j) for j in jobs)

    def close(self) -> None:
        state, self._state = self._state, None
        if state is not None and hasattr(state["renderer"], "close"):
            state["renderer"].close()

    def __enter__(self) -> "InlineImagePool":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def overlay_frames(chain: ImageChain, T_cam_targets: ArrayLike, labels: Sequence[str], seed: int, frames: int,
                   wanted: Iterable[str], stream: int | None = None) -> dict:
    """The first frame of the poses ``wanted`` (labels) rendered again exactly as :func:`measure_poses` drew them
    (same per-pose seed), in this thread, with its detection: {label: (frame (H, W) uint8, Detection, "")}
    (report.html's overlays: a few poses, rather than keeping every frame of the run). T_cam_targets (N, 4, 4) m
    and labels (N,) as given to measure_poses."""
    from ..measure import detect
    from ..sensor import effects_for_render, pose_frames

    stream = STREAM_IMAGES if stream is None else stream
    index = {str(lab): i for i, lab in enumerate(labels)}
    todo = [(str(w), index[str(w)]) for w in wanted if str(w) in index]
    if not todo:
        return {}
    state = chain_state(chain.target_path, chain.camera, chain.supersample)
    out = {}
    try:
        for lab, i in todo:
            ideal = state["renderer"].render(np.asarray(T_cam_targets[i], float))
            s = int(np.random.default_rng([seed, int(stream), i]).integers(2**31 - 1))
            img = pose_frames(ideal, effects_for_render(state["renderer"], chain.effects), frames, s,
                              state["intr"]).frame(0, full=True)
            out[lab] = (img, detect(img, state["target"], state["intr"], frame_index=0), "")
    finally:
        if hasattr(state["renderer"], "close"):
            state["renderer"].close()
    return out


#: random stream of the image noise of identification poses: pose i of run seed s draws from
#: ``default_rng([s, STREAM_IMAGES, i])`` (experiment.steps numbers the other streams 1-4)
STREAM_IMAGES = 5


def measure_poses(chain: ImageChain, T_cam_targets: ArrayLike, labels: Sequence[str], seed: int, frames: int,
                  workers: int | None = None, image_dir: str | Path | None = None, progress: bool = False,
                  pool: ImagePool | InlineImagePool | None = None, stream: int = STREAM_IMAGES,
                  desc: str = "render+measure") -> tuple[list[PoseMeasurement], dict]:
    """Render + effects + measure every pose T_cam_targets (N, 4, 4) [m, OpenCV camera frame].
    pool: an open :class:`ImagePool` or :class:`InlineImagePool` for this chain's camera/target/supersampling
    (reused, not closed);
    default: a pool of ``workers`` processes for this call only. stream: pose i's frames are seeded from
    ``default_rng([seed, stream, i])`` (another stream for another pose set of the same run, e.g. the
    validation poses, so that their noise is independent of the identification poses'); desc: progress label.
    Returns (list of PoseMeasurement in pose order, timings {stage: total CPU seconds over the workers,
    "worker_peak_rss_mib"})."""
    from ..errors import ConfigError

    cam = chain.camera
    jobs = [(i, labels[i], T_cam_targets[i], chain.effects, frames,
             int(np.random.default_rng([seed, int(stream), i]).integers(2**31 - 1)), chain.averaging, image_dir)
            for i in range(len(T_cam_targets))]
    results = [None] * len(jobs)
    stage = {"render": 0.0, "effects": 0.0, "write": 0.0, "measure": 0.0}
    if pool is not None and pool.key != (str(chain.target_path), cam, int(chain.supersample)):
        raise ConfigError("measure_poses: the image pool was started for another target/camera/supersample")
    own = pool is None
    if own:
        pool = ImagePool(chain, max(1, min(workers or os.cpu_count() or 1, len(jobs))))
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), desc=desc, unit="pose", leave=False)
    try:
        for i, pm, t in pool.run(jobs):
            results[i] = pm
            stage["worker_peak_rss_mib"] = max(stage.get("worker_peak_rss_mib", 0.0), t.pop("rss_mib"))
            for k, v in t.items():
                stage[k] += v
            if bar is not None:
                bar.update(1)
    except BaseException:
        if own:
            pool.close(cancel=True)
        raise
    finally:
        if own:
            pool.close()
        if bar is not None:
            bar.close()
    return results, stage
