"""URDF serial chains: forward model vs independent computations, analytic vs finite-difference
Jacobians, identifiability of the redundant per-joint model, recovery from noisy data, URDF export
round trip, remounting, and clear errors on bad files."""

from pathlib import Path

import numpy as np
import pytest
from kin_helpers import fd_pose_jacobian
import yourdfpy

from vision_calib.errors import ConfigError, DataError, ParameterError
from vision_calib.frames import rot_x, rot_z
from vision_calib.identify import analyze, base_problem, solve_lse
from vision_calib.identify.serial_problem import serial_problem, synthetic_pose_measurements
from vision_calib.kinematics.urdf import URDFChain, arm_parameter_names, export_urdf, load_urdf_robot

UR5E = Path(__file__).resolve().parents[2] / "scenes" / "robots" / "ur5e.urdf"

# a small chain with every case: fixed joints before/between/after movable ones, a prismatic joint,
# a continuous joint, an off-axis (non-z) axis, and a side branch off the chain
TOY = """<?xml version="1.0"?>
<robot name="toy">
  <link name="world"/><link name="l0"/><link name="l1"/><link name="l1b"/><link name="l2"/>
  <link name="l3"/><link name="tip"/><link name="side"/>
  <joint name="world-l0" type="fixed"><parent link="world"/><child link="l0"/>
    <origin xyz="0.1 0.2 0.3" rpy="0.1 0.2 0.3"/></joint>
  <joint name="j_a" type="revolute"><parent link="l0"/><child link="l1"/>
    <origin xyz="0 0 0.2" rpy="0 0 0.5"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="l1-l1b" type="fixed"><parent link="l1"/><child link="l1b"/>
    <origin xyz="0.05 0 0" rpy="0.3 0 0"/></joint>
  <joint name="j_b" type="prismatic"><parent link="l1b"/><child link="l2"/>
    <origin xyz="0.3 0 0.01" rpy="0 0.4 0"/><axis xyz="0 0.6 0.8"/>
    <limit lower="-0.2" upper="0.4" effort="1" velocity="1"/></joint>
  <joint name="j_c" type="continuous"><parent link="l2"/><child link="l3"/>
    <origin xyz="0 0.1 0.2" rpy="-0.2 0.1 1.0"/><axis xyz="0 1 0"/></joint>
  <joint name="l3-tip" type="fixed"><parent link="l3"/><child link="tip"/>
    <origin xyz="0 0 0.1" rpy="0 0 0.7"/></joint>
  <joint name="l1-side" type="fixed"><parent link="l1"/><child link="side"/></joint>
</robot>
"""


def _ur5e(**kw):
    return load_urdf_robot(UR5E, "base_link", "tool0", **kw)


def _toy(tmp_path, text=TOY, **kw):
    p = tmp_path / "toy.urdf"
    p.write_text(text)
    return load_urdf_robot(p, "world", "tip", **kw), p


def _random_T(rng, t=0.3, r=0.5):
    from vision_calib.frames import make_T, so3_exp

    return make_T(so3_exp(rng.uniform(-r, r, 3)), rng.uniform(-t, t, 3))


def _random_q(ch, rng, n):
    lo = np.where(np.isfinite(ch.joint_limits[:, 0]), ch.joint_limits[:, 0], -np.pi)
    hi = np.where(np.isfinite(ch.joint_limits[:, 1]), ch.joint_limits[:, 1], np.pi)
    return rng.uniform(np.maximum(lo, -np.pi), np.minimum(hi, np.pi), (n, ch.n_joints))


def _library_fk(path, ch, q, base, tip):
    """Forward kinematics of the URDF by yourdfpy itself (scene graph), one joint set at a time."""
    u = yourdfpy.URDF.load(str(path), load_meshes=False, build_collision_scene_graph=False)
    out = []
    for qk in q:
        u.update_cfg(dict(zip(ch.meta["joint_names"], qk)))
        out.append(u.get_transform(tip, base))
    return np.array(out)


