"""Seeded batch detection (detect once per pose, refine each frame) vs the per-frame path, on rendered frames."""

import numpy as np
import pytest

from vision_calib import frames
from vision_calib.camera import CameraIntrinsics
from vision_calib.errors import ConfigError
from vision_calib.measure import DetectConfig, detect_batch, measure_pose
from vision_calib.measure.pnp import target_lookup
from vision_calib.sensor import SensorEffects, apply_effects

from measure_helpers import random_pose, warp_view

DIST_INTR = CameraIntrinsics(1024, 768, 1100.0, 1090.0, 515.3, 380.7, (-0.12, 0.05, 0.0008, -0.0005, 0.0))
PER_FRAME = DetectConfig(batch="per_frame")
SEEDED = DetectConfig(batch="seeded")


def _frames(target, T, n, seed, read_noise=1.0):
    ideal = warp_view(target, DIST_INTR.without_distortion(), T)
    return apply_effects(ideal, SensorEffects(read_noise_grey=read_noise), n, seed, DIST_INTR)


def _corner_stats(target, runs):
    """runs: [(T, detections)] -> (per-corner bias RMS px, pooled scatter over frames px)."""
    lookup = target_lookup(target)
    bias, var = [], []
    for T, dets in runs:
        acc = {}
        for d in dets:
            p = np.array([lookup[int(i)] for i in d.ids])
            for i, e in zip(d.ids, d.uv_px - DIST_INTR.project(frames.transform_points(T, p))):
                acc.setdefault(int(i), []).append(e)
        for v in acc.values():
            v = np.array(v)
            bias.append(np.sum(v.mean(0) ** 2) / 2)
            var.append(v.var(0, ddof=1).mean())
    return float(np.sqrt(np.mean(bias))), float(np.sqrt(np.mean(var)))


def _compare(target, n_poses, n_seeds, n_frames, read_noise=1.0):
    rng = np.random.default_rng(21)
    out = {"per_frame": [], "seeded": [], "dpose": [], "err": {"per_frame": [], "seeded": []}}
    for k in range(n_poses):
        T = random_pose(rng, target)
        for s in range(n_seeds):
            imgs = _frames(target, T, n_frames, 100 * k + s, read_noise)
            for name, cfg in (("per_frame", PER_FRAME), ("seeded", SEEDED)):
                dets = detect_batch(imgs, target, DIST_INTR, cfg)
                assert all(d.valid for d in dets), [d.reason for d in dets]
                m = measure_pose(dets, target, DIST_INTR, k)
                assert m.valid
                out[name].append((T, dets))
                out["err"][name].append(frames.pose_error(T, m.T_cam_target))
            if name == "seeded":
                assert [d.diagnostics["batch"] for d in dets] == ["full"] + ["seeded"] * (n_frames - 1)
                assert all(d.diagnostics["seed_frame"] == 0 for d in dets[1:])
            out["dpose"].append(out["err"]["seeded"][-1] - out["err"]["per_frame"][-1])
    return out


@pytest.mark.parametrize("read_noise", [1.0, 8.0])
def test_charuco_seeded_equals_per_frame(charuco, read_noise):
    """ChArUco: same pose to 1e-3 mm / 1e-3 deg, same corner bias and scatter vs the projected truth."""
    out = _compare(charuco, n_poses=3, n_seeds=2, n_frames=5, read_noise=read_noise)
    d = np.abs(np.array(out["dpose"]))
    assert d[:, :3].max() < 1e-6 and np.degrees(d[:, 3:].max()) < 1e-3
    b0, s0 = _corner_stats(charuco, out["per_frame"])
    b1, s1 = _corner_stats(charuco, out["seeded"])
    assert abs(b1 - b0) < 0.002 and abs(s1 - s0) < 0.05 * s0, (b0, b1, s0, s1)


def test_chessboard_seeded_equals_per_frame(chessboard):
    """Chessboard: the seeded frames are refined by the saddle fit the full detection ends with (same
    windows), so corners and poses equal the per-frame path's to the fit's convergence tolerance."""
    out = _compare(chessboard, n_poses=2, n_seeds=2, n_frames=4, read_noise=4.0)
    d = np.abs(np.array(out["dpose"]))
    assert d[:, :3].max() < 1e-6 and np.degrees(d[:, 3:].max()) < 1e-4, d
    for (_, da), (_, db) in zip(out["per_frame"], out["seeded"]):
        for a, b in zip(da, db):
            assert np.array_equal(a.ids, b.ids)
            assert np.abs(a.uv_px - b.uv_px).max() < 1e-3


