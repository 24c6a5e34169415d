import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="the torch/kornia sensor path is the optional extra [gpu]")

from vision_calib.camera import CameraIntrinsics
from vision_calib.errors import ConfigError, DataError
from vision_calib.sensor import SensorEffects, apply_effects, distortion_source_map

INTR = CameraIntrinsics(160, 120, 150.0, 148.0, 81.3, 58.6, (-0.25, 0.08, 0.002, -0.001, 0.01))
NO_NOISE = dict(full_well_e=0.0, read_noise_grey=0.0)


def _blob(intr, u0, v0, sigma=1.5, amp=200.0):
    v, u = np.mgrid[0:intr.height, 0:intr.width].astype(float)
    return (amp * np.exp(-((u - u0) ** 2 + (v - v0) ** 2) / (2 * sigma**2))).astype(np.float32)


def _centroid(img):
    img = img.astype(float)
    v, u = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    return np.array([(img * u).sum(), (img * v).sum()]) / img.sum()


def test_source_map_inverts_distortion():
    src = distortion_source_map(INTR)
    K = INTR.K
    x = (src[..., 0] - K[0, 2]) / K[0, 0]
    y = (src[..., 1] - K[1, 2]) / K[1, 1]
    uv = INTR.project(np.stack([x.ravel(), y.ravel(), np.ones(x.size)], axis=1)).reshape(src.shape)
    v, u = np.mgrid[0:INTR.height, 0:INTR.width]
    assert np.abs(uv[..., 0] - u).max() < 1e-6 and np.abs(uv[..., 1] - v).max() < 1e-6
    # barrel distortion (k1 < 0): image corners come from further out in the ideal image
    assert src[0, 0, 0] < 0 and src[-1, -1, 0] > INTR.width - 1


@pytest.mark.parametrize("u_u,v_u", [(30.0, 25.0), (120.4, 95.7), (81.3, 58.6)])
def test_distortion_moves_blob_to_projected_position(u_u, v_u):
    """A feature at ideal pixel (u_u, v_u) lands at intr.project of its ray (pixel-centre convention)."""
    ideal = _blob(INTR, u_u, v_u)
    out = apply_effects(ideal, SensorEffects(blur_sigma_px=0.0, **NO_NOISE), 1, 0, INTR)[0]
    ray = np.array([[(u_u - INTR.cx) / INTR.fx, (v_u - INTR.cy) / INTR.fy, 1.0]])
    expected = INTR.project(ray)[0]
    assert np.linalg.norm(_centroid(out) - expected) < 0.05
    ideal_only = apply_effects(ideal, SensorEffects(apply_distortion=False, blur_sigma_px=0.0, **NO_NOISE), 1, 0, INTR)[0]
    assert np.linalg.norm(_centroid(ideal_only) - [u_u, v_u]) < 0.05


def test_noise_statistics_and_independence():
    intr = CameraIntrinsics(200, 150, 200.0, 200.0, 99.5, 74.5)
    ideal = np.full((150, 200), 128.0, np.float32)
    for model in ("gaussian", "poisson"):
        eff = SensorEffects(apply_distortion=False, blur_sigma_px=0.0, full_well_e=10000.0, read_noise_grey=1.0,
                            photon_model=model)
        f = apply_effects(ideal, eff, 4, seed=3, intrinsics=intr).astype(float)
        e = 128 / 255 * 10000
        expected_var = e * (255 / 10000) ** 2 + 1.0 + 1 / 12  # photon + read + quantisation
        assert f.mean() == pytest.approx(128.0, abs=0.05)
        assert f.var() == pytest.approx(expected_var, rel=0.05)
        c = np.corrcoef(f[0].ravel() - 128, f[1].ravel() - 128)[0, 1]
        assert abs(c) < 0.03
        assert not np.array_equal(f[0], f[1])


