"""Files a robot controller reads, written from a calibration result (``vision-calib export RESULT --format NAME``).

A result is a folder (or the file) with ``calibrated_model.yaml`` (``io.model_export``), or a hand-eye result
(``report.json`` of kind ``process_handeye``: the identified camera / target mounts only). Formats
(:data:`FORMATS`), each read back by an independent reader in tests/deploy:

- ``urdf``: the calibrated arm as URDF. URDF robots: the source URDF with the calibrated joint origins (joint
  offsets folded into them, ``kinematics.urdf.export_urdf``); modified-DH robots: a URDF generated from the table
  (joint i's origin = [Tz(l) Rx(alpha) Ry(beta) Tx(a) Rz(theta) Tz(d)], axis z). The mounts are not in it (ros_tf).
- ``dh``: the modified-DH table (CSV) of a modified-DH robot, with the base and tool mounts as extra rows and the
  joint offsets theta_i - theta_nominal_i (:func:`dh_table_text`).
- ``ur_yaml``: the ``kinematics:`` YAML of ur_description (shoulder, upper_arm, forearm, wrist_1..3: the origin of
  each joint, xyz + roll/pitch/yaw, joint offsets folded into them, as the UR calibration extraction writes it) of
  a 6-joint URDF arm whose joints turn about their z axes.
- ``ros_tf``: the identified mounts as ROS static transforms (tf2 ``static_transform_publisher`` argument lines
  ``x y z qx qy qz qw parent child`` and a YAML of the transforms with their std), from a calibrated model or a
  hand-eye result.

A format that cannot represent the result's kinematics (a DH table of an H4, a UR YAML of a modified-DH robot)
raises :class:`FormatNotSupportedError` naming both. All files are written atomically.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import re
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from .. import frames as F
from ..errors import ConfigError, DataError
from ..kinematics.h4 import H4Robot
from ..kinematics.protocols import ChainModel
from ..kinematics.serial import SerialChain
from ..kinematics.urdf import URDFChain, calibrated_origins, export_urdf, load_urdf_robot
from ..serialize import write_text_atomic
from ..io.model_export import OFFSET_CONVENTION, CalibratedModel, read_calibrated_model

#: the file of a result folder holding the calibrated model, and the hand-eye report
MODEL_FILE = "calibrated_model.yaml"
REPORT_FILE = "report.json"
#: ROS frame names of our frames (ROS-I: base_link, tool0; the camera frame is OpenCV's = ROS's optical frame:
#: x right, y down, z forward); a URDF robot's own base and tip link names replace base / flange
ROS_FRAMES = {"base": "base_link", "flange": "tool0", "cam": "camera_optical_frame", "target": "target",
              "world": "world", "tool": "tool", "nacelle": "nacelle"}
#: ur_description's names of the six joint origins, in chain order
UR_JOINTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
#: relative parameter step of the finite-difference mount covariance
MOUNT_FD_STEP = 1e-7
#: report kinds of a hand-eye result (recorded folder with flange poses; pose-pair file of process-poses)
HANDEYE_KINDS = ("process_handeye", "process_pose_pairs")
#: plausibility of the exported values: an arm parameter (length / angle) at most this far from the robot file's
#: nominal value, a mount translation at most this far from its parent frame's origin
MAX_LENGTH_CHANGE_M = 0.1
MAX_ANGLE_CHANGE_RAD = np.radians(20.0)
MAX_MOUNT_TRANSLATION_M = 10.0
#: the read-back check: joint sets (seeded, inside the joint limits), and the largest difference [m, rad] between
#: the file's forward kinematics and the calibrated model's
N_VERIFY_JOINTS = 64
VERIFY_TOL_M = 1e-6
VERIFY_TOL_RAD = 1e-6


class FormatNotSupportedError(ConfigError):
    """The result's kinematics cannot be written in the requested format (e.g. a DH table of the H4)."""


@dataclass(frozen=True)
class HandeyeResult:
    """A hand-eye result (``report.json`` of a kind in :data:`HANDEYE_KINDS`): mount "eye_in_hand" | "fixed"; transforms
    {name: (T (4, 4) m, std (6,) [m, rad] or None)} for T_flange_cam / T_base_target (eye in hand) or T_base_cam /
    T_flange_target (fixed camera)."""

    path: Path
    mount: str
    transforms: dict


