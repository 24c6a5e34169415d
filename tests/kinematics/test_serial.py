"""Serial arms: modified DH + Hayati forward model, analytic Jacobians, shipped thesis robots."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from kin_helpers import fd_pose_jacobian

from vision_calib.errors import ConfigError, DataError, ParameterError
from vision_calib.frames import T_from_xyz_rpy, make_T, pose_error, rot_x, rot_y, rot_z
from vision_calib.kinematics.serial import SerialChain, so3_exp, so3_right_jacobian
from vision_calib.kinematics.serial_file import load_serial_robot

ROBOTS = Path(__file__).resolve().parents[2] / "scenes" / "robots"
ROBOT_FILES = ["rx90", "thesis_arm", "thesis_arm_camera_table", "thesis_arm_tripod_probe"]
DEG = np.pi / 180


def _load(name):
    return load_serial_robot(ROBOTS / f"{name}.yaml")


def _rx90_dh():
    """Table 3.1 with D3 = RL4 = 0.45 m: rows [alpha, a, theta, d] (rad, m)."""
    return np.array([[0, 0, 0, 0], [90 * DEG, 0, 0, 0], [0, 0.45, 0, 0],
                     [-90 * DEG, 0, 0, 0.45], [90 * DEG, 0, 0, 0], [-90 * DEG, 0, 0, 0]])


def _naive_forward(chain, q, x):
    """Independent FK: plain 4x4 products per pose and per elementary transform."""
    v = chain.params.values(x)

    def T(R=None, t=None):
        return make_T(R, t)

    out = []
    for qk in np.atleast_2d(q):
        TL, TR = chain.nominal_transforms(x)
        F = TL.copy()
        for i in range(1, chain.n_joints + 1):
            if f"l{i}" in v:
                F = F @ T(t=[0, 0, v[f"l{i}"]])
            F = F @ T(R=rot_x(v[f"alpha{i}"]))
            if f"beta{i}" in v:
                F = F @ T(R=rot_y(v[f"beta{i}"]))
            F = F @ T(t=[v[f"a{i}"], 0, 0]) @ T(R=rot_z(v[f"theta{i}"] + qk[i - 1])) @ T(t=[0, 0, v[f"d{i}"]])
        out.append(F @ TR)
    return np.array(out)


def _random_x(chain, rng, scale=0.02):
    """Nominal + random deviations (m / rad), mount rotations included: a point away from nominal."""
    return chain.params.nominal + rng.normal(0.0, scale, len(chain.params))


def _random_q(chain, rng, n):
    if chain.joint_limits is None:
        return rng.uniform(-np.pi, np.pi, (n, chain.n_joints))
    lo, hi = chain.joint_limits[:, 0], chain.joint_limits[:, 1]
    return rng.uniform(np.maximum(lo, -np.pi), np.minimum(hi, np.pi), (n, chain.n_joints))


# ----------------------------------------------------------------------------- forward model
def test_rx90_positions_of_the_thesis_annex():
    """Annex 6.28 (unit lengths) x 0.45 m: flange origin at the six configurations of section 3.3.4."""
    ch = _load("rx90")
    c = ch.meta["configurations"]["thesis_six"]
    T = ch.forward(c["q"])
    np.testing.assert_allclose(T[:, :3, 3], c["thesis_positions"], atol=1e-12)
    # and the a4 = 0.2 variant of the thesis (annex 6.31), a4 = 0.2 unit = 0.09 m
    x = ch.params.vector({"a4": 0.2 * 0.45})
    expected = 0.45 * np.array([[1.2, 0, 1], [0, 1.2, 1], [-1, 0, 1.2], [0, 0, 0.2], [1.2, 0, 1], [1.2, 0, 1]])
    np.testing.assert_allclose(ch.forward(c["q"], x)[:, :3, 3], expected, atol=1e-12)


def test_thesis_arm_positions_of_the_thesis_annex():
    """Table 3.2 (+ l5 along z4) reproduces annex 6.34 and 6.37 to their printed precision (cm)."""
    ch = _load("thesis_arm")
    for name in ("six_plus_one", "annex_6_36"):
        c = ch.meta["configurations"][name]
        P = ch.forward(c["q"])[:, :3, 3]
        np.testing.assert_allclose(P, c["thesis_positions"], atol=0.0006, err_msg=name)


def test_camera_table_positions_of_the_thesis_annex():
    """Table 5.1 with theta_i = -zero_i: annex 6.45 (thesis pattern frame, z up) to ~1 cm.

    Our target frame is the thesis' pattern frame turned by Rx(180): p_thesis = (x, -y, -z).
    The annex prints y with the opposite sign (configs 2-10, so |y| is compared) and config 1 is
    garbled (left out)."""
    ch = _load("thesis_arm_camera_table")
    c = ch.meta["configurations"]["step_01"]
    P = ch.forward(c["q"])[:, :3, 3] * np.array([1.0, -1.0, -1.0])
    ref = c["thesis_positions"]
    np.testing.assert_allclose(P[1:, [0, 2]], ref[1:, [0, 2]], atol=0.012)
    np.testing.assert_allclose(np.abs(P[1:, 1]), np.abs(ref[1:, 1]), atol=0.012)


def test_tripod_probe_positions_of_the_thesis_annex():
    """Table 6.1: annex 6.47 (target in camera frame) to ~1 cm (|y|: two printed signs are lost)."""
    ch = _load("thesis_arm_tripod_probe")
    c = ch.meta["configurations"]["section_6_3"]
    P = ch.forward(c["q"])[:, :3, 3]
    ref = c["thesis_positions"]
    np.testing.assert_allclose(P[:, [0, 2]], ref[:, [0, 2]], atol=0.012)
    np.testing.assert_allclose(np.abs(P[:, 1]), np.abs(ref[:, 1]), atol=0.012)


@pytest.mark.parametrize("name", ROBOT_FILES)
def test_forward_matches_naive_product_at_random_parameters(name):
    ch = _load(name)
    rng = np.random.default_rng(3)
    q = _random_q(ch, rng, 7)
    x = _random_x(ch, rng, 0.05)
    np.testing.assert_allclose(ch.forward(q, x), _naive_forward(ch, q, x), atol=1e-12)
    F = ch.forward_all(q, x)
    assert F.shape == (7, ch.n_joints + 2, 4, 4)
    np.testing.assert_allclose(F[:, -1], ch.forward(q, x), atol=1e-15)
    TL, TR = ch.nominal_transforms(x)
    np.testing.assert_allclose(TL @ ch.flange(q, x) @ TR, ch.forward(q, x), atol=1e-12)


def test_hayati_with_zero_beta_equals_plain_mdh():
    rng = np.random.default_rng(0)
    dh = _rx90_dh() + np.c_[rng.normal(0, 0.01, (6, 4))]
    plain = SerialChain.build("plain", dh)
    hay = SerialChain.build("hayati", dh, hayati=(3,))
    q = rng.uniform(-np.pi, np.pi, (20, 6))
    # same alpha, a, theta, d (d3 kept, only fixed in the Hayati chain), beta3 = 0
    x_h = hay.params.vector(plain.params.values())
    np.testing.assert_allclose(hay.forward(q, x_h), plain.forward(q), atol=1e-14)
    # the shared columns of the Jacobians agree too
    Jp, Jh = plain.pose_jacobian(q), hay.pose_jacobian(q, x_h)
    for k, nm in enumerate(plain.params.names):
        np.testing.assert_allclose(Jh[:, :, hay.params.index(nm)], Jp[:, :, k], atol=1e-14, err_msg=nm)
    # a non-zero beta3 does change the model (it is a real parameter)
    assert np.abs(hay.forward(q, hay.params.vector({"beta3": 1e-3}, x_h)) - plain.forward(q)).max() > 1e-5


def test_hayati_d_is_fixed_by_default_and_redundancies_are_listed():
    ch = _load("rx90")
    assert "beta3" in ch.params.free_names and "d3" not in ch.params.free_names
    pairs = {(a, b) for a, b, _ in ch.redundant_pairs()}
    assert ("d3", "beta3") in pairs and ("d3", "d2") in pairs
    arm = _load("thesis_arm")
    assert "l5" not in arm.params.free_names and ("l5", "d4") in {(a, b) for a, b, _ in arm.redundant_pairs()}


def test_so3_helpers():
    rng = np.random.default_rng(1)
    for r in (rng.normal(0, 0.7, 3), np.array([1e-9, 0, 0]), np.zeros(3)):
        R = so3_exp(r)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
        Jr = so3_right_jacobian(r)
        for k in range(3):
            h = 1e-6
            e = np.zeros(3)
            e[k] = h
            dR = so3_exp(r).T @ so3_exp(r + e)
            w = np.array([dR[2, 1], dR[0, 2], dR[1, 0]]) / h
            np.testing.assert_allclose(w, Jr[:, k], atol=1e-6)


# ----------------------------------------------------------------------------- Jacobians
@pytest.mark.parametrize("name", ROBOT_FILES)
def test_analytic_jacobian_matches_central_differences(name):
    """Every column (free or fixed, mounts included), pose and position, at nominal and random x."""
    ch = _load(name)
    rng = np.random.default_rng(11)
    q = _random_q(ch, rng, 6)
    for x in (ch.params.nominal, _random_x(ch, rng, 0.05)):
        J = ch.pose_jacobian(q, x)
        Jfd = fd_pose_jacobian(ch, q, x)
        for k, nm in enumerate(ch.params.names):
            np.testing.assert_allclose(J[:, :, k], Jfd[:, :, k], atol=2e-8, err_msg=f"{name}: column {nm}")
        np.testing.assert_allclose(ch.position_jacobian(q, x), Jfd[:, :3, :], atol=2e-8)

        T, Jw = ch.pose_and_jacobian(q, x, frames=ch.walk_frames(q, x))  # the frames of a walk made before
        np.testing.assert_array_equal(Jw, J)
        np.testing.assert_array_equal(T, ch.forward(q, x))
    with pytest.raises(ParameterError, match="frames have shape"):
        ch.pose_and_jacobian(q, frames=ch.walk_frames(q[:2]))


# ----------------------------------------------------------------------------- identifiability
def _rank_report(ch, names, q, rows):
    """Rank of the column-normalised Jacobian (stacked over poses) of ``names`` and the names with a
    component in its null space. Columns that vanish (norm < 1e-12 of the largest) count as zero."""
    idx = ch.params.indices(names)
    J = ch.pose_jacobian(q)[:, rows, :][:, :, idx].reshape(-1, len(idx))
    nrm = np.linalg.norm(J, axis=0)
    nz = nrm > 1e-12 * nrm.max()
    A = np.where(nz, J / np.where(nz, nrm, 1.0), 0.0)
    _, s, Vt = np.linalg.svd(A, full_matrices=False)
    rank = int((s > 1e-9 * s[0]).sum())
    N = Vt[rank:].T
    in_null = [names[k] for k in np.flatnonzero(np.linalg.norm(N, axis=1) > 1e-6)]
    return rank, in_null, N, A


def _all_names(ch):
    return [nm for nm in ch.params.names if nm != "d3" and not nm.startswith("l")]


def test_rx90_rank_with_base_and_tool_frames():
    """36 parameters (24 MDH + beta3 - d3 + 12 mount): 30 identifiable with full pose, 27 with
    position only, for a tool point off the last joint axis (any real tool or marker)."""
    ch = _load("rx90")
    ch = ch.with_params(ch.params.with_nominal({"T_flange_tool.tx": 0.05, "T_flange_tool.ty": 0.03,
                                                "T_flange_tool.tz": 0.10}))
    q = _random_q(ch, np.random.default_rng(5), 50)
    names = _all_names(ch)
    assert len(names) == 36
    r_pose, null_pose, _, _ = _rank_report(ch, names, q, slice(0, 6))
    r_pos, null_pos, _, _ = _rank_report(ch, names, q, slice(0, 3))
    print(f"\nRX-90 + base + tool, full pose: rank {r_pose}/36, null space involves {null_pose}")
    print(f"RX-90 + base + tool, position : rank {r_pos}/36, null space involves {null_pos}")
    assert r_pose == 30 and r_pos == 27
    # joint 1 is absorbed by the base frame, theta6/d6 by the tool frame
    assert {"alpha1", "a1", "theta1", "d1", "theta6", "d6"} <= set(null_pose)
    assert {"T_flange_tool.rx", "T_flange_tool.ry", "T_flange_tool.rz"} <= set(null_pos)
    # with the identity tool the measured point is the wrist centre: rotations about the wrist
    # axes do not move it and position-only identifiability drops further
    r_wc, null_wc, _, _ = _rank_report(_load("rx90"), names, q, slice(0, 3))
    print(f"RX-90 + base + identity tool, position: rank {r_wc}/36, null space involves {null_wc}")
    assert r_wc == 21


def test_thesis_chapter3_setups_position_only():
    """The thesis' chapter-3 identification: flange origin position, parameters l, a, theta, d
    (no alpha, no mounts). Real robot (table 3.2): a6 is in the null space (a6 = c1 theta5 + c2 d6:
    the thesis' a6 = -54.68 cm), theta6 has a zero column, d2 ~ d3 (parallel axes) and l5 ~ d4.
    RX-90: the zero columns theta4..6 (the thesis' 'columns 10 11 12') and theta3 ~ a4."""
    rng = np.random.default_rng(2)
    arm = _load("thesis_arm")
    names = ["l5"] + [f"{p}{i}" for p in ("a", "theta", "d") for i in range(1, 7)]
    q = rng.uniform(-np.pi, np.pi, (50, 6))
    rank, null, N, A = _rank_report(arm, names, q, slice(0, 3))
    print(f"\nthesis arm, chapter 3 (19 parameters, position): rank {rank}, null space involves {null}")
    assert rank == 15
    assert set(null) == {"d2", "d3", "d4", "l5", "theta5", "a6", "theta6", "d6"}
    # a6's column is an exact combination of theta5 and d6
    k = names.index("a6")
    sub = [names.index("theta5"), names.index("d6")]
    c, *_ = np.linalg.lstsq(A[:, sub], A[:, k], rcond=None)
    assert np.linalg.norm(A[:, sub] @ c - A[:, k]) < 1e-10
    # the same holds at the thesis' own seven configurations
    rank7, null7, _, _ = _rank_report(arm, names, arm.meta["configurations"]["six_plus_one"]["q"], slice(0, 3))
    assert "a6" in null7 and rank7 < 19

    rx = _load("rx90")
    names_rx = [f"{p}{i}" for p in ("a", "theta", "d") for i in range(1, 7)]
    rank, null, _, _ = _rank_report(rx, names_rx, q, slice(0, 3))
    print(f"RX-90, chapter 3 (18 parameters, position): rank {rank}, null space involves {null}")
    assert rank == 13
    assert {"theta4", "theta5", "theta6", "d2", "d3", "theta3", "a4"} == set(null)


# ----------------------------------------------------------------------------- files and errors
def test_units_are_converted_on_load():
    rx = _load("rx90")
    assert rx.params.nominal[rx.params.index("a3")] == pytest.approx(0.45)
    assert rx.params.nominal[rx.params.index("alpha4")] == pytest.approx(-np.pi / 2)
    np.testing.assert_allclose(rx.joint_limits[1], np.radians([-137.5, 137.5]))
    cam = _load("thesis_arm_camera_table")
    assert cam.params.nominal[cam.params.index("theta1")] == pytest.approx(np.radians(-95))
    assert cam.params.nominal[cam.params.index("l2")] == pytest.approx(0.012)
    assert cam.params.nominal[cam.params.index("T_target_base.tx")] == pytest.approx(0.397)
    np.testing.assert_allclose(cam.meta["configurations"]["zero_position"]["q"], np.radians([[95, 75, 87, 78, 65, 85]]))
    arm = _load("thesis_arm")
    tr = arm.meta["trials"]["lse_essai_1"]
    assert tr["deviation"]["a6"] == pytest.approx(0.001)  # 0.1 cm
    assert tr["deviation"]["theta6"] == pytest.approx(0.06)  # rad (assumed unit of the thesis)
    assert tr["reported"]["a6"] == pytest.approx(-0.5468)


@pytest.mark.parametrize("name", ROBOT_FILES)
def test_shipped_files_load(name):
    ch = _load(name)
    assert ch.n_joints == 6 and ch.hayati == (3,)
    assert len(ch.params) == 6 * 4 + 1 + 12 + len(ch.pre_z)
    for c in ch.meta["configurations"].values():
        assert c["q"].shape[1] == 6
        if ch.joint_limits is not None:
            assert ch.within_limits(c["q"]).all()
    for name_t, t in ch.meta["trials"].items():
        # the trial's true vector moves exactly the named parameters, by the named amounts (SI)
        x = ch.deviated(t["deviation"])
        dx = x - ch.params.nominal
        idx = ch.params.indices(list(t["deviation"]))
        np.testing.assert_array_equal(np.delete(dx, idx), 0.0)
        np.testing.assert_allclose(dx[idx], list(t["deviation"].values()), rtol=1e-12, atol=0)
        # and the pose moves as the Jacobian says: pose_error(T(x0), T(x0 + dx)) = J(x0 + dx/2) dx up
        # to third order (measured: <= 5e-4 relative on the shipped trials); a deviation applied to
        # the wrong parameter or ignored breaks this
        q = ch.meta["configurations"][t["configurations"]]["q"]
        e = pose_error(ch.forward(q), ch.forward(q, x))
        lin = ch.pose_jacobian(q, ch.params.nominal + dx / 2) @ dx
        assert np.abs(lin).max() > 1e-3, name_t  # the deviation is visible in the pose
        assert np.abs(e - lin).max() < 2e-3 * np.abs(lin).max(), name_t


def _write(tmp_path, text):
    p = tmp_path / "robot.yaml"
    p.write_text(text)
    return p


GOOD = """
name: toy
units: {length: cm, angle: deg}
joints:
  - {alpha: 0, a: 0, theta: 0, d: 10}
  - {alpha: 90, a: 5, theta: 0, d: 0}
"""


def test_bad_yaml_names_file_and_key(tmp_path):
    ch = load_serial_robot(_write(tmp_path, GOOD))
    assert ch.params.nominal[ch.params.index("d1")] == pytest.approx(0.1)
    bad_key = GOOD.replace("{alpha: 90, a: 5", "{alpah: 90, a: 5")
    with pytest.raises(ConfigError, match=r"robot\.yaml: joints\[1\]\.alpah: unknown key"):
        load_serial_robot(_write(tmp_path, bad_key))
    with pytest.raises(ConfigError, match=r"robot\.yaml: joints\[0\]\.d: expected float"):
        load_serial_robot(_write(tmp_path, GOOD.replace("d: 10", "d: ten")))
    with pytest.raises(ConfigError, match=r"robot\.yaml: units\.length"):
        load_serial_robot(_write(tmp_path, GOOD.replace("length: cm", "length: inch")))
    with pytest.raises(ConfigError, match=r"robot\.yaml: mounts\.right\.name"):
        load_serial_robot(_write(tmp_path, GOOD + "mounts: {right: {name: T_flange_foo}}\n"))
    with pytest.raises(ConfigError, match=r"robot\.yaml: joint_limits"):
        load_serial_robot(_write(tmp_path, GOOD + "joint_limits: [[0, 10]]\n"))
    with pytest.raises(ConfigError, match=r"robot\.yaml: configurations\.c\.q"):
        load_serial_robot(_write(tmp_path, GOOD + "configurations: {c: {q: [[1, 2, 3]]}}\n"))
    with pytest.raises(ConfigError, match=r"robot\.yaml: trials\.t\.deviation\.a7: unknown parameter name"):
        load_serial_robot(_write(tmp_path, GOOD + "trials: {t: {deviation: {a7: 1}}}\n"))
    with pytest.raises(ConfigError, match="file not found"):
        load_serial_robot(tmp_path / "missing.yaml")


def test_bad_inputs_raise_named_errors():
    ch = _load("rx90")
    q = np.zeros((4, 6))
    q[2, 4] = np.nan
    with pytest.raises(DataError, match="pose 2"):
        ch.forward(q)
    with pytest.raises(DataError, match=r"\(N, 6\)"):
        ch.pose_jacobian(np.zeros((3, 5)))
    with pytest.raises(ParameterError, match="shape"):
        ch.forward(np.zeros(6), np.zeros(3))
    with pytest.raises(ParameterError, match="'beta2'"):
        ch.params.index("beta2")
    with pytest.raises(ParameterError, match="'a7'"):
        ch.deviated({"a7": 1.0})
    assert ch.forward(np.zeros(6)).shape == (1, 4, 4)


def test_chain_is_immutable():
    ch = _load("rx90")
    with pytest.raises(AttributeError):
        ch.name = "other"
    with pytest.raises(ValueError):
        ch.params.nominal[0] = 1.0
    with pytest.raises(ValueError):
        ch.left_R_nominal[0, 0] = 2.0


def test_kinematics_imports_no_heavy_modules():
    code = ("import sys; import vision_calib.kinematics.serial_file as s; "
            "s.load_serial_robot(sys.argv[1]); "
            "bad = [m for m in ('cv2', 'torch', 'OpenGL', 'pyrender', 'kornia') if m in sys.modules]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code, str(ROBOTS / "rx90.yaml")], check=True)


def test_vectorised_over_poses():
    """Same result for a batch as pose by pose (no hidden coupling between poses)."""
    ch = _load("thesis_arm_tripod_probe")
    rng = np.random.default_rng(4)
    q = _random_q(ch, rng, 5)
    x = _random_x(ch, rng)
    Jb = ch.pose_jacobian(q, x)
    for k in range(5):
        np.testing.assert_allclose(ch.pose_jacobian(q[k], x)[0], Jb[k], atol=1e-15)


def test_mount_rotation_convention_is_right_multiplied():
    ch = SerialChain.build("toy", _rx90_dh(), hayati=(3,), T_flange_right=T_from_xyz_rpy([0.1, 0, 0], [0.3, 0, 0]))
    r = np.array([0.01, -0.02, 0.03])
    x = ch.params.vector({"T_flange_tool.rx": r[0], "T_flange_tool.ry": r[1], "T_flange_tool.rz": r[2]})
    _, TR = ch.nominal_transforms(x)
    np.testing.assert_allclose(TR[:3, :3], rot_x(0.3) @ so3_exp(r), atol=1e-15)
    np.testing.assert_allclose(TR[:3, 3], [0.1, 0, 0])


def test_robot_file_mount_as_quat(tmp_path):
    """A robot file's mount given as xyz + quat [qx, qy, qz, qw] (scalar last) equals the same mount as rpy."""
    from scipy.spatial.transform import Rotation

    rpy = [10.0, -20.0, 90.0]
    quat = Rotation.from_euler("xyz", rpy, degrees=True).as_quat().tolist()  # R = Rz Ry Rx, as rpy
    p = tmp_path / "robot.yaml"
    p.write_text(GOOD + f"mounts: {{right: {{name: T_flange_tool, xyz: [1, 2, 3], rpy: {rpy}}}}}\n")
    a = load_serial_robot(p)
    p.write_text(GOOD + f"mounts: {{right: {{name: T_flange_tool, xyz: [1, 2, 3], quat: {quat}}}}}\n")
    b = load_serial_robot(p)
    q = np.array([[0.2, -0.4]])
    np.testing.assert_allclose(b.forward(q, b.params.nominal), a.forward(q, a.params.nominal), atol=1e-12)
    p.write_text(GOOD + "mounts: {right: {name: T_flange_tool, quat: [0.1, 0, 0, 1]}}\n")
    with pytest.raises(ConfigError, match=r"robot\.yaml: mounts\.right\.quat: expected a unit quaternion"):
        load_serial_robot(p)
