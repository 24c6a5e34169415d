"""SE(3) helpers and frame conventions (pure numpy/scipy).

Conventions (DESIGN.md §3):
- ``T_a_b`` is a (4, 4) float64 homogeneous transform, the pose of frame b expressed in
  frame a; it maps points from b to a: ``p_a = T_a_b @ p_b``. Inner names cancel:
  ``T_base_cam @ T_cam_target == T_base_target``.
- Batches are (..., 4, 4). Rotation vectors are axis*angle in rad, translations in m.
- A *pose error* between two transforms is the 6-vector ``[dt (3, m), dtheta (3, rad)]`` with
  ``dt = t_b - t_a`` and ``dtheta = rotvec(R_b @ R_a.T)`` (small rotation expressed in the
  common parent frame). Kinematic Jacobians of "position + small rotation" use the same
  convention, so ``pose_error(T(x), T(x + dx)) ~= J @ dx``.
- Camera frames are OpenCV (x right, y down, z forward). OpenGL/pyrender cameras (y up,
  z backward) are converted only by :func:`cam_cv_from_gl` / :data:`T_CV_GL`.
- Quaternions appear only at I/O, in scipy's scalar-last order (qx, qy, qz, qw).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from .errors import DataError

#: T_cvcam_glcam: pose of the OpenGL camera frame in the OpenCV camera frame (x same, y and z flipped).
T_CV_GL = np.diag([1.0, -1.0, -1.0, 1.0])


# ----------------------------------------------------------------------------- elementary
def rot_x(a):
    """Rotation matrices about x. a: (...,) rad -> (..., 3, 3)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0] = 1.0
    R[..., 1, 1] = c
    R[..., 1, 2] = -s
    R[..., 2, 1] = s
    R[..., 2, 2] = c
    return R


def rot_y(a):
    """Rotation matrices about y. a: (...,) rad -> (..., 3, 3)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 1, 1] = 1.0
    R[..., 0, 0] = c
    R[..., 0, 2] = s
    R[..., 2, 0] = -s
    R[..., 2, 2] = c
    return R


def rot_z(a):
    """Rotation matrices about z. a: (...,) rad -> (..., 3, 3)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 2, 2] = 1.0
    R[..., 0, 0] = c
    R[..., 0, 1] = -s
    R[..., 1, 0] = s
    R[..., 1, 1] = c
    return R


