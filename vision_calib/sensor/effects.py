"""Camera/sensor effects applied to an ideal pinhole render: the torch + kornia implementation (batched,
GPU-capable; ``apply_effects(..., device=...)`` uses it). The CPU default is :mod:`vision_calib.sensor.cpu`
(OpenCV, same model and statistics, ~2x faster on one core); both share :mod:`vision_calib.sensor.maps`.

Pipeline for one robot pose (:func:`apply_effects`), deterministic part computed once, noise
per frame:

1. lens distortion (Brown–Conrady k1, k2, p1, p2, k3 of the intrinsics) by resampling the ideal
   image: each output (distorted) pixel centre (u_d, v_d) is mapped to its undistorted location
   (u_u, v_u) (inverse of the distortion model, iterative, :func:`distortion_source_map`) and the
   ideal image is bilinearly sampled there. Pixel centres are at integer coordinates (OpenCV
   convention, see camera.py), i.e. ``grid_sample(..., align_corners=True)``.
2. defocus blur: Gaussian (``blur_sigma_px``) or uniform disc (``blur_disc_radius_px``).
3. vignetting: gain ``1 - vignetting * (r / r_corner)^2`` (r from the principal point).
4. exposure: mean signal in electrons ``e = exposure * full_well_e * I / 255``.
5. noise, independent per frame: photon (shot) noise on ``e`` + read noise (grey levels).
   ``photon_model="poisson"`` draws ``torch.poisson``; ``"gaussian"`` (default, 4x faster) draws
   ``e + sqrt(e) N(0, 1)``, the normal limit of the Poisson law (the two differ only in the
   skewness, invisible after 8-bit quantisation for more than a few electrons).
6. gain to grey levels ``g = gain * 255 * e / full_well_e + black_level_grey``, clip, round to uint8.

All random draws come from a CPU ``torch.Generator`` seeded by the user's seed, so the same
seed gives the same frames on CPU and on CUDA (the deterministic part may differ by float
rounding, i.e. at most one grey level on a few pixels after quantisation).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..camera import CameraIntrinsics
from ..errors import ConfigError, DataError, MissingExtraError

#: what this module needs beyond the default install, and how to get it
GPU_EXTRA = "pip install 'vision_calib[gpu]'"


def _missing(module: str, exc: ImportError) -> MissingExtraError:
    return MissingExtraError(
        f"the torch/kornia sensor path (apply_effects(..., device=...), deterministic_image) needs {module}, which "
        f"is not installed ({exc}): install the optional extra with `{GPU_EXTRA}` (the default OpenCV path, "
        "device=None, needs neither)")


try:
    import torch
except ImportError as _exc:  # torch is the optional extra [gpu], not a core dependency
    raise _missing("torch", _exc) from _exc
from .maps import disc_kernel, distortion_source_map, gaussian_ksize, vignetting_gain
from .settings import SensorEffects


def _grid_for(intr: CameraIntrinsics, device) -> torch.Tensor:
    return _grid_cached(intr, str(torch.device(device)))


@lru_cache(maxsize=8)
def _grid_cached(intr: CameraIntrinsics, device: str) -> torch.Tensor:
    """grid_sample grid (1, H, W, 2) of :func:`distortion_source_map`, cached per camera and device."""
    src = distortion_source_map(intr)
    h, w = intr.height, intr.width
    gx = src[..., 0] / (w - 1) * 2 - 1  # align_corners=True: -1 / +1 are the centres of the edge pixels
    gy = src[..., 1] / (h - 1) * 2 - 1
    return torch.from_numpy(np.stack([gx, gy], axis=-1)[None].astype(np.float32)).to(device)


def _vignetting_map(intr: CameraIntrinsics, strength: float, device) -> torch.Tensor:
    return torch.from_numpy(np.array(vignetting_gain(intr, float(strength)))).to(device)


def deterministic_image(ideal: torch.Tensor, effects: SensorEffects, intr: CameraIntrinsics) -> torch.Tensor:
    """Noise-free sensor image: distortion, blur, vignetting and exposure/gain applied.

    ideal: (H, W) or (B, H, W) float tensor [grey levels 0..255], pinhole render.
    Returns the expected *electrons* per pixel, same shape, float32, on ideal's device.
    """
    try:
        import kornia
    except ImportError as exc:
        raise _missing("kornia", exc) from exc

    squeeze = ideal.ndim == 2
    x = ideal[None] if squeeze else ideal
    x = x[:, None].float()  # (B, 1, H, W)
    if effects.apply_distortion and any(intr.dist):
        grid = _grid_for(intr, x.device).expand(x.shape[0], -1, -1, -1)
        x = torch.nn.functional.grid_sample(x, grid, mode="bilinear", padding_mode="border", align_corners=True)
    if effects.blur_sigma_px > 0:
        s = float(effects.blur_sigma_px)
        k = gaussian_ksize(s)
        x = kornia.filters.gaussian_blur2d(x, (k, k), (s, s), border_type="replicate")
    elif effects.blur_disc_radius_px > 0:
        x = kornia.filters.filter2d(x, torch.from_numpy(np.array(disc_kernel(float(effects.blur_disc_radius_px)))[None]).to(x.device), border_type="replicate")
    if effects.vignetting > 0:
        x = x * _vignetting_map(intr, effects.vignetting, x.device)
    fw = effects.full_well_e if effects.full_well_e > 0 else 255.0
    e = x[:, 0] * (effects.exposure * fw / 255.0)
    return e[0] if squeeze else e


def apply_effects_torch(
    ideal,
    effects: SensorEffects,
    n_frames: int,
    seed: int,
    intrinsics: CameraIntrinsics,
    device: str | torch.device | None = None,
) -> np.ndarray:
    """Simulate ``n_frames`` independent camera frames of one pose.

    ideal: (H, W) float array/tensor in [0, 255] (ideal pinhole render, H, W = intrinsics size).
    seed: user seed of the CPU torch.Generator for the noise (frames are independent draws).
    device: torch device for the deterministic part (default: ideal's device, else CPU).
    Returns (n_frames, H, W) uint8 numpy array.
    """
    if n_frames < 1:
        raise ConfigError(f"apply_effects: n_frames must be >= 1, got {n_frames}")
    if isinstance(ideal, np.ndarray):
        ideal_t = torch.from_numpy(np.ascontiguousarray(ideal, dtype=np.float32))
    else:
        ideal_t = ideal
    if tuple(ideal_t.shape) != (intrinsics.height, intrinsics.width):
        raise DataError(
            f"apply_effects: ideal image shape {tuple(ideal_t.shape)} does not match the intrinsics "
            f"(H, W) = ({intrinsics.height}, {intrinsics.width})"
        )
    if device is not None:
        ideal_t = ideal_t.to(device)
    dev = ideal_t.device
    with torch.no_grad():
        e = deterministic_image(ideal_t, effects, intrinsics)  # (H, W) electrons
        fw = effects.full_well_e if effects.full_well_e > 0 else 255.0
        grey_per_e = effects.gain * 255.0 / fw
        gen = torch.Generator(device="cpu").manual_seed(int(seed))
        shape = (n_frames,) + tuple(e.shape)
        if effects.full_well_e > 0 and effects.photon_model == "poisson":
            lam = e.clamp_min(0).to("cpu").expand(shape).contiguous()
            sig_e = torch.poisson(lam, generator=gen).to(dev)
            grey = sig_e * grey_per_e
            if effects.read_noise_grey > 0:
                grey = grey + effects.read_noise_grey * torch.randn(shape, generator=gen).to(dev)
        else:
            mean = e * grey_per_e
            var = torch.zeros_like(mean)
            if effects.full_well_e > 0:
                var = var + e.clamp_min(0) * grey_per_e ** 2
            if effects.read_noise_grey > 0:
                var = var + effects.read_noise_grey ** 2
            if effects.full_well_e > 0 or effects.read_noise_grey > 0:
                grey = mean + var.sqrt() * torch.randn(shape, generator=gen).to(dev)
            else:
                grey = mean.expand(shape)
        grey = grey + effects.black_level_grey
        out = grey.round().clamp(0, 255).to(torch.uint8)
    return out.cpu().numpy()
