"""Renderer: geometry (OpenCV intrinsics incl. off-centre principal point and fx != fy), pixel-centre
convention, grey levels, faces, occluders. Uses the ideal image: no distortion, no noise."""

from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh

from vision_calib.camera import CameraIntrinsics
from vision_calib.errors import ConfigError, DataError
from vision_calib.frames import T_from_rvec_tvec, make_T
from vision_calib.render import TargetRenderer, look_at_target
from vision_calib.targets import TargetSpec, load_target

ROOT = Path(__file__).resolve().parents[2]
A5 = load_target(ROOT / "targets" / "charuco_a5.yaml")
# small odd-sized camera with fx != fy and an off-centre principal point (fast tests)
K_SMALL = CameraIntrinsics(401, 301, 520.0, 470.0, 230.3, 121.7)
CRIT = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-5)


def project(spec, K, T):
    ids, P = spec.corner_points()
    uv, _ = cv2.projectPoints(P, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], K.K, None)
    return ids, uv.reshape(-1, 2)


@pytest.fixture(scope="module", params=["polygon", "warp", "pyrender"])
def small4(request):
    with TargetRenderer(A5, K_SMALL, supersample=4, background=100, backend=request.param) as r:
        yield r


def pose_edge_at(K, u0, v0, z):
    """Fronto-parallel, upright pose putting target point (0, 0) (outer corner of the first black
    square, white margin on its left and above) at pixel (u0, v0), at depth z [m]."""
    return make_T(t=[(u0 - K.cx) * z / K.fx, (v0 - K.cy) * z / K.fy, z])


@pytest.mark.parametrize("frac", [0.0, 0.25, 0.5, 0.75])
def test_pixel_centre_convention(small4, frac):
    """OpenCV convention: pixel u covers [u - 0.5, u + 0.5]. A black/white edge projected at
    u0 = 80 + frac covers the fraction (u0 - (80 - 0.5)) of pixel 80 with white, etc. A half-pixel
    error in the intrinsics mapping would change these values by ~128."""
    K, z = K_SMALL, 0.5
    u0, v0 = 80.0 + frac, 60.0 + frac
    img = small4.render(pose_edge_at(K, u0, v0, z))
    row = int(round(v0 + 0.6 * A5.square_m * K.fy / z))  # inside the first square, vertically
    col = int(round(u0 + 0.6 * A5.square_m * K.fx / z))
    for u in (79, 80, 81):
        white = np.clip(u0 - (u - 0.5), 0.0, 1.0)  # texture filtering spreads the edge by ~0.1 px
        assert img[row, u] == pytest.approx(255 * white, abs=12), (u, img[row, 78:83])
    for v in (59, 60, 61):
        white = np.clip(v0 - (v - 0.5), 0.0, 1.0)
        assert img[v, col] == pytest.approx(255 * white, abs=12), (v, img[58:63, col])
    # edge position from the integrated profile (exact for any symmetric blur): white area left of it
    u_edge = 75.5 + img[row, 76:86].sum() / 255.0
    v_edge = 55.5 + img[56:66, col].sum() / 255.0
    assert u_edge == pytest.approx(u0, abs=0.03)
    assert v_edge == pytest.approx(v0, abs=0.03)


def test_grey_levels_and_background(small4):
    K, z = K_SMALL, 0.5
    img = small4.render(pose_edge_at(K, 80.0, 60.0, z))
    c = 0.5 * A5.square_m
    u_black = int(round(80 + c * K.fx / z))  # centre of the first (black) square
    v_black = int(round(60 + c * K.fy / z))
    assert img[v_black - 3:v_black + 4, u_black - 3:u_black + 4].max() <= 0.5
    m = A5.margin_m / 2  # middle of the white margin above the board
    v_white = int(round(60 - m * K.fy / z))
    assert img[v_white, u_black - 3:u_black + 4].min() >= 254.5
    assert np.all(img[:, :60] == 100.0)  # left of the board: background grey
    assert img.dtype == np.float32 and img.shape == (K.height, K.width)
    u8 = small4.render(pose_edge_at(K, 80.0, 60.0, z), dtype=np.uint8)
    assert u8.dtype == np.uint8 and np.abs(u8.astype(float) - img).max() <= 0.5