def find_result(path) -> Path:
    """The result file of ``path``: itself (a calibrated_model.yaml or a report.json), or in a result folder its
    calibrated_model.yaml, else its report.json when that is a hand-eye result; DataError naming the folder
    otherwise (a failed fit writes no calibrated model)."""
    p = Path(path)
    if p.is_file():
        return p
    if not p.is_dir():
        raise DataError(f"{p}: no such result folder or file")
    if (p / MODEL_FILE).is_file():
        return p / MODEL_FILE
    rep = p / REPORT_FILE
    if rep.is_file() and read_report_json(rep).get("kind") in HANDEYE_KINDS:
        return rep
    raise DataError(f"{p}: no {MODEL_FILE} in this result folder (the fit was not usable: see its report.json "
                    "verdict) and no hand-eye result")


def read_report_json(path: Path) -> dict:
    """The JSON object of a result folder's report.json at ``path``; DataError naming it when it cannot be read or
    is not an object."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise DataError(f"{path}: cannot be read as report.json ({exc})") from None
    if not isinstance(doc, dict):
        raise DataError(f"{path}: not a report.json (expected a JSON object)")
    return doc


def read_handeye(path) -> HandeyeResult:
    """The hand-eye transforms of a hand-eye report.json (:data:`HANDEYE_KINDS`, :class:`HandeyeResult`)."""
    path = Path(path)
    doc = read_report_json(path)
    he = doc.get("handeye")
    if doc.get("kind") not in HANDEYE_KINDS or not isinstance(he, dict):
        raise DataError(f"{path}: not a hand-eye result (report kind {doc.get('kind')!r}); a calibrated robot has "
                        f"its {MODEL_FILE}")
    mount = he.get("mount")
    names = ("T_flange_cam", "T_base_target") if mount == "eye_in_hand" else ("T_base_cam", "T_flange_target")
    out = {}
    for n in names:
        t = (he.get("transforms") or {}).get(n)
        try:
            T = np.asarray(t["matrix"], float)
        except (TypeError, KeyError, ValueError):
            raise DataError(f"{path}: handeye.transforms.{n}.matrix is missing or not a 4 x 4 matrix") from None
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise DataError(f"{path}: handeye.transforms.{n}.matrix is not a finite 4 x 4 matrix")
        sd = [t.get("std_xyz_m"), t.get("std_rot_deg")]
        std = None
        if all(isinstance(s, list) and len(s) == 3 and all(v is not None for v in s) for s in sd):
            std = np.concatenate([np.asarray(sd[0], float), np.radians(np.asarray(sd[1], float))])
        out[n] = (T, std)
    return HandeyeResult(path, str(mount), out)


def load_result(path) -> CalibratedModel | HandeyeResult:
    """A calibrated model (``io.model_export.read_calibrated_model``) or a hand-eye result, from a result folder or
    file (:func:`find_result`)."""
    p = find_result(path)
    return read_handeye(p) if p.suffix.lower() == ".json" else read_calibrated_model(p)


def _need_model(res, fmt: str) -> CalibratedModel:
    if isinstance(res, HandeyeResult):
        raise FormatNotSupportedError(f"{res.path}: a hand-eye result has no robot kinematics: format {fmt!r} needs a "
                                      f"calibrated robot ({MODEL_FILE}); use --format ros_tf")
    return res


def _unsupported(res: CalibratedModel, fmt: str, why: str) -> FormatNotSupportedError:
    return FormatNotSupportedError(f"{res.path}: format {fmt!r} cannot represent this {res.kind} robot "
                                   f"({type(res.robot).__name__}): {why}")


def _name(value) -> str:
    """A name (robot, link, file) for a comment line: a JSON string (quoted, control characters and non-ASCII
    escaped): it cannot end the comment or start a line."""
    return json.dumps(str(value), ensure_ascii=True)


def _offset_lines(res: CalibratedModel, prefix: str) -> list[str]:
    """Comment lines listing the joint offsets of the model file (:data:`OFFSET_CONVENTION`)."""
    if not res.joint_offsets:
        return []
    out = [f"{prefix}joint offsets ({OFFSET_CONVENTION}):"]
    out += [f"{prefix}  {_name(j)} ({_name(o.get('parameter'))}): {float(o['offset'])!r} {_name(o.get('unit', ''))}"
            for j, o in res.joint_offsets.items()]
    return out


# ----------------------------------------------------------------------------- URDF
def urdf_text(res: CalibratedModel) -> str:
    """The calibrated arm as URDF text (module docstring); FormatNotSupportedError for a robot that is not a
    serial chain."""
    res = _need_model(res, "urdf")
    robot = res.robot
    if isinstance(robot, URDFChain):
        with tempfile.TemporaryDirectory() as tmp:
            text = export_urdf(robot, res.x, Path(tmp) / "model.urdf").read_text(encoding="utf-8")
    elif isinstance(robot, SerialChain):
        text = _mdh_urdf(robot, res.x)
    else:
        raise _unsupported(res, "urdf", "a URDF holds tree-shaped serial chains only (this robot closes loops)")
    head = "\n".join(["calibrated by vision_calib from " + _name(res.path.name) + "; the mounts (camera, target) are not in "
                      "this file: export them in format ros_tf"] + _offset_lines(res, "")).replace("--", "-")
    lines = text.split("\n", 1)
    if lines[0].startswith("<?xml"):
        return lines[0] + f"\n<!-- {head} -->\n" + lines[1]
    return f"<!-- {head} -->\n" + text


def _origin(el, T) -> None:
    xyz, rpy = F.xyz_rpy_from_T(T)
    ET.SubElement(el, "origin", xyz=" ".join(repr(float(v)) for v in xyz), rpy=" ".join(repr(float(v)) for v in rpy))


def _mdh_urdf(chain: SerialChain, x) -> str:
    """URDF of a modified-DH chain at x: links base_link, link_1 .. link_n (link_n = the flange), joint_i
    revolute about z with origin Tz(l) Rx(alpha) Ry(beta) Tx(a) Rz(theta) Tz(d) (Rz(q) Tz(d) = Tz(d) Rz(q))."""
    v = chain.params.values(x)
    root = ET.Element("robot", name=chain.name)
    ET.SubElement(root, "link", name="base_link")
    for i in range(1, chain.n_joints + 1):
        ET.SubElement(root, "link", name=f"link_{i}")
        j = ET.SubElement(root, "joint", name=f"joint_{i}", type="revolute" if chain.joint_limits is not None
                          else "continuous")
        ET.SubElement(j, "parent", link="base_link" if i == 1 else f"link_{i - 1}")
        ET.SubElement(j, "child", link=f"link_{i}")
        T = F.make_T(None, [0.0, 0.0, v.get(f"l{i}", 0.0)]) @ F.make_T(F.rot_x(v[f"alpha{i}"]))
        T = T @ F.make_T(F.rot_y(v.get(f"beta{i}", 0.0))) @ F.make_T(None, [v[f"a{i}"], 0.0, 0.0])
        T = T @ F.make_T(F.rot_z(v[f"theta{i}"]), [0.0, 0.0, 0.0]) @ F.make_T(None, [0.0, 0.0, v[f"d{i}"]])
        _origin(j, T)
        ET.SubElement(j, "axis", xyz="0 0 1")
        if chain.joint_limits is not None:
            lo, hi = chain.joint_limits[i - 1]
            ET.SubElement(j, "limit", lower=repr(float(lo)), upper=repr(float(hi)), effort="0", velocity="0")
    ET.indent(root)
    return "<?xml version='1.0' encoding='utf-8'?>\n" + ET.tostring(root, encoding="unicode") + "\n"


# ----------------------------------------------------------------------------- DH table
DH_COLUMNS = ("frame", "name", "alpha_rad", "beta_rad", "a_m", "theta_rad", "d_m", "l_m", "theta_offset_rad",
              "x_m", "y_m", "z_m", "qx", "qy", "qz", "qw")


def dh_table_text(res: CalibratedModel) -> str:
    """The modified-DH table CSV of a modified-DH robot: ``#`` comment lines stating the model, the units and the
    joint-offset convention, the header :data:`DH_COLUMNS`, a ``base`` row (the left mount T_<left>_base: x, y, z
    and a quaternion), one row per joint (frame ``joint<i>``) and a ``tool`` row (the right mount T_flange_<right>).
    FormatNotSupportedError for another robot."""
    res = _need_model(res, "dh")
    chain = res.robot
    if not isinstance(chain, SerialChain):
        raise _unsupported(res, "dh", "the DH table is the parameterisation of modified-DH robots only (a URDF arm: "
                                      "--format urdf or ur_yaml)" if isinstance(chain, ChainModel) else
                           "a DH table describes serial chains only")
    v = chain.params.values(res.x)
    nom = chain.params.values(res.nominal_robot.params.nominal) if res.nominal_robot is not None else v
    TL, TR = chain.nominal_transforms(res.x)
    lines = [
        f"# modified-DH table (Khalil-Kleinfinger / Craig) of {_name(chain.name)}, calibrated by vision_calib "
        f"({_name(res.path.name)})",
        "# link i: T_{i-1,i}(q_i) = Tz(l_i) Rx(alpha_i) Ry(beta_i) Tx(a_i) Rz(theta_i + q_i) Tz(d_i)"
        " (beta: Hayati, l: extra translation; 0 when the robot has none)",
        f"# chain: {_name(chain.measured_name)}(q) = base . T_{{0,1}}(q_1) ... T_{{n-1,n}}(q_n) . tool;"
        f" base = {_name(chain.left)}, tool = {_name(chain.right)} (x, y, z and a unit quaternion qx, qy, qz, qw, scalar last)",
        "# units: lengths m, angles rad; q_i: the controller's joint reading (rad)",
        "# joint offset: theta_offset_i = theta_i - theta_i(nominal); the calibrated joint i turns by theta_i + q_i:"
        " a controller using the nominal table adds theta_offset_i to its joint reading",
        ",".join(DH_COLUMNS),
    ]

    def pose_row(frame, name, T):
        xyz, quat = F.xyz_quat_from_T(T)
        return [frame, name] + [""] * 7 + [repr(float(c)) for c in (*xyz, *quat)]

    rows = [pose_row("base", chain.left, TL)]
    for i in range(1, chain.n_joints + 1):
        rows.append([f"joint{i}", f"joint {i}"] + [repr(float(c)) for c in (
            v[f"alpha{i}"], v.get(f"beta{i}", 0.0), v[f"a{i}"], v[f"theta{i}"], v[f"d{i}"], v.get(f"l{i}", 0.0),
            v[f"theta{i}"] - nom[f"theta{i}"])] + [""] * 7)
    rows.append(pose_row("tool", chain.right, TR))
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    return "\n".join(lines) + "\n" + buf.getvalue()


# ----------------------------------------------------------------------------- UR kinematics YAML
def ur_yaml_text(res: CalibratedModel) -> str:
    """ur_description's kinematics YAML (module docstring) of a 6-joint URDF arm turning about its joints' z axes;
    FormatNotSupportedError otherwise."""
    res = _need_model(res, "ur_yaml")
    chain = res.robot
    if not isinstance(chain, URDFChain):
        raise _unsupported(res, "ur_yaml", "the UR kinematics YAML holds the joint origins of a URDF arm "
                                           "(a modified-DH robot: --format dh or urdf)")
    if chain.n_joints != 6 or np.any(chain.prismatic) or not np.allclose(chain.axes, [0.0, 0.0, 1.0], atol=1e-12):
        raise _unsupported(res, "ur_yaml", "it needs 6 revolute joints turning about their z axes (a UR arm), this "
                                           f"chain has {chain.n_joints} joints, axes {np.round(chain.axes, 3).tolist()}")
    O = calibrated_origins(chain, res.x)
    kin = {}
    for name, T in zip(UR_JOINTS, O):
        xyz, rpy = F.xyz_rpy_from_T(T)
        kin[name] = {k: float(c) for k, c in zip(("x", "y", "z", "roll", "pitch", "yaw"), (*xyz, *rpy))}
    body = yaml.safe_dump({"kinematics": kin}, sort_keys=False)
    kin["hash"] = "vision_calib_" + hashlib.sha1(body.encode()).hexdigest()[:16]
    joints = chain.meta.get("joint_names") or ()
    head = [f"# UR kinematics of {_name(chain.name)} calibrated by vision_calib ({_name(res.path.name)}): the origin "
            "of each joint in its parent link",
            "# (" + ", ".join(f"{a} = {_name(b)}" for a, b in zip(UR_JOINTS, joints)) + "), x, y, z [m], roll, pitch, "
            "yaw [rad] (R = Rz(yaw) Ry(pitch) Rx(roll));",
            "# the joint offsets are folded into the origins (origin = URDF origin . correction . Rz(q0)), as the UR "
            "calibration extraction writes them; hash: of this file's numbers, not the robot's own calibration hash"]
    head += _offset_lines(res, "# ")
    return "\n".join(head) + "\n" + yaml.safe_dump({"kinematics": kin}, sort_keys=False)


# ----------------------------------------------------------------------------- ROS static transforms
#: a ROS frame name (tf2): letters, digits, _ and / (no space: the static_transform_publisher line splits on them)
ROS_FRAME_RE = re.compile(r"[A-Za-z_/][A-Za-z0-9_/]*")


def _ros_frame(label: str, robot=None) -> str:
    if isinstance(robot, URDFChain) and label in ("base", "flange"):
        name = robot.meta.get("base_link" if label == "base" else "tip_link") or ROS_FRAMES[label]
    else:
        name = ROS_FRAMES.get(label, label)
    if not ROS_FRAME_RE.fullmatch(str(name)):
        raise FormatNotSupportedError(f"frame {_name(name)} is not a ROS frame name (letters, digits, _ and / only, "
                                      "rule ROS_FRAME_RE): rename the link in the URDF")
    return name


def _split_name(name: str) -> tuple[str, str]:
    """("target", "base") of "T_target_base"."""
    a, b = name[2:].split("_", 1)
    return a, b


def _mount_functions(robot) -> list[tuple[str, Callable]]:
    """[(T_a_b name, x -> (4, 4))] of a robot's mounts, robot frames as parents: a chain's left mount inverted
    (T_base_<left>), its right mount (T_flange_<right>); the H4's T_base_cam and T_nacelle_target."""
    if isinstance(robot, H4Robot):
        return [("T_base_cam", robot.T_base_cam), ("T_nacelle_target", lambda x: F.inv_T(robot.T_target_nacelle(x)))]
    if isinstance(robot, ChainModel):
        left = _split_name(robot.left)[0]
        return [(robot.right, lambda x: robot.nominal_transforms(x)[1]),
                (f"T_base_{left}", lambda x: F.inv_T(robot.nominal_transforms(x)[0]))]
    raise FormatNotSupportedError(f"no mount transforms known for a {type(robot).__name__} robot")


