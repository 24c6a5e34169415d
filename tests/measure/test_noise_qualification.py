"""measure/noise_qualification.py: scatter intervals, corner and pose scatter against known noise, moved frames,
photon-transfer fit against known pixel noise."""

import numpy as np
import pytest

from vision_calib import frames
from vision_calib.camera import CameraIntrinsics
from vision_calib.measure.noise_qualification import (PixelAccumulator, Scatter, corner_scatter, photon_transfer,
                                                      pose_scatter, sensor_noise_settings)
from vision_calib.measure.pnp import project_pinhole
from vision_calib.render import look_at_target
from vision_calib.targets import load_target

CAM = CameraIntrinsics(640, 480, 600, 600, 319.5, 239.5)


def test_scatter_interval_covers_the_true_std_95_percent_of_the_time():
    rng = np.random.default_rng(0)
    hits = 0
    for _ in range(400):
        x = rng.normal(0, 2.0, 21)
        s = Scatter.from_ss(float(np.sum((x - x.mean()) ** 2)), 20)
        hits += s.lo <= 2.0 <= s.hi
    assert 0.92 <= hits / 400 <= 0.98  # binomial std 0.011 around 0.95


def _frames_uv(T, target, sigma, n, rng, shift=None):
    ids, p = target.corner_points()
    uv = project_pinhole(T, p, CAM)
    out = uv[None] + rng.normal(0, 1, (n,) + uv.shape) * np.asarray(sigma)
    if shift:
        for f, d in shift.items():
            out[f] += d
    return ids, out


def test_corner_scatter_recovers_known_noise_per_axis():
    t = load_target("targets/charuco_a5.yaml")
    ids, uv = _frames_uv(look_at_target(t, 0.35), t, (0.05, 0.1), 12, np.random.default_rng(1))
    cs = corner_scatter(uv)
    assert cs["x"].dof == len(ids) * 11
    assert cs["x"].lo < 0.05 < cs["x"].hi and cs["y"].lo < 0.1 < cs["y"].hi
    assert cs["per_corner_std_px"].shape == (len(ids), 2)


def test_pose_scatter_matches_its_prediction_and_names_a_moved_frame():
    t = load_target("targets/charuco_a5.yaml")
    T = look_at_target(t, 0.35, (0.3, -0.2, 0.1))
    ids, uv = _frames_uv(T, t, 0.05, 40, np.random.default_rng(2))
    ps = pose_scatter(ids, uv, t, CAM, 0.05)
    assert ps.moved == ()
    for j, (name, a) in enumerate(ps.axes.items()):
        assert a.dof == 39
        # measured std against the Cramer-Rao std of the true noise: inside the 99.9 % chi-square interval
        wide = Scatter.from_ss(39 * a.std**2, 39, level=0.999)
        assert wide.lo < ps.predicted_std[j] < wide.hi, name
    assert ps.residual_noise_px.lo < 0.05 < ps.residual_noise_px.hi
    # frame 7 shifted by 0.1 px (2 sigma of one corner, but 24 corners move together)
    ids, uv = _frames_uv(T, t, 0.05, 12, np.random.default_rng(3), shift={7: (0.1, 0.0)})
    ps = pose_scatter(ids, uv, t, CAM, 0.05)
    assert [m[0] for m in ps.moved] == [7]
    assert ps.moved[0][2] == pytest.approx(0.1, abs=0.03)


def test_photon_transfer_recovers_read_noise_and_full_well():
    rng = np.random.default_rng(4)
    read, fw, black = 2.5, 6000.0, 15.0
    levels = np.linspace(20, 220, 64)
    mean = np.repeat(levels[None], 64, axis=0)  # 64 x 64 flat columns of known grey level
    std = np.sqrt(read**2 + 255 / fw * (mean - black))
    acc = PixelAccumulator()
    for _ in range(8):
        acc.add(np.rint(mean + std * rng.standard_normal(mean.shape)).astype(np.uint8))
    pt = photon_transfer(acc.mean, acc.var, np.ones(mean.shape, bool), acc.n, min_pixels=20)
    s = sensor_noise_settings(pt, black)
    assert pt["photon"]
    assert abs(s["read_noise_grey"] - read) < 3 * s["read_noise_se"]
    assert abs(s["full_well_e"] - fw) < 3 * s["full_well_se"]
    assert s["read_noise_se"] < 0.1 and s["full_well_se"] < 600


def test_identical_frames_are_found():
    acc = PixelAccumulator()
    img = np.random.default_rng(5).integers(0, 255, (8, 8), dtype=np.uint8)
    for im in (img, img + 1, img):
        acc.add(im)
    assert acc.identical_to_first == [2]
