"""sensor stage: lens distortion, blur, exposure and noise on the frames of one pose.

Two implementations of one model: OpenCV/numpy on the CPU (:mod:`.cpu`, the default) and torch + kornia
(:mod:`.effects`, batched, GPU-capable: pass ``device``). Importing this package, the settings
(:class:`SensorEffects`) or the CPU path does NOT import torch; ``deterministic_image`` (torch) and
``apply_effects(..., device=...)`` import it on first use.
"""

from __future__ import annotations

import numpy as np

from ..camera import CameraIntrinsics
from ..errors import ConfigError, DataError
from .maps import distortion_source_map
from .settings import SensorEffects

__all__ = ["SensorEffects", "apply_effects", "deterministic_image", "distortion_source_map"]


def apply_effects(ideal, effects: SensorEffects, n_frames: int, seed: int, intrinsics: CameraIntrinsics,
                  device=None) -> np.ndarray:
    """Simulate ``n_frames`` independent camera frames of one pose.

    ideal: (H, W) float array in [0, 255] (ideal pinhole render, H, W = intrinsics size), or a torch tensor.
    seed: user seed of the noise (frames are independent draws; the same seed gives the same frames).
    device: None with a numpy ``ideal``: the OpenCV CPU implementation (:mod:`.cpu`); a torch device (or a
    tensor ``ideal``): the torch/kornia implementation on that device, noise from a CPU torch.Generator
    (same statistics, different draws than the CPU path for the same seed).
    Returns (n_frames, H, W) uint8 numpy array.
    """
    if n_frames < 1:
        raise ConfigError(f"apply_effects: n_frames must be >= 1, got {n_frames}")
    if device is None and isinstance(ideal, np.ndarray):
        if ideal.shape != (intrinsics.height, intrinsics.width):
            raise DataError(f"apply_effects: ideal image shape {tuple(ideal.shape)} does not match the intrinsics "
                            f"(H, W) = ({intrinsics.height}, {intrinsics.width})")
        from .cpu import apply_effects_cv

        return apply_effects_cv(ideal, effects, int(n_frames), seed, intrinsics)
    from .effects import apply_effects_torch

    return apply_effects_torch(ideal, effects, n_frames, seed, intrinsics, device)


def __getattr__(name):  # torch-only helpers, imported on first use
    if name == "deterministic_image":
        from .effects import deterministic_image

        return deterministic_image
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