# ----------------------------------------------------------------------------- forward model
def test_ur5e_matches_published_dh_table():
    """Independent check of the shipped file: standard DH of the UR5e, base_link = DH base turned by pi."""
    a = [0, -0.425, -0.3922, 0, 0, 0]
    d = [0.1625, 0, 0, 0.1333, 0.0997, 0.0996]
    alpha = [np.pi / 2, 0, 0, np.pi / 2, -np.pi / 2, 0]
    ch = _ur5e()
    q = _random_q(ch, np.random.default_rng(1), 10)
    T = ch.forward(q)
    for k in range(len(q)):
        M = np.eye(4)
        M[:3, :3] = rot_z(np.pi)
        for i in range(6):
            L = np.eye(4)
            L[:3, :3] = rot_z(q[k, i]) @ rot_x(alpha[i])
            L[:3, 3] = rot_z(q[k, i]) @ [a[i], 0, 0] + [0, 0, d[i]]
            M = M @ L
        np.testing.assert_allclose(T[k], M, atol=1e-12)
    assert ch.n_joints == 6 and len(ch.params) == 6 * 7 + 12
    assert ch.meta["joint_names"][0] == "shoulder_pan_joint"
    np.testing.assert_allclose(ch.joint_limits[2], [-np.pi, np.pi])


@pytest.mark.parametrize("which", ["ur5e", "toy"])
def test_forward_matches_library_fk(tmp_path, which):
    if which == "ur5e":
        ch, path, base, tip = _ur5e(), UR5E, "base_link", "tool0"
    else:
        (ch, path), base, tip = _toy(tmp_path), "world", "tip"
    q = _random_q(ch, np.random.default_rng(2), 8)
    np.testing.assert_allclose(ch.forward(q), _library_fk(path, ch, q, base, tip), atol=1e-12)
    np.testing.assert_allclose(ch.flange(q), ch.forward(q), atol=1e-12)  # identity mounts
    F = ch.forward_all(q)
    assert F.shape == (8, ch.n_joints + 2, 4, 4)


def test_toy_structure_and_parameter_names(tmp_path):
    ch, _ = _toy(tmp_path, left="T_cam_base", right="T_flange_target")
    assert ch.n_joints == 3 and list(ch.prismatic) == [False, True, False]
    assert ch.meta["joint_names"] == ("j_a", "j_b", "j_c")
    names = ch.params.names
    assert names[:6] == tuple(f"T_cam_base.{s}" for s in ("tx", "ty", "tz", "rx", "ry", "rz"))
    assert names[6:13] == ("j1.x", "j1.y", "j1.z", "j1.rx", "j1.ry", "j1.rz", "q0_1")
    assert names[-1] == "T_flange_target.rz" and ch.measured_name == "T_cam_target"
    assert ch.params.kinds[names.index("q0_2")] == "length" and ch.params.kinds[names.index("q0_3")] == "angle"
    assert np.isinf(ch.joint_limits[2]).all() and ch.redundant_pairs() == []


def test_parameters_act_as_documented(tmp_path):
    """q0_i adds to joint i; j<i>.* is origin @ Trans(xyz) @ Rot(Exp(r)) before the joint motion."""
    ch, _ = _toy(tmp_path)
    rng = np.random.default_rng(3)
    q = _random_q(ch, rng, 4)
    x = ch.deviated({"q0_2": 0.03, "q0_3": -0.2})
    np.testing.assert_allclose(ch.forward(q, x), ch.forward(q + [0, 0.03, -0.2]), atol=1e-13)
    # a pure translation along joint 2's (prismatic) axis in its frame equals a joint offset
    ax = ch.axes[1]
    x = ch.deviated({"j2.x": 0.01 * ax[0], "j2.y": 0.01 * ax[1], "j2.z": 0.01 * ax[2]})
    np.testing.assert_allclose(ch.forward(q, x), ch.forward(q + [0, 0.01, 0]), atol=1e-13)


