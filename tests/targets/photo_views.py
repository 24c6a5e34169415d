"""Photograph-like views of a planar target of any kind for detection tests: perspective, uneven lighting, a shadow
across part of the board, defocus, sensor noise and JPEG, on a textured background (no renderer needed: the board's
printable texture, ``TargetSpec.texture``, warped by the homography of a pinhole camera, 3x supersampled).

Boards (:func:`board_for`): a modified circle grid, a chessboard or a ChArUco board sized to the feature size in
px (dot diameter or square side); :func:`degraded_view` draws one view of a degradation kind (:data:`KINDS`)."""

from __future__ import annotations

import math

import cv2
import numpy as np

from vision_calib.targets.spec import TargetSpec

W, H, F = 800, 600, 900.0  # image size [px] and focal length [px]
K = np.array([[F, 0, W / 2], [0, F, H / 2], [0, 0, 1.0]])


def _rot(tilt_deg: float, roll_deg: float, tilt_axis_deg: float) -> np.ndarray:
    """R_cam_target: roll about the optical axis, then a tilt about an in-plane axis at tilt_axis_deg."""
    def rz(a):
        c, s = math.cos(a), math.sin(a)
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    a = math.radians(tilt_axis_deg)
    u = np.array([math.cos(a), math.sin(a), 0.0])
    R_tilt, _ = cv2.Rodrigues(u * math.radians(tilt_deg))
    return R_tilt @ rz(math.radians(roll_deg))


def feature_m(spec) -> float:
    """The size [m] that :func:`photo_view`'s feature_px refers to: the dot diameter (circle grids), else the
    square side (chessboard, ChArUco)."""
    return float(spec.diameter_m if hasattr(spec, "diameter_m") else spec.square_m)


def photo_view(spec, rng, feature_px: float, tilt_deg: float = 0.0, roll_deg: float = 0.0, light: float = 0.0,
               shadow: float = 0.0, blur_px: float = 0.0, jpeg: int = 0, noise: float = 2.0, ss: int = 3,
               shift: float = 0.1):
    """(uint8 (H, W) image, true corners / dot centres (K, 2) px in the order of spec.corner_points(), whole board
    inside the image) for a view where a feature (:func:`feature_m`: dot diameter or square side) appears
    feature_px across (at the board centre, frontal). light: relative brightness
    change across the image (linear ramp, 0..0.8); shadow: darkening of a half-plane across the board (0..0.7);
    blur_px: Gaussian defocus sigma; jpeg: JPEG quality (0: none); noise: grey-level std; shift: largest offset of
    the board centre from the image centre, as a fraction of the image size (a board that nearly fills the image
    needs a small one to be whole in view)."""
    z = F * feature_m(spec) / feature_px
    R = _rot(tilt_deg, roll_deg, rng.uniform(0, 180))
    x0, y0, x1, y1 = spec.texture_extent_m()
    c = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    t = np.array([rng.uniform(-shift, shift) * W / F * z, rng.uniform(-shift, shift) * H / F * z, z]) - R @ c
    Hm = K @ np.column_stack([R[:, 0], R[:, 1], t])  # target (x, y, 1) [m] -> image px
    # texture at ~2 texture px per image px at the nearest point
    ppm = 2.0 * ss * F / max(z - 0.5 * max(x1 - x0, y1 - y0), 0.2 * z)
    ppm = min(ppm, 4000.0 / max(x1 - x0, y1 - y0))
    tex = spec.texture(ppm).astype(np.float32)
    th, tw = tex.shape
    A = np.array([[(x1 - x0) / tw, 0, x0 + 0.5 * (x1 - x0) / tw - 0.0], [0, (y1 - y0) / th, y0 + 0.5 * (y1 - y0) / th],
                  [0, 0, 1.0]])  # texture px (pixel-centre convention) -> target m
    Sss = np.array([[ss, 0, (ss - 1) / 2], [0, ss, (ss - 1) / 2], [0, 0, 1.0]])  # image px -> supersampled px
    M = Sss @ Hm @ A
    # background: carpet-like texture (blobs of a few px) of mid-dark grey
    bg = rng.normal(70, 12, size=(H // 3 + 1, W // 3 + 1)).astype(np.float32)
    bg = cv2.resize(bg, (W * ss, H * ss), interpolation=cv2.INTER_CUBIC)
    mask = cv2.warpPerspective(np.ones_like(tex), M, (W * ss, H * ss), flags=cv2.INTER_LINEAR)
    board = cv2.warpPerspective(tex * 0.85 + 20, M, (W * ss, H * ss), flags=cv2.INTER_LINEAR)
    img = board * mask + bg * (1 - mask)
    img = cv2.resize(img, (W, H), interpolation=cv2.INTER_AREA)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    if light > 0:  # brightness ramp across the image in a random direction
        a = rng.uniform(0, 2 * math.pi)
        ramp = ((xx - W / 2) * math.cos(a) + (yy - H / 2) * math.sin(a)) / (0.5 * math.hypot(W, H))
        img = img * (1 + light * ramp) / (1 + light)
    _, p = spec.corner_points()
    q = np.column_stack([p[:, :2], np.ones(len(p))]) @ (Hm.T)
    uv = q[:, :2] / q[:, 2:]
    if shadow > 0:  # a soft-edged shadow over a half-plane through the board
        a = rng.uniform(0, 2 * math.pi)
        m = uv.mean(axis=0) + rng.uniform(-0.3, 0.3) * (uv.max(axis=0) - uv.min(axis=0))
        d = (xx - m[0]) * math.cos(a) + (yy - m[1]) * math.sin(a)
        img = img * (1 - shadow / (1 + np.exp(-d / 3.0)))
    if blur_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_px)
    img = img + rng.normal(0, noise, img.shape)
    img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if jpeg:
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg)])
        img = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
    corners = np.array([[x0, y0, 1], [x1, y0, 1], [x1, y1, 1], [x0, y1, 1.0]]) @ Hm.T
    cu = corners[:, :2] / corners[:, 2:]
    whole = bool(np.all(corners[:, 2] > 0) and np.all(cu >= 1) and np.all(cu[:, 0] <= W - 2) and np.all(cu[:, 1] <= H - 2))
    return img, uv, whole


