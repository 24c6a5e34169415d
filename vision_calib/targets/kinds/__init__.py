"""The target-kind registry: THE one place that knows which calibration target kinds exist.

A target kind is a :class:`TargetKind` subclass (instantiated once) that owns everything that differs
between kinds: its YAML keys (its typed spec, a :class:`TargetSpec` subclass, ``spec_class``) and their validation, the pattern geometry (corner ids and 3-D points), the
black shapes the texture and the coverage renderer draw, OpenCV board objects, the detector, the seeded
batch refinement it supports and the image model of its corner error (``corner_info``, ``bias_columns``:
:mod:`.image_model`, used by measure/covariance.py).
:class:`~vision_calib.targets.spec.TargetSpec` and :mod:`vision_calib.measure` call these methods and
never branch on the kind's name.

Adding a kind = one module (the kind class and its spec class) and one registry line (for the shipped kinds:
the lines at the end; from another package: an entry point of the group ``vision_calib.targets``,
:mod:`vision_calib.plugins`).
"""

from __future__ import annotations

from ...plugins import TARGET_GROUP, load_entry_points
from .base import KINDS, MarkerKind, TargetKind, TargetSpec, get_kind, register, unregister


def _register_shipped() -> None:
    from .aruco import AprilTagGridKind, CharucoKind
    from .chessboard import ChessboardKind
    from .circles import AsymmetricCirclesKind, ModifiedCircleGridKind

    for cls in (CharucoKind, AprilTagGridKind, ChessboardKind, AsymmetricCirclesKind, ModifiedCircleGridKind):
        register(cls())


def _register_plugin(obj) -> None:
    """An entry point's object: a TargetKind subclass (instantiated) or instance."""
    register(obj() if isinstance(obj, type) and issubclass(obj, TargetKind) else obj)


_register_shipped()
PLUGINS = load_entry_points(TARGET_GROUP, _register_plugin)  #: names of the target kinds registered by entry points

__all__ = ["KINDS", "MarkerKind", "PLUGINS", "TargetKind", "TargetSpec", "get_kind", "register", "unregister"]
