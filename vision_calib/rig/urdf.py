"""Serial robots read from URDF (``kinematics.urdf.URDFChain``: per-joint placement errors + joint
offsets, reduced to a base set by the identifiability analysis), with the camera/target mounts of
:mod:`.serial` (eye-in-hand or fixed camera). The calibrated robot is also written back as URDF
(``calibrated_model.urdf``: only the movable joints' origins changed).

Scene keys of this kind: ``urdf: {base_link, tip_link}`` (the chain, tip = flange; both optional: default
the URDF's root link and the one leaf link below the most movable joints, :func:`default_links`), ``mounts``
and ``poses.center`` / ``poses.spread`` as for serial robots.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

from numpy.typing import ArrayLike

from ..config import Section
from ..errors import ConfigError
from ..kinematics.urdf import URDFChain
from .serial import MOUNTS, SerialSetup


def default_links(path: str | Path) -> tuple[str, str]:
    """(base_link, tip_link) of a URDF when the scene names none: its root link, and the leaf link with the most
    movable (non-fixed) joints on its way up to the root, when exactly one leaf has that many. ConfigError naming
    the candidates otherwise (a gripper's fingers, two arms: give ``urdf: {base_link, tip_link}``). Only names
    are read here; the chain itself is checked by ``kinematics.urdf.load_urdf_robot``."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise ConfigError(f"{path}: cannot be read as URDF ({exc})") from None
    links = [el.get("name") for el in root.findall("link")]
    parent = {}  # child link -> (parent link, movable)
    for j in root.findall("joint"):
        p, c = j.find("parent"), j.find("child")
        if p is not None and c is not None:
            parent[c.get("link")] = (p.get("link"), j.get("type") != "fixed")
    roots = [lk for lk in links if lk not in parent]
    if len(roots) != 1:
        raise ConfigError(f"{path}: {len(roots)} root links ({', '.join(map(str, roots)) or 'none'}): give "
                          "urdf: {base_link, tip_link} in the scene")
    parents = {p for p, _ in parent.values()}
    depth = {}
    for leaf in (lk for lk in links if lk not in parents):
        n, lk, seen = 0, leaf, set()
        while lk in parent and lk not in seen:
            seen.add(lk)
            lk, movable = parent[lk]
            n += movable
        depth[leaf] = n
    most = max(depth.values(), default=0)
    tips = [lk for lk, n in depth.items() if n == most]
    if most == 0 or len(tips) != 1:
        raise ConfigError(f"{path}: no single tip link to calibrate up to ({len(tips)} leaf links below {most} movable "
                          f"joints: {', '.join(tips)}): give urdf: {{base_link, tip_link}} in the scene")
    return roots[0], tips[0]


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

        sec = ctx.top.section("urdf", default={}).check_known(("base_link", "tip_link"))
        left, right = MOUNTS[ctx.mount]
        base, tip = (None, None) if "base_link" in sec and "tip_link" in sec else default_links(ctx.robot_path)
        return load_urdf_robot(ctx.robot_path, sec.get("base_link", str, base), sec.get("tip_link", str, tip), left,
                               right)

    def joint_names(self) -> tuple[str, ...]:
        """The URDF names of the chain's movable joints, base to tip."""
        return tuple(self.chain.meta["joint_names"])

    def link_names(self) -> tuple[str, ...]:
        """URDF names of the :meth:`link_frames`: base_link, the child links of movable joints 1..n-1, tip_link, and
        the right mount (e.g. T_flange_cam)."""
        from ..kinematics.urdf_file import read_urdf

        m = self.chain.meta
        child = {j.name: j.child for j in read_urdf(Path(m["file"])).joints}
        return ((m["base_link"],) + tuple(child[j] for j in m["joint_names"][:-1]) + (m["tip_link"], self.chain.right))

    def model_dict(self) -> dict:
        m = self.chain.meta
        return {**super().model_dict(), "urdf": {"base_link": m["base_link"], "tip_link": m["tip_link"]}}

    @classmethod
    def load_model(cls, doc: Section, robot_path: Path) -> URDFChain:
        from ..kinematics.urdf import load_urdf_robot

        links = doc.section("urdf").check_known(("base_link", "tip_link"))
        return cls._model_mounts(load_urdf_robot(robot_path, links.get("base_link", str), links.get("tip_link", str)),
                                 doc)

    def export_model_files(self, out_dir: str | Path, x: ArrayLike) -> dict:
        """``calibrated_model.urdf``: the source URDF with the calibrated joint origins (atomic write)."""
        from ..serialize import write_bytes_atomic
        from ..kinematics.urdf import export_urdf

        with tempfile.TemporaryDirectory() as tmp:
            p = export_urdf(self.chain, x, Path(tmp) / "calibrated_model.urdf")
            write_bytes_atomic(Path(out_dir) / "calibrated_model.urdf", p.read_bytes())
        return {"urdf": "calibrated_model.urdf"}
