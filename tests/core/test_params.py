import numpy as np
import pytest

from vision_calib.errors import ParameterError
from vision_calib.kinematics.params import ParameterSet


def _ps():
    return ParameterSet.from_lists(["a1", "d2", "theta3", "T_flange_cam.tx"], [0.1, 0.2, 0.0, 0.05],
                                   ["length", "length", "angle", "length"])


def test_pack_unpack_by_name():
    ps = _ps().fix(["d2"])
    assert ps.free_names == ("a1", "theta3", "T_flange_cam.tx")
    x = ps.expand(np.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(x, [1.0, 0.2, 2.0, 3.0])
    assert ps.values(x)["theta3"] == 2.0
    np.testing.assert_allclose(ps.vector({"d2": 5.0}), [0.1, 5.0, 0.0, 0.05])
    assert ps.only_free(["d2"]).free_names == ("d2",)


def test_unknown_name_is_named_with_suggestion():
    with pytest.raises(ParameterError, match=r"'theta33'.*theta3"):
        _ps().fix(["theta33"])


def test_bad_construction():
    with pytest.raises(ParameterError, match="duplicate"):
        ParameterSet.from_lists(["a", "a"], [0, 0], ["length", "length"])
    with pytest.raises(ParameterError, match="kinds"):
        ParameterSet.from_lists(["a"], [0], ["furlong"])
