"""Serial robots read from URDF (``kinematics.urdf.URDFChain``: per-joint placement errors + joint
offsets, reduced to a base set by the identifiability analysis), with the camera/target mounts of
:mod:`.serial` (eye-in-hand or fixed camera). The calibrated robot is also written back as URDF
(``calibrated_model.urdf``: only the movable joints' origins changed).

Scene keys of this kind: ``urdf: {base_link, tip_link}`` (the chain, tip = flange), ``mounts`` and
``poses.center`` / ``poses.spread`` as for serial robots.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from .serial import MOUNTS, SerialSetup


@dataclass(frozen=True)
class URDFSetup(SerialSetup):
    kind: ClassVar[str] = "urdf"
    scene_keys: ClassVar[tuple[str, ...]] = ("mounts", "urdf")

    @staticmethod
    def claims(robot_path: Path, doc: dict | None) -> bool:
        return Path(robot_path).suffix.lower() == ".urdf"

    @classmethod
    def load_chain(cls, ctx):
        from ..kinematics.urdf import load_urdf_robot

        sec = ctx.top.section("urdf").check_known(("base_link", "tip_link"))
        left, right = MOUNTS[ctx.mount]
        return load_urdf_robot(ctx.robot_path, sec.get("base_link", str), sec.get("tip_link", str), left, right)

    def model_dict(self) -> dict:
        m = self.chain.meta
        return {**super().model_dict(), "urdf": {"base_link": m["base_link"], "tip_link": m["tip_link"]}}

    @classmethod
    def load_model(cls, doc, robot_path: Path):
        from ..kinematics.urdf import load_urdf_robot

        links = doc.section("urdf").check_known(("base_link", "tip_link"))
        return cls._model_mounts(load_urdf_robot(robot_path, links.get("base_link", str), links.get("tip_link", str)),
                                 doc)

    def export_model_files(self, out_dir, x) -> dict:
        """``calibrated_model.urdf``: the source URDF with the calibrated joint origins (atomic write)."""
        from ..serialize import write_bytes_atomic
        from ..kinematics.urdf import export_urdf

        with tempfile.TemporaryDirectory() as tmp:
            p = export_urdf(self.chain, x, Path(tmp) / "calibrated_model.urdf")
            write_bytes_atomic(Path(out_dir) / "calibrated_model.urdf", p.read_bytes())
        return {"urdf": "calibrated_model.urdf"}
