"""``vision-calib init``: a self-contained folder to start your own cell from, copied from the shipped data.

From a shipped cell (``--from ur5e|rx90|h4|thesis_tripod|...``)::

    DIR/scene.yaml        the entry point: the shipped scene, its ``robot`` and ``target`` naming the copies below,
                          each key a user edits commented
    DIR/robot/<file>      the robot file (MDH table YAML, H4 YAML or URDF)
    DIR/target.yaml       the target definition (print it with ``vision-calib target DIR/target.yaml --paper A4``)

From the example recording (``--from example``): DIR is a copy of the recording (``recording.yaml``,
``poses.csv``, ``images/``, ``scene/``): ``vision-calib process DIR --out RESULT`` runs on it.

From your own URDF (``--urdf my_robot.urdf``): the URDF cell (default ``ur5e``) with your robot file; the chain's
``base_link`` is the URDF's root link and ``tip_link`` the leaf with the most movable joints above it (both
printed with the other candidates; ``--base-link`` / ``--tip-link`` override); ``poses.center`` is the middle of
the joint limits when the arm has another joint count than the cell's: edit the mounts and the poses so that the camera sees the board.
"""

from __future__ import annotations

import re
import shutil
from dataclasses import dataclass
from pathlib import Path

import yaml

from ..config import load_yaml
from ..errors import ConfigError
from ..serialize import write_text_atomic
from ..shipped import examples_dir, scenes_dir, targets_dir
from .portable import copy_file


@dataclass(frozen=True)
class Starter:
    """A shipped starting point: a scene (``scenes/<scene>.yaml``) or an example recording (``examples/<example>``)."""

    name: str
    what: str
    scene: str | None = None
    example: str | None = None


#: the starting points ``init --list`` names (a shipped scene's own stem is accepted too)
STARTERS = (
    Starter("ur5e", "Universal Robots UR5e (URDF), camera on the flange, A5 ChArUco on the table", scene="ur5e_eye_in_hand"),
    Starter("rx90", "Staubli RX-90 (modified DH), camera on the flange, A5 ChArUco on the table", scene="rx90_eye_in_hand"),
    Starter("h4", "H4 parallel robot, camera on the base, ChArUco on the nacelle", scene="h4_vision"),
    Starter("thesis_tripod", "the thesis' arm holding a probe with a board, camera on a tripod (fixed)",
            scene="thesis_arm_tripod_probe"),
    Starter("example", "the example recording: RX-90, 12 poses x 1 photo (process it)", example="rx90_eye_in_hand"),
)

#: end-of-line comments for the scene keys a user edits (added where the shipped line has none)
KEY_COMMENTS = {
    "name": "a name for your cell (shown in reports)",
    "robot": "your robot file (copied here): MDH table YAML, H4 YAML or URDF",
    "urdf": "the calibrated chain of the URDF: base_link -> tip_link (the flange)",
    "mount": "eye_in_hand: camera on the flange, board fixed; fixed: camera on a stand, board on the flange",
    "model": "H4 model: '12' or '31' parameters (paper)",
    "units": "units of the numbers below (length m|cm|mm, angle rad|deg)",
    "mounts": "nominal placement of the board and the camera (xyz, rpy in the units above)",
    "camera": "your camera: image size [px], focal (fx, fy [px] or focal_mm + pixel_um), cx, cy, distortion k1 k2 p1 p2 k3",
    "target": "your board (copied here); print it: vision-calib target target.yaml --paper A4",
    "effects": "simulation only: image noise and blur of the simulated camera",
    "render": "simulation only: rendering settings",
    "truth": "simulation only: how far the simulated true robot is from the nominal one",
    "poses": "poses to simulate / identify on: joint sets around `center` +- `spread` (in units.angle)",
    "validation": "held-out poses for the accuracy check",
    "measurement": "frames averaged per pose and the pose noise of the measurement",
    "identification": "method (lse | ekf) and residual (pose | position)",
}


def starter(name: str) -> Starter:
    """The starting point named ``name`` (a :data:`STARTERS` name, or a shipped scene's stem); ConfigError listing them."""
    for s in STARTERS:
        if name == s.name:
            return s
    if (scenes_dir() / f"{name}.yaml").is_file():
        return Starter(name, f"shipped scene {name}", scene=name)
    if (examples_dir() / name / "recording.yaml").is_file():
        return Starter(name, f"shipped example recording {name}", example=name)
    known = [s.name for s in STARTERS] + sorted(p.stem for p in scenes_dir().glob("*.yaml"))
    raise ConfigError(f"init --from {name!r}: no such starting point (known: {', '.join(known)}; "
                      "vision-calib init --list)")


