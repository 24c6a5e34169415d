import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vision_calib import frames as F
from vision_calib.errors import DataError


def _random_T(rng, n=None):
    shape = () if n is None else (n,)
    R = Rotation.random(n, random_state=rng.integers(1 << 31)).as_matrix()
    t = rng.normal(size=shape + (3,))
    return F.make_T(R, t)


def test_inverse_and_composition_cancel_inner_names():
    rng = np.random.default_rng(0)
    T_a_b, T_b_c = _random_T(rng), _random_T(rng)
    T_a_c = T_a_b @ T_b_c
    p_c = rng.normal(size=(5, 3))
    np.testing.assert_allclose(F.transform_points(T_a_c, p_c), F.transform_points(T_a_b, F.transform_points(T_b_c, p_c)))
    np.testing.assert_allclose(F.inv_T(T_a_c) @ T_a_c, np.eye(4), atol=1e-12)
    batch = _random_T(rng, 7)
    np.testing.assert_allclose(F.inv_T(batch) @ batch, np.broadcast_to(np.eye(4), (7, 4, 4)), atol=1e-12)


def test_conversions_round_trip():
    rng = np.random.default_rng(1)
    T = _random_T(rng, 20)
    rv, tv = F.rvec_tvec_from_T(T)
    np.testing.assert_allclose(F.T_from_rvec_tvec(rv, tv), T, atol=1e-12)
    xyz, rpy = F.xyz_rpy_from_T(T)
    np.testing.assert_allclose(F.T_from_xyz_rpy(xyz, rpy), T, atol=1e-12)
    xyz, q = F.xyz_quat_from_T(T)
    np.testing.assert_allclose(F.T_from_xyz_quat(xyz, q), T, atol=1e-12)
    np.testing.assert_allclose(F.T_from_xyz_rotvec(F.xyz_rotvec_from_T(T)), T, atol=1e-12)
    # single transform keeps its (4, 4) shape
    assert F.T_from_rvec_tvec(rv[0], tv[0]).shape == (4, 4)


def test_rpy_matches_elementary_rotations():
    T = F.T_from_xyz_rpy([0, 0, 0], [0.1, -0.2, 0.3])
    np.testing.assert_allclose(T[:3, :3], F.rot_z(0.3) @ F.rot_y(-0.2) @ F.rot_x(0.1), atol=1e-15)
    np.testing.assert_allclose(F.rot_x(0.4), Rotation.from_rotvec([0.4, 0, 0]).as_matrix(), atol=1e-15)
    np.testing.assert_allclose(F.rot_y(0.4), Rotation.from_rotvec([0, 0.4, 0]).as_matrix(), atol=1e-15)


def test_pose_error_and_perturb_are_inverse():
    rng = np.random.default_rng(2)
    T = _random_T(rng, 10)
    d = rng.normal(scale=0.1, size=(10, 6))
    np.testing.assert_allclose(F.pose_error(T, F.perturb_pose(T, d)), d, atol=1e-12)


def test_opencv_opengl_flip_is_an_involution_and_flips_y_z():
    rng = np.random.default_rng(3)
    T_w_cv = _random_T(rng)
    T_w_gl = F.cam_gl_from_cv(T_w_cv)
    np.testing.assert_allclose(F.cam_cv_from_gl(T_w_gl), T_w_cv, atol=1e-15)
    # OpenCV looks along +z, OpenGL along -z: same viewing direction in the world
    np.testing.assert_allclose(T_w_cv[:3, 2], -T_w_gl[:3, 2])
    np.testing.assert_allclose(T_w_cv[:3, 1], -T_w_gl[:3, 1])
    np.testing.assert_allclose(T_w_cv[:3, 0], T_w_gl[:3, 0])


def test_mean_pose_recovers_centre_of_symmetric_spread():
    rng = np.random.default_rng(4)
    T0 = _random_T(rng)
    d = rng.normal(scale=0.01, size=(50, 6))
    Ts = F.perturb_pose(np.broadcast_to(T0, (100, 4, 4)), np.concatenate([d, -d]))
    np.testing.assert_allclose(F.mean_pose(Ts), T0, atol=1e-6)
    with pytest.raises(DataError):
        F.mean_pose(np.zeros((0, 4, 4)))


