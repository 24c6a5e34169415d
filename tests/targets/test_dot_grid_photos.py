"""Circle-grid detection on photographs: the real ROS-I photo in ../shared, generated photographic
degradations (tests/targets/photo_views.py), the point-order check and the messages."""

import os
from pathlib import Path

import numpy as np
import pytest

from photo_views import F, H, KINDS, W, degraded_view, grid_for, photo_view
from vision_calib.errors import ConfigError
from vision_calib.measure.detect import detect
from vision_calib.targets.kinds.dot_grid import MAX_OFF_GRID, grid_consistency
from vision_calib.targets.spec import TargetSpec, target_from_dict

REAL = Path(os.environ["VISION_CALIB_SHARED_DATA"]) / "real" / "rosi_noise_qualification"  # tests/conftest.py


def rosi_10x10(**kw):
    return TargetSpec(kind="modified_circle_grid", name="rosi_10x10", rows=10, cols=10, spacing_m=0.0254, **kw)


def found_right(spec, img, uv, dot_px) -> bool:
    d = detect(img, spec)
    return bool(d.valid and d.n_corners == len(uv)
                and np.max(np.linalg.norm(d.uv_px - uv[d.ids], axis=1)) < 0.2 * dot_px + 1.0)


@pytest.mark.skipif(not REAL.is_dir(), reason="real ROS-I photo not available (../shared/data)")
@pytest.mark.parametrize("settings", ["ours", "recording"])
def test_real_rosi_photo_all_dots_and_origin(settings):
    """The 640 x 480 photo of ROS-I's 10 x 10 modified circle grid (big dot bottom-left, carpet around): all 100 dots,
    the origin (id 90) on the big dot, rows and columns one spacing apart, and the same with the set's own
    circle_detector_params (import-rosi's mapping)."""
    import cv2

    from vision_calib.io.rosi import target_from_rosi
    from vision_calib.config import parse_yaml
    from vision_calib.errors import DataError

    if settings == "recording":
        tf = parse_yaml(REAL / "cal_data.yaml", DataError, "x")["target_finder"]
        spec = target_from_dict(target_from_rosi(tf, "cal_data.yaml"), "t")
        assert dict(spec.blob_detector)["minArea"] == 25.0 and dict(spec.blob_detector)["thresholdStep"] == 10.0
    else:
        spec = rosi_10x10()
    img = cv2.imread(str(REAL / "images" / "0.png"), cv2.IMREAD_GRAYSCALE)
    d = detect(img, spec)
    assert d.valid, d.reason
    assert d.n_corners == 100 and list(d.ids) == list(range(100))
    if settings == "recording":
        assert d.diagnostics["dot_stage"] == "given"
    g = d.uv_px.reshape(10, 10, 2)
    # the origin dot: the darkest large blob, found independently by thresholding
    _, bw = cv2.threshold(img, 60, 255, cv2.THRESH_BINARY_INV)
    n, lab, stats, cent = cv2.connectedComponentsWithStats(bw)
    round_ = [k for k in range(1, n) if 50 < stats[k, cv2.CC_STAT_AREA] < 2000
              and 0.6 < stats[k, cv2.CC_STAT_WIDTH] / stats[k, cv2.CC_STAT_HEIGHT] < 1.6]
    big = max(round_, key=lambda k: stats[k, cv2.CC_STAT_AREA])
    assert np.linalg.norm(g[9, 0] - cent[big]) < 2.0
    step_c = np.linalg.norm(np.diff(g, axis=1), axis=2)
    step_r = np.linalg.norm(np.diff(g, axis=0), axis=2)
    # neighbours one spacing apart (~18 px; the origin dot's centre up to 3 px off its row): no row or column skipped
    assert 12 < step_c.min() and step_c.max() < 22 and 12 < step_r.min() and step_r.max() < 22
    off_px, off = grid_consistency(rosi_10x10().corner_points()[1][:, :2], d.uv_px, 0.0254)
    assert off < MAX_OFF_GRID


@pytest.mark.slow
@pytest.mark.parametrize("kind, n_views", [("lighting", 12), ("defocus", 12), ("jpeg", 12), ("perspective", 12),
                                           ("shadow", 12), ("sizes", 12), ("mixed", 24)])
def test_degraded_views_detected(kind, n_views):
    """Each degradation at its strongest (dots of 12-40 px; 'sizes': dots of 5-60 px; 'mixed': all of them at
    random strengths, photo_views.degradation), random roll: the whole grid with the right ids in >= 95 % of the
    views where the whole board is visible (issue 17's goal)."""
    rng = np.random.default_rng([17, KINDS.index(kind)])
    ok, failed = 0, []
    for _ in range(n_views):
        spec, img, uv, dot, kw = degraded_view(kind, rng)
        good = found_right(spec, img, uv, dot)
        ok += good
        if not good:
            failed.append(f"dot {dot:.0f} px {kw}")
    assert ok >= np.ceil(0.95 * n_views), f"{kind}: {ok} of {n_views}; failed: {failed}"


