"""Helpers for the kinematics tests (tests only)."""

import numpy as np

from vision_calib.frames import pose_error


def fd(fun, x, eps=1e-6):
    """Central finite differences of fun (x (n,) -> array) -> (..., n)."""
    cols = []
    for k in range(len(x)):
        e = np.zeros(len(x))
        e[k] = eps
        cols.append((fun(x + e) - fun(x - e)) / (2 * eps))
    return np.stack(cols, -1)


def fd_pose_jacobian(ch, q, x, h=1e-6):
    """Central finite differences of ``pose_error(T(x), T(x + dx))`` of a chain's forward model:
    (N, 6, n) for joint sets q (N, n_joints) at parameters x (n,)."""
    J = np.zeros((q.shape[0], 6, len(x)))
    T0 = ch.forward(q, x)
    for k in range(len(x)):
        e = np.zeros(len(x))
        e[k] = h
        J[:, :, k] = (pose_error(T0, ch.forward(q, x + e)) - pose_error(T0, ch.forward(q, x - e))) / (2 * h)
    return J
