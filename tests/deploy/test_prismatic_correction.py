"""compensate's largest correction per joint kind: a revolute joint's in degrees, a prismatic joint's in millimetres
(``deploy.robot.MAX_CORRECTION_DEG`` / ``MAX_CORRECTION_MM``), each named in its own unit."""

from pathlib import Path

import numpy as np
import pytest

from vision_calib import frames as F
from vision_calib.deploy import CalibratedRobot
from vision_calib.deploy.robot import MAX_CORRECTION_DEG, MAX_CORRECTION_MM
from vision_calib.io.model_export import CalibratedModel
from vision_calib.kinematics.urdf import URDFChain


def _rpr_robot(deviation: dict) -> CalibratedRobot:
    """A revolute-prismatic-revolute URDF arm whose calibration moved the named parameters (SI) off the nominal."""
    O = np.array([np.eye(4)] * 3)
    O[1, :3, 3] = [0.3, 0.0, 0.1]
    O[2, :3, :3] = F.rot_x(np.pi / 2)
    chain = URDFChain.build("rpr", O, [[0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0]], [False, True, False])
    x = chain.deviated(deviation)
    n = len(x)
    model = CalibratedModel(Path("rpr.yaml"), "urdf", chain.with_params(chain.params.with_nominal(x)), chain,
                            chain.params.names, x, np.zeros(n), np.ones(n, bool), np.zeros((n, n)), "none")
    return CalibratedRobot.from_model(model)


Q = np.array([[0.3, 0.05, -0.4], [-1.0, 0.2, 0.7], [2.0, -0.1, 1.2]])


@pytest.mark.parametrize("mm", [4.0, -8.0])
def test_a_prismatic_zero_shift_below_the_limit_is_corrected_in_metres(mm):
    r = _rpr_robot({"q0_2": mm * 1e-3})
    c = r.compensate_rows(Q)
    assert c.corrected.all(), c.why
    np.testing.assert_allclose(c.q_corrected - Q, np.tile([0.0, -mm * 1e-3, 0.0], (3, 1)), atol=1e-9)


def test_a_prismatic_correction_above_the_limit_is_named_in_millimetres():
    mm = 1.5 * MAX_CORRECTION_MM  # 15 mm = 0.015 m: below 10 deg = 0.175 "rad" (the check once compared those)
    r = _rpr_robot({"q0_2": mm * 1e-3})
    c = r.compensate_rows(Q)
    assert not c.corrected.any()
    for why in c.why:
        assert f"{-mm:+.3g} mm on q2, more than {MAX_CORRECTION_MM:g} mm" in why and "deg" not in why


def test_a_revolute_correction_above_the_limit_is_named_in_degrees():
    deg = 1.5 * MAX_CORRECTION_DEG
    r = _rpr_robot({"q0_1": np.radians(deg)})
    c = r.compensate_rows(Q)
    assert not c.corrected.any()
    for why in c.why:
        assert f"{-deg:+.3g} deg on q1, more than {MAX_CORRECTION_DEG:g} deg" in why
    ok = _rpr_robot({"q0_1": np.radians(0.5 * MAX_CORRECTION_DEG)}).compensate_rows(Q)
    assert ok.corrected.all(), ok.why
    np.testing.assert_allclose(ok.q_corrected[:, 0] - Q[:, 0], -np.radians(0.5 * MAX_CORRECTION_DEG), atol=1e-9)