def test_back_face_is_plain(small4):
    T_front = look_at_target(A5, 0.5)
    T_back = look_at_target(A5, 0.5, rvec_tilt=(np.pi, 0.0, 0.0))  # turned about its centre's x axis
    front = small4.render(T_front)
    back = small4.render(T_back)
    assert front.min() < 5 and front.max() > 250
    board = back != 100.0
    assert abs(board.sum() - (front != 100.0).sum()) < 0.02 * board.sum()  # same silhouette
    inner = cv2.erode(board.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)  # drop AA edges
    assert inner.sum() > 0.8 * board.sum()
    np.testing.assert_allclose(back[inner], 200.0, atol=0.5)  # uniform back grey, no pattern


def test_occluder_hides_the_board():
    box = trimesh.creation.box(extents=[0.03, 0.03, 0.03])
    T_cam_box = make_T(t=[0.0, 0.0, 0.3])  # on the optical axis, in front of the board at 0.5 m
    T = look_at_target(A5, 0.5)
    with TargetRenderer(A5, K_SMALL, supersample=2, occluders=[(box, T_cam_box, 40)]) as r:
        img = r.render(T)
        u, v = K_SMALL.project(np.array([[0.0, 0.0, 0.285]]))[0]
        assert img[int(round(v)) - 2:int(round(v)) + 3, int(round(u)) - 2:int(round(u)) + 3] == pytest.approx(40, abs=1)
        moved = r.render(T, occluder_poses=[make_T(t=[0.0, 0.0, -1.0])])  # behind the camera: not seen
        assert abs(moved[int(round(v)), int(round(u))] - 40) > 10
        with pytest.raises(DataError, match="occluder_poses"):
            r.render(T, occluder_poses=[])
    with TargetRenderer(A5, K_SMALL, supersample=2, backend="pyrender") as plain:  # same image as without any occluder
        np.testing.assert_array_equal(moved, plain.render(T))


def test_render_batch_equals_single(small4):
    Ts = np.stack([look_at_target(A5, 0.45, (0.1 * i, -0.2, 0.05)) for i in range(3)])
    batch = small4.render_batch(Ts)
    assert batch.shape == (3, K_SMALL.height, K_SMALL.width)
    for i in range(3):
        np.testing.assert_array_equal(batch[i], small4.render(Ts[i]))


def test_bad_input(small4):
    T = look_at_target(A5, 0.5)
    T[0, 3] = np.nan
    with pytest.raises(DataError, match="T_cam_target"):
        small4.render(T)
    with pytest.raises(DataError):
        small4.render_batch(np.eye(4))
    with pytest.raises(ConfigError, match="supersample"):
        TargetRenderer(A5, K_SMALL, supersample=0)
    for backend in ("pyrender", "warp", "polygon"):
        with pytest.raises(ConfigError, match="GL_MAX_TEXTURE_SIZE"):
            TargetRenderer(A5, K_SMALL, texture_px_per_m=1e6, backend=backend)
    with pytest.raises(ConfigError, match="backend"):
        TargetRenderer(A5, K_SMALL, backend="vulkan")
    for backend in ("warp", "polygon"):
        with pytest.raises(ConfigError, match="occluders"):
            TargetRenderer(A5, K_SMALL, backend=backend, occluders=[(trimesh.creation.box(), np.eye(4))])


def _random_poses(spec, n, rng, d=(0.3, 0.55)):
    return [look_at_target(spec, rng.uniform(*d), rng.uniform(-0.45, 0.45, 3), rng.uniform(-0.04, 0.04, 2))
            for _ in range(n)]


