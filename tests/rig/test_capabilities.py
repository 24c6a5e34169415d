"""Kind-specific capabilities are explicit interfaces (typing.Protocol, checked with isinstance), not attribute
probes: which shipped setups and chains have them, and the errors that name a missing one."""

import numpy as np
import pytest

from vision_calib.errors import ConfigError, DataError, ParameterError
from vision_calib.identify.serial_problem import serial_problem
from vision_calib.kinematics.protocols import ChainModel, PrismaticJoints, Remountable
from vision_calib.kinematics.serial import SerialChain
from vision_calib.kinematics.urdf import URDFChain
from vision_calib.rig import SCENES_DIR, load_scene
from vision_calib.rig.base import (ChainMeasured, ModelVariants, NamedConfigurations, NamedTrials, PoseGrids, Setup,
                                   TiltsFromAxis)
from vision_calib.rig.serial import remount_chain


@pytest.mark.parametrize("scene, chain_measured", [("h4_vision.yaml", False), ("rx90_eye_in_hand.yaml", True),
                                                   ("ur5e_eye_in_hand.yaml", True)])
def test_shipped_setups_declare_their_capabilities(scene, chain_measured):
    setup = load_scene(SCENES_DIR / scene).setup
    assert isinstance(setup, ChainMeasured) is chain_measured
    if chain_measured:
        assert isinstance(setup.chain, ChainModel)
        assert isinstance(setup.chain, Remountable) is isinstance(setup.chain, URDFChain)
        assert isinstance(setup.chain, PrismaticJoints) is isinstance(setup.chain, URDFChain)


#: each optional interface and its members (none of them on the base Setup)
CAPS = {ModelVariants: ("with_variant",), NamedConfigurations: ("configurations",), NamedTrials: ("trials",),
        PoseGrids: ("pose_grids", "pose_grid"), TiltsFromAxis: ("tilt_mode", "tilt_names", "tilt_reference", "with_tilts")}


@pytest.mark.parametrize("scene, caps", [("h4_vision.yaml", {ModelVariants, PoseGrids, TiltsFromAxis}),
                                         ("rx90_eye_in_hand.yaml", {NamedConfigurations, NamedTrials}),
                                         ("ur5e_eye_in_hand.yaml", {NamedConfigurations, NamedTrials})])
def test_kind_hooks_are_optional_interfaces(scene, caps):
    """The base Setup has none of the kind-specific hooks; each shipped kind has exactly its own."""
    for cap, members in CAPS.items():
        assert not any(hasattr(Setup, m) for m in members), (cap, members)
    setup = load_scene(SCENES_DIR / scene).setup
    assert {c for c in CAPS if isinstance(setup, c)} == caps


def test_a_missing_capability_is_named_where_it_is_asked_for():
    from vision_calib.study.spec import scene_with, scene_with_trial

    serial = load_scene(SCENES_DIR / "rx90_eye_in_hand.yaml")
    with pytest.raises(ConfigError, match="variant/model choices need a robot kind that has them .*serial"):
        scene_with(serial, variant="D")
    h4 = load_scene(SCENES_DIR / "h4_vision.yaml")
    with pytest.raises(ConfigError, match="unknown trial 'x' .*no trials"):
        scene_with_trial(h4, "x")
    with pytest.raises(ConfigError, match="no pose grid 'grid9'"):
        h4.setup.pose_grid("grid9")


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


def test_only_revolute_joints_without_limits_are_held_to_a_turn():
    """A chain with the PrismaticJoints capability: a prismatic joint's value is a length, not refused beyond
    2 pi; the revolute joints of the same chain still are (degrees read as radians)."""
    from dataclasses import replace

    setup = load_scene(SCENES_DIR / "ur5e_eye_in_hand.yaml").setup
    n = setup.chain.n_joints
    chain = replace(setup.chain, prismatic=np.arange(n) == n - 1, joint_limits=None)
    free = replace(setup, chain=chain)
    q = np.full((2, n), 0.5)
    q[1, n - 1] = 7.0
    free.check_joints(q, "poses.csv", ["a", "b"])  # the prismatic joint: accepted
    q[1, 0] = 7.0
    with pytest.raises(DataError, match=r"poses.csv: pose 'b' joint q1 = 7 rad is more than a turn"):
        free.check_joints(q, "poses.csv", ["a", "b"])
