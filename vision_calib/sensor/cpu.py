"""Sensor effects on the CPU with OpenCV/numpy (the default of :func:`vision_calib.sensor.apply_effects`).

Same model, order and parameters as the torch/kornia implementation (:mod:`vision_calib.sensor.effects`,
whose docstring describes the pipeline), built for one core:
- distortion: exact bilinear resampling (:func:`remap_exact`): one sparse product with a per-camera
  matrix of bilinear weights (:func:`maps.bilinear_matrix`, border replicated) built once per camera, not
  per pose. Not ``cv2.remap``: its 1/32 px fixed-point source positions shifted corners systematically
  (demo validation 3x worse);
- blur: ``cv2.GaussianBlur`` with the same kernel size (``maps.gaussian_ksize``) or ``cv2.filter2D`` with
  the same disc kernel, border replicated;
- noise: the noise-free image and the per-pixel noise std are computed once per pose; each frame is one
  ``cv2.randn`` draw scaled in place, then ``cv2.add(..., dtype=CV_8U)`` adds the mean, rounds to the
  nearest integer (ties to even, as torch.round) and saturates to [0, 255] in a single pass. The random
  draws are the cost floor of this stage (~3.2 ms of CPU of the ~4.6 ms per 1024 x 768 frame, see
  ``benchmarks/bench_end_to_end.py``); everything else is computed once per pose, in place.

Random draws: OpenCV's RNG (multiply-with-carry; normal deviates by the ziggurat method), seeded with
the caller's seed through ``cv2.setRNGSeed`` (a per-thread state): the same seed gives the same frames.
They are *not* the same draws as the torch path for that seed, only the same distribution (tests compare
noise variance against signal, blur MTF and distortion with the analytic model). ``photon_model="poisson"``
draws from a ``numpy.random.Generator`` seeded with the same seed.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..camera import CameraIntrinsics
from .maps import bilinear_matrix, disc_kernel, gaussian_ksize, vignetting_gain
from .settings import SensorEffects


def remap_exact(img: np.ndarray, intr: CameraIntrinsics) -> np.ndarray:
    """Distorted image (H, W) float32 from the ideal one img (H, W): bilinear sample of img at
    :func:`distortion_source_map` (float32 weights, no position rounding; matches torch grid_sample with
    align_corners=True and border padding), as one sparse product (:func:`maps.bilinear_matrix`)."""
    f = np.ascontiguousarray(img, dtype=np.float32).reshape(-1)
    return (bilinear_matrix(intr) @ f).reshape(intr.height, intr.width)


def deterministic_image_cv(ideal: np.ndarray, effects: SensorEffects, intr: CameraIntrinsics) -> np.ndarray:
    """Noise-free expected *electrons* (H, W) float32 of the ideal render ideal (H, W) [grey 0..255]:
    distortion, blur, vignetting and exposure applied (see the torch ``deterministic_image``)."""
    x = np.ascontiguousarray(ideal, dtype=np.float32)
    if effects.apply_distortion and any(intr.dist):
        x = remap_exact(x, intr)
    if effects.blur_sigma_px > 0:
        s = float(effects.blur_sigma_px)
        k = gaussian_ksize(s)
        x = cv2.GaussianBlur(x, (k, k), s, sigmaY=s, borderType=cv2.BORDER_REPLICATE)
    elif effects.blur_disc_radius_px > 0:
        x = cv2.filter2D(x, cv2.CV_32F, disc_kernel(float(effects.blur_disc_radius_px)),
                         borderType=cv2.BORDER_REPLICATE)
    if effects.vignetting > 0:
        x = cv2.multiply(x, vignetting_gain(intr, float(effects.vignetting)))
    fw = effects.full_well_e if effects.full_well_e > 0 else 255.0
    return np.multiply(x, np.float32(effects.exposure * fw / 255.0), dtype=np.float32)


def apply_effects_cv(ideal: np.ndarray, effects: SensorEffects, n_frames: int, seed: int,
                     intr: CameraIntrinsics) -> np.ndarray:
    """``n_frames`` independent frames (n_frames, H, W) uint8 of one pose from its ideal render (H, W)
    [grey 0..255]; shapes are checked by the caller (:func:`vision_calib.sensor.apply_effects`)."""
    e = deterministic_image_cv(ideal, effects, intr)  # electrons
    fw = effects.full_well_e if effects.full_well_e > 0 else 255.0
    grey_per_e = effects.gain * 255.0 / fw
    out = np.empty((n_frames,) + e.shape, np.uint8)
    if effects.full_well_e > 0 and effects.photon_model == "poisson":
        rng = np.random.default_rng(int(seed))
        lam = np.maximum(e, 0.0).astype(np.float64)
        for k in range(n_frames):
            grey = rng.poisson(lam).astype(np.float32) * np.float32(grey_per_e)
            if effects.read_noise_grey > 0:
                grey += np.float32(effects.read_noise_grey) * rng.standard_normal(e.shape, dtype=np.float32)
            out[k] = cv2.add(grey, float(effects.black_level_grey), dtype=cv2.CV_8U)
        return out
    noisy = effects.full_well_e > 0 or effects.read_noise_grey > 0
    mean = cv2.addWeighted(e, grey_per_e, e, 0.0, float(effects.black_level_grey))  # grey levels
    if not noisy:
        out[:] = cv2.add(mean, 0.0, dtype=cv2.CV_8U)
        return out
    std = e  # the electrons are no longer needed: std computed in place (grey levels)
    if effects.full_well_e > 0:
        np.maximum(std, 0.0, out=std)
        np.multiply(std, np.float32(grey_per_e ** 2), out=std)
    else:
        std.fill(0.0)
    if effects.read_noise_grey > 0:
        np.add(std, np.float32(float(effects.read_noise_grey) ** 2), out=std)
    np.sqrt(std, out=std)
    z = np.empty_like(std)
    cv2.setRNGSeed(int(seed) & 0x7FFFFFFF)
    for k in range(n_frames):  # one draw per frame, scaled in place; add + round + saturate in one pass
        cv2.randn(z, 0.0, 1.0)
        cv2.multiply(z, std, dst=z)
        cv2.add(z, mean, dst=out[k], dtype=cv2.CV_8U)
    return out
