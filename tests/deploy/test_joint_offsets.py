"""Joint offsets a controller can take: the equivalent joint-offset form (every rotation about / translation along a
joint's own axis at its origin carried by its offset) predicts exactly what the calibrated model predicts, and the
offsets' sign convention (model joint value = controller reading + offset) is the one a controller needs."""

import numpy as np
import pytest

from vision_calib import frames as F
from vision_calib.io.model_export import joint_offsets
from vision_calib.kinematics.urdf import URDFChain

TOL = 1e-9


def test_ur5e_offset_form_predicts_the_same_and_carries_the_folded_offsets(results):
    r = results["ur5e_eye_in_hand"].robot
    chain = r.model.robot
    xe = r.offset_form()
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, size=(500, 6))
    assert np.abs(chain.forward(q, xe) - chain.forward(q, r.x)).max() < TOL
    assert np.abs(r.kin.tool(q, xe) - r.kin.tool(q, r.x)).max() < TOL
    ix = r.names.index
    # the identification folded q0_2 into j2.rz (q0_2 fixed at 0): the offset form moves it back
    assert r.x[ix("q0_2")] == 0.0 and abs(r.x[ix("j2.rz")]) > 1e-5
    assert xe[ix("q0_2")] == pytest.approx(r.x[ix("j2.rz")], abs=1e-6)  # = the twist (j2.rx, ry are small)
    for i in range(1, 7):  # no rotation about a joint's own (z) axis is left in its origin correction
        R = F.so3_exp(xe[[ix(f"j{i}.rx"), ix(f"j{i}.ry"), ix(f"j{i}.rz")]])
        assert abs(F.swing_twist(R, [0, 0, 1.0])[1]) < 1e-12
    offs = r.joint_offsets()
    assert [offs[f"q{i}"]["offset"] for i in range(1, 7)] == pytest.approx(xe[[ix(f"q0_{i}") for i in range(1, 7)]],
                                                                           abs=1e-15)


@pytest.mark.parametrize("name", ["ur5e_eye_in_hand", "rx90_eye_in_hand", "h4_vision"])
def test_a_controller_adding_the_offsets_to_its_readings_turns_the_joints_as_calibrated(results, name):
    """A calibration whose only change is the joints' zeros: the nominal model fed with reading + offset gives
    exactly the calibrated model at the reading (a sign error would double the error instead)."""
    r = results[name].robot
    robot = r.model.robot
    rng = np.random.default_rng(1)
    x = r.x_nominal.copy()
    zero = {"ur5e_eye_in_hand": "j{}.rz", "rx90_eye_in_hand": "theta{}", "h4_vision": "q0_{}"}[name]
    dev = rng.normal(scale=2e-3, size=r.n_joints)
    for i, d in enumerate(dev, start=1):
        x[r.names.index(zero.format(i))] += d
    offs = joint_offsets(robot, x, r.x_nominal, r.prismatic)
    o = np.array([offs[f"q{i}"]["offset"] for i in range(1, r.n_joints + 1)])
    np.testing.assert_allclose(o, dev, atol=1e-12)
    if name == "h4_vision":
        X = results[name].run.setup.sample_poses(rng, 30)
        q = robot.igm(X, x)  # the calibrated robot's readings at those poses
        np.testing.assert_allclose(robot.fgm(q + o, r.x_nominal, X0=X), X, atol=1e-10)
    else:
        q = rng.uniform(-2, 2, size=(50, r.n_joints))
        assert np.abs(robot.forward(q + o, r.x_nominal) - robot.forward(q, x)).max() < TOL
        assert np.abs(robot.forward(q - o, r.x_nominal) - robot.forward(q, x)).max() > 1e-4


def test_prismatic_offset_form_moves_the_axial_translation_into_the_offset():
    O = np.array([np.eye(4)] * 3)
    O[1, :3, 3] = [0.3, 0.0, 0.1]
    O[2, :3, :3] = F.rot_x(np.pi / 2)
    chain = URDFChain.build("rpr", O, [[0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0]], [False, True, False])
    rng = np.random.default_rng(2)
    x = chain.params.nominal + rng.normal(scale=0.02, size=len(chain.params))
    xe, off = chain.joint_offset_form(x)
    q = rng.uniform(-1, 1, size=(200, 3))
    assert np.abs(chain.forward(q, xe) - chain.forward(q, x)).max() < TOL
    ix = chain.params.index
    R = F.so3_exp(xe[[ix("j2.rx"), ix("j2.ry"), ix("j2.rz")]])
    t = xe[[ix("j2.x"), ix("j2.y"), ix("j2.z")]]
    assert abs(t @ (R @ [1.0, 0, 0])) < 1e-15  # no translation left along the moved axis
    assert off[1] == xe[ix("q0_2")] != x[ix("q0_2")]
    for i in (1, 3):  # revolute joints: their twists
        assert abs(F.swing_twist(F.so3_exp(xe[[ix(f"j{i}.rx"), ix(f"j{i}.ry"), ix(f"j{i}.rz")]]),
                                 chain.axes[i - 1])[1]) < 1e-12
    offs = joint_offsets(chain, x, chain.params.nominal, chain.prismatic)
    assert offs["q2"]["unit"] == "m" and offs["q1"]["unit"] == "rad"