def test_seed_reproducible():
    ideal = np.random.default_rng(0).uniform(0, 255, (INTR.height, INTR.width)).astype(np.float32)
    eff = SensorEffects()
    a = apply_effects(ideal, eff, 3, 7, INTR)
    b = apply_effects(ideal, eff, 3, 7, INTR)
    c = apply_effects(ideal, eff, 3, 8, INTR)
    assert a.dtype == np.uint8 and a.shape == (3, INTR.height, INTR.width)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


@pytest.mark.parametrize("kw,var", [({"blur_sigma_px": 1.3}, 1.3**2), ({"blur_sigma_px": 0.0, "blur_disc_radius_px": 3.0}, 3.0**2 / 4)])
def test_blur_psf_second_moment(kw, var):
    intr = CameraIntrinsics(61, 61, 100.0, 100.0, 30.0, 30.0)
    ideal = np.zeros((61, 61), np.float32)
    ideal[30, 30] = 1.0
    from vision_calib.sensor import deterministic_image

    eff = SensorEffects(apply_distortion=False, full_well_e=255.0, **kw)
    psf = deterministic_image(torch.from_numpy(ideal), eff, intr).numpy().astype(float)
    psf /= psf.sum()
    v, u = np.mgrid[0:61, 0:61]
    assert np.allclose(_centroid(psf), [30, 30], atol=1e-6)
    assert (psf * (u - 30) ** 2).sum() == pytest.approx(var, rel=0.06)


def test_exposure_gain_vignetting():
    intr = CameraIntrinsics(100, 80, 100.0, 100.0, 49.5, 39.5)
    ideal = np.full((80, 100), 100.0, np.float32)
    base = dict(apply_distortion=False, blur_sigma_px=0.0, **NO_NOISE)
    f = apply_effects(ideal, SensorEffects(exposure=1.5, gain=1.2, black_level_grey=4.0, **base), 1, 0, intr)[0]
    assert np.all(f == round(100 * 1.5 * 1.2 + 4))
    f = apply_effects(ideal, SensorEffects(vignetting=0.3, **base), 1, 0, intr)[0].astype(float)
    assert f[40, 50] == pytest.approx(100, abs=0.6)
    assert f[0, 0] == pytest.approx(100 * (1 - 0.3 * ((49.5**2 + 39.5**2) / (50**2 + 40**2))), abs=0.6)
    assert np.all(apply_effects(np.full((80, 100), 300.0, np.float32), SensorEffects(**base), 1, 0, intr) == 255)


def test_config_errors_and_dict_round_trip():
    e = SensorEffects(blur_sigma_px=0.9, vignetting=0.1, photon_model="poisson")
    assert SensorEffects.from_dict(e.to_dict()) == e
    with pytest.raises(ConfigError, match="read_noise_grey"):
        SensorEffects(read_noise_grey=-1)
    with pytest.raises(ConfigError, match="photon_model"):
        SensorEffects(photon_model="uniform")
    with pytest.raises(ConfigError, match="unknown"):
        SensorEffects.from_dict({"sigma": 1})
    with pytest.raises(DataError, match="shape"):
        apply_effects(np.zeros((10, 10), np.float32), SensorEffects(), 1, 0, INTR)
    with pytest.raises(ConfigError, match="n_frames"):
        apply_effects(np.zeros((INTR.height, INTR.width), np.float32), SensorEffects(), 0, 0, INTR)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA not available")
def test_cuda_matches_cpu():
    ideal = np.random.default_rng(0).uniform(0, 255, (INTR.height, INTR.width)).astype(np.float32)
    eff = SensorEffects(blur_sigma_px=0.8, vignetting=0.2)
    a = apply_effects(ideal, eff, 3, 11, INTR, device="cpu").astype(int)
    b = apply_effects(ideal, eff, 3, 11, INTR, device="cuda").astype(int)
    assert np.abs(a - b).max() <= 1
    assert np.mean(a != b) < 1e-3
