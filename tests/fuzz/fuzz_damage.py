"""Ways to damage a recorded folder (DESIGN.md §5 layout): each function edits a copy in place.

Cases are (id, damage function, expected outcome, pattern): "error" = exit 2 or 3 with ``pattern``
(a regex naming the file/key/pose) in the message; "correct" = exit 0 and every free parameter
within its stated uncertainty of the undamaged run. Cases that today end in a silent wrong result
carry the name of the missing pipeline check (they are xfail(strict=True) in the test).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import yaml


def _yaml(rec: Path, edit) -> None:
    p = rec / "recording.yaml"
    d = yaml.safe_load(p.read_text())
    edit(d)
    p.write_text(yaml.safe_dump(d, sort_keys=False))


def _set(path: str, value):
    """Edit recording.yaml: set a dotted key (creating it)."""
    def edit(d):
        *head, last = path.split(".")
        for k in head:
            d = d.setdefault(k, {})
        d[last] = value
    return lambda rec: _yaml(rec, edit)


def _drop(path: str):
    def edit(d):
        *head, last = path.split(".")
        for k in head:
            d = d[k]
        del d[last]
    return lambda rec: _yaml(rec, edit)


def _rename(path: str, new: str):
    def edit(d):
        *head, last = path.split(".")
        for k in head:
            d = d[k]
        d[new] = d.pop(last)
    return lambda rec: _yaml(rec, edit)


def _scale(path: str, factor: float):
    def edit(d):
        *head, last = path.split(".")
        for k in head:
            d = d[k]
        d[last] = d[last] * factor
    return lambda rec: _yaml(rec, edit)


def _raw_yaml(text: bytes):
    return lambda rec: (rec / "recording.yaml").write_bytes(text)


def _csv_rows(rec: Path) -> list[list[str]]:
    return [line.split(",") for line in (rec / "poses.csv").read_text().splitlines() if line]


def _write_csv(rec: Path, rows, encoding="utf-8", newline="\n", bom=False) -> None:
    text = newline.join(",".join(r) for r in rows) + newline
    (rec / "poses.csv").write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.encode(encoding))


def _csv_cell(row: int, col: int, value: str):
    def damage(rec):
        rows = _csv_rows(rec)
        rows[row][col] = value
        _write_csv(rec, rows)
    return damage


def _csv_header(header: str):
    def damage(rec):
        rows = _csv_rows(rec)
        rows[0] = header.split(",")
        _write_csv(rec, rows)
    return damage


def _csv_permute(order):
    """Reorder the columns (header and values together)."""
    def damage(rec):
        _write_csv(rec, [[r[i] for i in order] for r in _csv_rows(rec)])
    return damage


def _csv_edit(fn):
    def damage(rec):
        _write_csv(rec, fn(_csv_rows(rec)))
    return damage


def _csv_reencode(**kw):
    return lambda rec: _write_csv(rec, _csv_rows(rec), **kw)


def _latin1_pose_id(rec):
    rows = _csv_rows(rec)
    rows[3][0] = "pos\xe9"
    _write_csv(rec, rows, encoding="latin-1")


def _each_image(pose: str, fn):
    def damage(rec):
        for f in sorted((rec / "images" / pose).glob("*.png")):
            fn(f)
    return damage


def _blank(f):
    cv2.imwrite(str(f), np.full((768, 1024), 128, np.uint8))


def _small(f):
    cv2.imwrite(str(f), np.full((480, 640), 128, np.uint8))


def _corrupt(f):
    f.write_bytes(b"\x89PNG\r\n\x1a\n garbage")


def _mirror(f):
    cv2.imwrite(str(f), cv2.flip(cv2.imread(str(f), cv2.IMREAD_UNCHANGED), 1))


def _colour(f):
    cv2.imwrite(str(f), cv2.cvtColor(cv2.imread(str(f), cv2.IMREAD_GRAYSCALE), cv2.COLOR_GRAY2BGR))


def _sixteen_bit(f):
    cv2.imwrite(str(f), cv2.imread(str(f), cv2.IMREAD_GRAYSCALE).astype(np.uint16) * 257)


def _reformat(ext: str, params=(), convert=None, truncate=False):
    """Rewrite a PNG frame as ``ext`` (optionally converted, or truncated to half its bytes)."""
    def fn(f):
        img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
        new = f.with_suffix(ext)
        cv2.imwrite(str(new), convert(img) if convert else img, list(params))
        f.unlink()
        if truncate:
            new.write_bytes(new.read_bytes()[: new.stat().st_size // 2])
    return fn


def _flange_csv(scale_xyz=1.0, quat_scale=1.0):
    """Replace poses.csv by flange poses (poses: flange_pose) of plausible size, times scale_xyz; the
    first row's quaternion times quat_scale."""
    def damage(rec):
        _set("poses", "flange_pose")(rec)
        rows = _csv_rows(rec)
        out = [["pose_id", "x", "y", "z", "qx", "qy", "qz", "qw"]]
        for i, r in enumerate(rows[1:]):
            q = np.array([0.0, 0.0, np.sin(0.1 * i), np.cos(0.1 * i)]) * (quat_scale if i == 0 else 1.0)
            out.append([r[0]] + [repr(float(v)) for v in (0.4 * scale_xyz, 0.1 * scale_xyz, 0.5 * scale_xyz, *q)])
        _write_csv(rec, out)
    return damage