def mount_transforms(res: CalibratedModel | HandeyeResult) -> list[dict]:
    """[{name: "T_a_b", parent, child (ROS frame names), T (4, 4) [m], cov (6, 6) [m, rad] (frames.pose_error, parent
    frame) or None}] of the result's mounts, the camera mount first. A calibrated model's covariance is propagated
    from its parameter covariance (central differences over the mount's parameters); a hand-eye result's is
    diagonal, from its std."""
    out = []
    if isinstance(res, HandeyeResult):
        for name, (T, std) in res.transforms.items():
            a, b = _split_name(name)
            out.append({"name": name, "parent": _ros_frame(a), "child": _ros_frame(b), "T": T,
                        "cov": None if std is None else np.diag(std**2)})
        return out
    C = res.covariance
    for name, fun in _mount_functions(res.robot):
        T = fun(res.x)
        J = np.zeros((6, len(res.x)))
        for k in np.flatnonzero(np.diag(C) > 0):
            h = MOUNT_FD_STEP * max(1.0, abs(res.x[k]))
            dx = np.zeros(len(res.x))
            dx[k] = h
            J[:, k] = F.pose_error(fun(res.x - dx), fun(res.x + dx)) / (2 * h)
        a, b = _split_name(name)
        out.append({"name": name, "parent": _ros_frame(a, res.robot), "child": _ros_frame(b, res.robot), "T": T,
                    "cov": J @ C @ J.T if np.any(C) else None})
    return sorted(out, key=lambda m: "cam" not in _split_name(m["name"]))