def list_starters() -> str:
    """The text ``init --list`` prints: one line per starting point, then the other shipped scenes."""
    lines = [f"  {s.name:<14} {s.what}" for s in STARTERS]
    named = {s.scene for s in STARTERS}
    others = sorted(p.stem for p in scenes_dir().glob("*.yaml") if p.stem not in named)
    if others:
        lines.append("  other shipped scenes (by name): " + ", ".join(others))
    return "starting points for `vision-calib init DIR --from NAME`:\n" + "\n".join(lines)


def _empty_target_dir(dest: Path) -> None:
    if dest.exists() and (not dest.is_dir() or any(dest.iterdir())):
        raise ConfigError(f"init: {dest} already exists and is not an empty folder: choose a new folder "
                          "(nothing was written)")


def _flow(value) -> str:
    """``value`` (str, number, list, dict) as one line of YAML (PyYAML's emitter, flow style, strings double-quoted:
    quotes, ``#``, ``: `` and line breaks escaped, never a new key)."""
    out = yaml.safe_dump(value, default_flow_style=True, default_style='"', width=float("inf"), allow_unicode=False)
    out = out.rstrip("\n")
    if "\n" in out:  # the emitter kept it on one line above; a change there must not go unnoticed
        raise ConfigError(f"init: cannot write {value!r} on one YAML line")
    return out


def _set_line(text: str, key: str, value) -> str:
    """``text`` with its top-level ``key:`` line set to ``key: <value as YAML>`` (:func:`_flow`; comment kept), or
    the line appended."""
    value = _flow(value)
    pat = re.compile(rf"^{re.escape(key)}:[^\n#]*(#[^\n]*)?$", re.M)
    m = pat.search(text)
    if m is None:
        return text.rstrip("\n") + f"\n{key}: {value}\n"
    return text[: m.start()] + f"{key}: {value}" + (f"  {m.group(1)}" if m.group(1) else "") + text[m.end():]


def _comment_keys(text: str) -> str:
    """Append :data:`KEY_COMMENTS` to the top-level key lines that carry no comment yet."""
    out = []
    for line in text.splitlines():
        m = re.match(r"^([A-Za-z_]\w*):", line)
        if m and m.group(1) in KEY_COMMENTS and "#" not in line:
            line = f"{line}  # {KEY_COMMENTS[m.group(1)]}"
        out.append(line)
    return "\n".join(out) + "\n"


def init_cell(dest, name: str | None = None, urdf=None, base_link: str | None = None,
              tip_link: str | None = None) -> dict:
    """Write the starting folder ``dest`` (module docstring) from the starting point ``name`` (default ``ur5e``
    with ``urdf``) or the user's ``urdf`` file. Returns {"folder", "entry" (scene.yaml or the recording folder),
    "notes": [str]}. ConfigError (nothing written) when ``dest`` is a non-empty folder, the name is unknown, or
    the URDF has no usable chain."""
    dest = Path(dest)
    st = starter(name or "ur5e")
    _empty_target_dir(dest)
    if urdf is not None and st.scene is None:
        raise ConfigError(f"init --urdf: start from a shipped cell (--from ur5e), not the recording {st.name!r}")
    if st.example is not None:
        src = examples_dir() / st.example
        shutil.copytree(src, dest, symlinks=False, dirs_exist_ok=True)
        return {"folder": str(dest), "entry": str(dest),
                "notes": [f"copied the example recording {st.example} into {dest}: "
                          f"vision-calib process {dest} --out RESULT"]}
    scene_file = scenes_dir() / f"{st.scene}.yaml"
    doc = load_yaml(scene_file)
    text = scene_file.read_text(encoding="utf-8")
    notes: list[str] = []
    robot_src = scene_file.parent / str(doc["robot"])
    if urdf is not None:
        robot_src = Path(urdf)
        if robot_src.suffix.lower() != ".urdf" or "urdf" not in doc:
            raise ConfigError(f"init --urdf {urdf}: needs a .urdf file and a URDF cell to start from (--from ur5e)")
        base, tip, n, mid, note = _urdf_chain_guess(robot_src, base_link, tip_link)
        notes.append(note)
        text = _set_line(text, "urdf", {"base_link": base, "tip_link": tip})
        if len((doc.get("poses") or {}).get("center") or ()) != n:  # the cell's own joint sets fit another arm
            text = _urdf_poses(text, n, mid)
        text = _set_line(text, "name", f"{robot_src.stem}_cell")
    else:
        base = tip = None
        notes.append("edit mounts (where the board and the camera are) and poses.center/spread so that the camera "
                     "sees the board, then check with: vision-calib identifiability " + str(dest / "scene.yaml"))
    robot_ref = f"robot/{robot_src.name}"
    text = _set_line(text, "robot", robot_ref)
    if doc.get("target"):
        target_src = (scene_file.parent / str(doc["target"])).resolve()
        if not target_src.is_file():  # a shipped scene naming a shipped target by its folder
            target_src = targets_dir() / Path(str(doc["target"])).name
        text = _set_line(text, "target", "target.yaml")
    head = (f"# Your cell, started from the shipped scene {st.scene!r} by `vision-calib init` ({st.what}).\n"
            "# Every file it names is in this folder: edit them in place. Keys you edit are commented.\n")
    text = head + _comment_keys(text)
    want = {"robot": robot_ref, **({"target": "target.yaml"} if doc.get("target") else {}),
            **({"urdf": {"base_link": base, "tip_link": tip}, "name": f"{robot_src.stem}_cell"} if urdf is not None
               else {})}
    _check_scene_text(text, set(doc) | set(want), want, "scene.yaml (not written)")
    copy_file(robot_src, dest / robot_ref)
    if doc.get("target"):
        copy_file(target_src, dest / "target.yaml")
    entry = write_text_atomic(dest / "scene.yaml", text)
    _check_scene_text(load_yaml(entry), set(doc) | set(want), want, str(entry))  # as the scene loader reads it
    notes.insert(0, f"wrote {entry} (+ {robot_ref}{', target.yaml' if doc.get('target') else ''})")
    return {"folder": str(dest), "entry": str(entry), "notes": notes}