def make_T(R=None, t=None):
    """Build (..., 4, 4) transforms from rotations (..., 3, 3) and translations (..., 3) [m]."""
    if R is None and t is None:
        return np.eye(4)
    if R is None:
        t = np.asarray(t, dtype=float)
        R = np.broadcast_to(np.eye(3), t.shape[:-1] + (3, 3))
    R = np.asarray(R, dtype=float)
    if t is None:
        t = np.zeros(R.shape[:-2] + (3,))
    t = np.asarray(t, dtype=float)
    shape = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros(shape + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def inv_T(T):
    """Inverse of rigid transforms (..., 4, 4) (uses R.T, not a general inverse)."""
    T = np.asarray(T, dtype=float)
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    Rt = np.swapaxes(R, -1, -2)
    return make_T(Rt, -np.einsum("...ij,...j->...i", Rt, t))


def transform_points(T_a_b, p_b):
    """Map points (N, 3) [m] from frame b to frame a with T_a_b (4, 4) -> (N, 3)."""
    p_b = np.asarray(p_b, dtype=float)
    return p_b @ T_a_b[:3, :3].T + T_a_b[:3, 3]


#: skew(v) = (v @ _SKEW_MAP) reshaped (3, 3): the linear map of a vector to its skew-symmetric matrix
_SKEW_MAP = np.zeros((3, 9))
for _k, _i, _j, _s in ((2, 0, 1, -1.0), (1, 0, 2, 1.0), (2, 1, 0, 1.0), (0, 1, 2, -1.0), (1, 2, 0, -1.0),
                       (0, 2, 1, 1.0)):
    _SKEW_MAP[_k, 3 * _i + _j] = _s


def skew(v):
    """Skew-symmetric matrices (..., 3, 3) of vectors (..., 3): skew(a) @ b == cross(a, b)."""
    v = np.asarray(v, dtype=float)
    return (v @ _SKEW_MAP).reshape(v.shape[:-1] + (3, 3))


# ----------------------------------------------------------------------------- conversions
def T_from_rvec_tvec(rvec, tvec):
    """OpenCV rvec (..., 3) rad and tvec (..., 3) m -> (..., 4, 4)."""
    rvec = np.asarray(rvec, dtype=float)
    tvec = np.asarray(tvec, dtype=float)
    R = Rotation.from_rotvec(rvec.reshape(-1, 3)).as_matrix().reshape(rvec.shape[:-1] + (3, 3))
    return make_T(R, tvec.reshape(rvec.shape))


def rvec_tvec_from_T(T):
    """(4, 4) -> (rvec (3,) rad, tvec (3,) m), OpenCV convention."""
    T = np.asarray(T, dtype=float)
    return Rotation.from_matrix(T[..., :3, :3]).as_rotvec(), T[..., :3, 3].copy()


def T_from_xyz_rpy(xyz, rpy):
    """xyz (..., 3) m and roll-pitch-yaw (..., 3) rad -> (..., 4, 4), R = Rz(yaw) Ry(pitch) Rx(roll)."""
    rpy = np.asarray(rpy, dtype=float)
    R = rot_z(rpy[..., 2]) @ rot_y(rpy[..., 1]) @ rot_x(rpy[..., 0])
    return make_T(R, xyz)


def xyz_rpy_from_T(T):
    """(..., 4, 4) -> (xyz (..., 3) m, rpy (..., 3) rad) with R = Rz(yaw) Ry(pitch) Rx(roll)."""
    T = np.asarray(T, dtype=float)
    ypr = Rotation.from_matrix(T[..., :3, :3]).as_euler("ZYX")
    return T[..., :3, 3].copy(), ypr[..., ::-1].copy()


def T_from_xyz_quat(xyz, quat_xyzw):
    """xyz (..., 3) m, quaternion (..., 4) scalar-last -> (..., 4, 4). I/O only."""
    q = np.asarray(quat_xyzw, dtype=float)
    return make_T(Rotation.from_quat(q).as_matrix(), xyz)


def xyz_quat_from_T(T):
    """(..., 4, 4) -> (xyz (..., 3) m, quaternion (..., 4) scalar-last). I/O only."""
    T = np.asarray(T, dtype=float)
    return T[..., :3, 3].copy(), Rotation.from_matrix(T[..., :3, :3]).as_quat()


def T_from_xyz_rotvec(v6):
    """6-vector(s) (..., 6) = [x, y, z (m), rotation vector (rad)] -> (..., 4, 4)."""
    v6 = np.asarray(v6, dtype=float)
    R = Rotation.from_rotvec(v6[..., 3:].reshape(-1, 3)).as_matrix().reshape(v6.shape[:-1] + (3, 3))
    return make_T(R, v6[..., :3])


def xyz_rotvec_from_T(T):
    """(..., 4, 4) -> (..., 6) = [x, y, z (m), rotation vector (rad)]."""
    T = np.asarray(T, dtype=float)
    rv = rotvec_from_matrix(T[..., :3, :3]).reshape(T.shape[:-2] + (3,))
    return np.concatenate([T[..., :3, 3], rv], axis=-1)


def cam_cv_from_gl(T_world_camgl):
    """Pose of the OpenCV camera frame from the pose of the OpenGL camera frame (..., 4, 4).

    The only place the OpenCV <-> OpenGL camera flip lives; it is its own inverse:
    ``cam_gl_from_cv(T) == cam_cv_from_gl(T)``.
    """
    return np.asarray(T_world_camgl, dtype=float) @ T_CV_GL


def cam_gl_from_cv(T_world_camcv):
    """Pose of the OpenGL (pyrender) camera frame from the OpenCV one (..., 4, 4)."""
    return np.asarray(T_world_camcv, dtype=float) @ T_CV_GL


# ----------------------------------------------------------------------------- errors / perturbation
#: Shepperd's matrix of a rotation: K = (R.reshape(9) @ _SHEPPERD_MAP + _SHEPPERD_ONE).reshape(4, 4), row i =
#: 4 q_i q (x, y, z, w), its diagonal 4 q_i^2 (1 + 2 R_ii - tr for x, y, z; 1 + tr for w)
_SHEPPERD_MAP = np.zeros((9, 16))
_SHEPPERD_ONE = np.eye(4).reshape(16)
for _a, _signs in ((0, (1, -1, -1)), (1, (-1, 1, -1)), (2, (-1, -1, 1)), (3, (1, 1, 1))):
    for _d in range(3):
        _SHEPPERD_MAP[4 * _d, 5 * _a] = _signs[_d]
for _a, _b, _terms in ((0, 1, ((0, 1, 1), (1, 0, 1))), (0, 2, ((0, 2, 1), (2, 0, 1))), (1, 2, ((1, 2, 1), (2, 1, 1))),
                       (0, 3, ((2, 1, 1), (1, 2, -1))), (1, 3, ((0, 2, 1), (2, 0, -1))),
                       (2, 3, ((1, 0, 1), (0, 1, -1)))):
    for _i, _j, _s in _terms:
        _SHEPPERD_MAP[3 * _i + _j, 4 * _a + _b] += _s
        _SHEPPERD_MAP[3 * _i + _j, 4 * _b + _a] += _s


def _quat_xyzw(R: np.ndarray) -> np.ndarray:
    """(k, 4) unit quaternions, scalar last and >= 0, of rotation matrices R (k, 3, 3): Shepperd's stable row (the
    largest diagonal entry of Shepperd's matrix, 1 + tr or 1 + 2 R_ii - tr: one product with a constant map)."""
    K = (R.reshape(-1, 9) @ _SHEPPERD_MAP + _SHEPPERD_ONE).reshape(-1, 4, 4)
    q = K[np.arange(K.shape[0]), np.argmax(np.diagonal(K, axis1=1, axis2=2), axis=1)]  # x, y, z, w (unnormalised)
    q *= (np.where(q[:, 3] < 0, -1.0, 1.0) / np.sqrt(np.einsum("ij,ij->i", q, q)))[:, None]
    return q


def rotvec_from_matrix(R):
    """Rotation vector(s) (..., 3) [rad, angle in [0, pi]] of rotation matrices (..., 3, 3): Shepperd's stable
    quaternion (the row of the largest diagonal entry of Shepperd's matrix, 1 + tr or 1 + 2 R_ii - tr: one
    product with a constant map), normalised (an orthonormal matrix to rounding), then 2 atan2(|v|, w) v / |v|;
    the same as scipy's ``Rotation.from_matrix(R).as_rotvec()`` to ~1e-15 rad, 3x faster on small stacks (no
    object, no determinant check)."""
    R = np.asarray(R, dtype=float)
    shape = R.shape[:-2]
    q = _quat_xyzw(R.reshape(-1, 3, 3))
    v, w = q[:, :3], q[:, 3]
    nv = np.sqrt(np.einsum("ij,ij->i", v, v))
    small = nv < 1e-4  # angle / |v| by its series (2 / w) (1 - |v|^2 / (3 w^2)), exact to rounding there
    ws = np.where(small, w, 1.0)  # w ~ 1 there (w = 0 at a half turn is not small)
    f = np.where(small, 2.0 / ws * (1.0 - nv**2 / (3.0 * ws**2)),
                 2.0 * np.arctan2(nv, w) / np.where(small, 1.0, nv))
    return (v * f[:, None]).reshape(shape + (3,))


def pose_error(T_a, T_b):
    """6-vector(s) (..., 6) from pose T_a to T_b: [t_b - t_a (m), rotvec(R_b R_a^T) (rad)]."""
    T_a = np.asarray(T_a, dtype=float)
    T_b = np.asarray(T_b, dtype=float)
    dR = np.array(T_b[..., :3, :3] @ np.swapaxes(T_a[..., :3, :3], -1, -2))
    shape = dR.shape[:-2]
    rv = rotvec_from_matrix(dR).reshape(shape + (3,))
    return np.concatenate([T_b[..., :3, 3] - T_a[..., :3, 3], rv], axis=-1)


def perturb_pose(T, delta):
    """Apply a 6-vector pose error (..., 6) to T (..., 4, 4): inverse of :func:`pose_error`,
    i.e. ``pose_error(T, perturb_pose(T, d)) == d``."""
    T = np.asarray(T, dtype=float)
    delta = np.asarray(delta, dtype=float)
    shape = np.broadcast_shapes(T.shape[:-2], delta.shape[:-1])
    dR = Rotation.from_rotvec(np.array(np.broadcast_to(delta[..., 3:], shape + (3,))).reshape(-1, 3)).as_matrix()
    dR = dR.reshape(shape + (3, 3))
    return make_T(dR @ T[..., :3, :3], T[..., :3, 3] + delta[..., :3])


def mean_pose(Ts, weights=None):
    """SE(3) mean of poses (N, 4, 4): arithmetic mean of translations, chordal L2 rotation mean
    (the quaternion eigenvector method of scipy's ``Rotation.mean``: the largest eigenvector of sum w q q^T, the
    quaternions by Shepperd's method). weights: (N,) or None."""
    Ts = np.asarray(Ts, dtype=float)
    if Ts.ndim != 3 or Ts.shape[0] == 0:
        raise DataError("mean_pose needs a non-empty (N, 4, 4) array of poses")
    w = None if weights is None else np.asarray(weights, dtype=float)
    q = _quat_xyzw(Ts[:, :3, :3])
    _, V = np.linalg.eigh((q.T * (1.0 if w is None else w)) @ q)  # the largest eigenvector: the chordal mean
    x, y, z, s = V[:, -1]
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * s), 2 * (x * z + y * s)],
                  [2 * (x * y + z * s), 1 - 2 * (x * x + z * z), 2 * (y * z - x * s)],
                  [2 * (x * z - y * s), 2 * (y * z + x * s), 1 - 2 * (x * x + y * y)]])
    t = np.average(Ts[:, :3, 3], axis=0, weights=w)
    return make_T(R, t)


