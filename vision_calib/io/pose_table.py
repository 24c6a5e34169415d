"""Joint and pose tables (CSV) of the deploy commands (``vision-calib compensate`` / ``inverse``), with their units
in the header (DESIGN.md §3: the unit in the name), one row per robot pose::

    pose_id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg        joint values: q<j>_rad | q<j>_deg (revolute),
    p000,0.0,35.0,95.0,0.0,50.0,0.0                           q<j>_m | q<j>_mm (prismatic); any order

    pose_id,x_m,y_m,z_m,qx,qy,qz,qw                           pose of the tool in the robot base: x/y/z in m,
    p000,0.41,0.02,0.38,0.0,1.0,0.0,0.0                       cm or mm (one unit), unit quaternion scalar last

``pose_id`` is optional (the rows are then named by their number); empty lines and lines starting with ``#`` are
skipped. The value checks are those of recorded folders' poses.csv (``io.recording``: finite numbers, plausible
sizes, unit quaternions). Every error is a DataError naming the file, the line and the column.
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import ANGLE_UNITS, LENGTH_UNITS, did_you_mean
from ..errors import DataError
from ..frames import T_from_xyz_quat, xyz_quat_from_T
from ..serialize import write_text_atomic
from .recording import FLANGE_COLUMNS, MAX_ABS_JOINT, MAX_ABS_POSITION_M, read_text_utf8

#: units of a joint column: angle units (revolute) and length units (prismatic)
JOINT_UNITS = {**ANGLE_UNITS, **LENGTH_UNITS}
#: |norm - 1| above which a quaternion is refused (as recordings)
QUAT_TOL = 1e-3


@dataclass(frozen=True)
class JointTable:
    """path; ids (N,) pose ids (None: the file has no pose_id column); q (N, n) SI [rad, m]; units (n,) the
    file's unit per joint column; lines (N,) line number of each row."""

    path: Path
    ids: tuple | None
    q: np.ndarray
    units: tuple
    lines: tuple

    def labels(self) -> list[str]:
        """One name per row for messages: ``row 3 (pose_id 'p002', joints.csv line 4)``."""
        return _labels(self.path, self.ids, self.lines)


@dataclass(frozen=True)
class PoseTable:
    """path; ids (N,) or None; T (N, 4, 4) [m]; length_unit of the file; lines (N,)."""

    path: Path
    ids: tuple | None
    T: np.ndarray
    length_unit: str
    lines: tuple

    def labels(self) -> list[str]:
        return _labels(self.path, self.ids, self.lines)


def _labels(path, ids, lines) -> list[str]:
    return [f"row {k + 1} ({'pose_id ' + repr(ids[k]) + ', ' if ids else ''}{Path(path).name} line {ln})"
            for k, ln in enumerate(lines)]


def _rows(path: Path) -> tuple[list[str], list[tuple[int, list[str]]]]:
    """(header, [(line, cells)]) of a CSV file without empty and ``#`` lines; DataError when there is no row."""
    text = read_text_utf8(path)
    rows = [(ln, [c.strip() for c in r]) for ln, r in enumerate(csv.reader(io.StringIO(text, newline="")), start=1)
            if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]
    if len(rows) < 2:
        raise DataError(f"{path}: no rows (a header line, then one line per pose)")
    header = rows[0][1]
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise DataError(f"{path}: header: duplicate column(s) {', '.join(dup)}")
    return header, rows[1:]


def _values(path: Path, header, rows, cols: list[int]) -> tuple[tuple | None, np.ndarray, tuple]:
    """(ids or None, values (N, len(cols)), lines): the numbers of ``cols`` in each row, checked."""
    i_id = header.index("pose_id") if "pose_id" in header else None
    ids, vals, lines = [], [], []
    for ln, r in rows:
        if len(r) != len(header):
            raise DataError(f"{path}: line {ln}: {len(r)} values, expected {len(header)} ({','.join(header)})")
        pid = r[i_id] if i_id is not None else None
        if i_id is not None and not pid:
            raise DataError(f"{path}: line {ln}: empty pose_id")
        v = []
        for c in cols:
            try:
                v.append(float(r[c]))
            except ValueError:
                raise DataError(f"{path}: line {ln}: column {header[c]}: not a number: {r[c]!r}") from None
            if not np.isfinite(v[-1]):
                raise DataError(f"{path}: line {ln}: column {header[c]}: not finite ({r[c]})")
        ids.append(pid)
        vals.append(v)
        lines.append(ln)
    if i_id is not None:
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise DataError(f"{path}: duplicate pose ids {dup}")
    return (tuple(ids) if i_id is not None else None), np.array(vals, float), tuple(lines)


