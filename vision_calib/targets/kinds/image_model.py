"""Image models of the corner error, one per family of target kinds: the kinds' ``corner_info`` and
``bias_columns`` (:mod:`vision_calib.targets.kinds.base`) call them, :mod:`vision_calib.measure.covariance` uses
their result. numpy only (scipy's erf imported lazily); ``effects``: a :class:`vision_calib.sensor.SensorEffects`.

The bound below is computed from the image model alone (the sensor's noise and blur, the target's
contrast, the detector's window), not from measured frames: for a corner at position q seen in an image
mu(x - q) + noise, the Fisher information is F = sum over the pixels the detector uses of
grad(mu) grad(mu)^T / var(pixel) (Gaussian pixel noise), and CRLB(q) = F^-1.
- mu: white 255, black 0 (target texture) times exposure x gain, blurred by the sensor blur and the
  pixel's area (variance blur_sigma^2 + 1/12 px^2; a disc of radius R adds R^2 / 4).
- var(pixel) [grey^2] = photon (mu gain 255 / full_well) + read noise^2 + 1/12 (8-bit rounding).
- ChArUco (saddle corner refined by cv2.cornerSubPix in a (2 w + 1)^2 window, w = DetectConfig.subpix_win):
  mu = mid + C/2 erf(n1.x / (sqrt2 s)) erf(n2.x / (sqrt2 s)), n1, n2 the image normals of the two
  board edges through the corner; F summed over the window's pixels.
- Chessboard: the same saddle model (corners from the saddle-point fit of targets/kinds/saddle.py, window radius
  <= 12 px; the (2 w + 1)^2 window is an approximation): measured corner scatter 0.0045 / 0.0172 px vs the
  model's 0.0038 / 0.0159 px at read noise 1 / 8 (benchmarks/bench_detect.py --targets chessboard), i.e. the
  model is 18 % / 8 % optimistic.
- Circle grid (dark-area centroid of each dot): see :func:`circle_info`.
- AprilTag grid (OpenCV's AprilTag refinement fits a line to each tag side and intersects them): per
  unit length an edge of contrast C gives I1 = C^2 / (2 sqrt(pi) s var_mid); a line fitted over a side of
  L px locates its end (the corner) along its normal with variance 4 / (I1 L); F = sum_i n_i n_i^T I1 L_i / 4.
Corners are taken as independent and the distortion's local scale (~1) is ignored.
"""

from __future__ import annotations

import numpy as np


def edge_sigma_px(effects) -> float:
    """Std [px] of the blurred edge profile: sensor blur, defocus disc and the pixel's own area."""
    return float(np.sqrt(effects.blur_sigma_px**2 + effects.blur_disc_radius_px**2 / 4 + 1.0 / 12))


def pixel_variance(mean_grey, effects) -> np.ndarray:
    """Per-pixel noise variance [grey^2] of the sensor model (sensor.SensorEffects) at mean grey levels."""
    mean_grey = np.asarray(mean_grey, dtype=float)
    v = np.full(mean_grey.shape, effects.read_noise_grey**2 + 1.0 / 12)
    if effects.full_well_e > 0:
        v = v + np.maximum(mean_grey - effects.black_level_grey, 0.0) * effects.gain * 255.0 / effects.full_well_e
    return v


def contrast(effects) -> float:
    """White-minus-black grey level of the target in the image."""
    return 255.0 * effects.exposure * effects.gain


def saddle_info(normals: np.ndarray, effects, half_win: int) -> np.ndarray:
    """(K, 2, 2) Fisher information [1/px^2] of saddle corners with edge normals (K, 2, 2) in a
    (2 half_win + 1)^2 pixel window (see the comment above)."""
    g = np.arange(-half_win, half_win + 1, dtype=float)
    P = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)  # (N, 2)
    s, C = edge_sigma_px(effects), contrast(effects)
    a1 = np.einsum("nd,kd->kn", P, normals[:, 0]) / s
    a2 = np.einsum("nd,kd->kn", P, normals[:, 1]) / s
    e1, e2 = erf_(a1 / np.sqrt(2)), erf_(a2 / np.sqrt(2))
    mu = C / 2 * (1 + e1 * e2) + effects.black_level_grey
    k = np.sqrt(2 / np.pi) / s
    grad = C / 2 * k * ((np.exp(-a1**2 / 2) * e2)[..., None] * normals[:, None, 0]
                        + (np.exp(-a2**2 / 2) * e1)[..., None] * normals[:, None, 1])  # (K, N, 2)
    w = 1.0 / pixel_variance(mu, effects)
    return np.einsum("kn,kna,knb->kab", w, grad, grad)


