"""Circle-grid detection on photographs: the real ROS-I photo in ../shared, generated photographic
degradations (tests/targets/photo_views.py), the point-order check and the messages."""

import os
from pathlib import Path

import numpy as np
import pytest

from photo_views import W, photo_view
from vision_calib.errors import ConfigError
from vision_calib.measure.detect import detect
from vision_calib.targets.kinds.dot_grid import MAX_OFF_GRID, grid_consistency
from vision_calib.targets.spec import TargetSpec, target_from_dict

REAL = Path(os.environ["VISION_CALIB_SHARED_DATA"]) / "real" / "rosi_noise_qualification"  # tests/conftest.py


def rosi_10x10(**kw):
    return TargetSpec(kind="modified_circle_grid", name="rosi_10x10", rows=10, cols=10, spacing_m=0.0254, **kw)


def grid_for(dot_px: float) -> TargetSpec:
    """A modified circle grid (d = 0.4 spacing) whose frontal view spans <= ~60 % of the image width."""
    n = int(np.clip(0.6 * W / (dot_px / 0.4), 3, 10))
    return TargetSpec(kind="modified_circle_grid", name="m", rows=max(n - 1, 3), cols=n, spacing_m=0.025,
                      diameter_m=0.01, margin_m=0.015)


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
@pytest.mark.parametrize("family, kw", [
    ("lighting", dict(light=0.6)),
    ("defocus", dict(blur_px=2.0)),
    ("jpeg", dict(jpeg=30)),
    pytest.param("perspective", dict(tilt_deg=60.0), marks=pytest.mark.xfail(
        strict=False, reason="open (issue 17): 60-deg tilt measured 2-3 of 8 (the large origin dot near the board edge "
        "fails the dark-on-light ring test; strong size gradient)")),
    ("shadow", dict(shadow=0.5)),
])
def test_degraded_views_detected(family, kw):
    """Each degradation at its strongest, dots of 12-40 px, random roll: the whole grid, right ids, in >= 7 of 8
    views where the whole board is visible."""
    rng = np.random.default_rng(17)
    n = ok = 0
    while n < 8:
        dot = float(np.exp(rng.uniform(np.log(12), np.log(40))))
        spec = grid_for(dot)
        img, uv, whole = photo_view(spec, rng, dot, roll_deg=rng.uniform(0, 360), **kw)
        if whole:
            n += 1
            ok += found_right(spec, img, uv, dot)
    assert ok >= 7, f"{family}: {ok} of {n}"


@pytest.mark.slow
@pytest.mark.parametrize("dot_px", [5.0, 8.0, 20.0, 40.0, 60.0])
def test_dot_sizes(dot_px):
    """Dots of 5-60 px (tilt up to 30 deg, mild lighting ramp and blur): found with the right ids in 3 of 3 views."""
    rng = np.random.default_rng(int(dot_px))
    spec = grid_for(dot_px)
    n = ok = 0
    while n < 3:
        img, uv, whole = photo_view(spec, rng, dot_px, tilt_deg=rng.uniform(0, 30), roll_deg=rng.uniform(0, 360),
                                    light=0.2, blur_px=min(0.8, dot_px / 8))
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

    from vision_calib.io.report import verdict

    res = SimpleNamespace(free=np.ones(2, bool), identified=np.zeros(2), std=np.ones(2), cost_final=1.0,
                          converged=True, warnings=(), message="")
    v = verdict(res, {"n_poses": 15, "n_rejected": 9})
    assert v["status"] == "warning" and "9 of 15 poses rejected" in v["message"]
    assert verdict(res, {"n_poses": 15, "n_rejected": 4})["status"] == "ok"