# ----------------------------------------------------------------------------- Jacobians
@pytest.mark.parametrize("which", ["ur5e", "toy"])
def test_analytic_jacobian_matches_central_differences(tmp_path, which):
    rng = np.random.default_rng(4)
    if which == "ur5e":
        ch = _ur5e(left="T_target_base", right="T_flange_cam", T_left_base=_random_T(rng),
                   T_flange_right=_random_T(rng, 0.1))
    else:
        ch, _ = _toy(tmp_path, left="T_cam_base", right="T_flange_target", T_left_base=_random_T(rng))
    q = _random_q(ch, rng, 5)
    for x in (ch.params.nominal, ch.params.nominal + rng.normal(0, 0.05, len(ch.params))):
        J = ch.pose_jacobian(q, x)
        Jfd = fd_pose_jacobian(ch, q, x)
        for k, nm in enumerate(ch.params.names):
            np.testing.assert_allclose(J[:, :, k], Jfd[:, :, k], atol=2e-8, err_msg=f"{which}: column {nm}")
        np.testing.assert_allclose(ch.position_jacobian(q, x), Jfd[:, :3, :], atol=2e-8)


# ----------------------------------------------------------------------------- identification
def _eye_in_hand_problem(n_poses, seed, sigma_t=None, sigma_r=None, x_true=None):
    rng = np.random.default_rng(seed)
    ch = _ur5e(left="T_target_base", right="T_flange_cam", T_left_base=_random_T(rng),
               T_flange_right=_random_T(rng, 0.1))
    q = _random_q(ch, rng, n_poses)
    x_true = ch.params.nominal if x_true is None else x_true(ch, rng)
    if sigma_t is None:
        T = ch.forward(q, x_true)
        return ch, serial_problem(ch, q, T), x_true
    T = synthetic_pose_measurements(ch, q, x_true, sigma_t, sigma_r, rng)
    return ch, serial_problem(ch, q, T, sigma_t_m=sigma_t, sigma_r_rad=sigma_r), x_true


def test_identifiability_reduces_the_per_joint_model_to_30_base_parameters():
    """6R arm, base + tool mounts, full pose: 4 n + 6 = 30 identifiable out of 7 n + 12 = 54."""
    ch, prob, _ = _eye_in_hand_problem(50, 5)
    rep = analyze(prob, selection="order")
    assert rep.n_params == 54 and rep.rank == 30 and len(rep.base_parameters) == 30
    # the first joint's placement is the left mount again; each joint offset of a revolute joint
    # is a rotation about its axis, already given by the previous parameters in order
    assert {f"j1.{s}" for s in ("x", "y", "z", "rx", "ry", "rz")} <= set(rep.non_identifiable)
    assert np.isfinite(rep.condition_number)


def test_identifiable_count_with_a_prismatic_joint(tmp_path):
    """Toy chain R-P-R, both mounts, full pose: 4 R + 2 P + 6 = 16 of 3 * 7 + 12 = 33."""
    rng = np.random.default_rng(9)
    ch, _ = _toy(tmp_path, left="T_cam_base", right="T_flange_target", T_left_base=_random_T(rng),
                 T_flange_right=_random_T(rng, 0.1))
    q = _random_q(ch, rng, 50)
    rep = analyze(serial_problem(ch, q, ch.forward(q)), selection="order")
    assert rep.n_params == 33 and rep.rank == 16
    assert {"q0_2", "q0_3"} <= set(rep.non_identifiable)


