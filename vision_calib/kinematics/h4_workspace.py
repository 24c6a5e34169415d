"""H4 workspace poses: the seed's 81-pose grid and random poses in the workspace box.
Poses X (N, 4): nacelle position x, y, z [m] in the base frame and rotation theta [rad] about z."""

from __future__ import annotations

import numpy as np

DEFAULT_CENTER = np.array([0.0, 0.0, -0.65])
DEFAULT_SIZE = np.array([0.2, 0.2, 0.15])
DEFAULT_THETA_DEG = (-20.0, 0.0, 20.0)


def pose_grid_81(center=DEFAULT_CENTER, size=DEFAULT_SIZE, theta_deg=DEFAULT_THETA_DEG) -> np.ndarray:
    """Seed §5 pose set: 3x3x3 positions on a size (3,) m box centred on center (3,) m, times
    the orientations theta_deg (deg) -> X (27*len(theta_deg), 4) [m, m, m, rad]; x fastest,
    theta slowest."""
    c = np.asarray(center, float)
    s = np.asarray(size, float)
    axes = [c[k] + s[k] * np.array([-0.5, 0.0, 0.5]) for k in range(3)]
    rows = [
        (x, y, z, np.deg2rad(t))
        for t in theta_deg
        for z in axes[2]
        for y in axes[1]
        for x in axes[0]
    ]
    return np.array(rows, float)


def random_workspace_poses(n, rng, center=DEFAULT_CENTER, size=DEFAULT_SIZE, theta_max_deg=20.0) -> np.ndarray:
    """n poses (n, 4) drawn uniformly in the box (center (3,), size (3,), m) x [-theta_max, theta_max]."""
    c = np.asarray(center, float)
    s = np.asarray(size, float)
    p = c + (rng.random((n, 3)) - 0.5) * s
    th = np.deg2rad(theta_max_deg) * (2.0 * rng.random(n) - 1.0)
    return np.column_stack([p, th])