def test_check_finite_names_the_array_and_index():
    with pytest.raises(DataError, match=r"joints .* index \(1, 2\)"):
        F.check_finite("joints", [[0, 0, 0], [0, 0, np.nan]])


def test_inverse_error_map_matches_finite_differences():
    rng = np.random.default_rng(5)
    T = _random_T(rng)
    G = F.inverse_error_map(T)
    eps = 1e-6
    num = np.zeros((6, 6))
    for k in range(6):
        d = np.zeros(6)
        d[k] = eps
        plus = F.pose_error(F.inv_T(T), F.inv_T(F.perturb_pose(T, d)))
        minus = F.pose_error(F.inv_T(T), F.inv_T(F.perturb_pose(T, -d)))
        num[:, k] = (plus - minus) / (2 * eps)
    np.testing.assert_allclose(G, num, atol=1e-7)


def test_rotvec_from_matrix_matches_scipy_at_every_angle():
    """The log map of pose_error (Shepperd's quaternion) against scipy's, from 1e-12 rad to pi, including the
    identity and half turns about each axis (where the vector's sign is a convention: compared as rotations)."""
    from scipy.spatial.transform import Rotation

    from vision_calib.frames import rotvec_from_matrix

    rng = np.random.default_rng(3)
    axes = rng.normal(size=(400, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    angles = np.concatenate([10.0 ** rng.uniform(-12, 0, 300), np.pi - 10.0 ** rng.uniform(-9, -1, 100)])
    rv = axes * angles[:, None]
    R = np.concatenate([Rotation.from_rotvec(rv).as_matrix(), np.eye(3)[None],
                        np.diag([1.0, -1, -1])[None], np.diag([-1.0, 1, -1])[None], np.diag([-1.0, -1, 1])[None]])
    ours = rotvec_from_matrix(R)
    ref = Rotation.from_matrix(R).as_rotvec()
    between = (Rotation.from_rotvec(ref).inv() * Rotation.from_rotvec(ours)).magnitude()
    assert np.max(between) < 1e-14
    assert np.allclose(np.linalg.norm(ours, axis=1), np.linalg.norm(ref, axis=1), rtol=1e-12, atol=1e-15)
    assert np.allclose(ours[:300], rv[:300], rtol=1e-10, atol=1e-16)  # small and moderate angles: the vector itself
    assert rotvec_from_matrix(R.reshape(2, -1, 3, 3)).shape == (2, R.shape[0] // 2, 3)


def test_one_vector_paths_of_so3_exp_and_its_jacobian_equal_the_batched_ones():
    """so3_exp and so3_right_jacobian of one (3,) vector (scalar arithmetic) equal the (N, 3) path to rounding,
    about 0, below and above the series' switch and at a half turn, and against scipy's rotation."""
    from scipy.spatial.transform import Rotation

    from vision_calib.frames import so3_exp, so3_right_jacobian

    rng = np.random.default_rng(8)
    vecs = np.concatenate([rng.normal(size=(30, 3)) * 2, [[0, 0, 0], [1e-9, -2e-9, 0], [3e-7, 0, 1e-7],
                                                         [2e-6, 1e-6, 0], [np.pi, 0, 0]]])
    for r in vecs:
        np.testing.assert_allclose(so3_exp(r), so3_exp(r[None])[0], rtol=0, atol=4e-15)
        np.testing.assert_allclose(so3_right_jacobian(r), so3_right_jacobian(r[None])[0], rtol=0, atol=4e-15)
        np.testing.assert_allclose(so3_exp(r), Rotation.from_rotvec(r).as_matrix(), rtol=0, atol=4e-15)
        h = 1e-7  # Exp(r + dr) ~= Exp(r) Exp(Jr dr)
        for e in np.eye(3):
            lhs = so3_exp(r + h * e)
            rhs = so3_exp(r) @ so3_exp(h * so3_right_jacobian(r) @ e)
            assert np.abs(lhs - rhs).max() < 1e-12