@pytest.mark.slow
def test_perspective_60_deg_centres():
    """Tilt 60 deg: the detected centres are the image ellipses' centres, off the projected circle centres by the
    offset ellipse_centre_offset predicts (up to ~1 px for the origin dot); with the intrinsics given (the offset
    removed) every dot is within 0.15 px of its true projection, and without them the error is that offset."""
    from vision_calib.camera import CameraIntrinsics
    from vision_calib.targets.kinds.circles import ellipse_centre_offset

    intr = CameraIntrinsics(W, H, F, F, W / 2, H / 2)
    rng = np.random.default_rng(60)
    biggest = 0.0
    for _ in range(4):
        spec, img, uv, dot, kw = degraded_view("perspective", rng)
        d = detect(img, spec, intr)
        assert d.valid, d.reason
        err = np.linalg.norm(d.uv_px - uv[d.ids], axis=1)
        assert err.max() < 0.15, (kw, err.max())
        raw = detect(img, spec)
        _, p = spec.corner_points()
        off = ellipse_centre_offset(spec, p, raw.uv_px, intr, radii=spec.kind_impl.radii(spec))
        biggest = max(biggest, float(np.abs(off).max()))
        assert np.max(np.linalg.norm(raw.uv_px - off - uv, axis=1)) < 0.15  # the raw error is that offset
    assert biggest > 0.3  # ... and it is real at 60 deg (0.38 px measured on these views)


@pytest.mark.slow
@pytest.mark.parametrize("dot_px", [5.0, 8.0, 20.0, 40.0, 60.0])
def test_dot_sizes(dot_px):
    """Dots of 5-60 px (tilt up to 30 deg, mild lighting ramp and blur): found with the right ids in 3 of 3 views."""
    rng = np.random.default_rng(int(dot_px))
    spec = grid_for(dot_px)
    n = ok = 0
    while n < 3:
        img, uv, whole = photo_view(spec, rng, dot_px, tilt_deg=rng.uniform(0, 30), roll_deg=rng.uniform(0, 360),
                                    light=0.2, blur_px=min(0.8, dot_px / 8),
                                    shift=0.1 if dot_px < 40 else 0.02)  # a 3 x 3 grid of 60 px dots fills the view
        if whole:
            n += 1
            ok += found_right(spec, img, uv, dot_px)
    assert ok == 3


def test_shifted_ids_are_inconsistent():
    """A grid whose ids of one row are shifted by one column (or mirrored) is about one spacing off the board's
    homography: refused (> MAX_OFF_GRID); the true order is far below it."""
    spec = rosi_10x10()
    _, p = spec.corner_points()
    rng = np.random.default_rng(0)
    img, uv, _ = photo_view(grid_for(15.0), rng, 15.0, tilt_deg=35.0)
    spec = grid_for(15.0)
    _, p = spec.corner_points()
    assert grid_consistency(p[:, :2], uv, spec.spacing_m)[1] < 0.05
    bad = uv.reshape(spec.rows, spec.cols, 2).copy()
    bad[2] = np.roll(bad[2], 1, axis=0)
    assert grid_consistency(p[:, :2], bad.reshape(-1, 2), spec.spacing_m)[1] > MAX_OFF_GRID
    mir = uv.reshape(spec.rows, spec.cols, 2).copy()
    mir[-1] = mir[-1, ::-1]
    assert grid_consistency(p[:, :2], mir.reshape(-1, 2), spec.spacing_m)[1] > MAX_OFF_GRID


def test_not_found_message_says_what_was_found():
    """A board with its lower half hidden: the message gives the blobs found, their sizes, and the count needed."""
    rng = np.random.default_rng(3)
    spec = grid_for(20.0)
    img, uv, _ = photo_view(spec, rng, 20.0)
    y = int(np.median(uv[:, 1]))
    img[y:] = 60
    d = detect(img, spec)
    assert not d.valid
    assert f"{spec.rows * spec.cols} dots needed" in d.reason and "px across" in d.reason
    assert "whole board must be visible" not in d.reason