def test_recovers_base_parameters_within_predicted_std():
    """Deviations on the base set only (the dropped ones stay nominal, so the truth is the base
    solution); 1 mm / 1 mrad noise on 60 poses; every estimate within 4 predicted std, and the
    normalised errors have a mean square of about 1."""
    _, nominal_prob, _ = _eye_in_hand_problem(60, 6)
    base = analyze(nominal_prob, selection="order").base_parameters

    def truth(ch, rng):
        x = ch.params.nominal.copy()
        idx = ch.params.indices(base)
        x[idx] += rng.normal(0, 2e-3, len(idx))
        return x

    _, prob, x_true = _eye_in_hand_problem(60, 6, 1e-3, 1e-3, truth)
    bp = prob.with_params(prob.params.only_free(base))
    res = solve_lse(bp)
    assert res.converged and res.free.sum() == 30 and not res.warnings
    f = res.free
    z = (res.identified[f] - x_true[f]) / res.std[f]
    assert np.all(np.abs(z) < 4.0), dict(zip(np.array(res.names)[f], z.round(2)))
    assert 0.4 < np.mean(z**2) < 2.0
    # the full redundant problem fixed by base_problem keeps the same 30
    bp2, rep, warnings = base_problem(prob.with_params(prob.params), x=None)
    assert bp2.params.n_free == 30 and len(warnings) == 24


# ----------------------------------------------------------------------------- export / remount
@pytest.mark.parametrize("which", ["ur5e", "toy"])
def test_export_round_trip(tmp_path, which):
    rng = np.random.default_rng(7)
    if which == "ur5e":
        ch, base, tip = _ur5e(left="T_target_base", right="T_flange_cam", T_left_base=_random_T(rng)), "base_link", "tool0"
    else:
        (ch, _), base, tip = _toy(tmp_path, left="T_cam_base", right="T_flange_target"), "world", "tip"
    x = ch.params.nominal + rng.normal(0, 0.02, len(ch.params))
    out = export_urdf(ch, x, tmp_path / "calibrated.urdf")
    TL, TR = ch.nominal_transforms(x)
    back = load_urdf_robot(out, base, tip, left=ch.left, right=ch.right, T_left_base=TL, T_flange_right=TR)
    q = _random_q(ch, rng, 10)
    np.testing.assert_allclose(back.forward(q), ch.forward(q, x), atol=1e-12)
    # only the movable joints' origins changed; limits and fixed joints are as in the source
    src = yourdfpy.URDF.load(ch.meta["file"], load_meshes=False, build_scene_graph=False)
    new = yourdfpy.URDF.load(str(out), load_meshes=False, build_scene_graph=False)
    for j in src.robot.joints:
        k = new.joint_map[j.name]
        assert (k.type, k.parent, k.child) == (j.type, j.parent, j.child)
        if j.type == "fixed":
            eye = np.eye(4)
            np.testing.assert_allclose(eye if k.origin is None else k.origin, eye if j.origin is None else j.origin,
                                       atol=1e-15)
        if j.limit is not None:
            assert (k.limit.lower, k.limit.upper) == (j.limit.lower, j.limit.upper)
    # exporting the nominal gives the source kinematics back
    nom = load_urdf_robot(export_urdf(ch, ch.params.nominal, tmp_path / "nominal.urdf"), base, tip)
    np.testing.assert_allclose(nom.forward(q), load_urdf_robot(ch.meta["file"], base, tip).forward(q), atol=1e-12)


def test_remounted_keeps_arm_values_and_free_mask():
    ch = _ur5e()
    ps = ch.params.fix(["j1.x", "q0_3"]).with_nominal({"j2.rx": 0.01})
    ch = ch.with_params(ps)
    rng = np.random.default_rng(8)
    TL, TR = _random_T(rng), _random_T(rng, 0.1)
    new = ch.remounted("T_cam_base", "T_flange_target", TL, TR)
    assert new.mount_names == ("T_cam_base", "T_flange_target")
    arm = arm_parameter_names(6)
    np.testing.assert_array_equal(new.params.free[new.params.indices(arm)], ps.free[ps.indices(arm)])
    np.testing.assert_array_equal(new.params.nominal[new.params.indices(arm)], ps.nominal[ps.indices(arm)])
    q = _random_q(ch, rng, 5)
    np.testing.assert_allclose(new.forward(q), TL @ ch.forward(q) @ TR, atol=1e-12)
    assert not new.params.free[new.params.index("j1.x")] and new.params.free[new.params.index("T_cam_base.tx")]


