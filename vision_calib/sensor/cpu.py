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

Random draws: OpenCV's RNG (multiply-with-carry; normal deviates by the ziggurat method), seeded per frame
from the caller's seed through ``cv2.setRNGSeed`` (a per-thread state): the same seed gives the same frames.
They are *not* the same draws as the torch path for that seed, only the same distribution (tests compare
noise variance against signal, blur MTF and distortion with the analytic model). ``photon_model="poisson"``
draws from a ``numpy.random.Generator`` seeded with the same seed.
"""

from __future__ import annotations

import time

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


def _frame_seed(seed: int, k: int) -> int:
    """OpenCV RNG seed of frame k of a pose drawn with the user seed ``seed``: each frame is seeded on its
    own, so a frame is the same whatever runs between the draws (the measurement, lazily) or in which order."""
    return (int(seed) * 1_000_003 + 7919 * int(k) + 1) & 0x7FFFFFFF


class PoseFrames:
    """The ``n_frames`` independent frames of one pose, drawn one at a time when asked (iteration or
    :meth:`frame`); the noise-free mean and the per-pixel noise std are computed once per pose.

    :meth:`focus` (bool mask (H, W)) restricts the noise of the frames drawn afterwards to the masked
    pixels; the other pixels then hold the rounded noise-free mean. A consumer that reads only masked
    pixels sees exactly the statistics of full frames (the seeded refinement of ``measure/seeded.py``
    names the pixels its per-frame estimator reads and asks for them: a few percent of the frame, so a
    pose costs one full draw instead of ``n_frames``). :meth:`frame` (k, full=True) draws a full frame again
    (a frame that falls back to a full detection). Frames drawn for writing to disk are always full.
    Sequence of (H, W) uint8 arrays; ``len()`` is n_frames; :meth:`stack` -> (n_frames, H, W) uint8."""

    #: every frame shows the same view (one pose, one render): a consumer may skip view-consistency checks
    same_view = True

    def __init__(self, ideal: np.ndarray, effects: SensorEffects, n_frames: int, seed: int, intr: CameraIntrinsics):
        e = deterministic_image_cv(ideal, effects, intr)  # electrons
        fw = effects.full_well_e if effects.full_well_e > 0 else 255.0
        self.n_frames, self.seed, self.effects = int(n_frames), int(seed), effects
        self.grey_per_e = effects.gain * 255.0 / fw
        self.shape = e.shape
        self.draw_cpu_s = 0.0
        self._focus = None  # flat indices of the pixels that get noise, or None: every pixel
        self._mean8 = None
        if effects.full_well_e > 0 and effects.photon_model == "poisson":
            self.kind = "poisson"
            self.lam = np.maximum(e, 0.0).astype(np.float64)
            return
        self.kind = "normal" if effects.full_well_e > 0 or effects.read_noise_grey > 0 else "none"
        self.mean = cv2.addWeighted(e, self.grey_per_e, e, 0.0, float(effects.black_level_grey))  # grey levels
        if self.kind == "none":
            return
        std = e  # the electrons are no longer needed: std computed in place (grey levels)
        if effects.full_well_e > 0:
            np.maximum(std, 0.0, out=std)
            np.multiply(std, np.float32(self.grey_per_e ** 2), out=std)
        else:
            std.fill(0.0)
        if effects.read_noise_grey > 0:
            np.add(std, np.float32(float(effects.read_noise_grey) ** 2), out=std)
        np.sqrt(std, out=std)
        self.std = std

    def __len__(self) -> int:
        return self.n_frames

    def __iter__(self):
        for k in range(self.n_frames):
            yield self.frame(k)

    def focus(self, mask: np.ndarray | None) -> None:
        """Draw the noise of later frames only on ``mask`` (H, W) bool (None: everywhere again)."""
        if mask is None:
            self._focus = None
            return
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != self.shape:
            raise ValueError(f"PoseFrames.focus: mask shape {mask.shape} != frame shape {self.shape}")
        self._focus = np.flatnonzero(mask)

    def _mean_frame(self) -> np.ndarray:
        if self._mean8 is None:
            mean = self.mean if self.kind != "poisson" else np.float32(self.grey_per_e) * self.lam.astype(np.float32)
            self._mean8 = cv2.add(mean, 0.0 if self.kind != "poisson" else float(self.effects.black_level_grey),
                                  dtype=cv2.CV_8U)
        return self._mean8

    def frame(self, k: int, full: bool = False) -> np.ndarray:
        """Frame k (H, W) uint8: noise everywhere when ``full`` or no focus is set, else on the focus only.
        ``draw_cpu_s`` accumulates the CPU seconds spent drawing frames."""
        t = time.process_time()
        try:
            return self._draw(int(k), full)
        finally:
            self.draw_cpu_s += time.process_time() - t

    def _draw(self, k: int, full: bool) -> np.ndarray:
        if not 0 <= k < self.n_frames:
            raise IndexError(f"frame {k} of {self.n_frames}")
        if self.kind == "none":
            return self._mean_frame().copy()
        idx = None if full else self._focus
        if self.kind == "poisson":
            rng = np.random.default_rng([self.seed, k])
            lam = self.lam if idx is None else self.lam.reshape(-1)[idx]
            grey = rng.poisson(lam).astype(np.float32) * np.float32(self.grey_per_e)
            if self.effects.read_noise_grey > 0:
                grey += np.float32(self.effects.read_noise_grey) * rng.standard_normal(grey.shape, dtype=np.float32)
            vals = cv2.add(grey, float(self.effects.black_level_grey), dtype=cv2.CV_8U)
        else:
            cv2.setRNGSeed(_frame_seed(self.seed, k))
            if idx is None:  # one draw, scaled in place; add + round + saturate in one pass
                z = np.empty(self.shape, np.float32)
                cv2.randn(z, 0.0, 1.0)
                cv2.multiply(z, self.std, dst=z)
                return cv2.add(z, self.mean, dtype=cv2.CV_8U)
            z = np.empty((len(idx), 1), np.float32)
            cv2.randn(z, 0.0, 1.0)
            z *= self.std.reshape(-1)[idx, None]
            vals = cv2.add(z, self.mean.reshape(-1)[idx, None], dtype=cv2.CV_8U)
        if idx is None:
            return vals.reshape(self.shape)
        out = self._mean_frame().copy()
        out.reshape(-1)[idx] = vals.reshape(-1)
        return out

    def stack(self) -> np.ndarray:
        """Every frame, full: (n_frames, H, W) uint8."""
        out = np.empty((self.n_frames,) + self.shape, np.uint8)
        for k in range(self.n_frames):
            out[k] = self.frame(k, full=True)
        return out
