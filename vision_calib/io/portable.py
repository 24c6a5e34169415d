"""Paths in output files (issue 19 item 4): stored relative to the folder of the file that holds them, and the
small input files a written file needs (robot file, scene, target) copied next to it, so a result or exported
folder stays whole when it is moved (``config.confine`` refuses a ``../`` path out of a file's folder anyway).

Layout of a copied scene (:func:`copy_scene_bundle`, e.g. FOLDER = ``recording/scene``)::

    FOLDER/<scene stem>.yaml          the scene, its ``robot`` and ``target`` pointing at the copies below
    FOLDER/robot/<robot file name>
    FOLDER/target/<target file name>  (when the scene names a target)
    FOLDER/poses/<pose file name>     (when the scene's poses come from a file: ``poses: {kind: file}``)
"""

from __future__ import annotations

import os
from pathlib import Path

import yaml

from ..serialize import write_bytes_atomic, write_text_atomic

#: keys of report.json's ``source`` (and of its ``scene``) whose values are file or folder paths
SOURCE_PATH_KEYS = ("path", "folder", "file", "csv", "flange_csv")


def relative_ref(path, holder_dir) -> str:
    """``path`` as written into a file of the folder ``holder_dir``: relative to it (symbolic links resolved,
    '/' separators), never absolute."""
    try:
        return Path(os.path.relpath(Path(path).resolve(), Path(holder_dir).resolve())).as_posix()
    except ValueError:  # another drive (Windows): no relative path exists
        return Path(path).resolve().as_posix()


def copy_file(src, dest) -> Path:
    """Copy the file ``src`` to ``dest`` (atomic; parents created); returns ``dest``."""
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    return write_bytes_atomic(dest, Path(src).read_bytes())


def copy_robot_file(robot_path, holder_dir, sub: str = "robot") -> str:
    """Copy the robot file into ``holder_dir/sub/`` and return its reference relative to ``holder_dir``."""
    robot_path = Path(robot_path)
    dest = copy_file(robot_path, Path(holder_dir) / sub / robot_path.name)
    return relative_ref(dest, holder_dir)


def copy_scene_bundle(scene, folder) -> Path:
    """Copy ``scene`` (a loaded ``rig.scene.Scene``) with its robot and target files into ``folder`` (layout in
    the module docstring); the copied scene names them relatively and keeps the scene's name. Returns the
    path of the copied scene file. The scene's comments are not kept (it is rewritten as YAML)."""
    from ..config import load_yaml

    folder = Path(folder)
    doc = dict(load_yaml(scene.path))
    doc["name"] = scene.name
    robot_path = scene.setup.meta.get("robot_path")
    if robot_path is not None:
        doc["robot"] = copy_robot_file(robot_path, folder)
    if scene.target_path is not None:
        tp = Path(scene.target_path)
        doc["target"] = relative_ref(copy_file(tp, folder / "target" / tp.name), folder)
    if scene.poses.path is not None and isinstance(doc.get("poses"), dict):  # poses: {kind: file, path: ...}
        pp = Path(scene.poses.path)
        doc["poses"] = {**doc["poses"], "path": relative_ref(copy_file(pp, folder / "poses" / pp.name), folder)}
        if "units" not in doc["poses"] and pp.parent.joinpath("recording.yaml").is_file():
            # the unit came from the recording.yaml beside the file, which is not copied: write it down
            doc["poses"]["units"] = {"angle": "rad" if abs(scene.poses.angle_factor - 1.0) < 1e-15 else "deg"}
    head = (f"# scene {scene.name!r} as used for this folder (copied by vision_calib: robot and target name the "
            "copies next to it)\n")
    return write_text_atomic(folder / Path(scene.path).name, head + yaml.safe_dump(doc, sort_keys=False))


def relative_source(source: dict, holder_dir) -> dict:
    """report.json's ``source`` block with its paths (:data:`SOURCE_PATH_KEYS`, also inside ``scene``) made
    relative to ``holder_dir`` (the report's folder)."""
    out = {}
    for k, v in source.items():
        if isinstance(v, dict):
            out[k] = relative_source(v, holder_dir)
        elif k in SOURCE_PATH_KEYS and isinstance(v, (str, os.PathLike)) and str(v):
            out[k] = relative_ref(v, holder_dir)
        else:
            out[k] = v
    return out


__all__ = ["relative_ref", "copy_file", "copy_robot_file", "copy_scene_bundle", "relative_source"]
