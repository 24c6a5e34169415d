"""URDF files as text: their kinematic content read with the standard library's XML parser, and written back with
only joint origins changed (:mod:`vision_calib.kinematics.urdf` builds and calibrates the chain from it).

Only ``<robot>``, ``<link name>`` and ``<joint>`` (type, parent, child, origin, axis, limit, mimic) are read: no
mesh or other file named in the URDF is opened, so no path inside it leads anywhere. Checks (ConfigError naming
the file and the joint): well-formed XML, unique names, origins/axes/limits with exactly the right count of
numbers, and the joints forming one tree (one root link, no link with two parents, no loop).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ConfigError

#: joint types that move (one joint value each)
MOVABLE = ("revolute", "continuous", "prismatic")


@dataclass(frozen=True)
class UrdfLimit:
    lower: float | None
    upper: float | None


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>`` as read: origin (4, 4) in the parent link's frame [m], axis (3,) or None, limit."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray | None
    axis: np.ndarray | None
    limit: UrdfLimit | None
    mimic: str | None


@dataclass(frozen=True)
class UrdfRobot:
    """The kinematic content of a URDF file: robot name, link names, joints (file order), the XML tree."""

    name: str
    links: tuple[str, ...]
    joints: tuple[UrdfJoint, ...]
    tree: object  # xml.etree.ElementTree.ElementTree (for writing back with only origins changed)


def _floats(el, attr: str, n: int, default, where: str) -> np.ndarray:
    """``n`` floats of an XML attribute (space-separated); ConfigError naming ``where`` unless exactly n numbers."""
    text = el.get(attr) if el is not None else None
    if text is None:
        return np.array(default, float)
    parts = text.split()
    try:
        vals = np.array([float(v) for v in parts], float)
    except ValueError:
        raise ConfigError(f"{where}: {el.tag} {attr}={text!r} is not a list of numbers") from None
    if vals.size != n:
        raise ConfigError(f"{where}: {el.tag} {attr}={text!r} must hold exactly {n} numbers, got {vals.size}")
    return vals


def _origin_matrix(el, where: str) -> np.ndarray:
    """(4, 4) of an ``<origin xyz rpy>`` element (URDF: R = Rz(yaw) Ry(pitch) Rx(roll)); identity if absent."""
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    if el is None:
        return T
    xyz = _floats(el, "xyz", 3, (0.0, 0.0, 0.0), where)
    rpy = _floats(el, "rpy", 3, (0.0, 0.0, 0.0), where)
    if np.all(np.isfinite(rpy)):
        T[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
    else:
        T[:3, :3] = np.nan
    T[:3, 3] = xyz
    return T


def read_urdf(path: Path) -> UrdfRobot:
    """The kinematic content of the URDF file ``path``, read with the standard library's XML parser (no
    mesh, no package:// path and no other file is opened). Checks: well-formed XML, ``<robot>`` root, unique
    link and joint names, every joint with a type, a parent and a child, origins/axes/limits with the right
    number of numbers, and the joints forming a tree (one root link, no link with two parents, no cycle).
    ConfigError naming the file and joint."""
    import xml.etree.ElementTree as ET

    if not path.is_file():
        raise ConfigError(f"{path}: URDF file not found")
    try:
        tree = ET.parse(path)
    except ET.ParseError as exc:
        raise ConfigError(f"{path}: not well-formed XML (line {exc.position[0]}, column {exc.position[1]}): {exc}") from None
    root = tree.getroot()
    if root.tag != "robot":
        raise ConfigError(f"{path}: the root element must be <robot>, got <{root.tag}>")
    for kind in ("link", "joint"):
        seen = set()
        for el in root.findall(kind):
            nm = el.get("name")
            if not nm:
                raise ConfigError(f"{path}: a <{kind}> has no name attribute")
            if nm in seen:
                raise ConfigError(f"{path}: {kind} {nm!r} is defined twice")
            seen.add(nm)
    links = tuple(el.get("name") for el in root.findall("link"))
    joints = []
    for el in root.findall("joint"):
        where = f"{path}: joint {el.get('name')!r}"
        refs = {}
        for role in ("parent", "child"):
            sub = el.find(role)
            if sub is None or not sub.get("link"):
                raise ConfigError(f"{where}: needs <{role} link=...>")
            refs[role] = sub.get("link")
        jtype = el.get("type")
        if not jtype:
            raise ConfigError(f"{where}: has no type attribute")
        axis_el = el.find("axis")
        lim_el = el.find("limit")
        limit = None
        if lim_el is not None:
            vals = {k: (None if lim_el.get(k) is None else _floats(lim_el, k, 1, (), where)[0]) for k in ("lower", "upper")}
            limit = UrdfLimit(vals["lower"], vals["upper"])
        mimic_el = el.find("mimic")
        joints.append(UrdfJoint(el.get("name"), jtype, refs["parent"], refs["child"],
                                _origin_matrix(el.find("origin"), where),
                                None if axis_el is None else _floats(axis_el, "xyz", 3, (1.0, 0.0, 0.0), where),
                                limit, None if mimic_el is None else mimic_el.get("joint", "")))
    robot = UrdfRobot(root.get("name", path.stem), links, tuple(joints), tree)
    _check_tree(robot, path)
    return robot


def _check_tree(robot: UrdfRobot, path: Path) -> None:
    """ConfigError unless the joints make the links one tree: each joint's links defined, no link the child
    of two joints, exactly one root link, and every link reachable from it (no cycle)."""
    links = set(robot.links)
    parent_of: dict[str, UrdfJoint] = {}
    for j in robot.joints:
        for role, lk in (("parent", j.parent), ("child", j.child)):
            if lk not in links:
                raise ConfigError(f"{path}: joint {j.name!r}: {role} link {lk!r} is not defined")
        if j.child in parent_of:
            raise ConfigError(f"{path}: link {j.child!r} is the child of two joints ({parent_of[j.child].name!r} and "
                              f"{j.name!r}): a URDF must be a tree")
        parent_of[j.child] = j
    roots = [lk for lk in robot.links if lk not in parent_of]
    if len(roots) != 1:
        cyc = sorted(j.name for j in robot.joints)
        raise ConfigError(f"{path}: the links must form one tree with one root link, found {len(roots)} root links "
                          f"({', '.join(roots) or 'none: the joints ' + ', '.join(map(repr, cyc[:6])) + ' form a loop'})")
    children: dict[str, list[str]] = {}
    for j in robot.joints:
        children.setdefault(j.parent, []).append(j.child)
    reached, todo = {roots[0]}, [roots[0]]
    while todo:
        for c in children.get(todo.pop(), ()):
            if c not in reached:
                reached.add(c)
                todo.append(c)
    if reached != links:
        lost = sorted(links - reached)
        loop = [j.name for j in robot.joints if j.child in lost]
        raise ConfigError(f"{path}: the joints {', '.join(map(repr, loop[:6]))} form a loop through links "
                          f"{', '.join(map(repr, lost[:6]))}, not reachable from the root link {roots[0]!r} "
                          "(a URDF must be a tree)")


def urdf_leaves(path: str | os.PathLike) -> tuple[str, list[tuple[str, int]]]:
    """(root link, [(leaf link, number of movable joints from the root to it)]) of the URDF file ``path``, for
    guessing a chain (``vision-calib init --urdf``); leaves with no movable joint above them are left out."""
    robot = read_urdf(Path(path))
    parent_of = {j.child: j for j in robot.joints}
    root = next(lk for lk in robot.links if lk not in parent_of)
    has_child = {j.parent for j in robot.joints}
    out = []
    for leaf in robot.links:
        if leaf in has_child or leaf == root:
            continue
        n, link = 0, leaf
        while link in parent_of:
            n += parent_of[link].type in MOVABLE
            link = parent_of[link].parent
        if n:
            out.append((leaf, n))
    return root, out




# ----------------------------------------------------------------------------- writing URDF
def set_origin(joint_el, T) -> None:
    """Set the ``<origin xyz rpy>`` of a ``<joint>`` element to T (4, 4) (full float precision)."""
    import xml.etree.ElementTree as ET
    from scipy.spatial.transform import Rotation

    el = joint_el.find("origin")
    if el is None:
        el = ET.Element("origin")
        joint_el.insert(0, el)
    rpy = Rotation.from_matrix(np.asarray(T)[:3, :3]).as_euler("xyz")
    el.set("xyz", " ".join(repr(float(v)) for v in np.asarray(T)[:3, 3]))
    el.set("rpy", " ".join(repr(float(v)) for v in rpy))


def urdf_xml_text(tree) -> str:
    """The XML text of an ElementTree (with declaration), as written by :func:`export_urdf`."""
    import xml.etree.ElementTree as ET

    return '<?xml version="1.0"?>\n' + ET.tostring(tree.getroot(), encoding="unicode") + "\n"
