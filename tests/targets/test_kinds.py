"""New target kinds (chessboard, asymmetric circle grid) and the kind registry: geometry vs OpenCV's
conventions, texture area/centroid, render -> detect -> PnP against the true pose (incl. a camera rolled
180 degrees), refusal of 180-degree-symmetric boards, validation messages, printable export."""

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from vision_calib import frames
from vision_calib.camera import CameraIntrinsics
from vision_calib.errors import ConfigError
from vision_calib.measure import detect, measure_pose
from vision_calib.render import TargetRenderer
from vision_calib.sensor import SensorEffects, apply_effects
from vision_calib.targets import TargetSpec, export_printable, load_target, target_from_dict
from vision_calib.targets.kinds import KINDS

ROOT = Path(__file__).resolve().parents[2]
CHESS = load_target(ROOT / "targets" / "chessboard_a4.yaml")
CIRCLES = load_target(ROOT / "targets" / "circles_asymmetric_a4.yaml")
MODCIRC = load_target(ROOT / "targets" / "modified_circle_grid_a4.yaml")
INTR = CameraIntrinsics(1024, 768, 1013.0, 1013.0, 511.5, 383.5)  # the H4 base camera


def chess(**kw):
    d = dict(kind="chessboard", name="c", rows=5, cols=8, square_m=0.02)
    d.update(kw)
    return TargetSpec(**d)


def circles(**kw):
    d = dict(kind="circles_asymmetric", name="a", rows=7, cols=4, spacing_m=0.02, diameter_m=0.01)
    d.update(kw)
    return TargetSpec(**d)


def test_registry_holds_all_kinds():
    assert {"charuco", "apriltag_grid", "chessboard", "circles_asymmetric", "modified_circle_grid"} <= set(KINDS)
    for s in (CHESS, CIRCLES, MODCIRC):
        assert s.kind_impl is KINDS[s.kind]
        assert target_from_dict(s.to_dict()) == s
        assert "dictionary" not in s.to_dict()


