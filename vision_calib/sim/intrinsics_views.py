"""Simulated calibration views for checking :mod:`.intrinsics` against truth (tests, benchmarks):
poses that spread the target over the image at varied tilts, rendered by the CPU coverage renderer
(``render.TargetRenderer``, backend "polygon") with sensor effects (distortion, blur, noise)."""

from __future__ import annotations

import numpy as np

from .. import frames
from ..camera import CameraIntrinsics


def calibration_poses(target, intr: CameraIntrinsics, n: int, seed: int, tilt_deg=(20.0, 45.0),
                      dist_range=(0.4, 0.65), min_visible: float = 0.6, max_tries: int = 200) -> np.ndarray:
    """(n, 4, 4) T_cam_target [m, OpenCV camera frame]: the board centre aimed at image points cycling over
    a 3 x 3 grid (fractions 0.15 / 0.5 / 0.85 of width and height, jittered), at distance U(dist_range),
    tilted by U(tilt_deg) [deg] about a random in-plane axis plus a random roll; at least ``min_visible``
    of the corners inside the image (distorted projection)."""
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = target.texture_extent_m()
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    _, p = target.corner_points()
    spots = [(a, b) for b in (0.15, 0.5, 0.85) for a in (0.15, 0.5, 0.85)]
    out = []
    for k in range(n):
        for _ in range(max_tries):
            a, b = spots[(k + rng.integers(0, 2) * 4) % 9]
            u = (a + rng.uniform(-0.08, 0.08)) * intr.width
            v = (b + rng.uniform(-0.08, 0.08)) * intr.height
            ray = np.array([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, 1.0])
            phi = rng.uniform(0, 2 * np.pi)
            tilt = frames.T_from_xyz_rotvec(np.r_[0, 0, 0, np.radians(rng.uniform(*tilt_deg))
                                                  * np.array([np.cos(phi), np.sin(phi), 0.0])])[:3, :3]
            roll = frames.T_from_xyz_rotvec(np.r_[0, 0, 0, 0, 0, np.radians(rng.uniform(-30, 30))])[:3, :3]
            R = tilt @ roll
            T = frames.make_T(R, rng.uniform(*dist_range) * ray - R @ centre)
            pc = p @ T[:3, :3].T + T[:3, 3]
            if np.any(pc[:, 2] <= 0.05):
                continue
            uv = intr.project(pc)
            inside = (uv[:, 0] > 3) & (uv[:, 0] < intr.width - 4) & (uv[:, 1] > 3) & (uv[:, 1] < intr.height - 4)
            if inside.mean() >= min_visible:
                out.append(T)
                break
        else:
            raise RuntimeError("calibration_poses: no pose with the target in view; widen dist_range")
    return np.array(out)


def render_views(target, intr: CameraIntrinsics, T_cam_targets, seed: int, effects=None,
                 exact_distortion: bool = True) -> list[np.ndarray]:
    """One uint8 (H, W) image per pose, noise seeded by (seed, view index). effects: ``SensorEffects()``
    defaults unless given (blur 0.6 px, photon + read noise). exact_distortion (default): the distortion
    of ``intr`` drawn geometrically (``TargetRenderer(distort=True)``, exact pixel areas), then blur and noise;
    False: ideal pinhole render (CPU polygon backend) resampled by the sensor stage (bilinear, see
    README "Camera calibration" for the corner bias this adds)."""
    from ..render import TargetRenderer
    from ..sensor import SensorEffects, apply_effects, effects_for_render

    effects = effects or SensorEffects()
    r = TargetRenderer(target, intr, backend="polygon", distort=exact_distortion and effects.apply_distortion)
    images = []
    for i, T in enumerate(T_cam_targets):
        ideal = r.render(T)
        s = int(np.random.default_rng([seed, 7, i]).integers(2**31 - 1))
        images.append(apply_effects(ideal, effects_for_render(r, effects), 1, s, intr)[0])
    return images