def check_finite(name: str, a) -> np.ndarray:
    """Return ``a`` as float64; raise DataError naming ``name`` and the first bad index on NaN/inf."""
    arr = np.asarray(a, dtype=float)
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise DataError(f"{name} contains a non-finite value (NaN or inf) at index {idx}")
    return arr


def inverse_error_map(T):
    """(..., 6, 6) linear map G with ``pose_error(inv(T), inv(perturb_pose(T, d))) ~= G @ d``.

    Used to carry a pose covariance from T_cam_target to T_target_cam: ``cov_inv = G cov G^T``.
    """
    T = np.asarray(T, dtype=float)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    G = np.zeros(T.shape[:-2] + (6, 6))
    G[..., :3, :3] = -Rt
    G[..., :3, 3:] = -Rt @ skew(T[..., :3, 3])
    G[..., 3:, 3:] = -Rt
    return G


# ----------------------------------------------------------------------------- SO(3) exponential and Jacobians
def so3_exp(r) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of rotation vectors r (..., 3) rad (Rodrigues: cos th I + sinc th [r]x +
    (1 - cos th) / th^2 r r^T, the series below th = 1e-8)."""
    r = np.asarray(r, dtype=float)
    if r.size == 3 and r.shape[-1:] == (3,):  # one vector (a mount's or a joint's rotation): scalar arithmetic
        return _so3_exp_one(*(float(v) for v in r.reshape(3))).reshape(r.shape[:-1] + (3, 3))
    th2 = np.einsum("...i,...i->...", r, r)[..., None, None]
    th = np.sqrt(th2)
    small = th < 1e-8
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th2 / 6.0, np.sin(ths) / ths)
    b = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(ths)) / ths**2)
    return (1.0 - b * th2) * np.eye(3) + a * skew(r) + b * (r[..., :, None] * r[..., None, :])


def _so3_exp_one(x: float, y: float, z: float) -> np.ndarray:
    """:func:`so3_exp` of one rotation vector (x, y, z) rad, in scalar arithmetic."""
    th2 = x * x + y * y + z * z
    th = math.sqrt(th2)
    if th < 1e-8:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    c = 1.0 - b * th2
    return np.array([[c + b * x * x, -a * z + b * x * y, a * y + b * x * z],
                     [a * z + b * x * y, c + b * y * y, -a * x + b * y * z],
                     [-a * y + b * x * z, a * x + b * y * z, c + b * z * z]])


def so3_right_jacobian(r) -> np.ndarray:
    """Right Jacobian (..., 3, 3) of Exp at r (..., 3): Exp(r + dr) ~= Exp(r) Exp(Jr(r) dr)."""
    r = np.asarray(r, dtype=float)
    if r.size == 3 and r.shape[-1:] == (3,):  # one vector: scalar arithmetic, the same formula
        x, y, z = (float(v) for v in r.reshape(3))
        th2 = x * x + y * y + z * z
        th = math.sqrt(th2)
        if th < 1e-6:
            b, c = 0.5 - th2 / 24.0, 1.0 / 6.0 - th2 / 120.0
        else:
            b, c = (1.0 - math.cos(th)) / th2, (th - math.sin(th)) / (th2 * th)
        d = 1.0 - c * th2  # I + c K^2 = (1 - c th^2) I + c r r^T
        return np.array([[d + c * x * x, b * z + c * x * y, -b * y + c * x * z],
                         [-b * z + c * x * y, d + c * y * y, b * x + c * y * z],
                         [b * y + c * x * z, -b * x + c * y * z, d + c * z * z]]).reshape(r.shape[:-1] + (3, 3))
    th = np.linalg.norm(r, axis=-1)[..., None, None]
    K = skew(r)
    small = th < 1e-6
    ths = np.where(small, 1.0, th)
    b = np.where(small, 0.5 - th**2 / 24.0, (1.0 - np.cos(ths)) / ths**2)
    c = np.where(small, 1.0 / 6.0 - th**2 / 120.0, (ths - np.sin(ths)) / ths**3)
    return np.eye(3) - b * K + c * (K @ K)


def so3_right_jacobian_inv(r) -> np.ndarray:
    """Inverse right Jacobian (..., 3, 3) of Exp at rotation vectors r (..., 3) rad."""
    r = np.asarray(r, dtype=float)
    th = np.linalg.norm(r, axis=-1)[..., None, None]
    K = skew(r)
    small = th < 1e-6
    ths = np.where(small, 1.0, th)
    # 1/th^2 - (1 + cos th) / (2 th sin th) = 1/th^2 - cot(th/2) / (2 th) (finite at a half turn), series
    # 1/12 + th^2/720 near 0
    c = np.where(small, 1.0 / 12.0 + th**2 / 720.0, 1.0 / ths**2 - np.cos(ths / 2) / (2.0 * ths * np.sin(ths / 2)))
    return np.eye(3) + 0.5 * K + c * (K @ K)


def swing_twist(R, axis):
    """Swing-twist split of rotations R (..., 3, 3) about the unit ``axis`` (3,) of their own (right-hand) frame:
    ``(R_swing (..., 3, 3), twist (...,) rad)`` with ``R = R_swing @ Rot(axis, twist)``, R_swing a rotation about
    an axis perpendicular to ``axis`` and twist in (-pi, pi]. Exact (to rounding) for any R whose swing is not a
    half turn."""
    R = np.asarray(R, dtype=float)
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat()  # (k, 4) scalar last
    twist = 2.0 * np.arctan2(q[:, :3] @ a, q[:, 3])
    twist = (twist + np.pi) % (2.0 * np.pi) - np.pi
    twist = np.where(twist == -np.pi, np.pi, twist)
    Rt = Rotation.from_rotvec(twist[:, None] * a[None, :]).as_matrix()
    swing = R.reshape(-1, 3, 3) @ np.swapaxes(Rt, -1, -2)
    return swing.reshape(R.shape), twist.reshape(R.shape[:-2])
