"""Target definitions: conventions (frame, ids) checked against OpenCV's own boards and detectors."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from vision_calib.errors import ConfigError
from vision_calib.targets import TargetSpec, load_target, target_from_dict

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted((ROOT / "targets").glob("*.yaml"))


def charuco(**kw):
    d = dict(kind="charuco", name="t", rows=5, cols=7, dictionary="DICT_5X5_100", square_m=0.025, marker_m=0.018)
    d.update(kw)
    return TargetSpec(**d)


def grid(**kw):
    d = dict(kind="apriltag_grid", name="g", rows=4, cols=6, dictionary="DICT_APRILTAG_36h11", tag_m=0.03, spacing_m=0.009)
    d.update(kw)
    return TargetSpec(**d)


def test_shipped_targets_load_and_fit():
    names = {p.stem for p in SHIPPED}
    assert {"charuco_a5", "charuco_h4", "apriltag_grid"} <= names
    a5 = load_target(ROOT / "targets" / "charuco_a5.yaml")
    w, h = a5.outline_m()
    assert w <= 0.210 and h <= 0.148  # A5 landscape
    # charuco_h4 must stay in view over the H4 workspace: tests/experiment/test_scenes.py
    for p in SHIPPED:
        s = load_target(p)
        ids, P = s.corner_points()
        assert ids.shape == (s.n_corners,) and P.shape == (s.n_corners, 3)
        assert len(np.unique(ids)) == len(ids)


@pytest.mark.parametrize("legacy", [False, True])
def test_points_match_opencv_board(legacy):
    """corner_points / marker_corners are OpenCV's board object points (computed in float64)."""
    for s in (charuco(rows=6, cols=5, legacy_pattern=legacy, first_id=4), grid(first_id=7)):
        np.testing.assert_allclose(s.marker_corners(), np.asarray(s.cv_board().getObjPoints()).reshape(-1, 4, 3),
                                   atol=1e-7)
        if s.kind == "charuco":
            np.testing.assert_allclose(s.corner_points()[1], s.cv_board().getChessboardCorners(), atol=1e-7)
            assert np.array_equal(s.marker_ids(), np.arange(4, 4 + 15))


def test_charuco_corner_convention():
    s = charuco()
    ids, P = s.corner_points()
    assert np.array_equal(ids, np.arange(24))
    r, c = np.divmod(ids, s.cols - 1)  # row-major, x along columns, y along rows, origin at outer corner
    np.testing.assert_allclose(P[:, 0], (c + 1) * s.square_m)
    np.testing.assert_allclose(P[:, 1], (r + 1) * s.square_m)
    np.testing.assert_array_equal(P[:, 2], 0.0)