def _swap_poses(a: str, b: str):
    def damage(rec):
        i = rec / "images"
        os.rename(i / a, i / "tmp")
        os.rename(i / b, i / a)
        os.rename(i / "tmp", i / b)
    return damage


def _remove(rel: str):
    def damage(rec):
        p = rec / rel
        shutil.rmtree(p) if p.is_dir() else p.unlink()
    return damage


def _symlink_out(rel: str):
    """Move ``rel`` out of the folder and leave a symlink to it."""
    def damage(rec):
        p = rec / rel
        outside = rec.parent / f"outside_{p.name}"
        shutil.move(str(p), str(outside))
        p.symlink_to(outside)
    return damage


def _symlink_inside(rec):
    f = rec / "images" / "002" / "01.png"
    f.unlink()
    f.symlink_to(rec / "images" / "002" / "00.png")


def _extra_frame(rec):
    shutil.copyfile(rec / "images" / "001" / "00.png", rec / "images" / "001" / "02.png")


def _perturb_joint(rec):
    rows = _csv_rows(rec)
    rows[4][2] = repr(float(rows[4][2]) + float(np.radians(10.0)))
    _write_csv(rec, rows)


#: outcome of every fuzz case, filled by the test: {case id: "named_error" | "correct" | "silent_wrong" | ...}
TALLY: dict[str, str] = {}

ERR, OK = "error", "correct"

