"""sensor stage: lens distortion, blur, exposure and noise on the frames of one pose.

Two implementations of one model: OpenCV/numpy on the CPU (:mod:`.cpu`, the default) and torch + kornia
(:mod:`.effects`, batched, GPU-capable: pass ``device``). Importing this package, the settings
(:class:`SensorEffects`) or the CPU path does NOT import torch; ``deterministic_image`` (torch) and
``apply_effects(..., device=...)`` import it on first use. torch and kornia are the optional extra
``pip install 'vision_calib[gpu]'``: without it those two raise :class:`~vision_calib.errors.MissingExtraError`
naming the extra.
"""

from __future__ import annotations

import numpy as np

from ..camera import CameraIntrinsics
from ..errors import ConfigError, DataError
from .maps import distortion_source_map
from .settings import SensorEffects

__all__ = ["SensorEffects", "apply_effects", "deterministic_image", "distortion_source_map", "effects_for_render", "ideal_render_grid",
           "supersampled_intrinsics"]


def supersampled_intrinsics(intr: CameraIntrinsics, s: int) -> CameraIntrinsics:
    """The camera on an s-times finer pixel grid (same distortion coefficients): fine pixel j has its centre
    at coarse coordinate (j + 0.5) / s - 0.5, so an s x s box average of the fine image is the coarse one."""
    return CameraIntrinsics(intr.width * s, intr.height * s, intr.fx * s, intr.fy * s, s * (intr.cx + 0.5) - 0.5,
                            s * (intr.cy + 0.5) - 0.5, intr.dist)


def ideal_render_grid(intr: CameraIntrinsics, supersample: int) -> tuple:
    """(intrinsics, supersample) for the renderer of the ideal image handed to :func:`apply_effects`.

    Camera with lens distortion and supersample s > 1: the undistorted camera on the s-times finer grid and
    supersample 1, so that the distortion resamples the fine render and the s x s box average follows it
    (:func:`apply_effects`), as a sensor integrates the distorted image over its pixels. Resampling a
    pixel-integrated render at the coarse grid instead (bilinear) shifted corners radially by +0.021 px near
    the image centre and +0.004 to +0.007 px further out, the same in every pose (H4 scene, noise-free,
    ``benchmarks/bench_zscores.py --corner-bias``): a mean depth error of 40-50 um over the poses at
    0.6-0.75 m, and the identified H4 h -3.5 std off in every seed. (Effects without distortion on a fine
    render: the box average alone, the same image as a coarse render.) Cost, s = 2, 1024 x 768: about 6 ms
    render + 40 ms distortion per pose, and 1.9 s and ~100 MB of cached distortion tables per process for
    the fine grid. Otherwise: the undistorted camera at supersample s."""
    s = int(supersample)
    if s > 1 and any(intr.dist):
        return supersampled_intrinsics(intr, s).without_distortion(), 1
    return intr.without_distortion(), s


def effects_for_render(renderer, effects: SensorEffects) -> SensorEffects:
    """``effects`` for the image the ``renderer`` (render.TargetRenderer) drew last: without the lens
    distortion when that image already holds it (``TargetRenderer(distort=True)``, polygon backend), else
    unchanged (the sensor stage then applies it)."""
    if getattr(renderer, "last_distorted", False) and effects.apply_distortion:
        from dataclasses import replace

        return replace(effects, apply_distortion=False)
    return effects


def _coarse_ideal(ideal: np.ndarray, effects: SensorEffects, intr: CameraIntrinsics, s: int) -> np.ndarray:
    """Fine ideal render (s H, s W) -> coarse (H, W) float32: distortion on the fine grid, then s x s box average."""
    import cv2

    x = np.ascontiguousarray(ideal, dtype=np.float32)
    if effects.apply_distortion and any(intr.dist):
        from .cpu import remap_exact

        x = remap_exact(x, supersampled_intrinsics(intr, s))
    return cv2.resize(x, intr.size, interpolation=cv2.INTER_AREA)  # exact box average for an integer factor


def apply_effects(ideal, effects: SensorEffects, n_frames: int, seed: int, intrinsics: CameraIntrinsics,
                  device=None) -> np.ndarray:
    """Simulate ``n_frames`` independent camera frames of one pose.

    ideal: (H, W) float array in [0, 255] (ideal pinhole render, H, W = intrinsics size), or a torch tensor;
    or a numpy render (s H, s W) on the s-times finer grid of :func:`supersampled_intrinsics` (integer s >= 2):
    the distortion is then applied on that grid before the s x s box average (:func:`ideal_render_grid`).
    seed: user seed of the noise (frames are independent draws; the same seed gives the same frames).
    device: None with a numpy ``ideal``: the OpenCV CPU implementation (:mod:`.cpu`); a torch device (or a
    tensor ``ideal``): the torch/kornia implementation on that device, noise from a CPU torch.Generator
    (same statistics, different draws than the CPU path for the same seed).
    Returns (n_frames, H, W) uint8 numpy array.
    """
    if device is None and isinstance(ideal, np.ndarray):
        return pose_frames(ideal, effects, n_frames, seed, intrinsics).stack()
    if n_frames < 1:
        raise ConfigError(f"apply_effects: n_frames must be >= 1, got {n_frames}")
    if isinstance(ideal, np.ndarray):
        ideal, effects = _coarse_checked(ideal, effects, intrinsics)
    from .effects import apply_effects_torch

    return apply_effects_torch(ideal, effects, n_frames, seed, intrinsics, device)


def pose_frames(ideal: np.ndarray, effects: SensorEffects, n_frames: int, seed: int, intrinsics: CameraIntrinsics):
    """The frames of :func:`apply_effects` (CPU path, numpy ``ideal`` of the same shapes), drawn one at a time
    when asked: a :class:`.cpu.PoseFrames` (sequence of (H, W) uint8 frames; ``focus(mask)`` restricts the
    noise of later frames to the pixels a consumer reads). Same frames as apply_effects for the same seed."""
    if n_frames < 1:
        raise ConfigError(f"apply_effects: n_frames must be >= 1, got {n_frames}")
    ideal, effects = _coarse_checked(ideal, effects, intrinsics)
    from .cpu import PoseFrames

    return PoseFrames(ideal, effects, int(n_frames), seed, intrinsics)


def _coarse_checked(ideal: np.ndarray, effects: SensorEffects, intrinsics: CameraIntrinsics):
    """(ideal (H, W), effects): a supersampled render box-averaged (distortion applied on the fine grid);
    DataError for any other shape than (H, W) or an integer multiple of it."""
    H, W = intrinsics.height, intrinsics.width
    if ideal.ndim == 2 and ideal.shape != (H, W) and ideal.shape[0] % H == 0 \
            and ideal.shape[0] // H >= 2 and ideal.shape == (ideal.shape[0] // H * H, ideal.shape[0] // H * W):
        from dataclasses import replace

        ideal = _coarse_ideal(ideal, effects, intrinsics, ideal.shape[0] // H)
        effects = replace(effects, apply_distortion=False)
    if ideal.shape != (H, W):
        raise DataError(f"apply_effects: ideal image shape {tuple(ideal.shape)} does not match the intrinsics "
                        f"(H, W) = ({H}, {W}) or an integer multiple of it")
    return ideal, effects


def __getattr__(name):  # torch-only helpers, imported on first use
    if name == "deterministic_image":
        from .effects import deterministic_image

        return deterministic_image
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
