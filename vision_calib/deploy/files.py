"""The deploy commands on files (``vision-calib compensate`` / ``inverse``): joint and pose tables in, joint tables
out (``io.pose_table``: units in the header, atomic writes). Errors name the file and the row."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..config import check_output_apart
from ..io.pose_table import read_joint_table, read_pose_table, write_joint_table
from .robot import CalibratedRobot, model_path


def _apart(out, result, *files) -> None:
    r = Path(result)
    check_output_apart(out, [(r, "folder" if r.is_dir() else "file")] + [(f, "file") for f in files])


def compensate_file(result, joints_csv, out) -> dict:
    """Compensate the joint table ``joints_csv`` (joint values meant for the nominal model) with the calibrated
    robot of ``result`` (folder or calibrated_model.yaml) and write the corrected joints to ``out`` in the same
    units and row names. Returns {rows, out, max_correction: {joint, value, unit}} (in the file's unit)."""
    _apart(out, result, joints_csv)
    robot = CalibratedRobot.load(model_path(result))
    table = read_joint_table(joints_csv, robot.n_joints, robot.prismatic)
    qc = robot.compensate(table.q, labels=table.labels())
    write_joint_table(out, qc, table.units, table.ids)
    from ..io.pose_table import JOINT_UNITS

    d = (qc - table.q) / np.array([JOINT_UNITS[u] for u in table.units])
    k, j = np.unravel_index(int(np.argmax(np.abs(d))), d.shape)
    return {"rows": int(len(qc)), "out": str(out),
            "max_correction": {"joint": f"q{j + 1}", "row": table.labels()[k], "value": float(d[k, j]),
                               "unit": table.units[j]}}


def inverse_file(result, poses_csv, out, tcp=None, angle_unit: str = "rad") -> dict:
    """Joint values of the calibrated robot of ``result`` for each tool pose of the pose table ``poses_csv``
    (T_base_tool, ``io.pose_table``; tcp: x, y, z [m] in the flange frame), written to ``out`` as a joint table
    (revolute joints in ``angle_unit``, prismatic in m) with the same row names. Returns {rows, out}."""
    _apart(out, result, poses_csv)
    robot = CalibratedRobot.load(model_path(result), tcp=tcp)
    table = read_pose_table(poses_csv)
    q = robot.inverse(table.T, labels=table.labels())
    write_joint_table(out, q, tuple("m" if p else angle_unit for p in robot.prismatic), table.ids)
    return {"rows": int(len(q)), "out": str(out)}


__all__ = ["compensate_file", "inverse_file"]