def test_apriltag_seeded_not_worse_than_per_frame(aprilgrid):
    """AprilTag grid: the edge-fit refinement has a smaller corner bias and no larger scatter than OpenCV's
    AprilTag refinement (per-frame path), and the pose errors vs truth are no larger."""
    out = _compare(aprilgrid, n_poses=2, n_seeds=2, n_frames=4)
    b0, s0 = _corner_stats(aprilgrid, out["per_frame"])
    b1, s1 = _corner_stats(aprilgrid, out["seeded"])
    assert b1 < 0.5 * b0 and b1 < 0.05, (b0, b1)
    assert s1 < 1.1 * s0, (s0, s1)
    e0, e1 = (np.abs(np.array(out["err"][m])) for m in ("per_frame", "seeded"))
    assert e1[:, :3].max() < 0.1e-3 and np.degrees(e1[:, 3:].max()) < 0.02
    assert np.sqrt(np.mean(e1**2)) < 1.2 * np.sqrt(np.mean(e0**2))


@pytest.mark.parametrize("name", ["charuco", "aprilgrid"])
@pytest.mark.parametrize("swap", [0, 2])
def test_swapped_frame_is_not_refined_from_wrong_seeds(name, swap, request):
    """A frame of another pose among a pose's frames gets a full detection of its own view."""
    target = request.getfixturevalue(name)
    lookup = target_lookup(target)
    rng = np.random.default_rng(5)
    Ta, Tb = random_pose(rng, target), random_pose(rng, target)
    imgs = _frames(target, Ta, 4, 1)
    imgs[swap] = _frames(target, Tb, 1, 2)[0]
    dets = detect_batch(imgs, target, DIST_INTR, SEEDED)
    assert all(d.valid for d in dets)
    for k, d in enumerate(dets):
        T = Tb if k == swap else Ta
        p = np.array([lookup[int(i)] for i in d.ids])
        err = d.uv_px - DIST_INTR.project(frames.transform_points(T, p))
        assert np.abs(err).max() < 0.5, (k, np.abs(err).max())
    assert dets[swap].diagnostics["batch"] == "full"
    if swap == 0:  # frame 1 no longer matches the seed: full detection, then it seeds frames 2, 3
        assert "fallback" in dets[1].diagnostics
        assert [d.diagnostics.get("seed_frame") for d in dets[2:]] == [1, 1]
    else:
        assert "view differs" in dets[swap].diagnostics["fallback"]
        assert [d.diagnostics.get("seed_frame") for d in dets[1:] if d.frame_index != swap] == [0, 0]


def test_shifted_view_falls_back(charuco):
    """A frame whose view moved by 3 px (same look at 1/8 scale) exceeds max_shift_px: full detection."""
    T = random_pose(np.random.default_rng(6), charuco)
    imgs = _frames(charuco, T, 3, 3)
    imgs[2] = np.roll(imgs[2], 3, axis=1)
    dets = detect_batch(imgs, charuco, DIST_INTR, SEEDED)
    assert dets[1].diagnostics["batch"] == "seeded" and dets[1].diagnostics["max_shift_px"] < 0.3
    assert dets[2].diagnostics["batch"] == "full" and "moved" in dets[2].diagnostics["fallback"]
    common = np.intersect1d(dets[0].ids, dets[2].ids)
    shift = dets[2].uv_px[np.isin(dets[2].ids, common)] - dets[0].uv_px[np.isin(dets[0].ids, common)]
    assert np.allclose(shift.mean(0), [3.0, 0.0], atol=0.1)


def test_paths_and_arrays_give_identical_detections(tmp_path, aprilgrid):
    """process (PNG files) and simulate (arrays) go through the same seeded path: identical corners."""
    import cv2

    T = random_pose(np.random.default_rng(7), aprilgrid)
    imgs = _frames(aprilgrid, T, 3, 4)
    paths = []
    for k, im in enumerate(imgs):
        paths.append(str(tmp_path / f"f{k}.png"))
        cv2.imwrite(paths[-1], im)
    a = detect_batch(imgs, aprilgrid, DIST_INTR)
    b = detect_batch(paths, aprilgrid, DIST_INTR)
    for da, db in zip(a, b):
        assert da.valid and np.array_equal(da.ids, db.ids) and np.array_equal(da.uv_px, db.uv_px)


def test_seeded_config_validation():
    with pytest.raises(ConfigError, match="batch"):
        DetectConfig(batch="once")
    with pytest.raises(ConfigError, match="max_shift_px"):
        DetectConfig(max_shift_px=0.0)
    assert DetectConfig().batch == "seeded" and DetectConfig().seed_config().refine == "none"
    assert DetectConfig(refine="subpix").seed_config().refine == "subpix"