def static_transform_args(T, parent: str, child: str) -> str:
    """tf2 static_transform_publisher argument line ``x y z qx qy qz qw parent child`` of T_parent_child (4, 4)."""
    xyz, quat = F.xyz_quat_from_T(np.asarray(T, float))
    return " ".join([repr(float(v)) for v in (*xyz, *quat)] + [parent, child])


def ros_tf_text(res: CalibratedModel | HandeyeResult) -> str:
    """The ROS static-transform YAML of the result's mounts (module docstring)."""
    items = []
    for m in mount_transforms(res):
        xyz, quat = F.xyz_quat_from_T(m["T"])
        d = {"name": m["name"], "parent_frame": m["parent"], "child_frame": m["child"],
             "translation": {k: float(v) for k, v in zip("xyz", xyz)},
             "rotation": {k: float(v) for k, v in zip("xyzw", quat)},
             "static_transform_publisher": static_transform_args(m["T"], m["parent"], m["child"])}
        if m["cov"] is not None:
            s = np.sqrt(np.clip(np.diag(m["cov"]), 0.0, None))
            d["std"] = {"translation_m": [float(v) for v in s[:3]], "rotation_rad": [float(v) for v in s[3:]]}
        items.append(d)
    head = ["# ROS static transforms of the identified mounts, written by vision_calib from " + _name(res.path.name),
            "# parent_frame -> child_frame: translation [m], rotation (unit quaternion, scalar last); camera frames are",
            "# optical (x right, y down, z forward). Publish one with:",
            "#   ros2 run tf2_ros static_transform_publisher <static_transform_publisher>",
            "# std: of the transform's pose error (translation, then rotation vector, in the parent frame)"]
    doc = {"format": "vision_calib.ros_static_transforms/1", "transforms": items}
    return "\n".join(head) + "\n" + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=1000)


