"""Pose-pair files of other hand-eye tools: the ``TransformPairs`` YAML that handeye_calib_camodocal records
(``TransformPairsInput.yml``, read back as ``TransformPairsOutput.yml``; the same layout from easy_handeye-style
samplers), and ``vision-calib import-pairs`` turning one into a pose-pair file for ``process-poses``
(:func:`vision_calib.io.measured_poses_writer.write_pose_pairs`).

Layout (OpenCV FileStorage YAML)::

    %YAML:1.0
    ---
    frameCount: 42
    T1_0: !!opencv-matrix          # T_base_ee: the end effector (flange) pose in the robot base [m]
       rows: 4
       cols: 4
       dt: d
       data: [ r11, r12, r13, tx, r21, ..., 0., 0., 0., 1. ]   # row-major
    T2_0: !!opencv-matrix          # T_cam_marker: the marker (target) pose in the camera [m]
       ...

``%YAML:1.0`` is not a YAML directive PyYAML accepts (nor is the ``---`` that follows it in OpenCV's own
reader's eyes): directive lines (``%...``) are read as comments, keeping the line numbers of every error, and the
``!!opencv-matrix`` tag (``tag:yaml.org,2002:opencv-matrix``) is read by this module, not by a global constructor.
Every key is checked: ``frameCount`` (optional; must equal the number of pairs), ``T1_<i>`` / ``T2_<i>`` for
i = 0..N-1 without holes, each a 4 x 4 matrix (``rows: 4, cols: 4``, ``dt`` d or f, 16 finite numbers) with a
rotation (orthonormal to 1e-4, determinant +1) and a last row 0 0 0 1; anything else is a DataError naming the
file, the key and its line.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import DataError

#: the tag of an OpenCV matrix node (``!!opencv-matrix``)
OPENCV_MATRIX_TAG = "tag:yaml.org,2002:opencv-matrix"
#: a rotation block orthonormal to this (max |R R^T - I|) is a rotation (renormalised); beyond it: an error
ROTATION_TOL = 1e-4
_KEY = re.compile(r"(T[12])_(\d+)")


def _line(node) -> int:
    return node.start_mark.line + 1


def _matrix(node, path, key: str) -> np.ndarray:
    """(4, 4) float of an opencv-matrix node (or a plain mapping with rows/cols/dt/data); DataError naming the key."""
    import yaml

    where = f"{path}: line {_line(node)}: {key}"
    if not isinstance(node, yaml.MappingNode):
        raise DataError(f"{where}: expected an !!opencv-matrix mapping (rows, cols, dt, data)")
    fields = {}
    for kn, vn in node.value:
        if kn.value in fields:
            raise DataError(f"{path}: line {_line(kn)}: {key}.{kn.value} given twice")
        fields[kn.value] = vn
    unknown = sorted(set(fields) - {"rows", "cols", "dt", "data"})
    if unknown:
        raise DataError(f"{where}: unknown key(s) {', '.join(unknown)} (an opencv-matrix has rows, cols, dt, data)")
    for k in ("rows", "cols", "dt", "data"):
        if k not in fields:
            raise DataError(f"{where}: missing {k!r} (an opencv-matrix has rows, cols, dt, data)")
    for k in ("rows", "cols"):
        if not isinstance(fields[k], yaml.ScalarNode) or fields[k].value.strip() != "4":
            raise DataError(f"{path}: line {_line(fields[k])}: {key}.{k}: expected 4 (a 4 x 4 transform), got "
                            f"{getattr(fields[k], 'value', fields[k])!r}")
    if not isinstance(fields["dt"], yaml.ScalarNode) or fields["dt"].value.strip() not in ("d", "f"):
        raise DataError(f"{path}: line {_line(fields['dt'])}: {key}.dt: expected d (double) or f (float)")
    data = fields["data"]
    if not isinstance(data, yaml.SequenceNode) or len(data.value) != 16:
        n = len(data.value) if isinstance(data, yaml.SequenceNode) else "no list"
        raise DataError(f"{path}: line {_line(data)}: {key}.data: expected 16 numbers (4 x 4, row-major), got {n}")
    vals = []
    for i, item in enumerate(data.value):
        text = getattr(item, "value", None)
        try:
            v = float(str(text).strip().replace(".Inf", "inf").replace(".NaN", "nan"))
        except ValueError:
            raise DataError(f"{path}: line {_line(item)}: {key}.data[{i}]: not a number ({text!r})") from None
        if not np.isfinite(v):
            raise DataError(f"{path}: line {_line(item)}: {key}.data[{i}]: NaN or infinite value")
        vals.append(v)
    T = np.array(vals).reshape(4, 4)
    if np.max(np.abs(T[3] - [0, 0, 0, 1])) > 1e-9:
        raise DataError(f"{where}: last row {T[3].tolist()} is not 0 0 0 1 (not a rigid transform)")
    R = T[:3, :3]
    err = float(np.max(np.abs(R @ R.T - np.eye(3))))
    if err > ROTATION_TOL or np.linalg.det(R) < 0:
        raise DataError(f"{where}: the rotation block is not a rotation (|R R^T - I| = {err:.2g}, det "
                        f"{np.linalg.det(R):.4g}): a transposed or scaled matrix?")
    U, _, Vt = np.linalg.svd(R)
    T[:3, :3] = U @ Vt  # renormalised (printed to 17 digits: exact to ~1e-16)
    return T


_HEAD = re.compile(r"(T[12])_(\d+):\s*!!opencv-matrix\s*")
_FIELD = re.compile(r"\s+(rows|cols|dt):\s*(\S+)\s*")


def _streamed_pairs(path: Path, progress: bool = False):
    """(T1, T2) of a TransformPairs file in the layout OpenCV (and :func:`write_transform_pairs`) writes, read
    line by line (a progress bar over the bytes with ``progress``) without building a YAML node per number; None
    as soon as the file departs from that layout or holds anything the checks of :func:`read_transform_pairs`
    refuse, which then reads it (and names what is wrong)."""
    mats, count, cur, buf = {"T1": {}, "T2": {}}, None, None, None
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=path.stat().st_size, unit="B", unit_scale=True, desc="read pairs", leave=False)
    try:
        with open(path, "rb") as f:
            for raw in f:
                if bar is not None:
                    bar.update(len(raw))
                line = raw.decode("utf-8", "replace").rstrip("\r\n")
                if buf is not None:  # inside data: [ ... ]
                    buf.append(line)
                    if "]" in line:
                        cur["data"], buf = " ".join(buf), None
                    continue
                s = line.strip()
                if not s or s.startswith("%") or s == "---" or s.startswith("#"):
                    continue
                m = _HEAD.fullmatch(line)
                if m:
                    if cur is not None and "data" not in cur:
                        return None
                    idx = int(m.group(2))
                    if idx in mats[m.group(1)]:
                        return None
                    cur = mats[m.group(1)][idx] = {}
                    continue
                if s.startswith("frameCount:") and count is None and cur is None:
                    count = s.split(":", 1)[1].strip()
                    continue
                m = _FIELD.fullmatch(line)
                if cur is not None and m and m.group(1) not in cur:
                    cur[m.group(1)] = m.group(2)
                    continue
                if cur is not None and line.startswith((" ", "\t")) and s.startswith("data:") and "data" not in cur:
                    buf = [s[5:]]
                    if "]" in s:
                        cur["data"], buf = s[5:], None
                    continue
                return None
    finally:
        if bar is not None:
            bar.close()
    n = len(mats["T1"])
    if buf is not None or n < 3 or sorted(mats["T1"]) != list(range(n)) or sorted(mats["T2"]) != list(range(n)):
        return None
    if count is not None and count != str(n):
        return None
    out = []
    for name in ("T1", "T2"):
        rows = []
        for i in range(n):
            c = mats[name][i]
            if (c.get("rows"), c.get("cols")) != ("4", "4") or c.get("dt") not in ("d", "f") or "data" not in c:
                return None
            text = c["data"].strip()
            if not (text.startswith("[") and text.endswith("]")):
                return None
            try:
                v = np.array(text[1:-1].split(","), dtype=float)
            except ValueError:
                return None
            if v.size != 16:
                return None
            rows.append(v)
        T = np.array(rows).reshape(n, 4, 4)
        if not np.all(np.isfinite(T)) or np.max(np.abs(T[:, 3] - [0, 0, 0, 1])) > 1e-9:
            return None
        R = T[:, :3, :3]
        if np.max(np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3))) > ROTATION_TOL or np.any(np.linalg.det(R) < 0):
            return None
        U, _, Vt = np.linalg.svd(R)
        T[:, :3, :3] = U @ Vt  # renormalised, as _matrix does
        out.append(T)
    return out[0], out[1]


def read_transform_pairs(path, progress: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(T1 (N, 4, 4), T2 (N, 4, 4)) of a TransformPairs file (module docstring): T1 = T_base_ee, T2 =
    T_cam_marker [m]. DataError naming the file, the key and its line for anything it does not expect. The layout
    OpenCV writes is streamed (:func:`_streamed_pairs`: O(N), a progress bar with ``progress``); any other is
    composed as YAML."""
    import yaml

    from ..config import BoundedLoader, read_text

    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: file not found")
    fast = _streamed_pairs(path, progress)
    if fast is not None:
        return fast
    text = read_text(path, DataError)
    # directives (%YAML:1.0, which PyYAML refuses) as comments: the line numbers stay those of the file
    text = "\n".join("#" + ln if ln.lstrip().startswith("%") else ln for ln in text.splitlines())
    try:
        docs = [d for d in yaml.compose_all(text, Loader=BoundedLoader) if d is not None]
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f"line {mark.line + 1}: " if mark is not None else ""
        raise DataError(f"{path}: {at}not a readable YAML file ({getattr(exc, 'problem', None) or exc})") from None
    if len(docs) != 1 or not isinstance(docs[0], yaml.MappingNode):
        raise DataError(f"{path}: expected one mapping of frameCount, T1_<i>, T2_<i> (got {len(docs)} YAML documents)")
    mats, count, seen = {"T1": {}, "T2": {}}, None, set()
    for kn, vn in docs[0].value:
        key = str(kn.value)
        if key in seen:
            raise DataError(f"{path}: line {_line(kn)}: key {key!r} given twice")
        seen.add(key)
        m = _KEY.fullmatch(key)
        if key == "frameCount":
            try:
                count = int(str(vn.value).strip())
            except (ValueError, AttributeError):
                raise DataError(f"{path}: line {_line(vn)}: frameCount: expected an integer, got "
                                f"{getattr(vn, 'value', '?')!r}") from None
        elif m:
            mats[m.group(1)][int(m.group(2))] = _matrix(vn, path, key)
        else:
            raise DataError(f"{path}: line {_line(kn)}: unknown key {key!r} (a TransformPairs file has frameCount, "
                            "T1_<i> (base -> end effector), T2_<i> (camera -> marker))")
    n = max([len(mats["T1"]), len(mats["T2"])])
    for name, other in (("T1", "T2"), ("T2", "T1")):
        missing = [f"{name}_{i}" for i in range(n) if i not in mats[name]]
        if missing or (mats[name] and max(mats[name]) >= n):
            gap = missing or [f"{name}_{max(mats[name])}"]
            raise DataError(f"{path}: {', '.join(gap[:5])}: the pairs must be numbered 0..{n - 1} without holes, each "
                            f"with its {other}")
    if n < 3:
        raise DataError(f"{path}: {n} transform pairs; a hand-eye calibration needs at least 3")
    if count is not None and count != n:
        raise DataError(f"{path}: frameCount is {count} but the file holds {n} pairs (T1_0..T1_{n - 1})")
    return (np.array([mats["T1"][i] for i in range(n)]), np.array([mats["T2"][i] for i in range(n)]))