def test_blob_detector_key_checked():
    base = dict(kind="modified_circle_grid", rows=5, cols=7, spacing_m=0.03)
    assert dict(target_from_dict({**base, "blob_detector": {"minArea": 9}}).blob_detector) == {"minArea": 9.0}
    with pytest.raises(ConfigError, match="minAera"):
        target_from_dict({**base, "blob_detector": {"minAera": 9}})
    with pytest.raises(ConfigError, match="minThreshold"):
        target_from_dict({**base, "blob_detector": {"minThreshold": 200, "maxThreshold": 100}})
    with pytest.raises(ConfigError, match="does not apply"):
        target_from_dict(dict(kind="chessboard", rows=5, cols=7, square_m=0.03, blob_detector={"minArea": 9}))


def test_rosi_circle_detector_params_mapping():
    from vision_calib.io.rosi import blob_settings

    b = blob_settings({"minThreshold": 20, "maxThreshold": 220, "nThresholds": 20, "circleColor": 0,
                       "circleInclusionRadius": 5, "minArea": 25.0}, "w")
    assert b == {"minThreshold": 20, "maxThreshold": 220, "thresholdStep": 10.0, "blobColor": 0, "minArea": 25.0}
    with pytest.raises(ConfigError, match="bogus"):
        blob_settings({"bogus": 1}, "w")


def test_detection_failures_count_in_the_verdict():
    """9 of 15 views not detected (60 %): the verdict is a warning naming the count, not 'ok'; 4 of 15 stays ok."""
    from types import SimpleNamespace

    from vision_calib.report.build import verdict

    res = SimpleNamespace(free=np.ones(2, bool), identified=np.zeros(2), std=np.ones(2), cost_final=1.0,
                          converged=True, warnings=(), message="")
    v = verdict(res, {"n_poses": 15, "n_rejected": 9})
    assert v["status"] == "warning" and "9 of 15 poses rejected" in v["message"]
    assert verdict(res, {"n_poses": 15, "n_rejected": 4})["status"] == "ok"


def test_board_axes_undo_a_sheared_lattice_basis():
    """A 7 x 5 grid whose cells are numbered in a sheared basis (as grow_lattice may pick from the image's shortest
    neighbour vectors, e.g. a diagonal at 60 deg tilt): board_axes gives back a 7 x 5 (or 5 x 7) box holding
    every cell once; the sheared numbering itself spans a larger box."""
    from vision_calib.targets.kinds.dot_lattice import board_axes

    ij = np.stack(np.meshgrid(np.arange(7), np.arange(5)), -1).reshape(-1, 2)
    sheared = ij @ np.array([[1, 1], [0, 1]]).T  # (i + j, j)
    assert tuple(np.ptp(sheared, axis=0) + 1) == (11, 5)
    back = board_axes(map(tuple, sheared))
    assert sorted(tuple(np.ptp(back, axis=0) + 1)) == [5, 7]
    assert len({tuple(c) for c in back.tolist()}) == 35


def _disc_image(cx, cy, r, shade, blur):
    """(60, 60) image of a dark disc (reflectance 0.08 of the board) at (cx, cy) px of radius r px, 8x supersampled,
    lit by shade(x, y) (board grey level), blurred (sigma px), grey noise 1."""
    ss = 8
    yy, xx = (np.mgrid[0:60 * ss, 0:60 * ss] + 0.5) / ss - 0.5
    refl = np.where(np.hypot(xx - cx, yy - cy) <= r, 0.08, 1.0)
    img = (refl * shade(xx, yy)).reshape(60, ss, 60, ss).mean(axis=(1, 3))
    import cv2

    img = cv2.GaussianBlur(img, (0, 0), blur) + np.random.default_rng(0).normal(0, 1.0, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("light", ["ramp", "shadow edge"])
def test_refine_dot_centre_under_uneven_light(light):
    """refine_dot on a blurred dot (radius 8 px, sigma 1.5 px) lit by a steep ramp, or cut by a shadow edge (half
    the light) through the dot: the centre within 0.1 px (ramp) / 0.3 px (edge) of the disc's, the dark area within
    10 % of pi r^2 (ramp)."""
    from vision_calib.targets.kinds.dot_lattice import refine_dot

    cx, cy, r = 30.3, 29.6, 8.0
    if light == "ramp":
        shade = lambda x, y: 110 + 2.0 * x  # noqa: E731  (110-230 grey across the image)
    else:
        shade = lambda x, y: np.where(x - 0.5 * y < 17.0, 220.0, 110.0)  # noqa: E731
    img = _disc_image(cx, cy, r, shade, 1.5)
    c, area = refine_dot(img, (cx + 2.0, cy - 1.5), 25.0)
    err = float(np.hypot(c[0] - cx, c[1] - cy))
    assert err < (0.1 if light == "ramp" else 0.3), err
    if light == "ramp":
        assert abs(area / (np.pi * r * r) - 1) < 0.1
