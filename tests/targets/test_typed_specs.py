"""One typed spec per target kind: each kind's dataclass holds, writes and reads only its own keys; files written
before (every kind's keys, the others at zero) still read; a new kind is one module + one registry line."""

import sys
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from vision_calib.errors import ConfigError
from vision_calib.targets import TargetSpec, target_from_dict
from vision_calib.targets.kinds import KINDS, MarkerKind, register, unregister
from vision_calib.targets.kinds.base import COMMON_KEYS

SPECS = {
    "charuco": dict(rows=5, cols=7, dictionary="DICT_5X5_100", square_m=0.025, marker_m=0.018),
    "apriltag_grid": dict(rows=4, cols=6, dictionary="DICT_APRILTAG_36h11", tag_m=0.03, spacing_m=0.009),
    "chessboard": dict(rows=5, cols=8, square_m=0.02),
    "circles_asymmetric": dict(rows=7, cols=4, spacing_m=0.02, diameter_m=0.01),
    "modified_circle_grid": dict(rows=5, cols=7, spacing_m=0.03, diameter_m=0.012),
}
#: the flat spec of before: every kind's key, at the value it wrote for a kind that does not use it
OLD_FLAT = {"dictionary": "", "square_m": 0.0, "marker_m": 0.0, "tag_m": 0.0, "spacing_m": 0.0,
            "legacy_pattern": False, "first_id": 0, "diameter_m": 0.0, "allow_symmetric": False,
            "origin_diameter_m": 0.0, "blob_detector": []}


def _spec(kind):
    return TargetSpec(kind=kind, name="t", **SPECS[kind])


@pytest.mark.parametrize("kind", sorted(SPECS))
def test_each_kind_writes_only_its_keys(kind):
    s = _spec(kind)
    assert type(s) is KINDS[kind].spec_class and isinstance(s, TargetSpec)
    d = s.to_dict()
    assert set(d) <= set(COMMON_KEYS) | set(KINDS[kind].keys)
    others = set().union(*(KINDS[k].keys for k in SPECS if k != kind)) - set(KINDS[kind].keys)
    assert not (set(d) & others), f"{kind} writes keys of other kinds: {set(d) & others}"
    assert target_from_dict(d) == s


@pytest.mark.parametrize("kind", sorted(SPECS))
def test_a_file_with_every_kinds_zero_keys_still_reads(kind):
    """recording.yaml files written by the flat TargetSpec carried every kind's keys at zero."""
    old = {**OLD_FLAT, **_spec(kind).to_dict()}
    assert target_from_dict(old) == _spec(kind)


def test_another_kinds_key_with_a_value_is_refused_naming_it():
    with pytest.raises(ConfigError, match=r"key 'tag_m' does not apply to kind 'charuco'"):
        target_from_dict({**_spec("charuco").to_dict(), "tag_m": 0.03})
    with pytest.raises(ConfigError, match=r"key 'diameter_m' does not apply to kind 'chessboard'"):
        TargetSpec(kind="chessboard", name="c", rows=5, cols=8, square_m=0.02, diameter_m=0.01)


def test_spec_fields_of_other_kinds_do_not_exist():
    s = _spec("charuco")
    assert not any(f.name in ("tag_m", "diameter_m", "origin_diameter_m", "spacing_m") for f in fields(s))
    with pytest.raises(AttributeError):
        s.tag_m  # noqa: B018


# the toy kind of the plugin example (tests/plugins/vc_toy_plugin: one spec dataclass + one kind class), here
# registered by hand under its own name
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "plugins" / "vc_toy_plugin"))
from vc_toy_plugin.target import SquaresKind as PluginSquaresKind, SquaresSpec  # noqa: E402


class SquaresKind(PluginSquaresKind):
    name = "toy_squares"


def test_a_new_kind_is_one_class_pair_and_one_registry_line():
    register(SquaresKind())
    try:
        s = target_from_dict({"kind": "toy_squares", "rows": 2, "cols": 3, "side_m": 0.01, "margin_m": 0.0})
        assert type(s) is SquaresSpec and s.kind_impl.name == "toy_squares"
        assert s.to_dict() == {"kind": "toy_squares", "name": "target", "rows": 2, "cols": 3, "margin_m": 0.0,
                               "side_m": 0.01}
        img = s.texture(1000.0)  # 10 px per square: the texture is drawn from the kind's rectangles
        assert img.shape == (30, 50) and np.isclose((img == 0).mean(), 6 * 100 / 1500)
        with pytest.raises(ConfigError, match="side_m"):
            target_from_dict({"kind": "toy_squares", "rows": 2, "cols": 3, "side_m": -1.0})
    finally:
        unregister("toy_squares")
    with pytest.raises(ConfigError, match="key 'kind' must be one of"):
        target_from_dict({"kind": "toy_squares", "rows": 2, "cols": 3})
    with pytest.raises(ConfigError, match="side_m: unknown key"):  # its key went with it
        target_from_dict({"kind": "charuco", "rows": 2, "cols": 3, "side_m": 0.01})


@pytest.mark.parametrize("kind", sorted(SPECS))
def test_markers_are_an_optional_interface_of_a_kind(kind):
    """The marker boards (charuco, apriltag_grid) are the MarkerKind kinds; asking another kind for markers is a
    ConfigError naming the target and what was asked; registering a non-TargetKind is refused."""
    s = _spec(kind)
    assert isinstance(KINDS[kind], MarkerKind) is (kind in ("charuco", "apriltag_grid"))
    if isinstance(KINDS[kind], MarkerKind):
        assert s.marker_corners().shape == (len(s.marker_ids()), 4, 3)
    else:
        with pytest.raises(ConfigError, match=r"target 't': kind '\w+' has no markers \(marker_ids\)"):
            s.marker_ids()
    with pytest.raises(TypeError, match="must be a TargetKind instance, got type"):
        register(type(KINDS[kind]))
