"""Joint sets from a file for a scene's identification poses (``poses: {kind: file, path: poses.csv}``), e.g. the
``poses.csv`` that ``vision-calib plan`` writes, so that ``simulate`` renders exactly a plan.

The file is a recording's ``poses.csv`` (:mod:`vision_calib.io.recording`): a header ``pose_id,q1..qn`` then one
row per pose. Its angle unit (length unit for prismatic joints) is, in this order: the scene's ``poses.units``
(``{angle: deg|rad, length: m|cm|mm}``), else the ``units`` of a ``recording.yaml`` beside the file (a recording
folder, or a plan's output folder), else the scene's own ``units``.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from ..config import ANGLE_UNITS, LENGTH_UNITS, Section, did_you_mean, load_yaml, read_text
from ..errors import DataError


def pose_file_units(path: Path, Lf: float, Af: float, units: Section | None = None) -> tuple[float, float, str]:
    """(length factor to m, angle factor to rad, where they come from) of a pose file (module docstring): the
    mapping ``units`` ({length, angle}) when given, else the recording.yaml beside the file, else (Lf, Af)."""
    if units is not None:
        lu = units.get("length", str, "m", choices=LENGTH_UNITS)
        au = units.get("angle", str, "rad", choices=ANGLE_UNITS)
        units.check_known(("length", "angle"))
        return LENGTH_UNITS[lu], ANGLE_UNITS[au], units.where()
    rec = path.parent / "recording.yaml"
    if rec.is_file():
        u = Section(load_yaml(rec), rec).section("units", default={})
        lu = u.get("length", str, "m", choices=LENGTH_UNITS)
        au = u.get("angle", str, "rad", choices=ANGLE_UNITS)
        return LENGTH_UNITS[lu], ANGLE_UNITS[au], f"{rec}: units"
    return Lf, Af, "the scene's units"


def read_joint_file(path: Path, n_joints: int, Af: float) -> tuple[list[str], np.ndarray]:
    """(pose ids, joints (N, n_joints) rad) of a ``pose_id,q1..qn`` CSV whose values are in an angle unit of factor
    ``Af`` to rad. DataError naming the file, the line and the pose on a bad header, a missing or non-numeric
    value, a duplicate id or a joint count other than the robot's."""
    text = read_text(path, DataError, "pose file")
    rows = [(ln, r) for ln, r in enumerate(csv.reader(io.StringIO(text, newline="")), start=1)
            if r and any(c.strip() for c in r)]
    if len(rows) < 2:
        raise DataError(f"{path}: no pose rows (header pose_id,q1..q{n_joints}, then one row per pose)")
    header = [h.strip() for h in rows[0][1]]
    expected = ["pose_id"] + [f"q{j}" for j in range(1, n_joints + 1)]
    for h in header:
        if h not in expected:
            raise DataError(f"{path}: header: unknown column {h!r}{did_you_mean(h, expected)}; expected "
                            f"{','.join(expected)} (the robot has {n_joints} joints)")
    missing = [h for h in expected if h not in header]
    if missing or len(header) != len(expected):
        raise DataError(f"{path}: header: {'missing column(s) ' + ', '.join(missing) if missing else 'duplicate columns'}"
                        f"; expected {','.join(expected)}")
    cols = [header.index(h) for h in expected]
    ids, vals = [], []
    for ln, r in rows[1:]:
        if len(r) != len(header):
            raise DataError(f"{path}: line {ln}: {len(r)} values, expected {len(header)} ({','.join(header)})")
        pid = r[cols[0]].strip()
        if not pid:
            raise DataError(f"{path}: line {ln}: empty pose_id")
        try:
            v = [float(r[c]) for c in cols[1:]]
        except ValueError:
            raise DataError(f"{path}: line {ln} (pose {pid!r}): non-numeric joint value in "
                            f"{[r[c] for c in cols[1:]]}") from None
        if not np.all(np.isfinite(v)):
            raise DataError(f"{path}: line {ln} (pose {pid!r}): NaN or infinite joint value")
        if pid in ids:
            raise DataError(f"{path}: line {ln}: pose id {pid!r} is used twice")
        ids.append(pid)
        vals.append(v)
    return ids, np.array(vals, float) * Af


__all__ = ["pose_file_units", "read_joint_file"]
