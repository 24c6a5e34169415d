"""The deploy commands on files (``vision-calib compensate`` / ``inverse``): joint and pose tables in, joint tables
out (``io.pose_table``: units in the header, atomic writes). Errors name the file and the row."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import csv
import io

from ..config import check_output_apart
from ..errors import DataError
from ..io.pose_table import JOINT_UNITS, read_joint_table, read_pose_table, write_joint_table
from ..serialize import write_text_atomic
from .kinematics import PoseNotReachedError
from .robot import AMPLIFIED_DEG_PER_MM, CalibratedRobot, model_path

#: rows named one by one in the messages of compensate_file (the report file names them all)
N_NAMED = 10


def _apart(out, result, *files) -> None:
    r = Path(result)
    check_output_apart(out, [(r, "folder" if r.is_dir() else "file")] + [(f, "file") for f in files])


def report_path(out) -> Path:
    """The per-row report written next to the corrected table ``out``: ``<stem>_report.csv``."""
    out = Path(out)
    return out.with_name(out.stem + "_report.csv")


def _report_text(c, labels, ids, units) -> str:
    """CSV: one line per row of the compensation ``c`` (``deploy.robot.Compensation``): its name, status,
    correction per joint (file units), remaining tool error, predicted accuracy, amplification, why."""
    f = np.array([JOINT_UNITS[u] for u in units])
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["pose_id" if ids is not None else "row", "status"] + [f"dq{j + 1}_{u}" for j, u in enumerate(units)]
               + ["remaining_mm", "remaining_mrad", "accuracy_mm", "accuracy_mrad", "amplification_deg_per_mm", "why"])
    d = (c.q_corrected - c.q) / f
    for k in range(len(c.q)):
        w.writerow([ids[k] if ids is not None else k + 1, c.status[k]] + [f"{v:.6g}" for v in d[k]]
                   + [f"{v:.4g}" for v in (c.remaining_t_m[k] * 1e3, c.remaining_r_rad[k] * 1e3, c.tolerance_t_m[k] * 1e3,
                                           c.tolerance_r_rad[k] * 1e3, c.amplification[k])] + [c.why[k]])
    return buf.getvalue()


def compensate_file(result, joints_csv, out, report=None, progress=None) -> dict:
    """Compensate the joint table ``joints_csv`` (joint values meant for the nominal model) row by row with the
    calibrated robot of ``result`` (folder or calibrated_model.yaml, ``CalibratedRobot.compensate_rows``); write the
    corrected rows to ``out`` (same units and row names; a pose_id column of the input row numbers when rows are left
    out of a table without one) and the per-row report to ``report`` (default :func:`report_path`). Rows that
    cannot be corrected (outside the joint limits, not converging) are left out and named; PoseNotReachedError (exit
    3, nothing written) only when no row is corrected. ``progress(rows_done, rows_total)``: see compensate_rows.
    Returns {rows, written, out, report, max_correction: {joint, row, value, unit}, flagged: [message],
    not_corrected: [message]} (values in the file's units; messages name the row)."""
    report = report_path(out) if report is None else Path(report)
    _apart(out, result, joints_csv)
    _apart(report, result, joints_csv, out)
    robot = CalibratedRobot.load(model_path(result))
    table = read_joint_table(joints_csv, robot.n_joints, robot.prismatic)
    labels = table.labels()
    c = robot.compensate_rows(table.q, progress=progress)
    ok = c.corrected
    failed = [f"{labels[k]}: {c.why[k]}" for k in np.flatnonzero(~ok)]
    if not ok.any():
        raise PoseNotReachedError(f"{table.path}: no row could be compensated: " + "; ".join(failed[:N_NAMED])
                                  + (f"; ... ({len(failed)} rows)" if len(failed) > N_NAMED else ""))
    ids = table.ids
    if ids is None and not ok.all():
        ids = tuple(str(k + 1) for k in range(len(table.q)))
    f = np.array([JOINT_UNITS[u] for u in table.units])
    d = np.where(ok[:, None], (c.q_corrected - table.q) / f, 0.0)
    k, j = np.unravel_index(int(np.argmax(np.abs(d))), d.shape)
    flagged = []
    for i in np.flatnonzero(c.status == "near_singularity"):
        jj = int(np.argmax(np.abs(d[i])))
        flagged.append(f"{labels[i]}: near a singularity ({c.amplification[i]:.3g} deg of joint motion per mm, "
                       f"above {AMPLIFIED_DEG_PER_MM:g}): correction damped to {d[i, jj]:+.4g} {table.units[jj]} on "
                       f"q{jj + 1}, the tool left {c.remaining_t_m[i] * 1e3:.3g} mm, {c.remaining_r_rad[i] * 1e3:.3g} "
                       f"mrad from the nominal pose (predicted accuracy {c.tolerance_t_m[i] * 1e3:.3g} mm, "
                       f"{c.tolerance_r_rad[i] * 1e3:.3g} mrad)")
    write_text_atomic(report, _report_text(c, labels, table.ids, table.units))
    write_joint_table(out, c.q_corrected[ok], table.units, None if ids is None else [ids[i] for i in np.flatnonzero(ok)])
    return {"rows": int(len(table.q)), "written": int(ok.sum()), "out": str(out), "report": str(report),
            "max_correction": {"joint": f"q{j + 1}", "row": labels[k], "value": float(d[k, j]), "unit": table.units[j]},
            "flagged": flagged, "not_corrected": failed}


def _near_joints(near, robot, table) -> np.ndarray:
    """(N, n) SI start joints of the inverse from the joint table ``near``: one row for all poses or one per pose
    (their pose ids, when both tables have them, equal); DataError naming the file otherwise."""
    nt = read_joint_table(near, robot.n_joints, robot.prismatic)
    N = len(table.T)
    if len(nt.q) not in (1, N):
        raise DataError(f"{nt.path}: {len(nt.q)} joint sets for the {N} poses of {table.path.name} (--near takes one "
                        "joint set for all poses, or one per pose in the same order)")
    if len(nt.q) == N and nt.ids is not None and table.ids is not None:
        diff = [k for k in range(N) if nt.ids[k] != table.ids[k]]
        if diff:
            k = diff[0]
            raise DataError(f"{nt.path}: row {k + 1} has pose_id {nt.ids[k]!r}, the pose table's row {k + 1} "
                            f"{table.ids[k]!r} (the rows must be in the same order)")
    return np.broadcast_to(nt.q, (N, robot.n_joints))


def inverse_file(result, poses_csv, out, tcp=None, angle_unit: str = "rad", near=None, progress=None) -> dict:
    """Joint values of the calibrated robot of ``result`` for each tool pose of the pose table ``poses_csv``
    (T_base_tool, ``io.pose_table``; tcp: x, y, z [m] in the flange frame), written to ``out`` as a joint table
    (revolute joints in ``angle_unit``, prismatic in m) with the same row names (a pose_id column of the input row
    numbers when rows are left out of a table without one). ``near``: a joint table (one row, or one per pose): the
    solution nearest it (Newton from it), else the one nearest the nominal model's solution. Poses not reached
    (``CalibratedRobot.inverse_rows``) are left out and named; PoseNotReachedError (exit 3, nothing written) only
    when no pose is reached. Returns {rows, written, out, not_reached: [message naming the row]}."""
    _apart(out, result, poses_csv, *([near] if near is not None else []))
    robot = CalibratedRobot.load(model_path(result), tcp=tcp)
    table = read_pose_table(poses_csv)
    start = None if near is None else _near_joints(near, robot, table)
    q, why = robot.inverse_rows(table.T, q_start=start, labels=table.labels(), progress=progress)
    ok = why == ""
    failed = [str(w) for w in why[~ok]]
    if not ok.any():
        raise PoseNotReachedError(f"{table.path}: no pose could be reached: " + "; ".join(failed[:N_NAMED])
                                  + (f"; ... ({len(failed)} poses)" if len(failed) > N_NAMED else ""))
    ids = table.ids
    if ids is None and not ok.all():
        ids = tuple(str(k + 1) for k in range(len(q)))
    write_joint_table(out, q[ok], tuple("m" if p else angle_unit for p in robot.prismatic),
                      None if ids is None else [ids[i] for i in np.flatnonzero(ok)])
    return {"rows": int(len(q)), "written": int(ok.sum()), "out": str(out), "not_reached": failed}


__all__ = ["compensate_file", "inverse_file", "report_path"]