# ----------------------------------------------------------------------------- registry
@dataclass(frozen=True)
class ExportFormat:
    """text(result) -> str; file: the default file name in a result folder; what: one line for --help."""

    text: Callable
    file: str
    what: str


FORMATS = {
    "urdf": ExportFormat(urdf_text, "calibrated_model.urdf", "the calibrated arm as URDF (serial robots)"),
    "dh": ExportFormat(dh_table_text, "calibrated_dh.csv", "modified-DH table CSV with base/tool rows and joint "
                                                            "offsets (modified-DH robots)"),
    "ur_yaml": ExportFormat(ur_yaml_text, "calibrated_ur_kinematics.yaml", "ur_description kinematics YAML "
                                                                           "(6-joint URDF arms about z: UR)"),
    "ros_tf": ExportFormat(ros_tf_text, "calibrated_static_transforms.yaml", "ROS static transforms of the "
                                                                             "identified mounts (also hand-eye results)"),
}


# ----------------------------------------------------------------------------- value checks, read-back check
def _is_mount(name: str) -> bool:
    return name.split(".", 1)[0].startswith("T_")


def check_values(res: CalibratedModel | HandeyeResult) -> None:
    """DataError naming the parameter (or transform) and the rule when a value to export is not finite, an arm
    parameter is further than :data:`MAX_LENGTH_CHANGE_M` / :data:`MAX_ANGLE_CHANGE_RAD` from the robot file's
    nominal value, or a mount translation is beyond :data:`MAX_MOUNT_TRANSLATION_M`."""
    if isinstance(res, HandeyeResult):
        for n, (T, _) in res.transforms.items():
            if np.linalg.norm(T[:3, 3]) > MAX_MOUNT_TRANSLATION_M:
                raise DataError(f"{res.path}: {n} translation {np.linalg.norm(T[:3, 3]):.6g} m is implausible (rule: a "
                                f"mount within {MAX_MOUNT_TRANSLATION_M:g} m of its parent frame): nothing exported")
        return
    nom_robot = res.nominal_robot if res.nominal_robot is not None else res.robot
    nom = dict(zip(nom_robot.params.names, nom_robot.params.nominal))
    kinds = dict(zip(res.robot.params.names, res.robot.params.kinds))
    for n, v in zip(res.names, res.x):
        if not np.isfinite(v):
            raise DataError(f"{res.path}: parameter {n} = {v} is not finite: nothing exported")
        kind, rule = kinds.get(n), None
        if _is_mount(n):
            if n.rsplit(".", 1)[-1] in ("tx", "ty", "tz") and abs(v) > MAX_MOUNT_TRANSLATION_M:
                rule = f"a mount translation within {MAX_MOUNT_TRANSLATION_M:g} m"
        elif n in nom and kind == "length" and abs(v - nom[n]) > MAX_LENGTH_CHANGE_M:
            rule = f"a length within {MAX_LENGTH_CHANGE_M:g} m of the robot file's {nom[n]:.6g} m"
        elif n in nom and kind == "angle" and abs(np.angle(np.exp(1j * (v - nom[n])))) > MAX_ANGLE_CHANGE_RAD:
            rule = f"an angle within {np.degrees(MAX_ANGLE_CHANGE_RAD):g} deg of the robot file's {nom[n]:.6g} rad"
        if rule:
            raise DataError(f"{res.path}: parameter {n} = {v:.6g} {'m' if kind == 'length' else 'rad'} is implausible "
                            f"(rule: {rule}): nothing exported")