def test_chessboard_corners_are_opencv_charuco_corners():
    """Same inner corners, ids and frame as OpenCV's ChArUco board of the same squares."""
    s = chess(rows=6, cols=9, square_m=0.025)
    board = cv2.aruco.CharucoBoard((9, 6), 0.025, 0.018, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    ids, P = s.corner_points()
    assert np.array_equal(ids, np.arange(40)) and s.n_corners == 40
    np.testing.assert_allclose(P, board.getChessboardCorners(), atol=1e-7)
    tex = s.texture(1000)  # 25 px squares on the pixel grid: square (0, 0) black, alternating
    m = round(s.margin_m * 1000)
    assert tex[m + 12, m + 12] == 0 and tex[m + 12, m + 37] == 255 and tex[m + 37, m + 37] == 0


def test_circle_centres_follow_opencv_asymmetric_convention():
    """OpenCV's calibration sample: point (i, j) at ((2 j + i % 2) s, i s); ours are offset by the radius."""
    s = circles()
    ids, P = s.corner_points()
    i, j = np.divmod(ids, s.cols)
    ref = np.column_stack([(2 * j + i % 2) * 0.02, i * 0.02, 0 * i]) + [0.005, 0.005, 0]
    np.testing.assert_allclose(P, ref, atol=1e-12)
    w, h = s.pattern_size_m()
    assert (w, h) == pytest.approx((7 * 0.02 + 0.01, 6 * 0.02 + 0.01))
    # rows odd: a 180-degree rotation does not map the dot set onto itself; rows even: it does
    for rows, sym in ((7, False), (6, True)):
        t = circles(rows=rows, allow_symmetric=True)
        _, Q = t.corner_points()
        w, h = t.pattern_size_m()
        rot = np.column_stack([w - Q[:, 0], h - Q[:, 1]])
        d = np.min(np.linalg.norm(rot[:, None] - Q[None, :, :2], axis=2), axis=1)
        assert bool(np.all(d < 1e-9)) == sym == bool(t.symmetric())


def test_circle_texture_area_and_centroids():
    """Dots drawn with exact coverage: black area per dot = pi r^2 within 1e-3, centroid within 0.005 px."""
    s = circles(margin_m=0.0)
    ppm = 2345.6  # edges off the pixel grid
    cov = 1.0 - s._coverage(ppm)
    H, W = cov.shape
    x0, y0, x1, y1 = s.texture_extent_m()
    sx, sy = W / (x1 - x0), H / (y1 - y0)
    _, P = s.corner_points()
    r_px = 0.005 * sx
    vv, uu = np.mgrid[0:H, 0:W]
    for p in P[[0, 5, 27]]:
        cu, cv = (p[0] - x0) * sx - 0.5, (p[1] - y0) * sy - 0.5  # pixel-centre coordinates
        win = (np.abs(uu - cu) < r_px + 3) & (np.abs(vv - cv) < r_px + 3)
        a = cov[win].sum()
        assert a == pytest.approx(math.pi * 0.005**2 * sx * sy, rel=1e-3)
        assert (cov[win] @ uu[win]) / a == pytest.approx(cu, abs=0.005)
        assert (cov[win] @ vv[win]) / a == pytest.approx(cv, abs=0.005)


def _pose(target, dist, rvec, roll180=False):
    x0, y0, x1, y1 = target.texture_extent_m()
    T = frames.T_from_rvec_tvec(np.asarray(rvec, float), np.array([0.0, 0.0, dist])) @ frames.make_T(
        t=[-(x0 + x1) / 2, -(y0 + y1) / 2, 0.0])
    if roll180:
        T = frames.make_T(np.diag([-1.0, -1.0, 1.0]), np.zeros(3)) @ T
    return T


POSES = [(0.65, (0.0, 0.0, 0.1), False), (0.7, (0.5, -0.3, 0.2), False), (0.6, (-0.2, 0.55, -0.3), False),
         (0.7, (0.3, 0.2, 0.1), True)]


@pytest.mark.parametrize("target, tol_mm, tol_deg", [(CHESS, 0.6, 0.1), (CIRCLES, 0.6, 0.1), (MODCIRC, 0.6, 0.1)],
                         ids=["chess", "circles", "modified_circles"])
def test_render_detect_pose(target, tol_mm, tol_deg):
    """Polygon renderer + default sensor effects -> detect -> measure_pose: ids tied to the physical board
    (also with the camera rolled 180 degrees) and pose error within tol (about 4x the RMS measured by
    benchmarks/bench_detect.py at this geometry)."""
    r = TargetRenderer(target, INTR, backend="polygon")
    ids, P = target.corner_points()
    for dist, rvec, roll in POSES:
        T = _pose(target, dist, rvec, roll)
        img = apply_effects(r.render(T), SensorEffects(), 1, 7, INTR)[0]
        d = detect(img, target, INTR)
        assert d.valid, d.reason
        assert np.array_equal(d.ids, ids)
        truth = INTR.project(frames.transform_points(T, P))
        assert np.sqrt(np.mean((d.uv_px - truth) ** 2)) < 0.1  # a wrong id map is off by a square
        m = measure_pose([d], target, INTR)
        e = frames.pose_error(T, m.T_cam_target)
        assert np.all(np.abs(e[:3]) < tol_mm * 1e-3) and np.all(np.abs(np.degrees(e[3:])) < tol_deg), e


def test_ellipse_centre_correction_removes_perspective_bias():
    """At a 40-degree tilt the dot centres without the correction are biased by the perspective offset
    of the ellipse centre; with intrinsics given the error vs the projected centres drops."""
    target = circles(rows=9, cols=5, spacing_m=0.02, diameter_m=0.016)
    T = _pose(target, 0.45, (0.7, 0.0, 0.0))
    img = np.clip(TargetRenderer(target, INTR, backend="polygon").render(T), 0, 255).astype(np.uint8)
    truth = INTR.project(frames.transform_points(T, target.corner_points()[1]))
    raw, corr = detect(img, target), detect(img, target, INTR)
    e_raw = np.sqrt(np.mean((raw.uv_px - truth) ** 2))
    e_corr = np.sqrt(np.mean((corr.uv_px - truth) ** 2))
    assert e_corr < 0.6 * e_raw, (e_raw, e_corr)


def test_symmetric_boards_refused_for_poses():
    with pytest.raises(ConfigError, match=r"180-degree.*rows \+ cols odd"):
        chess(rows=6, cols=8)
    with pytest.raises(ConfigError, match=r"180-degree.*odd number of rows"):
        circles(rows=6)
    s = chess(rows=6, cols=8, allow_symmetric=True)  # intrinsics only: detection works, poses refused
    T = _pose(s, 0.5, (0.2, 0.1, 0.0))
    img = np.clip(TargetRenderer(s, INTR, backend="polygon").render(T), 0, 255).astype(np.uint8)
    d = detect(img, s, INTR)
    assert d.valid and d.n_corners == 35
    with pytest.raises(ConfigError, match="intrinsics calibration only"):
        measure_pose([d], s, INTR)


@pytest.mark.parametrize("d, key", [
    (dict(kind="chessboard", rows=5, cols=8), "square_m"),
    (dict(kind="chessboard", rows=5, cols=8, square_m=-0.02), "square_m"),
    (dict(kind="chessboard", rows=1, cols=8, square_m=0.02), "rows"),
    (dict(kind="chessboard", rows=5, cols=8, square_m=0.02, marker_m=0.01), "marker_m"),
    (dict(kind="circles_asymmetric", rows=7, cols=4, spacing_m=0.02), "diameter_m"),
    (dict(kind="circles_asymmetric", rows=7, cols=4, diameter_m=0.01), "spacing_m"),
    (dict(kind="circles_asymmetric", rows=7, cols=4, spacing_m=0.02, diameter_m=0.03), "diameter_m"),
    (dict(kind="circles_asymmetric", rows=7, cols=4, spacing_m=0.02, diameter_m=-0.01), "diameter_m"),
    (dict(kind="circles_asymmetric", rows=7, cols=4, spacing_m=0.02, diameter_m=0.01, allow_symmetric="y"),
     "allow_symmetric"),
    (dict(kind="hexagons", rows=7, cols=4), "kind"),
    (dict(kind="modified_circle_grid", rows=5, cols=7, diameter_m=0.01), "spacing_m"),
    (dict(kind="modified_circle_grid", rows=1, cols=7, spacing_m=0.03), "rows"),
    (dict(kind="modified_circle_grid", rows=5, cols=7, spacing_m=0.03, diameter_m=0.012, origin_diameter_m=0.05),
     "origin_diameter_m"),
    (dict(kind="modified_circle_grid", rows=5, cols=7, spacing_m=0.03, diameter_m=0.012, origin_diameter_m=0.01),
     "origin_diameter_m"),
    (dict(kind="modified_circle_grid", rows=5, cols=7, spacing_m=0.03, diameter_m=-0.01), "diameter_m"),
])
def test_bad_values_name_file_and_key(tmp_path, d, key):
    import yaml

    f = tmp_path / "bad.yaml"
    f.write_text(yaml.safe_dump(d))
    with pytest.raises(ConfigError) as ei:
        load_target(f)
    assert str(f) in str(ei.value) and key in str(ei.value)


@pytest.mark.parametrize("target", [CHESS, CIRCLES, MODCIRC], ids=["chess", "circles", "modified_circles"])
def test_printable_export_detects_at_geometry(tmp_path, target):
    """The exported PNG, detected as an image, gives corners at corner_points() (pixel -> metres by the
    file's pHYs resolution)."""
    from vision_calib.targets import read_png_phys

    out = export_printable(target, tmp_path / "board.png", dpi=150)
    img = cv2.imread(str(out), cv2.IMREAD_GRAYSCALE)
    _, _, ppm, _ = read_png_phys(out)
    img = cv2.GaussianBlur(img, (0, 0), 0.7)
    d = detect(img, target)
    assert d.valid, d.reason
    x0, y0, _, _ = target.texture_extent_m()
    xy = np.column_stack([x0 + (d.uv_px[:, 0] + 0.5) / ppm, y0 + (d.uv_px[:, 1] + 0.5) / ppm])
    np.testing.assert_allclose(xy, target.corner_points()[1][d.ids, :2], atol=0.5 / ppm)  # 0.5 px; a wrong id is off by a square


def test_image_bound_for_new_kinds():
    """The image-model bound runs through the kind's info model: positive definite, and a dot of twice the
    diameter (twice the edge length) halves the variance of a circle grid's orientation (all else equal)."""
    from vision_calib.measure.covariance import image_bound_pose_cov

    T = _pose(CIRCLES, 0.7, (0.2, 0.1, 0.0))
    for t in (CHESS, CIRCLES):
        C = image_bound_pose_cov(t, INTR, _pose(t, 0.7, (0.2, 0.1, 0.0)), SensorEffects())
        assert np.all(np.linalg.eigvalsh(C) > 0)
    small = circles(rows=9, cols=6, spacing_m=0.018, diameter_m=0.005)
    big = circles(rows=9, cols=6, spacing_m=0.018, diameter_m=0.010)
    # same centres up to the radius offset of the frame: compare at poses of the same dot centres
    Tb = T @ frames.make_T(t=[-0.0025, -0.0025, 0.0])
    Cs = image_bound_pose_cov(small, INTR, T, SensorEffects())
    Cb = image_bound_pose_cov(big, INTR, Tb, SensorEffects())
    # the rotation block does not depend on the frame origin (the translation block moves with the lever arm)
    np.testing.assert_allclose(Cb[3:, 3:] / Cs[3:, 3:], 0.5, rtol=1e-6)


def _rolled(T, deg):
    a = math.radians(deg)
    Rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    return frames.make_T(Rz, np.zeros(3)) @ T


def test_modified_circle_grid_ids_at_every_roll():
    """ROS-I's square 10 x 10 grid (25.4 mm, 10 mm dots; its 4 rotations look alike but for the origin dot) and
    the A4 5 x 7 one (found with rows and cols swapped when the camera is rolled 90 degrees): ids tied to the
    board at 0/90/180/270 degrees of roll, corners within 0.1 px of the projected centres."""
    square = TargetSpec(kind="modified_circle_grid", name="rosi_10x10", rows=10, cols=10, spacing_m=0.0254,
                        diameter_m=0.01)
    for target in (square, MODCIRC):
        r = TargetRenderer(target, INTR, backend="polygon")
        ids, P = target.corner_points()
        for k, (dist, rvec, _) in enumerate(POSES[:3]):
            for deg in (0, 90, 180, 270):
                T = _rolled(_pose(target, dist + 0.1 * (target is square), rvec), deg)
                img = apply_effects(r.render(T), SensorEffects(), 1, 11 * k + deg, INTR)[0]
                d = detect(img, target, INTR)
                assert d.valid, (target.name, deg, d.reason)
                assert np.array_equal(d.ids, ids)
                err = d.uv_px - INTR.project(frames.transform_points(T, P))
                assert np.sqrt(np.mean(err ** 2)) < 0.1, (target.name, deg)
                assert d.diagnostics["origin_dot_ratio"] > 3  # ROS-I's origin dot: 4x the area


def test_modified_circle_grid_without_diameters_and_without_a_large_dot():
    """A ROS-I target file gives no dot diameter: detection needs none (no ellipse-centre correction; points
    at (c s, r s)); a board whose origin dot is barely larger than the others is refused, not misread."""
    bare = TargetSpec(kind="modified_circle_grid", name="rosi", rows=5, cols=7, spacing_m=0.03)
    T = _pose(MODCIRC, 0.65, (0.3, -0.2, 0.1))
    img = apply_effects(TargetRenderer(MODCIRC, INTR, backend="polygon").render(T), SensorEffects(), 1, 3, INTR)[0]
    d = detect(img, bare, INTR)
    assert d.valid and d.diagnostics["ellipse_correction"] is False
    shift = frames.make_T(t=[MODCIRC.diameter_m, MODCIRC.diameter_m / 2, 0.0])  # D / 2, d / 2: the frames' offset
    e = frames.pose_error(T @ shift, measure_pose([d], bare, INTR).T_cam_target)
    assert np.all(np.abs(e[:3]) < 0.6e-3) and np.all(np.abs(np.degrees(e[3:])) < 0.1), e
    with pytest.raises(ConfigError, match="diameter_m' is needed to draw"):
        bare.black_polygons()
    weak = TargetSpec(kind="modified_circle_grid", name="weak", rows=5, cols=7, spacing_m=0.03, diameter_m=0.012,
                      origin_diameter_m=0.0132)
    img = apply_effects(TargetRenderer(weak, INTR, backend="polygon").render(T), SensorEffects(), 1, 3, INTR)[0]
    d = detect(img, weak, INTR)
    assert not d.valid and "origin (large) dot" in d.reason