def test_apriltag_corner_ids_and_order():
    s = grid(first_id=10)
    ids, P = s.corner_points()
    tag, k = np.divmod(ids, 4)
    assert set(tag) == set(range(10, 34))
    byid = dict(zip(ids.tolist(), P))
    for t in range(10, 34):
        p0, p1, p2, p3 = (byid[4 * t + j] for j in range(4))
        np.testing.assert_allclose(p1 - p0, [s.tag_m, 0, 0], atol=1e-12)  # k=0 -> 1 along +x
        np.testing.assert_allclose(p3 - p0, [0, s.tag_m, 0], atol=1e-12)  # k=0 -> 3 along +y
        np.testing.assert_allclose(p2 - p0, [s.tag_m, s.tag_m, 0], atol=1e-12)
    i = t - 10  # last tag: row-major position
    np.testing.assert_allclose(byid[4 * t][:2], [(i % 6) * 0.039, (i // 6) * 0.039], atol=1e-12)


@pytest.mark.parametrize(
    "spec, ppm",
    [
        (charuco(square_m=0.028, marker_m=0.021, margin_m=0.0), 2000),  # 56 px squares, 6 px bits
        (charuco(rows=6, cols=8, dictionary="DICT_4X4_50", square_m=0.02, marker_m=0.012, margin_m=0.0), 2000),
        (charuco(rows=6, cols=8, dictionary="DICT_4X4_50", square_m=0.02, marker_m=0.012, margin_m=0.0,
                 legacy_pattern=True), 2000),
        (grid(tag_m=0.032, spacing_m=0.008, margin_m=0.0), 1000),
    ],
)
def test_texture_matches_opencv_board_image(spec, ppm):
    """At scales where every edge falls on a pixel boundary our area-coverage texture is OpenCV's image."""
    tex = spec.texture(ppm)
    ref = spec.cv_board().generateImage((tex.shape[1], tex.shape[0]), marginSize=0, borderBits=1)
    assert tex.shape == ref.shape
    assert np.array_equal(tex, ref)


def _px_to_target(spec, tex, uv):
    """Texture pixel coordinates (pixel centre at integers) -> target x, y [m]."""
    x0, y0, x1, y1 = spec.texture_extent_m()
    H, W = tex.shape
    return np.column_stack([x0 + (uv[:, 0] + 0.5) * (x1 - x0) / W, y0 + (uv[:, 1] + 0.5) * (y1 - y0) / H])


def test_charuco_detected_on_texture_maps_to_corner_points():
    """Frame + id convention: OpenCV's CharucoDetector on our texture (non-integer scale, with margin)
    returns ids whose pixel positions map to corner_points()."""
    s = charuco(margin_m=0.0123)
    ppm = 3333.3  # 83.3 px per square: edges off the pixel grid
    tex = s.texture(ppm)
    cc, ci, _, _ = cv2.aruco.CharucoDetector(s.cv_board()).detectBoard(tex)
    assert ci is not None and len(ci) == s.n_corners
    cc = cv2.cornerSubPix(tex.astype(np.float32), cc.astype(np.float32), (5, 5), (-1, -1),
                          (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-6))
    ids, P = s.corner_points()
    xy = _px_to_target(s, tex, cc.reshape(-1, 2))
    # cornerSubPix's own bias on exact area-sampled edges is < 0.1 texel; a wrong id map is off by squares
    np.testing.assert_allclose(xy, P[ci.ravel(), :2], atol=0.15 / ppm)


def test_apriltag_detected_on_texture_maps_to_corner_points():
    s = grid(margin_m=0.011)
    ppm = 2777.7
    tex = s.texture(ppm)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    corners, mids, _ = cv2.aruco.ArucoDetector(s.cv_dictionary(), params).detectMarkers(tex)
    assert mids is not None and len(mids) == s.rows * s.cols
    ids, P = s.corner_points()
    byid = dict(zip(ids.tolist(), P))
    # OpenCV's marker corners are the outer corners of the black border, same as getObjPoints()
    uv = np.concatenate([c.reshape(4, 2) for c in corners])
    cid = np.concatenate([4 * m + np.arange(4) for m in mids.ravel()])
    xy = _px_to_target(s, tex, uv)
    np.testing.assert_allclose(xy, np.array([byid[i][:2] for i in cid]), atol=0.5 / ppm)


def test_frame_is_right_handed_and_extent():
    s = charuco(margin_m=0.01)
    assert s.texture_extent_m() == pytest.approx((-0.01, -0.01, 0.185, 0.135))
    assert s.outline_m() == pytest.approx((0.195, 0.145))
    tex = s.texture(2000)
    assert tex.shape == (290, 390)
    assert tex[0, 0] == 255 and tex[20 + 25, 20 + 25] == 0  # white margin, first square black (x right, y down)
    # z = x cross y points into the board: a camera with R_cam_target = I (looking along +z) sees it upright
    ids, P = s.corner_points()
    n = np.cross(P[1] - P[0], P[s.cols - 1] - P[0])
    assert n[2] > 0


@pytest.mark.parametrize(
    "change, key",
    [
        (dict(dictionary="DICT_NOPE"), "dictionary"),
        (dict(square_m=-0.02), "square_m"),
        (dict(marker_m=0.0), "marker_m"),
        (dict(marker_m=0.03), "marker_m"),
        (dict(rows=1), "rows"),
        (dict(margin_m=-1.0), "margin_m"),
        (dict(first_id=90), "first_id"),  # 17 markers from id 90 > 100 in DICT_5X5_100
        (dict(kind="chessboard"), "kind"),
        (dict(rows=5.5), "rows"),
        (dict(legacy_pattern="no"), "legacy_pattern"),
    ],
)
def test_bad_charuco_values_name_file_and_key(tmp_path, change, key):
    import yaml

    d = dict(kind="charuco", rows=5, cols=7, dictionary="DICT_5X5_100", square_m=0.025, marker_m=0.018)
    d.update(change)
    f = tmp_path / "bad_board.yaml"
    f.write_text(yaml.safe_dump(d))
    with pytest.raises(ConfigError) as ei:
        load_target(f)
    msg = str(ei.value)
    assert str(f) in msg and key in msg


def test_bad_files(tmp_path):
    f = tmp_path / "x.yaml"
    f.write_text("kind: apriltag_grid\nrows: 2\ncols: 2\ndictionary: DICT_APRILTAG_36h11\ntag_m: 0.03\nspacing_m: 0\n")
    with pytest.raises(ConfigError, match="spacing_m"):
        load_target(f)
    f.write_text("kind: charuco\nrows: 5\ncols: 7\ndictionary: DICT_5X5_100\nsquare_m: 0.02\nmarker_m: 0.01\nsqare_m: 1\n")
    with pytest.raises(ConfigError, match="sqare_m"):
        load_target(f)
    f.write_text("kind: [unclosed\n")
    with pytest.raises(ConfigError, match="invalid YAML"):
        load_target(f)
    with pytest.raises(ConfigError, match="file not found|cannot read"):
        load_target(tmp_path / "missing.yaml")
    with pytest.raises(ConfigError, match="units"):
        target_from_dict(dict(kind="charuco", rows=5, cols=7, dictionary="DICT_5X5_100", square_m=25.0,
                              marker_m=18.0, units="mm"))


def test_round_trip_dict():
    s = grid(first_id=3, margin_m=0.02)
    assert target_from_dict(s.to_dict()) == s
