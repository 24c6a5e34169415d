"""Robot and target kinds from other packages, through entry points (bottom floor: any module may use it).

A package adds kinds by declaring, in its ``pyproject.toml``::

    [project.entry-points."vision_calib.robots"]
    my_arm = "my_package.arm:MyArmSetup"        # a rig.base.Setup subclass (rig.registry.register)

    [project.entry-points."vision_calib.targets"]
    my_board = "my_package.board:MyBoardKind"   # a targets.kinds.TargetKind subclass or instance

The registries load their group once, after the shipped kinds (:data:`ROBOT_GROUP`, :data:`TARGET_GROUP`). A
plugin that fails to load is reported by a warning naming it and its error; the other kinds stay usable.
"""

from __future__ import annotations

import warnings
from importlib.metadata import entry_points

ROBOT_GROUP = "vision_calib.robots"
TARGET_GROUP = "vision_calib.targets"


class PluginWarning(UserWarning):
    """A plugin's entry point could not be loaded or registered."""


def load_entry_points(group: str, register) -> list[str]:
    """Load every entry point of ``group`` and pass the loaded object to ``register``; returns the names of the
    entry points registered (a failing one: PluginWarning naming it, skipped)."""
    done = []
    for ep in sorted(entry_points(group=group), key=lambda e: e.name):
        try:
            register(ep.load())
        except Exception as exc:  # noqa: BLE001 -- a broken third-party plugin must not break the package
            warnings.warn(f"vision_calib plugin {ep.name!r} ({ep.value}, entry point group {group!r}) was not "
                          f"loaded: {type(exc).__name__}: {exc}", PluginWarning, stacklevel=2)
            continue
        done.append(ep.name)
    return done