def _rows16(T: np.ndarray) -> str:
    vals = [repr(float(v)) for v in np.asarray(T, float).reshape(-1)]
    return "[ " + ",\n       ".join(", ".join(vals[i:i + 4]) for i in range(0, 16, 4)) + " ]"


def write_transform_pairs(path, T1, T2) -> Path:
    """A TransformPairs file (module docstring; ``%YAML:1.0`` and ``---`` header as OpenCV writes it) of T1
    (N, 4, 4) T_base_ee and T2 (N, 4, 4) T_cam_marker [m], numbers to 17 significant digits (atomic write)."""
    from ..serialize import write_text_atomic

    T1, T2 = np.asarray(T1, float), np.asarray(T2, float)
    lines = ["%YAML:1.0", "---", f"frameCount: {len(T1)}"]
    for i, (a, b) in enumerate(zip(T1, T2)):
        for name, T in (("T1", a), ("T2", b)):
            lines += [f"{name}_{i}: !!opencv-matrix", "   rows: 4", "   cols: 4", "   dt: d", f"   data: {_rows16(T)}"]
    return write_text_atomic(path, "\n".join(lines) + "\n")


def import_pairs(path, mount: str, out, units: dict | None = None, folds: int = 5, seed: int = 0,
                 progress: bool = False) -> Path:
    """Write the pose-pair file ``out`` (YAML + ``<stem>.csv`` + ``<stem>_flange.csv``,
    :func:`vision_calib.io.measured_poses_writer.write_pose_pairs`) of a TransformPairs file: flange poses T1, measured
    T_cam_target T2, pose ids ``p000``..; the measured poses' noise is estimated per axis of the target frame
    (their files carry no noise). mount: "eye_in_hand" | "fixed". progress: a bar while the file is read. Returns
    the YAML's path."""
    from .measured_poses import PAIR_MOUNTS
    from .measured_poses_writer import write_pose_pairs

    if mount not in PAIR_MOUNTS:
        raise DataError(f"--mount: expected one of {', '.join(PAIR_MOUNTS)}, got {mount!r}")
    out = Path(out)
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise DataError(f"{out}: the pose-pair file to write must end in .yaml (its CSVs are written beside it)")
    T1, T2 = read_transform_pairs(path, progress)
    ids = [f"p{i:03d}" for i in range(len(T1))]
    out.parent.mkdir(parents=True, exist_ok=True)
    return write_pose_pairs(out, ids, T1, T2, mount, "T_cam_target", units=units or {"length": "m", "angle": "deg"},
                            noise_frame="target", folds=folds, seed=seed)


__all__ = ["OPENCV_MATRIX_TAG", "read_transform_pairs", "write_transform_pairs", "import_pairs"]
