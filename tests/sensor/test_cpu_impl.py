"""The OpenCV CPU implementation (default) against the torch/kornia one and the analytic model."""

import numpy as np
import pytest

from vision_calib.camera import CameraIntrinsics
from vision_calib.sensor import SensorEffects, apply_effects
from vision_calib.sensor.cpu import deterministic_image_cv

INTR = CameraIntrinsics(160, 120, 150.0, 148.0, 81.3, 58.6, (-0.25, 0.08, 0.002, -0.001, 0.01))


@pytest.mark.parametrize("kw", [dict(blur_sigma_px=0.6), dict(blur_sigma_px=0.0, blur_disc_radius_px=2.0),
                                dict(blur_sigma_px=1.3, vignetting=0.2, exposure=0.8)])
def test_deterministic_part_matches_torch(kw):
    """Distortion (exact bilinear, no 1/32 px rounding), blur, vignetting, exposure: same electrons as the
    torch path to float32 rounding."""
    torch = pytest.importorskip("torch")
    from vision_calib.sensor import deterministic_image

    ideal = np.random.default_rng(0).uniform(0, 255, (INTR.height, INTR.width)).astype(np.float32)
    eff = SensorEffects(**kw)
    a = deterministic_image_cv(ideal, eff, INTR)
    b = deterministic_image(torch.from_numpy(ideal), eff, INTR).numpy()
    assert np.abs(a - b).max() < 1e-5 * eff.full_well_e * eff.exposure  # ~ 1e-3 grey level


def test_noise_variance_follows_signal():
    """Per-pixel variance over frames = photon (e * g^2) + read + quantisation, on a ramp of grey levels."""
    intr = CameraIntrinsics(256, 64, 200.0, 200.0, 127.5, 31.5)
    ideal = np.tile(np.linspace(10, 240, 256, dtype=np.float32), (64, 1))
    eff = SensorEffects(apply_distortion=False, blur_sigma_px=0.0, full_well_e=5000.0, read_noise_grey=1.5)
    f = apply_effects(ideal, eff, 200, seed=4, intrinsics=intr).astype(float)
    g = 255 / 5000
    for col in (20, 128, 230):
        x = f[:, :, col]  # (frames, rows): one grey level
        expected = ideal[0, col] * 5000 / 255 * g ** 2 + 1.5 ** 2 + 1 / 12
        assert x.mean() == pytest.approx(ideal[0, col], abs=0.05)
        assert x.var(axis=0).mean() == pytest.approx(expected, rel=0.05), col
    assert not np.array_equal(f[0], f[1])
    np.testing.assert_array_equal(apply_effects(ideal, eff, 2, 4, intr), apply_effects(ideal, eff, 2, 4, intr))


def test_gaussian_blur_mtf():
    """MTF of the blurred image of a sine grating = exp(-2 pi^2 sigma^2 f^2) (sampled Gaussian kernel)."""
    intr = CameraIntrinsics(256, 16, 200.0, 200.0, 127.5, 7.5)
    sigma = 1.2
    eff = SensorEffects(apply_distortion=False, blur_sigma_px=sigma, full_well_e=255.0, read_noise_grey=0.0)
    u = np.arange(256)
    for period in (8.0, 16.0, 32.0):
        ideal = np.tile((128 + 100 * np.sin(2 * np.pi * u / period)).astype(np.float32), (16, 1))
        out = deterministic_image_cv(ideal, eff, intr)[8, 32:-32]
        s = np.sin(2 * np.pi * u[32:-32] / period)
        c = np.cos(2 * np.pi * u[32:-32] / period)
        amp = np.hypot((out - 128) @ s, (out - 128) @ c) / (s @ s) / 100
        assert amp == pytest.approx(np.exp(-2 * np.pi ** 2 * sigma ** 2 / period ** 2), rel=0.01), period


def test_remap_exact_is_bilinear_at_the_source_map():
    """Bilinear interpolation is exact on an affine image: the distorted image equals the affine function
    at the (border-clamped) source positions of the analytic distortion, to float32 rounding, and a
    bilinear (u v) term is reproduced too (no 1/32 px position rounding)."""
    from vision_calib.sensor import distortion_source_map
    from vision_calib.sensor.cpu import remap_exact

    v, u = np.mgrid[0:INTR.height, 0:INTR.width].astype(np.float64)
    src = distortion_source_map(INTR)
    su = np.clip(src[..., 0], 0, INTR.width - 1)
    sv = np.clip(src[..., 1], 0, INTR.height - 1)
    for f in (lambda x, y: 3.0 + 0.7 * x - 0.4 * y, lambda x, y: 1e-2 * x * y):
        out = remap_exact(f(u, v).astype(np.float32), INTR)
        assert out.dtype == np.float32 and out.shape == (INTR.height, INTR.width)
        # bilinear of x*y in one cell is exact too: the cell's corner values span it
        np.testing.assert_allclose(out, f(su, sv), atol=5e-6 * np.abs(f(u, v)).max())  # 1/32 px: ~1e-4


@pytest.mark.parametrize("photon_model", ["gaussian", "poisson"])
def test_focused_frames_have_full_statistics_on_the_focus(photon_model):
    """PoseFrames.focus(mask): on the mask, the same per-pixel mean and variance as full frames; elsewhere the
    rounded noise-free mean; a full frame k equals apply_effects' frame k; frames do not depend on what else
    draws from OpenCV's RNG in between (the measurement runs between two lazy draws)."""
    import cv2

    from vision_calib.sensor import pose_frames

    intr = CameraIntrinsics(256, 64, 200.0, 200.0, 127.5, 31.5)
    ideal = np.tile(np.linspace(10, 240, 256, dtype=np.float32), (64, 1))
    eff = SensorEffects(apply_distortion=False, blur_sigma_px=0.0, full_well_e=5000.0, read_noise_grey=1.5,
                        photon_model=photon_model)
    n = 200
    full = apply_effects(ideal, eff, n, seed=4, intrinsics=intr)
    pf = pose_frames(ideal, eff, n, 4, intr)
    mask = np.zeros((64, 256), bool)
    mask[10:30, ::3] = True
    pf.focus(mask)
    focused = np.empty_like(full)
    for k in range(n):
        focused[k] = pf.frame(k)
        cv2.randn(np.empty((5, 5), np.float32), 0.0, 1.0)  # someone else's draw in between
    np.testing.assert_array_equal(pf.frame(3, full=True), full[3])
    mean8 = pose_frames(ideal, SensorEffects(apply_distortion=False, blur_sigma_px=0.0, full_well_e=0.0,
                                             read_noise_grey=0.0), 1, 0, intr).frame(0)
    assert np.all(focused[:, ~mask] == mean8[~mask])
    a, b = full[:, mask].astype(float), focused[:, mask].astype(float)
    assert abs(a.mean() - b.mean()) < 0.05
    assert b.var(axis=0).mean() == pytest.approx(a.var(axis=0).mean(), rel=0.05)
    assert not np.array_equal(focused[0][mask], focused[1][mask])
    pf.focus(None)
    np.testing.assert_array_equal(pf.frame(7), full[7])