def grid_for(dot_px: float) -> TargetSpec:
    """A modified circle grid (d = 0.4 spacing) whose frontal view spans <= ~60 % of the image width."""
    n = int(np.clip(0.6 * W / (dot_px / 0.4), 3, 10))
    return TargetSpec(kind="modified_circle_grid", name="m", rows=max(n - 1, 3), cols=n, spacing_m=0.025,
                      diameter_m=0.01, margin_m=0.015)


#: target kinds :func:`board_for` draws
TARGETS = ("modified_circle_grid", "chessboard", "charuco")


def board_for(target: str, feature_px: float) -> TargetSpec:
    """A board of a target kind (:data:`TARGETS`) whose frontal view at feature_px per dot / square spans <= ~60 %
    of the image width: the circle grid of :func:`grid_for`; a chessboard of n x (n - 1) squares of 20 mm
    (n <= 11, rows + cols odd: not symmetric); a ChArUco board of n x (n - 1) squares of 20 mm (n <= 10),
    DICT_4X4_50 markers of 15 mm; margins of half a square."""
    if target == "modified_circle_grid":
        return grid_for(feature_px)
    if target == "chessboard":
        n = int(np.clip(0.6 * W / feature_px, 3, 11))
        return TargetSpec(kind="chessboard", name="c", rows=n - 1, cols=n, square_m=0.02, margin_m=0.01)
    if target == "charuco":
        n = int(np.clip(0.6 * W / feature_px, 3, 10))
        return TargetSpec(kind="charuco", name="a", rows=n - 1, cols=n, square_m=0.02, marker_m=0.015,
                          dictionary="DICT_4X4_50", margin_m=0.01)
    raise ValueError(f"unknown target {target!r}; known: {', '.join(TARGETS)}")


#: (degradation kinds' size range, 'sizes' range) [px] per target kind: dot diameter or square side. ChArUco: the
#: markers' bits (square / 8 for DICT_4X4 markers of 0.75 square) must stay >= ~2.5 px and >= 2.5 blur sigmas to
#: be decoded (measured, benchmarks/bench_target_photos.py: squares of 32 px decode at sigma 1.5 px, not at 2 px;
#: 40 px at 2 px), so its degradations use squares of 40-80 px and its sizes 20-80 px.
SIZE_RANGES = {"modified_circle_grid": ((12, 40), (5, 60)), "chessboard": ((12, 40), (5, 60)),
               "charuco": ((40, 80), (20, 80))}


def degradation(kind: str, rng, ranges=((12, 40), (5, 60))) -> tuple[float, dict]:
    """(dot diameter px, photo_view keyword arguments) of one view of a degradation kind (:data:`KINDS`), random
    roll; dots log-uniform 12-40 px unless said (ranges: the (degradations, sizes) ranges [px]). lighting: ramp 0.6; defocus: blur sigma 2 px; jpeg: quality 30;
    perspective: tilt 60 deg; shadow: 0.5; sizes: dots 5-60 px, tilt 0-30 deg, ramp 0.2, blur min(0.8, dot / 8);
    mixed: all at once at random strengths, tilt U(0, 60) deg, ramp U(0, 0.6), shadow U(0, 0.5), blur U(0, 2) px,
    JPEG quality U(30, 95)."""
    (lo, hi), (slo, shi) = ranges
    dot = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    roll = dict(roll_deg=rng.uniform(0, 360))
    if kind == "lighting":
        return dot, dict(light=0.6, **roll)
    if kind == "defocus":
        return dot, dict(blur_px=2.0, **roll)
    if kind == "jpeg":
        return dot, dict(jpeg=30, **roll)
    if kind == "perspective":
        return dot, dict(tilt_deg=60.0, **roll)
    if kind == "shadow":
        return dot, dict(shadow=0.5, **roll)
    if kind == "sizes":
        dot = float(np.exp(rng.uniform(np.log(slo), np.log(shi))))
        return dot, dict(tilt_deg=rng.uniform(0, 30), light=0.2, blur_px=min(0.8, dot / 8), **roll)
    if kind == "mixed":
        return dot, dict(tilt_deg=rng.uniform(0, 60), light=rng.uniform(0, 0.6), shadow=rng.uniform(0, 0.5),
                         blur_px=rng.uniform(0, 2.0), jpeg=int(rng.uniform(30, 95)), **roll)
    raise ValueError(f"unknown degradation kind {kind!r}; known: {', '.join(KINDS)}")


KINDS = ("lighting", "defocus", "jpeg", "perspective", "shadow", "sizes", "mixed")


def degraded_view(kind: str, rng, target: str = "modified_circle_grid"):
    """(spec, image, true corners / centres (K, 2) px by id, feature size px, photo_view kwargs) of one view of a
    degradation kind (:func:`degradation`; the dot sizes there are the squares' sides of a chessboard or ChArUco
    board, in the target's :data:`SIZE_RANGES`) of a target kind (:func:`board_for`) where the whole board is inside
    the image."""
    while True:
        dot, kw = degradation(kind, rng, SIZE_RANGES[target])
        spec = board_for(target, dot)
        img, uv, whole = photo_view(spec, rng, dot, **kw)
        if whole:
            return spec, img, uv, dot, kw