CASES = [
    # --- recording.yaml: keys
    ("yaml-typo-frames_per_poses", _rename("frames_per_pose", "frames_per_poses"), ERR, r"frames_per_poses.*did you mean 'frames_per_pose'"),
    ("yaml-unknown-measurment", _set("measurment", {"frames": 2}), ERR, r"recording.yaml: measurment: unknown key"),
    ("yaml-camera-k9", _set("camera.k9", 0.1), ERR, r"camera.k9: unknown key"),
    ("yaml-units-typo", _set("units.lenght", "mm"), ERR, r"units.lenght.*did you mean 'length'"),
    ("yaml-target-typo", _rename("target.square_m", "squar_m"), ERR, r"squar_m.*did you mean 'square_m'"),
    # no intrinsics: calibrated from the recording's images, their uncertainty propagated into the std
    ("yaml-missing-camera", _drop("camera"), OK, None),
    ("yaml-missing-dist", _drop("camera.dist"), ERR, r"camera: missing key\(s\) dist.*dist: \[0, 0, 0, 0, 0\]"),
    ("yaml-missing-mount", _drop("camera_mount"), ERR, r"camera_mount: missing"),
    ("yaml-missing-target", _drop("target"), ERR, r"target: missing"),
    ("yaml-missing-cx", _drop("camera.cx"), ERR, r"camera: missing key\(s\) cx"),
    # --- recording.yaml: values, types, ranges
    ("yaml-dist-4", _set("camera.dist", [0.0, 0.0, 0.0, 0.0]), ERR, r"recording.yaml: camera.dist: expected 5"),
    ("yaml-dist-nan", _set("camera.dist", [float("nan"), 0, 0, 0, 0]), ERR, r"camera.dist: expected 5 finite"),
    ("yaml-fx-zero", _set("camera.fx", 0.0), ERR, r"recording.yaml: camera.fx: expected a focal length > 0"),
    ("yaml-fx-negative", _set("camera.fx", -1100.0), ERR, r"camera.fx: expected a focal length > 0"),
    ("yaml-fx-nan", _set("camera.fx", float("nan")), ERR, r"recording.yaml: camera.fx: expected a finite"),
    ("yaml-fx-string", _set("camera.fx", "1100px"), ERR, r"camera.fx: expected a number"),
    ("yaml-width-float", _set("camera.width", 1024.5), ERR, r"camera.width: expected a positive integer"),
    ("yaml-width-x2", _scale("camera.width", 2), ERR, r"camera.width: 2048 px but the images are 1024x768 px \(.*images/000/00.png\)"),
    ("yaml-fx-x10", _scale("camera.fx", 10), ERR, r"fx|plausib|converge"),
    ("yaml-frames-zero", _set("frames_per_pose", 0), ERR, r"frames_per_pose: expected a value >= 1"),
    ("yaml-frames-text", _set("frames_per_pose", "two"), ERR, r"frames_per_pose: expected int"),
    ("yaml-frames-1-of-2", _set("frames_per_pose", 1), ERR, r"images/000: 2 images but recording.yaml frames_per_pose is 1"),
    ("yaml-format", _set("format", "vision_calib.recording/9"), ERR, r"format: expected"),
    ("yaml-averaging", _set("averaging", "median"), ERR, r"averaging: expected one of"),
    ("yaml-mount-bad", _set("camera_mount", "hand"), ERR, r"camera_mount: expected one of"),
    ("yaml-poses-flange", _set("poses", "flange_pose"), ERR, r"poses.csv: header: unknown column 'q1'"),
    ("yaml-units-mm", _set("units.length", "mm"), OK, None),  # joints only: lengths unused
    ("yaml-units-cubit", _set("units.length", "cubit"), ERR, r"units.length: expected one of"),
    ("yaml-scene-missing", _set("scene", "/nonexistent/scene.yaml"), OK, None),  # falls back to scenes/<scene_name>
    ("yaml-scene-and-name-missing", lambda r: (_set("scene", "nope.yaml")(r), _set("scene_name", "nope")(r)), ERR, r"scene: file not found"),
    ("yaml-target-square-x2", lambda r: (_scale("target.square_m", 2)(r), _scale("target.marker_m", 2)(r)), ERR, r"measured motions are .* x the commanded ones.*square_m"),
    ("yaml-target-rows-cols-swapped", lambda r: (_set("target.rows", 7)(r), _set("target.cols", 5)(r)), ERR, r"too few|usable|valid"),
    ("yaml-target-dictionary", _set("target.dictionary", "DICT_6X6_250"), ERR, r"too few|usable|valid"),
    ("yaml-angle-deg", _set("units.angle", "deg"), ERR, r"do not follow the commanded joints.*wrong angle unit"),
    ("yaml-mount-fixed", _set("camera_mount", "fixed"), ERR, r"recording.yaml: camera_mount: 'fixed' but the scene"),
    ("yaml-empty", _raw_yaml(b""), ERR, r"recording.yaml: expected a mapping"),
    ("yaml-list", _raw_yaml(b"- 1\n- 2\n"), ERR, r"recording.yaml: expected a mapping"),
    ("yaml-syntax", _raw_yaml(b"camera: {width: 1024\n"), ERR, r"recording.yaml: invalid YAML"),
    ("yaml-latin1", _raw_yaml(b"format: vision_calib.recording/1\nnotes: caf\xe9\n"), ERR, r"recording.yaml: line 2: not UTF-8"),
    ("yaml-removed", _remove("recording.yaml"), ERR, r"recording.yaml: file not found"),
    # --- poses.csv
    ("csv-columns-reordered", _csv_permute([0, 3, 1, 2, 6, 5, 4]), OK, None),
    ("csv-pose_id-last", _csv_permute([1, 2, 3, 4, 5, 6, 0]), OK, None),
    ("csv-header-lies", _csv_header("pose_id,q2,q1,q3,q4,q5,q6"), ERR, r"do not follow the commanded joints|outside the robot's limits|outlier poses"),
    ("csv-unknown-column", _csv_edit(lambda rows: [r + (["temp"] if i == 0 else ["21.5"]) for i, r in enumerate(rows)]), ERR, r"poses.csv: header: unknown column 'temp'"),
    ("csv-typo-column", _csv_header("pose_id,q1,q2,q3,q4,q5,g6"), ERR, r"unknown column 'g6'"),
    ("csv-duplicate-column", _csv_header("pose_id,q1,q2,q3,q3,q5,q6"), ERR, r"duplicate column\(s\) q3"),
    ("csv-missing-column", _csv_permute([0, 1, 2, 3, 5, 6]), ERR, r"missing column\(s\) q4"),
    ("csv-no-pose_id", _csv_header("id,q1,q2,q3,q4,q5,q6"), ERR, r"unknown column 'id'"),
    ("csv-extra-joint", _csv_edit(lambda rows: [r + (["q7"] if i == 0 else ["0.1"]) for i, r in enumerate(rows)]), ERR, r"poses.csv: 7 joint columns, the robot has 6"),
    ("csv-nan", _csv_cell(3, 2, "nan"), ERR, r"poses.csv: line 4 \(pose '002'\): NaN"),
    ("csv-inf", _csv_cell(3, 2, "-inf"), ERR, r"line 4 \(pose '002'\): NaN or infinite"),
    ("csv-1e300", _csv_cell(3, 2, "1e300"), ERR, r"line 4 \(pose '002'\): implausible value"),
    ("csv-text", _csv_cell(2, 5, "abc"), ERR, r"line 3 \(pose '001'\): non-numeric"),
    ("csv-empty-cell", _csv_cell(2, 5, ""), ERR, r"line 3 \(pose '001'\): non-numeric"),
    ("csv-short-row", _csv_edit(lambda rows: rows[:2] + [rows[2][:-1]] + rows[3:]), ERR, r"poses.csv: line 3: 6 values"),
    ("csv-duplicate-id", _csv_cell(3, 0, "001"), ERR, r"duplicate pose ids \['001'\]"),
    ("csv-bad-id", _csv_cell(3, 0, "../x"), ERR, r"line 4: invalid pose_id"),
    ("csv-latin1", _latin1_pose_id, ERR, r"poses.csv: line 4: not UTF-8"),
    ("csv-utf16", _csv_reencode(encoding="utf-16"), ERR, r"poses.csv: line 1: not UTF-8"),
    ("csv-bom", _csv_reencode(bom=True), OK, None),
    ("csv-crlf", _csv_reencode(newline="\r\n"), OK, None),
    ("csv-header-only", _csv_edit(lambda rows: rows[:1]), ERR, r"poses.csv: no pose rows"),
    ("csv-removed", _remove("poses.csv"), ERR, r"poses.csv: file not found"),
    ("csv-row-dropped", _csv_edit(lambda rows: rows[:5] + rows[6:]), OK, None),
    ("csv-rows-shuffled", _csv_edit(lambda rows: rows[:1] + rows[1:][::-1]), OK, None),
    ("csv-joint-off-10deg", _perturb_joint, OK, "the pose is rejected: its motion does not follow its joints"),
    # --- images
    ("img-pose-missing", _remove("images/004"), OK, None),
    ("img-corrupt", _each_image("005", _corrupt), OK, None),
    ("img-blank", _each_image("006", _blank), OK, None),
    ("img-wrong-size", _each_image("007", _small), ERR, r"images/007/00.png: image size 640x480 does not match the camera intrinsics 1024x768"),
    ("img-jpeg-95", _each_image("002", _reformat(".jpg", [cv2.IMWRITE_JPEG_QUALITY, 95])), OK, None),
    ("img-bmp", _each_image("003", _reformat(".bmp")), OK, None),
    ("img-tiff-12bit", _each_image("004", _reformat(".tif", convert=lambda a: a.astype(np.uint16) << 4)), OK, None),
    ("img-jpeg-truncated", _each_image("005", _reformat(".jpg", truncate=True)), OK, None),  # pose rejected, file named
    ("img-tiff-truncated", _each_image("006", _reformat(".tiff", truncate=True)), OK, None),
    # --- unit and frame checks up front
    ("csv-joints-in-degrees", _csv_edit(lambda rows: rows[:1] + [[r[0]] + [repr(float(v) * 57.29577951308232) for v in r[1:]] for r in rows[1:]]), ERR, r"poses.csv: (line \d+ \(pose '\d+'\): implausible value .*degrees declared as radians|pose .* outside the robot's limits .*wrong angle unit)"),
    ("csv-flange-mm-as-m", _flange_csv(scale_xyz=1000.0), ERR, r"poses.csv: line 2 \(pose '000'\): implausible value 500 .*millimetres declared as metres"),
    ("csv-flange-quat-norm", _flange_csv(quat_scale=1.01), ERR, r"poses.csv: pose '000': quaternion norm 1.0100 is not 1"),
    ("img-mirrored", _each_image("003", _mirror), OK, None),
    ("img-colour", _each_image("002", _colour), OK, None),
    ("img-16bit", _each_image("002", _sixteen_bit), OK, None),
    ("img-all-missing", _remove("images"), ERR, r"too few|usable|valid"),
    ("img-extra-frame", _extra_frame, ERR, r"images/001: 3 images but recording.yaml frames_per_pose is 2"),
    ("img-symlink-inside", _symlink_inside, OK, "identical frames (zero scatter): the pose is rejected with the reason"),
    ("img-symlink-file-out", _symlink_out("images/001/00.png"), ERR, r"images/001/00.png: a symbolic link leading out"),
    ("img-symlink-pose-out", _symlink_out("images/002"), ERR, r"images/002: a symbolic link leading out"),
    ("img-symlink-images-out", _symlink_out("images"), ERR, r"images: a symbolic link leading out"),
    ("yaml-symlink-out", _symlink_out("recording.yaml"), ERR, r"recording.yaml: a symbolic link leading out"),
    ("img-swapped-between-poses", _swap_poses("001", "008"), OK, "both poses are rejected: motion inconsistent"),
]