@pytest.mark.slow
@pytest.mark.parametrize("K", [
    CameraIntrinsics(1024, 768, 1100.0, 1000.0, 480.3, 410.7),  # fx != fy, off-centre principal point
    CameraIntrinsics(1024, 768, 1200.0, 1200.0, 611.5, 330.25),
])
def test_charuco_corners_match_projectpoints(K):
    """Render, detect with OpenCV (CharucoDetector + cornerSubPix) and compare with cv2.projectPoints
    of the known 3-D corners: sub-0.1 px RMS, no mean offset (a half-pixel or flip error would show)."""
    rng = np.random.default_rng(1)
    det = cv2.aruco.CharucoDetector(A5.cv_board())
    d = []
    with TargetRenderer(A5, K, supersample=2) as r:
        for T in _random_poses(A5, 5, rng):
            img = r.render(T)
            cc, ci, _, _ = det.detectBoard(np.round(img).astype(np.uint8))
            assert ci is not None and len(ci) == A5.n_corners
            cc = cv2.cornerSubPix(img, cc.astype(np.float32), (4, 4), (-1, -1), CRIT).reshape(-1, 2)
            ids, uv = project(A5, K, T)
            d.append(cc - uv[ci.ravel()])
    d = np.concatenate(d)
    rms = np.sqrt((d ** 2).sum(axis=1).mean())
    assert rms < 0.1, rms
    assert np.all(np.abs(d.mean(axis=0)) < 0.02)
    assert np.abs(d).max() < 0.3


@pytest.mark.slow
def test_apriltag_corners_match_projectpoints():
    """AprilTag grid: aruco's subpixel marker corners on the render agree with the same detector on an
    independent CPU rendering (homography warp of the texture, 8x supersampled) to < 0.05 px, and with
    cv2.projectPoints up to the detector's own inward bias on L-shaped corners (~0.2 px, zero mean)."""
    from vision_calib.sim.render_bench import reference_image

    spec = load_target(ROOT / "targets" / "apriltag_grid.yaml")
    K = CameraIntrinsics(1024, 768, 1100.0, 1000.0, 520.8, 361.2)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det = cv2.aruco.ArucoDetector(spec.cv_dictionary(), params)

    def detect(img):
        corners, mids, _ = det.detectMarkers(np.round(img).astype(np.uint8))
        assert mids is not None and len(mids) == spec.rows * spec.cols
        return {4 * m + k: c.reshape(4, 2)[k] for c, m in zip(corners, mids.ravel()) for k in range(4)}

    rng = np.random.default_rng(2)
    d_ref, d_proj = [], []
    with TargetRenderer(spec, K, supersample=2) as r:
        for T in _random_poses(spec, 2, rng, d=(0.4, 0.6)):
            got = detect(r.render(T))
            ref = detect(reference_image(spec, K, T, px_per_m=4096 / max(spec.outline_m())))
            ids, uv = project(spec, K, T)
            d_ref += [got[i] - ref[i] for i in ids]
            d_proj += [got[i] - p for i, p in zip(ids, uv)]
    d_ref, d_proj = np.array(d_ref), np.array(d_proj)
    assert np.sqrt((d_ref ** 2).sum(axis=1).mean()) < 0.05
    assert np.sqrt((d_proj ** 2).sum(axis=1).mean()) < 0.35
    assert np.all(np.abs(d_proj.mean(axis=0)) < 0.02)


@pytest.mark.slow
def test_solvepnp_recovers_pose_with_identity_convention():
    """Target frame = OpenCV board frame: solvePnP on detected ids + corner_points() gives back T."""
    K = CameraIntrinsics(1024, 768, 1150.0, 1130.0, 500.0, 400.0)
    spec = load_target(ROOT / "targets" / "charuco_h4.yaml")
    T = T_from_rvec_tvec(np.array([0.25, -0.15, 0.4]), np.array([0.02, -0.01, 0.7]))
    with TargetRenderer(spec, K, supersample=2) as r:
        img = np.round(r.render(T)).astype(np.uint8)
    cc, ci, _, _ = cv2.aruco.CharucoDetector(spec.cv_board()).detectBoard(img)
    assert ci is not None and len(ci) == spec.n_corners
    cc = cv2.cornerSubPix(img, cc.astype(np.float32), (3, 3), (-1, -1), CRIT)
    _, P = spec.corner_points()
    ok, rvec, tvec = cv2.solvePnP(P[ci.ravel()], cc, K.K, None, flags=cv2.SOLVEPNP_ITERATIVE)
    assert ok
    np.testing.assert_allclose(tvec.ravel(), T[:3, 3], atol=5e-4)
    np.testing.assert_allclose(cv2.Rodrigues(rvec)[0], T[:3, :3], atol=2e-3)


