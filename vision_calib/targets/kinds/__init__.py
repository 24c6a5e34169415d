"""The target-kind registry: THE one place that knows which calibration target kinds exist.

A target kind is a :class:`TargetKind` subclass (instantiated once) that owns everything that differs
between kinds: its YAML keys (its typed spec, a :class:`TargetSpec` subclass, ``spec_class``) and their validation, the pattern geometry (corner ids and 3-D points), the
black shapes the texture and the coverage renderer draw, OpenCV board objects, the detector, the seeded
batch refinement it supports and the image model of its corner error (``corner_info``, ``bias_columns``:
:mod:`.image_model`, used by measure/covariance.py).
:class:`~vision_calib.targets.spec.TargetSpec` and :mod:`vision_calib.measure` call these methods and
never branch on the kind's name.

Adding a kind = one module (the kind class and its spec class) and one registry line (for the shipped kinds:
the lines at the end; from another package: an entry point, :func:`load_plugins`).
"""

from __future__ import annotations

from .base import KINDS, TargetKind, TargetSpec, get_kind, register, unregister


def _register_shipped() -> None:
    from .aruco import AprilTagGridKind, CharucoKind
    from .chessboard import ChessboardKind
    from .circles import AsymmetricCirclesKind, ModifiedCircleGridKind

    for cls in (CharucoKind, AprilTagGridKind, ChessboardKind, AsymmetricCirclesKind, ModifiedCircleGridKind):
        register(cls())


_register_shipped()

__all__ = ["KINDS", "TargetKind", "TargetSpec", "get_kind", "register", "unregister"]