def _verify_joints(robot) -> np.ndarray:
    """(N_VERIFY_JOINTS, n) joint sets inside the joint limits (within +-pi), seeded."""
    n = robot.n_joints
    lim = np.tile([-np.pi, np.pi], (n, 1)) if robot.joint_limits is None else np.asarray(robot.joint_limits, float)
    lo, hi = np.maximum(lim[:, 0], -np.pi), np.minimum(lim[:, 1], np.pi)
    return lo + np.random.default_rng(0).uniform(size=(N_VERIFY_JOINTS, n)) * (hi - lo)


def _mdh_fk(rows: list, q: np.ndarray) -> np.ndarray:
    """(N, 4, 4) base . prod Tz(l) Rx(alpha) Ry(beta) Tx(a) Rz(theta + q) Tz(d) . tool of the DH table's rows."""
    def num(r, k):
        return float(r[k])

    pose = {r["frame"]: F.T_from_xyz_quat([num(r, k) for k in ("x_m", "y_m", "z_m")],
                                          [num(r, k) for k in ("qx", "qy", "qz", "qw")])
            for r in rows if r["frame"] in ("base", "tool")}
    T = np.broadcast_to(pose["base"], (len(q), 4, 4))
    for r, qi in zip([r for r in rows if r["frame"].startswith("joint")], q.T):
        C = F.make_T(None, [0, 0, num(r, "l_m")]) @ F.make_T(F.rot_x(num(r, "alpha_rad")))
        C = C @ F.make_T(F.rot_y(num(r, "beta_rad"))) @ F.make_T(None, [num(r, "a_m"), 0, 0])
        T = T @ C @ F.make_T(F.rot_z(num(r, "theta_rad") + qi), np.broadcast_to([0, 0, num(r, "d_m")], (len(q), 3)))
    return T @ pose["tool"]