@pytest.mark.slow
def test_supersample_factors_agree():
    K = CameraIntrinsics(640, 480, 700.0, 690.0, 300.0, 250.0)
    T = look_at_target(A5, 0.45, (0.3, -0.2, 0.1))
    imgs = []
    for s in (2, 3):
        with TargetRenderer(A5, K, supersample=s, backend="pyrender") as r:
            imgs.append(r.render(T))
    assert np.mean(np.abs(imgs[0] - imgs[1])) < 1.0


def test_closing_one_renderer_keeps_others_alive():
    """pyrender's delete() terminates the shared EGL display; TargetRenderer.close() must not."""
    T = look_at_target(A5, 0.5)
    a = TargetRenderer(A5, K_SMALL, supersample=1, backend="pyrender")
    b = TargetRenderer(A5, K_SMALL, supersample=1, backend="pyrender")
    img_a = a.render(T)
    a.close()
    a.close()  # idempotent
    np.testing.assert_array_equal(b.render(T), img_a)
    b.close()
    with TargetRenderer(A5, K_SMALL, supersample=1, backend="pyrender") as c:  # a fresh one after all were closed
        np.testing.assert_array_equal(c.render(T), img_a)


# H4 board (seed 000): its texture, 4096 x 2821 texels, is not a power of two. Mesa llvmpipe's anisotropic
# sampler mis-addresses such textures (see renderer._pad_for_mipmaps): before the power-of-two padding the
# rendered pattern had a v scale error (edges up to 0.09 px off at supersample 2, pose bias 0.1 deg).
H4_LIKE = TargetSpec(kind="charuco", name="h4_like", rows=6, cols=9, dictionary="DICT_4X4_50", square_m=0.025,
                     marker_m=0.019, margin_m=0.008)
K_H4 = CameraIntrinsics(1024, 768, 1013.0, 1013.0, 511.5, 383.5)


def border_edge_offsets(img, K, T, spec):
    """Measured - projected position [px] of the outer edges of the black squares on the pattern border
    (top/bottom edges: dv, left/right edges: du), from integrated grey profiles across each edge, exact
    for any symmetric blur. Fronto-parallel, upright T only (edges along image rows/columns).
    Returns (dv (n,), du (m,))."""
    sq, R, C = spec.square_m, spec.rows, spec.cols
    z = T[2, 3]
    half = min(8, int(min(spec.margin_m, sq / 2) * min(K.fx, K.fy) / z) - 2)  # profile stays in margin / square
    assert half >= 3, "board too small in the image for the profile method"

    def uv(x, y):
        return K.fx * (x + T[0, 3]) / z + K.cx, K.fy * (y + T[1, 3]) / z + K.cy

    dv, du = [], []
    for r in range(R):
        for c in range(C):
            if (r + c) % 2:  # square (0, 0) is black
                continue
            for f in (0.3, 0.5, 0.7):
                for y, white_first in ((0.0, True), (R * sq, False)):
                    if (y == 0.0 and r == 0) or (y > 0 and r == R - 1):
                        u, v = uv((c + f) * sq, y)
                        v0 = int(np.floor(v))
                        white = img[v0 - half:v0 + half + 1, int(round(u))].sum() / 255.0
                        dv.append((v0 - half - 0.5 + white if white_first else v0 + half + 0.5 - white) - v)
                for x, white_first in ((0.0, True), (C * sq, False)):
                    if (x == 0.0 and c == 0) or (x > 0 and c == C - 1):
                        u, v = uv(x, (r + f) * sq)
                        u0 = int(np.floor(u))
                        white = img[int(round(v)), u0 - half:u0 + half + 1].sum() / 255.0
                        du.append((u0 - half - 0.5 + white if white_first else u0 + half + 0.5 - white) - u)
    return np.array(dv), np.array(du)


