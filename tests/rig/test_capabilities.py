"""Kind-specific capabilities are explicit interfaces (typing.Protocol, checked with isinstance), not attribute
probes: which shipped setups and chains have them, and the errors that name a missing one."""

import numpy as np
import pytest

from vision_calib.errors import ParameterError
from vision_calib.identify.serial_problem import serial_problem
from vision_calib.kinematics.protocols import ChainModel, Remountable
from vision_calib.kinematics.serial import SerialChain
from vision_calib.kinematics.urdf import URDFChain
from vision_calib.rig import SCENES_DIR, load_scene
from vision_calib.rig.base import ChainMeasured
from vision_calib.rig.serial import remount_chain


@pytest.mark.parametrize("scene, chain_measured", [("h4_vision.yaml", False), ("rx90_eye_in_hand.yaml", True),
                                                   ("ur5e_eye_in_hand.yaml", True)])
def test_shipped_setups_declare_their_capabilities(scene, chain_measured):
    setup = load_scene(SCENES_DIR / scene).setup
    assert isinstance(setup, ChainMeasured) is chain_measured
    if chain_measured:
        assert isinstance(setup.chain, ChainModel)
        assert isinstance(setup.chain, Remountable) is isinstance(setup.chain, URDFChain)


def test_remount_keeps_the_arm_for_both_chain_kinds():
    for scene in ("rx90_eye_in_hand.yaml", "ur5e_eye_in_hand.yaml"):
        chain = load_scene(SCENES_DIR / scene).setup.chain
        T = np.eye(4)
        T[:3, 3] = [0.1, 0.2, 0.3]
        new = remount_chain(chain, "T_cam_base", "T_flange_target", T, np.eye(4))
        assert type(new) is type(chain) and isinstance(new, (SerialChain, URDFChain))
        arm = [n for n in chain.params.names if not n.startswith(("T_", "B_", "M_"))]
        np.testing.assert_array_equal([new.params.values()[n] for n in arm], [chain.params.values()[n] for n in arm])
        q = np.zeros((1, chain.n_joints))
        assert not np.allclose(new.forward(q), chain.forward(q))  # the new mounts are used


def test_serial_problem_names_the_interface_a_chain_lacks():
    class NotAChain:
        name = "x"

    with pytest.raises(ParameterError, match="ChainModel interface"):
        serial_problem(NotAChain(), np.zeros((3, 2)), np.tile(np.eye(4), (3, 1, 1)))
