"""The robot-kind registry: THE one place that knows which robot kinds exist.

A robot kind is a :class:`~vision_calib.rig.base.Setup` subclass that also provides:

- ``kind`` (its name, e.g. ``"serial"``), ``mounts`` (camera mounts it supports), ``residuals`` and
  ``methods`` (first = default);
- ``claims(robot_path, doc) -> bool``: whether a robot file is of this kind (``doc`` is the parsed
  YAML mapping, or None for a non-YAML file such as a URDF);
- ``from_scene(ctx) -> Setup``: build the setup of a scene (:class:`vision_calib.rig.scene.SceneContext`);
- ``load_model(doc, robot_path)``: rebuild the robot of a calibrated-model file;
- optionally, the capabilities of :mod:`vision_calib.rig.base` it has (``PoseGrids``, ``NamedConfigurations``,
  ``NamedTrials``, ``ModelVariants``, ``TiltsFromAxis``, ``ChainMeasured``): plain methods and attributes, checked
  with ``isinstance`` where they are used.

Adding a robot kind = writing that class and calling :func:`register` on it (for the shipped kinds:
one line below; from another package: an entry point of the group ``vision_calib.robots``,
:mod:`vision_calib.plugins`). Nothing else in the package branches on the kind.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol, runtime_checkable

from ..config import Section
from ..errors import ConfigError
from ..plugins import ROBOT_GROUP, load_entry_points
from .base import Setup

KINDS: dict = {}


@runtime_checkable
class RobotKind(Protocol):
    """What a robot kind class has besides the members of :class:`~vision_calib.rig.base.Setup` (``kind``,
    ``residuals``, ``methods``): see the module docstring. ``isinstance(cls, RobotKind)`` on the class."""

    mounts: tuple[str, ...]

    def claims(self, robot_path: Path, doc: dict | None) -> bool: ...

    def from_scene(self, ctx) -> Setup: ...

    def load_model(self, doc: Section, robot_path: Path): ...


def register(cls: type[Setup]) -> type[Setup]:
    """Register a Setup subclass of the :class:`RobotKind` interface as a robot kind (returns it, usable as a
    decorator); TypeError naming what it lacks."""
    if not (isinstance(cls, type) and issubclass(cls, Setup)):
        raise TypeError(f"a robot kind must be a Setup subclass, got {cls!r}")
    if not isinstance(cls, RobotKind):
        missing = [m for m in ("mounts", "claims", "from_scene", "load_model") if m not in dir(cls)]
        raise TypeError(f"robot kind {cls.__name__} lacks {', '.join(map(repr, missing))} (rig.registry.RobotKind)")
    KINDS[cls.kind] = cls
    return cls


def unregister(kind: str) -> None:
    """Remove a registered kind (tests registering toy kinds clean up with it)."""
    KINDS.pop(kind, None)


def get_kind(name: str, where: str = "kind") -> type[Setup]:
    """The Setup class of a kind name; ConfigError naming ``where`` and the known kinds."""
    try:
        return KINDS[name]
    except KeyError:
        raise ConfigError(f"{where}: unknown robot kind {name!r} (known: {', '.join(sorted(KINDS))})") from None


def kind_of_robot_file(path: str | Path, where: str = "robot") -> type[Setup]:
    """The Setup class whose ``claims`` accepts the robot file at ``path``."""
    path = Path(path)
    doc = None
    if path.suffix.lower() in (".yaml", ".yml"):
        from ..config import load_yaml

        doc = load_yaml(path)
    for cls in KINDS.values():
        if cls.claims(path, doc):
            return cls
    raise ConfigError(f"{where}: {path}: no robot kind reads this file (known kinds: {', '.join(sorted(KINDS))})")


def _register_shipped() -> None:
    from .h4 import H4Setup
    from .serial import SerialSetup
    from .urdf import URDFSetup

    for cls in (H4Setup, URDFSetup, SerialSetup):
        register(cls)


_register_shipped()
PLUGINS = load_entry_points(ROBOT_GROUP, register)  #: names of the robot kinds registered by entry points
