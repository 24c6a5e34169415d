"""The batched forward kinematics of deploy (``deploy.kinematics.BatchedArm``: link constants built once per
parameter vector, one matrix product per joint over all rows) against the chains' own forward kinematics
(``kinematics.serial`` / ``kinematics.urdf``), and its joint Jacobian against central differences of those."""

import numpy as np
import pytest

from vision_calib import frames as F
from vision_calib.deploy.kinematics import BatchedArm, ChainKinematics
from vision_calib.deploy.solve import joint_jacobian
from vision_calib.kinematics.urdf import URDFChain


def _rpr():
    O = np.array([np.eye(4)] * 3)
    O[1, :3, 3] = [0.3, 0.0, 0.1]
    O[2, :3, :3] = F.rot_x(np.pi / 2)
    # axes: -z (a coordinate axis with a sign), x (prismatic), a tilted one (the general Rodrigues path)
    return URDFChain.build("rpr", O, [[0, 0, -1.0], [1.0, 0, 0], [0, 0.6, 0.8]], [False, True, False],
                           tail=F.make_T(F.rot_z(0.3), [0.01, 0.02, 0.05]))


def _cases(results):
    """(ChainKinematics with a tcp, a parameter vector off the nominal) of the RX-90 (MDH), the UR5e (URDF) and a
    revolute-prismatic-revolute URDF arm."""
    rng = np.random.default_rng(3)
    for name in ("rx90_eye_in_hand", "ur5e_eye_in_hand"):
        r = results[name].robot
        yield name, ChainKinematics(r.model.robot, [0.01, -0.02, 0.12]), r.x
    chain = _rpr()
    yield "rpr", ChainKinematics(chain, [0.0, 0.03, 0.1]), chain.params.nominal + rng.normal(scale=0.02,
                                                                                             size=len(chain.params))


def _joints(kin, rng, N):
    q = rng.uniform(-np.pi, np.pi, (N, kin.n_joints))
    pr = getattr(kin.robot, "prismatic", np.zeros(kin.n_joints, bool))
    q[:, pr] = rng.uniform(-0.5, 0.5, (N, int(np.sum(pr))))
    return q


def test_batched_forward_equals_the_chains_own_to_1e_12_m(results):
    rng = np.random.default_rng(0)
    for name, kin, x in _cases(results):
        q = _joints(kin, rng, 2000)
        arm = kin.arm_at(x)
        batched = BatchedArm(arm)
        T_own = arm.forward(q)
        T = batched.forward(q)
        assert np.abs(T[:, :3, 3] - T_own[:, :3, 3]).max() < 1e-12, name
        assert np.abs(T[:, :3, :3] - T_own[:, :3, :3]).max() < 1e-12, name
        assert np.all(T[:, 3] == [0, 0, 0, 1])
        np.testing.assert_array_equal(kin.tool(q, x), T)  # what compensate / inverse use
        # a wrong link constant would show: the same chain at another parameter vector differs
        assert np.abs(BatchedArm(kin.arm_at(x + 1e-3)).forward(q) - T_own).max() > 1e-4


@pytest.mark.parametrize("case", [0, 1, 2])
def test_batched_joint_jacobian_matches_central_differences_of_the_chains_own(results, case):
    name, kin, x = list(_cases(results))[case]
    q = _joints(kin, np.random.default_rng(1), 200)
    arm = kin.arm_at(x)
    T, J = BatchedArm(arm).forward(q, jacobian=True)
    np.testing.assert_allclose(J, joint_jacobian(arm.forward, q, arm.forward(q)), atol=1e-8, err_msg=name)
    assert np.abs(T - arm.forward(q)).max() < 1e-12