def tag_edge_info(normals: np.ndarray, side_px: np.ndarray, effects) -> np.ndarray:
    """(K, 2, 2) Fisher information [1/px^2] of tag corners from two fitted sides of side_px (K, 2) px."""
    s, C = edge_sigma_px(effects), contrast(effects)
    I1 = C**2 / (2 * np.sqrt(np.pi) * s) / pixel_variance(C / 2 + effects.black_level_grey, effects)
    return np.einsum("ki,kia,kib->kab", I1 * side_px / 4, normals, normals)


def erf_(x):  # noqa: D103 (scipy imported lazily: measure imports stay light)
    from scipy.special import erf

    return erf(x)


def circle_info(radius_px: np.ndarray, effects) -> np.ndarray:
    """(K, 2, 2) Fisher information [1/px^2] of dot centres from their whole edge: a dot of radius R px
    (mean over the two axes) is an edge of length 2 pi R whose normals cover all directions, so
    F = I1 pi R I2 (I1 as for a tag side)."""
    s, C = edge_sigma_px(effects), contrast(effects)
    I1 = C**2 / (2 * np.sqrt(np.pi) * s) / pixel_variance(C / 2 + effects.black_level_grey, effects)
    return np.einsum("k,ab->kab", I1 * np.pi * np.asarray(radius_px, float), np.eye(2))


def field_directions(uv_px: np.ndarray) -> np.ndarray:
    """(2K, 4) d(uv)/d(eps_u, eps_v, kappa_u, kappa_v) [px per px of amplitude] of the smooth corner error
    field (module docstring) at the corners uv_px (K, 2): x = (uv - mean) / (largest |uv - mean|), strain
    terms e = a x (per axis), keystone terms e = x (kappa . x); rows (u0, v0, u1, v1, ...)."""
    d = uv_px - uv_px.mean(axis=0)
    x = d / max(float(np.max(np.linalg.norm(d, axis=1))), 1e-9)
    A = np.zeros((2 * len(x), 4))
    A[0::2, 0] = x[:, 0]
    A[1::2, 1] = x[:, 1]
    for j in range(2):
        A[0::2, 2 + j] = x[:, 0] * x[:, j]
        A[1::2, 2 + j] = x[:, 1] * x[:, j]
    return A


#: stds [px] of the AprilTag detector terms, per corner estimator (module docstring): common shift per axis,
#: tag growth, smooth field (strain u, v, keystone u, v; px at the pattern's edge)
APRILTAG_TERMS = {"edges": (0.0, 0.007, (0.0, 0.0, 0.0, 0.0)),
                  "opencv": (0.05, 0.015, (0.05, 0.05, 0.05, 0.05))}


def apriltag_terms(ids: np.ndarray, uv_px: np.ndarray, estimator: str = "edges") -> np.ndarray:
    """(2K, m) columns of S for AprilTag-grid corners (ids 4 marker + k): common shift u, v, tag growth and
    the smooth field terms, scaled by :data:`APRILTAG_TERMS` of the corner estimator; zero columns dropped."""
    shift, growth, field = APRILTAG_TERMS[estimator]
    tag = np.asarray(ids) // 4
    centre = np.zeros_like(uv_px)
    for t in np.unique(tag):
        centre[tag == t] = uv_px[tag == t].mean(axis=0)
    d = uv_px - centre
    n = d / np.maximum(np.linalg.norm(d, axis=1), 1e-9)[:, None]
    n[np.bincount(tag)[tag] < 2] = 0.0  # a lone corner of its tag: no growth direction
    S = np.column_stack([shift * np.tile(np.eye(2), (len(ids), 1)), growth * n.ravel(),
                         field_directions(uv_px) * np.asarray(field, float)])
    return S[:, np.any(S != 0, axis=0)]