def read_joint_table(path, n_joints: int, prismatic=None) -> JointTable:
    """The joint table ``path`` (module docstring) of a robot with n_joints joints; prismatic (n,) bool or None
    (all revolute): a revolute joint's column needs an angle unit, a prismatic one a length unit."""
    path = Path(path)
    header, rows = _rows(path)
    cols, units = {}, {}
    for k, h in enumerate(header):
        if h == "pose_id":
            continue
        m = re.fullmatch(r"q(\d+)(?:_(\w+))?", h)
        if not m:
            raise DataError(f"{path}: header: unknown column {h!r}; expected pose_id "
                            f"and q1_<unit> .. q{n_joints}_<unit> (unit: {' | '.join(JOINT_UNITS)})")
        j, u = int(m.group(1)), m.group(2)
        if u is None:
            raise DataError(f"{path}: header: column {h!r} has no unit: write {h}_rad or {h}_deg (m or mm for a "
                            "prismatic joint)")
        if u not in JOINT_UNITS:
            raise DataError(f"{path}: header: column {h!r}: unknown unit {u!r}{did_you_mean(u, list(JOINT_UNITS))} "
                            f"(expected {' | '.join(JOINT_UNITS)})")
        if not 1 <= j <= n_joints:
            raise DataError(f"{path}: header: column {h!r}: the robot has {n_joints} joints (q1..q{n_joints})")
        pr = bool(prismatic[j - 1]) if prismatic is not None else False
        if (u in LENGTH_UNITS) != pr:
            raise DataError(f"{path}: header: column {h!r}: joint {j} is {'prismatic' if pr else 'revolute'}: its unit "
                            f"must be {' or '.join(LENGTH_UNITS if pr else ANGLE_UNITS)}")
        cols[j], units[j] = k, u
    missing = [f"q{j}" for j in range(1, n_joints + 1) if j not in cols]
    if missing:
        raise DataError(f"{path}: header: missing joint column(s) {', '.join(missing)} (the robot has {n_joints} joints)")
    ids, v, lines = _values(path, header, rows, [cols[j] for j in range(1, n_joints + 1)])
    f = np.array([JOINT_UNITS[units[j]] for j in range(1, n_joints + 1)])
    q = v * f
    big = np.argwhere(np.abs(q) > MAX_ABS_JOINT)
    if big.size:
        k, j = (int(t) for t in big[0])
        raise DataError(f"{path}: line {lines[k]}: column {header[cols[j + 1]]}: implausible value {v[k, j]:.4g} "
                        f"(|value| > {MAX_ABS_JOINT:g} SI: wrong unit?)")
    return JointTable(path, ids, q, tuple(units[j] for j in range(1, n_joints + 1)), lines)


def read_pose_table(path) -> PoseTable:
    """The pose table ``path`` (module docstring): T (N, 4, 4) [m] from x/y/z and a unit quaternion."""
    path = Path(path)
    header, rows = _rows(path)
    units = {re.fullmatch(r"[xyz]_(\w+)", h).group(1) for h in header if re.fullmatch(r"[xyz]_(\w+)", h)}
    bad_u = sorted(u for u in units if u not in LENGTH_UNITS)
    if bad_u:
        raise DataError(f"{path}: header: unknown length unit {bad_u[0]!r} (expected {' | '.join(LENGTH_UNITS)})")
    if len(units) > 1:
        raise DataError(f"{path}: header: x, y, z in different units ({', '.join(sorted(units))}): use one")
    unit = units.pop() if units else None
    for h in ("x", "y", "z"):
        if h in header:
            raise DataError(f"{path}: header: column {h!r} has no unit: write {h}_m (or {h}_mm, {h}_cm)")
    expected = [f"{c}_{unit}" if c in "xyz" else c for c in FLANGE_COLUMNS] if unit else \
        ["x_m", "y_m", "z_m", *FLANGE_COLUMNS[3:]]
    known = ["pose_id", *expected]
    for h in header:
        if h not in known:
            raise DataError(f"{path}: header: unknown column {h!r}{did_you_mean(h, known)}; expected [pose_id,] "
                            f"{','.join(expected)}")
    missing = [h for h in expected if h not in header]
    if missing:
        raise DataError(f"{path}: header: missing column(s) {', '.join(missing)}")
    ids, v, lines = _values(path, header, rows, [header.index(h) for h in expected])
    xyz = v[:, :3] * LENGTH_UNITS[unit]
    far = np.flatnonzero(np.linalg.norm(xyz, axis=1) > MAX_ABS_POSITION_M)
    if far.size:
        raise DataError(f"{path}: line {lines[far[0]]}: position {np.linalg.norm(xyz[far[0]]):.4g} m from the base is "
                        f"implausible (> {MAX_ABS_POSITION_M:g} m: millimetres written as {unit}?)")
    nq = np.linalg.norm(v[:, 3:], axis=1)
    bad = np.flatnonzero(np.abs(nq - 1) > QUAT_TOL)
    if bad.size:
        raise DataError(f"{path}: line {lines[bad[0]]}: quaternion (qx, qy, qz, qw) norm {nq[bad[0]]:.4f} is not 1")
    return PoseTable(path, ids, T_from_xyz_quat(xyz, v[:, 3:] / nq[:, None]), unit, lines)


def _fmt(v: float) -> str:
    return repr(float(v))


def write_joint_table(path, q, units, ids=None) -> Path:
    """Write joint values q (N, n) SI as a joint table in ``units`` (n,) (e.g. ("deg",) * 6); ids: pose ids or
    None (no pose_id column). Atomic."""
    q = np.asarray(q, float)
    f = np.array([JOINT_UNITS[u] for u in units])
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow((["pose_id"] if ids is not None else []) + [f"q{j + 1}_{u}" for j, u in enumerate(units)])
    for k, row in enumerate(q / f):
        w.writerow(([ids[k]] if ids is not None else []) + [_fmt(v) for v in row])
    return write_text_atomic(path, buf.getvalue())


def write_pose_table(path, T, ids=None, length_unit: str = "m") -> Path:
    """Write poses T (N, 4, 4) [m] as a pose table (x/y/z in ``length_unit``, quaternion scalar last). Atomic."""
    xyz, quat = xyz_quat_from_T(np.asarray(T, float))
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow((["pose_id"] if ids is not None else []) + [f"{c}_{length_unit}" for c in "xyz"]
               + list(FLANGE_COLUMNS[3:]))
    for k in range(len(xyz)):
        w.writerow(([ids[k]] if ids is not None else []) + [_fmt(v) for v in xyz[k] / LENGTH_UNITS[length_unit]]
                   + [_fmt(v) for v in quat[k]])
    return write_text_atomic(path, buf.getvalue())


__all__ = ["JOINT_UNITS", "JointTable", "PoseTable", "read_joint_table", "read_pose_table", "write_joint_table",
           "write_pose_table"]
