"""Camera/sensor effects applied to an ideal pinhole render (torch + kornia).

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

import math
from dataclasses import asdict, dataclass
from functools import lru_cache

import cv2
import numpy as np
import torch

from ..camera import CameraIntrinsics
from ..errors import ConfigError, DataError


@dataclass(frozen=True)
class SensorEffects:
    """Sensor/lens effect parameters (recorded in reports via :meth:`to_dict`).

    apply_distortion: resample with the intrinsics' Brown–Conrady coefficients.
    blur_sigma_px: Gaussian defocus std [px] (0 = none). blur_disc_radius_px: disc defocus
    radius [px] (0 = none; exclusive with the Gaussian). exposure: scale of the ideal intensity
    (1 = nominal). gain: digital gain (grey levels per 255/full_well electrons).
    full_well_e: electrons at grey level 255 for exposure = gain = 1 (0 = no photon noise).
    read_noise_grey: read-noise std [grey levels]. black_level_grey: offset [grey levels].
    vignetting: relative intensity loss at the image corner (0 = none, quadratic in radius).
    photon_model: "gaussian" | "poisson". Output is always clipped and rounded to uint8.
    """

    apply_distortion: bool = True
    blur_sigma_px: float = 0.6
    blur_disc_radius_px: float = 0.0
    exposure: float = 1.0
    gain: float = 1.0
    full_well_e: float = 10000.0
    read_noise_grey: float = 1.0
    black_level_grey: float = 0.0
    vignetting: float = 0.0
    photon_model: str = "gaussian"

    def __post_init__(self):
        for name in ("blur_sigma_px", "blur_disc_radius_px", "exposure", "gain", "full_well_e",
                     "read_noise_grey", "black_level_grey", "vignetting"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise ConfigError(f"SensorEffects.{name} must be finite and >= 0, got {v!r}")
        if self.vignetting >= 1:
            raise ConfigError(f"SensorEffects.vignetting must be < 1, got {self.vignetting}")
        if self.blur_sigma_px > 0 and self.blur_disc_radius_px > 0:
            raise ConfigError("SensorEffects: give either blur_sigma_px or blur_disc_radius_px, not both")
        if self.photon_model not in ("gaussian", "poisson"):
            raise ConfigError(f"SensorEffects.photon_model must be 'gaussian' or 'poisson', got {self.photon_model!r}")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict, where: str = "sensor") -> "SensorEffects":
        known = set(cls.__dataclass_fields__)
        unknown = set(d) - known
        if unknown:
            raise ConfigError(f"{where}: unknown sensor effect key(s) {sorted(unknown)} (known: {sorted(known)})")
        try:
            return cls(**d)
        except TypeError as exc:
            raise ConfigError(f"{where}: invalid sensor effects ({exc})") from None

    @classmethod
    def ideal(cls) -> "SensorEffects":
        """No distortion, blur, noise or vignetting (only 8-bit quantisation)."""
        return cls(apply_distortion=False, blur_sigma_px=0.0, full_well_e=0.0, read_noise_grey=0.0)


# ----------------------------------------------------------------------------- distortion map
@lru_cache(maxsize=8)
def _source_map_cached(intr: CameraIntrinsics) -> np.ndarray:
    h, w = intr.height, intr.width
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    uv_d = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
    K = intr.K
    uv_u = cv2.undistortPointsIter(uv_d, K, intr.dist_array, None, K, crit).reshape(h, w, 2)
    uv_u.setflags(write=False)
    return uv_u


def distortion_source_map(intr: CameraIntrinsics) -> np.ndarray:
    """(H, W, 2) float64: for every distorted pixel centre (u_d, v_d) = (col, row), the ideal
    (undistorted) pixel location (u_u, v_u) that projects there, i.e.
    ``intr.project(undistorted ray) == (u_d, v_d)``. Cached per intrinsics (read-only array)."""
    return _source_map_cached(intr)


def _grid_for(intr: CameraIntrinsics, device) -> torch.Tensor:
    src = distortion_source_map(intr)
    h, w = intr.height, intr.width
    gx = src[..., 0] / (w - 1) * 2 - 1  # align_corners=True: -1 / +1 are the centres of the edge pixels
    gy = src[..., 1] / (h - 1) * 2 - 1
    return torch.from_numpy(np.stack([gx, gy], axis=-1)[None].astype(np.float32)).to(device)


# ----------------------------------------------------------------------------- helpers
def _disc_kernel(radius_px: float) -> torch.Tensor:
    """Normalised (1, k, k) disc kernel, edge pixels weighted by 4x4 supersampled coverage."""
    r = int(math.ceil(radius_px))
    k = 2 * r + 1
    sub = (np.arange(4) + 0.5) / 4 - 0.5
    ys, xs = np.mgrid[-r:r + 1, -r:r + 1]
    cov = np.zeros((k, k))
    for dy in sub:
        for dx in sub:
            cov += ((xs + dx) ** 2 + (ys + dy) ** 2) <= radius_px ** 2
    cov /= cov.sum()
    return torch.from_numpy(cov[None].astype(np.float32))


def _vignetting_map(intr: CameraIntrinsics, strength: float, device) -> torch.Tensor:
    h, w = intr.height, intr.width
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float32, device=device),
                          torch.arange(w, dtype=torch.float32, device=device), indexing="ij")
    r2 = (u - intr.cx) ** 2 + (v - intr.cy) ** 2
    corners = [(x - intr.cx) ** 2 + (y - intr.cy) ** 2 for x in (-0.5, w - 0.5) for y in (-0.5, h - 0.5)]
    return 1.0 - strength * r2 / max(corners)


def deterministic_image(ideal: torch.Tensor, effects: SensorEffects, intr: CameraIntrinsics) -> torch.Tensor:
    """Noise-free sensor image: distortion, blur, vignetting and exposure/gain applied.

    ideal: (H, W) or (B, H, W) float tensor [grey levels 0..255], pinhole render.
    Returns the expected *electrons* per pixel, same shape, float32, on ideal's device.
    """
    import kornia

    squeeze = ideal.ndim == 2
    x = ideal[None] if squeeze else ideal
    x = x[:, None].float()  # (B, 1, H, W)
    if effects.apply_distortion and any(intr.dist):
        grid = _grid_for(intr, x.device).expand(x.shape[0], -1, -1, -1)
        x = torch.nn.functional.grid_sample(x, grid, mode="bilinear", padding_mode="border", align_corners=True)
    if effects.blur_sigma_px > 0:
        s = float(effects.blur_sigma_px)
        k = 2 * int(math.ceil(3.5 * s)) + 1
        x = kornia.filters.gaussian_blur2d(x, (k, k), (s, s), border_type="replicate")
    elif effects.blur_disc_radius_px > 0:
        x = kornia.filters.filter2d(x, _disc_kernel(effects.blur_disc_radius_px).to(x.device), border_type="replicate")
    if effects.vignetting > 0:
        x = x * _vignetting_map(intr, effects.vignetting, x.device)
    fw = effects.full_well_e if effects.full_well_e > 0 else 255.0
    e = x[:, 0] * (effects.exposure * fw / 255.0)
    return e[0] if squeeze else e


def apply_effects(
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