def _check_scene_text(text, keys: set, want: dict, where: str) -> None:
    """Read the scene text (or its loaded dict) back: ConfigError naming ``where`` unless it loads as YAML, its
    top-level keys are ``keys`` and the values of ``want`` are there as written."""
    try:
        doc = yaml.safe_load(text) if isinstance(text, str) else text
    except yaml.YAMLError as exc:
        raise ConfigError(f"init: {where} does not load as YAML ({exc})") from None
    if not isinstance(doc, dict) or set(doc) != keys:
        raise ConfigError(f"init: {where} reads back with the keys {sorted(doc) if isinstance(doc, dict) else doc!r}, "
                          f"expected {sorted(keys)}")
    bad = [k for k, v in want.items() if doc.get(k) != v]
    if bad:
        raise ConfigError(f"init: {where}: {bad[0]} reads back as {doc.get(bad[0])!r}, written {want[bad[0]]!r}")


def _urdf_chain_guess(path: Path, base_link, tip_link):
    """(base, tip, n movable joints, joint-limit middles [rad], note) of a user's URDF: the root link and the
    leaf with the most movable joints above it unless given; the note lists the candidates."""
    import numpy as np

    from ..kinematics.urdf import load_urdf_robot
    from ..kinematics.urdf_file import urdf_leaves

    root, leaves = urdf_leaves(path)
    base = base_link or root
    if tip_link is None:
        if not leaves:
            raise ConfigError(f"{path}: no link below {base!r} with a movable joint above it: give --tip-link")
        tip = max(leaves, key=lambda kv: kv[1])[0]
    else:
        tip = tip_link
    chain = load_urdf_robot(path, base, tip)
    lim = np.asarray(chain.joint_limits, float)
    mid = np.where(np.isfinite(lim).all(axis=1), lim.mean(axis=1), 0.0)
    cands = ", ".join(f"{lk} ({n} joints)" for lk, n in sorted(leaves, key=lambda kv: -kv[1]))
    note = (f"{path.name}: base_link {base!r}{'' if base_link else ' (the root link)'}, tip_link {tip!r}"
            f"{'' if tip_link else ' (guessed)'}, {chain.n_joints} movable joints; tip candidates: {cands}; "
            "override with --base-link / --tip-link")
    return base, tip, chain.n_joints, mid, note


def _urdf_poses(text: str, n: int, mid) -> str:
    """The ``poses`` block's center/spread lines set for ``n`` joints (center: ``mid`` [rad] in the scene's angle
    unit; spread: 20 deg or its equivalent)."""
    import numpy as np

    deg = re.search(r"^units:.*angle:\s*deg", text, re.M) is not None
    center = np.degrees(mid) if deg else np.asarray(mid)
    spread = np.full(n, 20.0 if deg else np.radians(20.0))
    fmt = (lambda v: ", ".join(f"{x:.1f}" for x in v)) if deg else (lambda v: ", ".join(f"{x:.4f}" for x in v))
    text = re.sub(r"^(\s+center:\s*)\[[^\]]*\]", lambda m: f"{m.group(1)}[{fmt(center)}]", text, count=1, flags=re.M)
    return re.sub(r"^(\s+spread:\s*)\[[^\]]*\]", lambda m: f"{m.group(1)}[{fmt(spread)}]", text, count=1, flags=re.M)


__all__ = ["STARTERS", "Starter", "starter", "list_starters", "init_cell"]