def _read_back(res, fmt: str, text: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(T from the file (N, 4, 4), T of the calibrated model (N, 4, 4))] of the written text, parsed by the
    format's reader (xml.etree through kinematics.urdf, csv, yaml)."""
    if fmt == "ros_tf":
        doc = yaml.safe_load(text)
        if set(doc) != {"format", "transforms"}:
            raise DataError(f"ros_tf: the written YAML has the top-level keys {sorted(doc)}")
        out = []
        for item, m in zip(doc["transforms"], mount_transforms(res)):
            t, r = item["translation"], item["rotation"]
            args = item["static_transform_publisher"].split(" ")
            if args[7:] != [m["parent"], m["child"]] or [item["parent_frame"], item["child_frame"]] != args[7:]:
                raise DataError(f"ros_tf: {m['name']}: the frames read back are {args[7:]}")
            T_yaml = F.T_from_xyz_quat([t[k] for k in "xyz"], [r[k] for k in "xyzw"])
            T_args = F.T_from_xyz_quat([float(v) for v in args[:3]], [float(v) for v in args[3:7]])
            out.append((np.stack([T_yaml, T_args]), np.stack([m["T"], m["T"]])))
        return out
    robot = res.robot
    q = _verify_joints(robot)
    if fmt == "dh":
        rows = list(csv.DictReader(io.StringIO("\n".join(ln for ln in text.splitlines() if not ln.startswith("#")))))
        return [(_mdh_fk(rows, q), robot.forward(q, res.x))]
    if fmt == "urdf":
        base, tip = ((robot.meta.get("base_link"), robot.meta.get("tip_link")) if isinstance(robot, URDFChain)
                     else ("base_link", f"link_{robot.n_joints}"))
        with tempfile.TemporaryDirectory() as tmp:
            (Path(tmp) / "model.urdf").write_text(text, encoding="utf-8")
            back = load_urdf_robot(Path(tmp) / "model.urdf", base, tip)
        return [(back.flange(q), robot.flange(q, res.x))]
    doc = yaml.safe_load(text)  # ur_yaml
    kin = doc.get("kinematics") if isinstance(doc, dict) else None
    if set(doc) != {"kinematics"} or list(kin) != [*UR_JOINTS, "hash"]:
        raise DataError(f"ur_yaml: the written YAML reads back as {sorted(doc)} / {list(kin or ())}")
    raw = robot.meta["raw_origins"]
    T = np.broadcast_to(np.eye(4), (len(q), 4, 4))
    for i, name in enumerate(UR_JOINTS):  # fixed joints before joint i (origins = fixed . raw), file origin, Rz(q)
        o = kin[name]
        O = F.T_from_xyz_rpy([o["x"], o["y"], o["z"]], [o["roll"], o["pitch"], o["yaw"]])
        T = T @ (robot.origins[i] @ F.inv_T(raw[i]) @ O) @ F.make_T(F.rot_z(q[:, i]))
    return [(T @ robot.tail, robot.flange(q, res.x))]


