"""The target-kind registry: THE one place that knows which calibration target kinds exist.

A target kind is a :class:`TargetKind` subclass (instantiated once) that owns everything that differs
between kinds: its YAML keys and their validation, the pattern geometry (corner ids and 3-D points), the
black shapes the texture and the coverage renderer draw, OpenCV board objects, the detector, the seeded
batch refinement it supports and the image model of its corner error (measure/covariance.py).
:class:`~vision_calib.targets.spec.TargetSpec` and :mod:`vision_calib.measure` call these methods and
never branch on the kind's name.

Adding a kind = writing that class and registering it (for the shipped kinds: the lines at the end).
"""

from __future__ import annotations

from ...errors import ConfigError
from .base import TargetKind

KINDS: dict = {}


def register(kind: TargetKind) -> TargetKind:
    """Register a target kind instance under ``kind.name``."""
    KINDS[kind.name] = kind
    return kind


def unregister(name: str) -> None:
    KINDS.pop(name, None)


def get_kind(name, where: str = "target") -> TargetKind:
    """The TargetKind of a name; ConfigError naming ``where`` and the known kinds."""
    try:
        return KINDS[name]
    except (KeyError, TypeError):
        raise ConfigError(f"{where}: key 'kind' must be one of {tuple(KINDS)}, got {name!r}") from None


def _register_shipped() -> None:
    from .aruco import AprilTagGridKind, CharucoKind
    from .chessboard import ChessboardKind
    from .circles import AsymmetricCirclesKind, ModifiedCircleGridKind

    for cls in (CharucoKind, AprilTagGridKind, ChessboardKind, AsymmetricCirclesKind, ModifiedCircleGridKind):
        register(cls())


_register_shipped()