# ----------------------------------------------------------------------------- errors
def _edit(old, new):
    assert old in TOY
    return TOY.replace(old, new)


BAD = [
    (_edit('<child link="l2"/>', '<child link="l9"/>'), "joint 'j_b': child link 'l9' is not defined"),
    (_edit('type="prismatic"', 'type="floating"'), "joint type 'floating' is not supported"),
    (_edit('xyz="0 0 0.2" rpy="0 0 0.5"', 'xyz="0 nan 0.2" rpy="0 0 0.5"'), "joint 'j_a'"),
    (_edit('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>'), "joint 'j_c'"),
    (_edit('<limit lower="-3" upper="3" effort="1" velocity="1"/>', ""), "joint 'j_a' (l0 -> l1): a revolute joint needs"),
    (_edit('<limit lower="-3" upper="3"', '<limit lower="3" upper="-3"'), "lower <= upper"),
    (_edit('<link name="side"/>', '<link name="side"/><link name="side"/>'), "link 'side' is defined twice"),
    (_edit('<joint name="l1-side" type="fixed"><parent link="l1"/><child link="side"/>',
           '<joint name="l1-side" type="fixed"><parent link="side"/><child link="l1"/>'), "child of two joints"),
    (_edit('</robot>', '<joint name="m" type="revolute"><parent link="l0"/><child link="side2"/>'
           '<mimic joint="j_a"/></joint><link name="side2"/></robot>'), None),  # off the chain: accepted
    (_edit('<robot name="toy">', '<robot name="toy"'), "not well-formed XML"),
]


@pytest.mark.parametrize("text,msg", BAD)
def test_bad_files_name_file_and_element(tmp_path, text, msg):
    if msg is None:
        ch, _ = _toy(tmp_path, text)
        assert ch.n_joints == 3
        return
    with pytest.raises(ConfigError) as e:
        _toy(tmp_path, text)
    assert "toy.urdf" in str(e.value) and msg in str(e.value)


def test_bad_links_and_loops(tmp_path):
    p = tmp_path / "toy.urdf"
    p.write_text(TOY)
    with pytest.raises(ConfigError, match="base_link 'nope' is not a link"):
        load_urdf_robot(p, "nope", "tip")
    with pytest.raises(ConfigError, match="tip_link 'l0' is not below base_link 'l1'"):
        load_urdf_robot(p, "l1", "l0")
    with pytest.raises(ConfigError, match="no movable joint"):
        load_urdf_robot(p, "l1", "side")
    loop = TOY.replace('<joint name="world-l0" type="fixed"><parent link="world"/>',
                       '<joint name="world-l0" type="fixed"><parent link="l3"/>')
    p.write_text(loop)
    with pytest.raises(ConfigError, match="form a loop"):
        load_urdf_robot(p, "world", "tip")
    with pytest.raises(ConfigError, match="not found"):
        load_urdf_robot(tmp_path / "missing.urdf", "a", "b")
    p.write_text(TOY.replace('<joint name="j_c" type="continuous">', '<joint name="j_c" type="continuous"><mimic joint="j_a"/>'))
    with pytest.raises(ConfigError, match="mimic"):
        load_urdf_robot(p, "world", "tip")


def test_bad_joint_values_and_parameters():
    ch = _ur5e()
    with pytest.raises(DataError, match="shape"):
        ch.forward(np.zeros((2, 5)))
    with pytest.raises(DataError, match="pose 1 are not finite"):
        ch.forward(np.array([[0.0] * 6, [0, 0, np.nan, 0, 0, 0]]))
    x = ch.params.nominal.copy()
    x[ch.params.index("j3.rz")] = np.inf
    with pytest.raises(ParameterError, match="j3.rz"):
        ch.forward(np.zeros(6), x)
    with pytest.raises(ParameterError, match="mounts must be"):
        ch.remounted("T_base", "T_flange_cam")
    assert isinstance(ch, URDFChain)