@pytest.mark.parametrize("name", ["charuco", "aprilgrid", "chessboard"])
def test_refinement_reads_only_its_read_mask(name, request):
    """The per-frame estimator started from the seed reads only the pixels of Refiner.read_mask: the same
    frame with every other pixel set to 0 gives bit-identical corners (what lets the simulated chain draw
    the noise of the frames after the first only there: sensor.cpu.PoseFrames.focus)."""
    from vision_calib.measure.seeded import Refiner

    target = request.getfixturevalue(name)
    rng = np.random.default_rng(11)
    n_checked = 0
    for k in range(3):
        imgs = _frames(target, random_pose(rng, target), 4, 40 + k, read_noise=6.0)
        d0 = detect_batch(imgs[:1], target, DIST_INTR, SEEDED)[0]
        assert d0.valid
        ref = Refiner(target, DIST_INTR, SEEDED, target.kind_impl.seeded_mode(SEEDED))
        mask = ref.read_mask(d0.uv_px, imgs[0].shape, SEEDED.max_shift_px)
        assert 0 < mask.mean() < 0.15
        for img in imgs[1:]:
            blank = np.where(mask, img, 0).astype(np.uint8)
            _, uv_a, ok_a, _ = ref.refine(img, d0.ids, d0.uv_px)
            _, uv_b, ok_b, _ = ref.refine(blank, d0.ids, d0.uv_px)
            np.testing.assert_array_equal(ok_a, ok_b)
            np.testing.assert_array_equal(uv_a, uv_b)
            n_checked += int(ok_a.sum())
    assert n_checked > 50


def test_frames_drawn_on_demand_measure_like_full_frames(charuco):
    """detect_batch on sensor.pose_frames (noise of frames 1.. drawn on the read mask only) vs on full
    frames: every frame seeded, same corner bias and scatter vs the projected truth."""
    from vision_calib.sensor import pose_frames

    rng = np.random.default_rng(12)
    runs = {"full": [], "lazy": []}
    eff = SensorEffects(read_noise_grey=4.0)
    for k in range(4):
        T = random_pose(rng, charuco)
        ideal = warp_view(charuco, DIST_INTR.without_distortion(), T)
        for s in range(3):
            for name, imgs in (("full", apply_effects(ideal, eff, 6, 10 * k + s, DIST_INTR)),
                               ("lazy", pose_frames(ideal, eff, 6, 1000 + 10 * k + s, DIST_INTR))):
                dets = detect_batch(imgs, charuco, DIST_INTR, SEEDED)
                assert [d.diagnostics["batch"] for d in dets] == ["full"] + ["seeded"] * 5
                # frames of one simulated view skip the view check; recorded frames get it
                assert all((d.diagnostics["view_ncc"] is None) == (name == "lazy") for d in dets[1:])
                runs[name].append((T, dets))
    b0, s0 = _corner_stats(charuco, runs["full"])
    b1, s1 = _corner_stats(charuco, runs["lazy"])
    assert abs(b1 - b0) < 0.01 and abs(s1 - s0) < 0.1 * s0, (b0, b1, s0, s1)


def test_a_frame_that_falls_back_is_drawn_in_full(charuco, monkeypatch):
    """With frames drawn on demand, a frame whose seeded refinement is refused gets its full detection on a
    frame drawn in full (not on the masked one), and the later frames are focused on the new seed."""
    from vision_calib.measure import seeded
    from vision_calib.sensor import pose_frames

    T = random_pose(np.random.default_rng(13), charuco)
    pf = pose_frames(warp_view(charuco, DIST_INTR.without_distortion(), T), SensorEffects(read_noise_grey=2.0),
                     4, 5, DIST_INTR)
    calls, foci = [], []
    frame, focus = pf.frame, pf.focus
    monkeypatch.setattr(pf, "frame", lambda k, full=False: calls.append((k, full)) or frame(k, full))
    monkeypatch.setattr(pf, "focus", lambda mask: foci.append(mask.mean()) or focus(mask))
    real = seeded._from_seed

    def refuse_frame_2(img, size, source, i, *a):
        return (None, "refused by the test") if i == 2 else real(img, size, source, i, *a)

    monkeypatch.setattr(seeded, "_from_seed", refuse_frame_2)
    dets = detect_batch(pf, charuco, DIST_INTR, SEEDED)
    assert [d.diagnostics["batch"] for d in dets] == ["full", "seeded", "full", "seeded"]
    assert (2, True) in calls and len(foci) == 1  # frame 2 redrawn in full; the confirmed seed 0 stays
    assert all(d.valid for d in dets)
