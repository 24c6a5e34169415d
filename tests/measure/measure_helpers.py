"""Helpers for measure tests: a fast homography "renderer" of a planar target (no OpenGL)."""

import cv2
import numpy as np

from vision_calib import frames
from vision_calib.camera import CameraIntrinsics


def warp_view(target, intr: CameraIntrinsics, T_cam_target, background=128.0, supersample=3):
    """Ideal pinhole image (H, W) float32 [0, 255] of the target texture seen from T_cam_target,
    by a homography warp at ``supersample`` x resolution then area averaging (pixel centres at
    integer coordinates, OpenCV convention)."""
    s = supersample
    x_min, y_min, x_max, y_max = target.texture_extent_m()
    px_per_m = 4 * s * intr.fx / T_cam_target[2, 3]
    tex = target.texture(px_per_m).astype(np.float32)
    H_t, W_t = tex.shape
    sx, sy = W_t / (x_max - x_min), H_t / (y_max - y_min)
    A = np.array([[1 / sx, 0, x_min + 0.5 / sx], [0, 1 / sy, y_min + 0.5 / sy], [0, 0, 1]])
    Ks = np.diag([s, s, 1.0]) @ np.array([[1, 0, 0.5], [0, 1, 0.5], [0, 0, 1]]) @ intr.K
    Ks[:2, 2] -= 0.5  # big-pixel centre c -> small-pixel coords s*(c+0.5)-0.5
    Rt = np.column_stack([T_cam_target[:3, 0], T_cam_target[:3, 1], T_cam_target[:3, 3]])
    H = Ks @ Rt @ A
    big = cv2.warpPerspective(tex, H, (intr.width * s, intr.height * s), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=float(background))
    return big.reshape(intr.height, s, intr.width, s).mean(axis=(1, 3)).astype(np.float32)


def random_pose(rng, target, dist_range=(0.45, 0.7), tilt_deg=30.0):
    """T_cam_target looking at the target centre from a random direction within tilt_deg."""
    w, h = target.pattern_size_m()
    centre = np.array([w / 2, h / 2, 0.0])
    rv = rng.normal(size=3)
    rv = rv / np.linalg.norm(rv) * np.radians(rng.uniform(0, tilt_deg))
    R = frames.T_from_xyz_rotvec(np.r_[0, 0, 0, rv])[:3, :3]
    d = rng.uniform(*dist_range)
    off = rng.uniform(-0.03, 0.03, size=2)
    t = np.array([off[0], off[1], d]) - R @ centre
    return frames.make_T(R, t)