def verify_export(res, fmt: str, text: str) -> dict:
    """Read the written ``text`` back (:func:`_read_back`) and compare its forward kinematics (ros_tf: its
    transforms) with the calibrated model on :data:`N_VERIFY_JOINTS` joint sets. Returns {joint_sets (0 for
    ros_tf), max_m, max_rad}; DataError above :data:`VERIFY_TOL_M` / :data:`VERIFY_TOL_RAD`."""
    pairs = _read_back(res, fmt, text)
    e = np.concatenate([F.pose_error(a, b) for a, b in pairs])
    et, er = float(np.linalg.norm(e[:, :3], axis=1).max()), float(np.linalg.norm(e[:, 3:], axis=1).max())
    if not (et <= VERIFY_TOL_M and er <= VERIFY_TOL_RAD):
        raise DataError(f"{fmt}: the written file read back differs from the calibrated model by {et:.3g} m, "
                        f"{er:.3g} rad (tolerance {VERIFY_TOL_M:g} m, {VERIFY_TOL_RAD:g} rad): nothing exported")
    return {"joint_sets": 0 if fmt == "ros_tf" else N_VERIFY_JOINTS, "max_m": et, "max_rad": er}


def export_verified(result, fmt: str, out) -> dict:
    """Write the result (a result folder or file, or a loaded :class:`CalibratedModel` / :class:`HandeyeResult`) in
    format ``fmt`` (:data:`FORMATS`) to the file ``out`` (atomic) after :func:`check_values` and
    :func:`verify_export` of the text. Returns {out: Path, format, verified: {joint_sets, max_m, max_rad}}."""
    if fmt not in FORMATS:
        raise ConfigError(f"unknown export format {fmt!r} (known: {', '.join(FORMATS)})")
    res = result if isinstance(result, (CalibratedModel, HandeyeResult)) else load_result(result)
    check_values(res)
    text = FORMATS[fmt].text(res)
    verified = verify_export(res, fmt, text)
    return {"out": write_text_atomic(out, text), "format": fmt, "verified": verified}


def export(result, fmt: str, out) -> Path:
    """:func:`export_verified`, returning the path written."""
    return export_verified(result, fmt, out)["out"]


def verified_text(v: dict) -> str:
    """One line of :func:`verify_export`'s figures for messages."""
    if not v["joint_sets"]:
        return f"read back and verified: max {v['max_m']:.1g} m, {v['max_rad']:.1g} rad from the result's transforms"
    return (f"read back and verified on {v['joint_sets']} joint sets: max {v['max_m']:.1g} m, {v['max_rad']:.1g} rad "
            "from the calibrated model")


__all__ = ["FORMATS", "read_report_json", "ExportFormat", "FormatNotSupportedError", "HandeyeResult", "check_values", "dh_table_text",
           "export", "export_verified", "verified_text", "verify_export",
           "find_result", "load_result", "mount_transforms", "read_handeye", "ros_tf_text", "static_transform_args",
           "ur_yaml_text", "urdf_text"]