@pytest.mark.parametrize("backend", ["pyrender", "warp", "polygon"])
def test_pattern_edges_unbiased_on_non_power_of_two_texture(backend):
    """Edges of the H4 pattern at 0.45 / 0.68 / 1.0 m (different mip levels), supersample 2: no mean offset
    and < 0.025 px everywhere for pyrender (before the fix: mean dv +0.04 px, max 0.09 px at 0.68 m); the
    mip-mapped warp: < 0.05 px; the polygon backend (exact pixel areas): < 1e-4 px (float32 rounding)."""
    H, W = H4_LIKE.texture_shape(4096 / max(H4_LIKE.outline_m()))
    assert H & (H - 1) != 0  # the case that was biased
    with TargetRenderer(H4_LIKE, K_H4, supersample=2, backend=backend) as r:
        assert r.texture_shape == (H, W)
        for z in (0.45, 0.68, 1.0):
            T = make_T(t=[-0.105, -0.083, z])  # board near the image centre, corners at arbitrary sub-pixel phases
            dv, du = border_edge_offsets(r.render(T), K_H4, T, H4_LIKE)
            assert len(dv) >= 24 and len(du) >= 12
            # measured max: pyrender < 0.025, warp 0.048, polygon 2e-5 (the float32 image's rounding)
            mean_tol, max_tol = {"pyrender": (0.01, 0.025), "warp": (0.02, 0.05), "polygon": (1e-4, 1e-4)}[backend]
            for d in (dv, du):
                assert abs(d.mean()) < mean_tol, (z, dv.mean(), du.mean())
                assert np.abs(d).max() < max_tol, (z, np.abs(dv).max(), np.abs(du).max())


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["pyrender", "polygon"])
def test_charuco_corners_unbiased_on_non_power_of_two_texture(backend):
    """H4 board at 0.6-0.76 m, supersample 2, 5 poses (one fronto-parallel): cornerSubPix corners of the
    render agree with cv2.projectPoints with no mean offset (< 0.01 px; the detector's own bias is
    ~0.005 px mean here), and with the same detector on a CPU reference (homography warp of the texture,
    8x supersampled) to 0.03 px RMS (pyrender before the fix: mean dv +0.03 px, RMS 0.07-0.11 px; the
    polygon backend: < 0.01 px RMS, measured 0.005 px, the reference's own sampling error)."""
    from vision_calib.sim.render_bench import reference_image, subpix_at

    rng = np.random.default_rng(3)
    poses = [look_at_target(H4_LIKE, 0.68)] + [
        look_at_target(H4_LIKE, rng.uniform(0.6, 0.76), rng.uniform(-0.35, 0.35, 3), rng.uniform(-0.03, 0.03, 2))
        for _ in range(4)]
    d_proj, d_ref = [], []
    with TargetRenderer(H4_LIKE, K_H4, supersample=2, backend=backend) as r:
        for T in poses:
            _, uv = project(H4_LIKE, K_H4, T)
            got = subpix_at(r.render(T), uv)
            ref = subpix_at(reference_image(H4_LIKE, K_H4, T, px_per_m=4096 / max(H4_LIKE.outline_m())), uv)
            d_proj.append(got - uv)
            d_ref.append(got - ref)
    d_proj, d_ref = np.concatenate(d_proj), np.concatenate(d_ref)
    assert np.all(np.abs(d_proj.mean(axis=0)) < 0.01), d_proj.mean(axis=0)
    assert np.all(np.abs(d_ref.mean(axis=0)) < 0.005), d_ref.mean(axis=0)
    assert np.sqrt((d_ref ** 2).sum(axis=1).mean()) < (0.03 if backend == "pyrender" else 0.01)
