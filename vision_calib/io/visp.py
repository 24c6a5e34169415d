"""ViSP files: camera XML (vpXmlParserCamera), pose YAML (t + theta-u vectors), pattern descriptions
(``chessboard-data.txt``, ``apriltag-data.txt``), and hand-eye folders (AprilTag eye-to-hand, chessboard
eye-in-hand) converted into recorded folders (:func:`import_visp` picks the kind from the folder's own files).

A ViSP hand-eye folder, as its acquisition apps write it (``visp-acquire-franka-calib-data``)::

    franka_camera.xml        intrinsics (any ``*camera*.xml``)
    franka_image-N.png       one image per robot pose (any ``*image-N.<png|jpg|bmp|tif>``)
    franka_pose_rPe_N.yaml   flange pose in the robot base, t [m] + theta-u [rad] (``*pose_rPe_N`` /
                             ``*pose_fPe_N`` / ``*w_P_ee-N``)
    chessboard-data.txt      "Chessboard / 9 x 6 / square size: 0.0236 m" (inner corners, ViSP's -w x -h)
    apriltag-data.txt        "36h11 ... / size: 0.048 m" (the tag family and side)
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .. import frames
from ..camera import CameraIntrinsics
from ..errors import ConfigError, DataError


def read_visp_camera_xml(path, camera_name: str | None = None) -> CameraIntrinsics:
    """ViSP camera XML -> CameraIntrinsics. px, py [px] -> fx, fy; u0, v0 -> cx, cy.

    ViSP's distortion model (kud/kdu, single radial term) differs from Brown–Conrady: only
    ``perspectiveProjWithoutDistortion`` or zero kud/kdu are accepted; a non-zero one raises
    ConfigError. camera_name selects a <camera> by <name> (default: the first)."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(f"{path}: cannot read ViSP camera XML ({exc})") from None
    cams = root.findall("camera")
    if camera_name is not None:
        cams = [c for c in cams if (c.findtext("name") or "").strip() == camera_name]
    if not cams:
        raise ConfigError(f"{path}: no <camera> element" + (f" named {camera_name!r}" if camera_name else ""))
    cam = cams[0]

    def num(el, key, where):
        txt = el.findtext(key)
        if txt is None:
            raise ConfigError(f"{path}: {where}: missing <{key}>")
        try:
            return float(txt)
        except ValueError:
            raise ConfigError(f"{path}: {where}: <{key}> is not a number ({txt!r})") from None

    w, h = num(cam, "image_width", "camera"), num(cam, "image_height", "camera")
    if not (w >= 1 and h >= 1 and float(w).is_integer() and float(h).is_integer()):
        raise ConfigError(f"{path}: camera: <image_width>/<image_height> must be positive integers, got {w} x {h}")
    w, h = int(w), int(h)
    models = cam.findall("model")
    if not models:
        raise ConfigError(f"{path}: camera: missing <model>")
    model = next((m for m in models if (m.findtext("type") or "").strip() == "perspectiveProjWithoutDistortion"),
                 models[0])
    mtype = (model.findtext("type") or "").strip()
    if mtype == "perspectiveProjWithDistortion":
        for key in ("kud", "kdu"):
            if model.findtext(key) is not None and num(model, key, "model") != 0.0:
                raise ConfigError(f"{path}: model {mtype}: non-zero <{key}> (ViSP radial model) is not supported")
    try:
        return CameraIntrinsics(w, h, num(model, "px", "model"), num(model, "py", "model"),
                                num(model, "u0", "model"), num(model, "v0", "model"))
    except ConfigError as exc:  # non-positive or non-finite px/py/size: name the file
        raise ConfigError(f"{path}: {exc}") from None


_POSE_KEYS = ("rows", "cols", "data")


def read_visp_pose_yaml(path) -> np.ndarray:
    """ViSP pose YAML (rows: 6, cols: 1, data: [tx, ty, tz (m), theta-u (rad)]) -> (4, 4) transform."""
    from ..config import parse_yaml

    path = Path(path)
    d = parse_yaml(path, DataError, "ViSP pose YAML")
    if not isinstance(d, dict):
        raise DataError(f"{path}: expected a mapping with rows, cols, data, got {type(d).__name__}")
    from ..config import did_you_mean

    for key in d:
        if key not in _POSE_KEYS:
            raise DataError(f"{path}: {key}: unknown key{did_you_mean(key, _POSE_KEYS)}; allowed: {', '.join(_POSE_KEYS)}")
    if d.get("rows", 6) != 6 or d.get("cols", 1) != 1:
        raise DataError(f"{path}: expected rows: 6, cols: 1 (6 numbers: t [m], theta-u [rad]), got rows: {d.get('rows')}, "
                        f"cols: {d.get('cols')}")
    try:
        v = np.asarray(d["data"], dtype=float).reshape(-1)
    except (TypeError, KeyError, ValueError) as exc:
        raise DataError(f"{path}: key 'data' must hold 6 numbers (t [m], theta-u [rad]) ({exc})") from None
    if v.size != 6:
        raise DataError(f"{path}: key 'data' must hold 6 numbers (t [m], theta-u [rad]), got {v.size}")
    frames.check_finite(f"{path}: data", v)
    angle = float(np.linalg.norm(v[3:]))
    if angle > np.pi + 1e-6:  # a rotation vector's angle is at most pi: a larger one is in degrees (or garbage)
        raise DataError(f"{path}: theta-u (data[3:6]) has angle {angle:.4g}, more than pi rad: ViSP writes theta-u in "
                        f"radians (degrees would be {np.radians(angle):.4g} rad)")
    return frames.T_from_xyz_rotvec(v)


def _detect_tag_id(image_path, dictionary: str) -> int:
    import cv2

    from ..measure.detect import load_gray  # the one decoder: header and pixel limit checked first

    img, why = load_gray(image_path)
    if img is None:
        raise DataError(f"{image_path}: unreadable image ({why})")
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)))
    _, ids, _ = det.detectMarkers(img)
    if ids is None or len(ids) != 1:
        raise DataError(f"{image_path}: expected exactly one {dictionary} tag, found "
                        f"{0 if ids is None else len(ids)}; give the tag id explicitly")
    return int(ids[0][0])


def copy_no_looser(src_file: Path, dst_file: Path) -> None:
    """Copy a file's bytes; the copy is never more readable/writable than the source (mode & source mode)."""
    import shutil

    mode = src_file.stat().st_mode & 0o777
    shutil.copyfile(src_file, dst_file)
    os.chmod(dst_file, (dst_file.stat().st_mode & 0o777) & mode)


def _collect(src: Path, allow_symlinks: bool):
    """(camera, {n: T_base_flange}, {n: image path}) of a ViSP hand-eye folder: ``*camera*.xml``,
    ``*pose_rPe_N.yaml`` or ``*pose_fPe_N.yaml`` (flange in the robot base/reference frame, t [m] +
    theta-u [rad]), ``*image-N.<png|jpg|bmp|tif>``. DataError naming the file for a missing part, a
    translation beyond 20 m (millimetres?) or an image whose size differs from the camera XML's."""
    import re

    from .images import IMAGE_EXT, check_image_sizes
    from .recording import MAX_ABS_POSITION_M, check_inside

    if not src.is_dir():
        raise DataError(f"{src}: ViSP folder not found")
    cams = [check_inside(p, src, allow_symlinks) for p in sorted(src.glob("*camera*.xml"))]
    if not cams:
        raise DataError(f"{src}: no ViSP camera XML (*camera*.xml)")
    intr = read_visp_camera_xml(cams[0])
    poses, named = {}, {}
    for p in sorted([*src.glob("*pose_[rf]Pe_*.yaml"), *src.glob("*w_P_ee-*.yaml")]):
        m = re.search(r"[_-](\d+)\.yaml$", p.name)
        if m:
            if int(m.group(1)) in named:
                raise DataError(f"{src}: two flange poses for image {m.group(1)}: {named[int(m.group(1))].name} and "
                                f"{p.name}; keep one")
            named[int(m.group(1))] = p
            T = read_visp_pose_yaml(check_inside(p, src, allow_symlinks))
            if np.max(np.abs(T[:3, 3])) > MAX_ABS_POSITION_M:
                raise DataError(f"{p}: data: translation {np.max(np.abs(T[:3, 3])):.4g} m from the robot base "
                                f"(limit {MAX_ABS_POSITION_M:g} m): millimetres written as metres? ViSP poses are in m")
            poses[int(m.group(1))] = T
    if not poses:
        raise DataError(f"{src}: no ViSP flange poses (*pose_rPe_N.yaml, *pose_fPe_N.yaml or *w_P_ee-N.yaml)")
    images = {}
    for p in sorted(src.glob("*image-*.*")):
        m = re.search(r"-(\d+)\.[A-Za-z]+$", p.name)
        if m and p.suffix.lower() in IMAGE_EXT:
            images[int(m.group(1))] = check_inside(p, src, allow_symlinks)
    check_image_sizes([images[k] for k in sorted(images)], intr, str(cams[0]))
    return intr, poses, images


def _write_visp_recording(src, dst, intr, poses, images, mount: str, target: dict, notes=()) -> Path:
    """recording.yaml + poses.csv (flange poses) + images/<n>/00.<ext> of a ViSP folder."""
    import csv
    import io

    import yaml

    from ..serialize import write_text_atomic

    dst.mkdir(parents=True, exist_ok=True)
    doc = {
        "format": "vision_calib.recording/1",
        "source": f"imported from ViSP folder {src}",
        "units": {"length": "m", "angle": "rad"},
        "camera": intr.to_dict(),
        "camera_mount": mount,
        "target": target,
        "poses": "flange_pose",
        "frames_per_pose": 1,
    }
    if notes:
        doc["notes"] = list(notes)
    write_text_atomic(dst / "recording.yaml", yaml.safe_dump(doc, sort_keys=False))
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["pose_id", "x", "y", "z", "qx", "qy", "qz", "qw"])
    for k in sorted(poses):
        xyz, q = frames.xyz_quat_from_T(poses[k])
        w.writerow([str(k)] + [repr(float(v)) for v in (*xyz, *q)])
    write_text_atomic(dst / "poses.csv", buf.getvalue())
    for k, p in images.items():
        d = dst / "images" / str(k)
        d.mkdir(parents=True, exist_ok=True)
        copy_no_looser(p, d / f"00{p.suffix.lower()}")
    return dst


#: ViSP's pattern descriptions (beside the images), in the order looked for
PATTERN_FILES = ("chessboard-data.txt", "apriltag-data.txt")
#: AprilTag families of ViSP's apriltag-data.txt first line -> OpenCV dictionaries
TAG_FAMILIES = {"36h11": "DICT_APRILTAG_36h11", "36h10": "DICT_APRILTAG_36h10", "25h9": "DICT_APRILTAG_25h9",
                "16h5": "DICT_APRILTAG_16h5"}


def read_pattern_file(src, allow_symlinks: bool = False) -> dict | None:
    """The pattern description of a ViSP folder: ``chessboard-data.txt`` ("Chessboard", "9 x 6" inner corners as
    ViSP's -w x -h, "square size: 0.0236 m") -> {file, kind: "chessboard", inner: (cols, rows), square_m}, or
    ``apriltag-data.txt`` ("36h11 ...", "size: 0.048 m") -> {file, kind: "apriltag", tag_m (None without a size
    line), dictionary}; None
    when the folder has neither. DataError naming the file when a value cannot be read, or when both exist."""
    import re

    from ..config import read_text
    from .recording import check_inside

    src = Path(src)
    found = [src / n for n in PATTERN_FILES if (src / n).is_file()]
    if not found:
        return None
    if len(found) > 1:
        raise DataError(f"{src}: both {' and '.join(p.name for p in found)}: keep the one of the pattern in the images")
    path = found[0]
    text = read_text(check_inside(path, src, allow_symlinks), DataError)
    num = r"([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)"
    if path.name == "chessboard-data.txt":
        size = re.search(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$", text, re.M)
        sq = re.search(r"square[ _-]?size\s*:\s*" + num + r"\s*m\b", text)
        if not size or not sq:
            raise DataError(f"{path}: expected a line 'W x H' (inner corners, ViSP's -w x -h) and 'square size: S m'"
                            f"; found {'neither' if not (size or sq) else 'no square size' if size else 'no W x H line'}")
        return {"file": path, "kind": "chessboard", "inner": (int(size.group(1)), int(size.group(2))),
                "square_m": float(sq.group(1))}
    m = re.search(r"size\s*:\s*" + num + r"\s*m\b", text)
    fam = re.search(r"\b(36h11|36h10|25h9|16h5)\b", text)
    return {"file": path, "kind": "apriltag", "tag_m": float(m.group(1)) if m else None,
            "dictionary": TAG_FAMILIES[fam.group(1)] if fam else "DICT_APRILTAG_36h11"}


def import_visp(src, dst, chessboard: tuple[int, int] | None = None, square_m: float | None = None,
                tag_m: float | None = None, tag_id: int | None = None, mount: str | None = None,
                allow_symlinks: bool = False, notes: list | None = None) -> Path:
    """A ViSP hand-eye folder (module docstring) into a recorded folder, the pattern taken from the folder's own
    ``chessboard-data.txt`` or ``apriltag-data.txt`` unless given: ``chessboard`` (inner cols, rows) and
    ``square_m`` [m] (each overriding the file's), or ``tag_m`` [m] / ``tag_id`` for an AprilTag. mount: where the
    camera is for a chessboard (default eye_in_hand, ViSP's eye-in-hand tutorial); an AprilTag folder is ViSP's
    eye-to-hand one (fixed camera, tag on the flange). DataError naming the files looked for when the pattern is
    neither given nor described in the folder."""
    src = Path(src)
    if not src.is_dir():
        raise DataError(f"{src}: ViSP folder not found")
    info = read_pattern_file(src, allow_symlinks)
    if chessboard is not None or (info and info["kind"] == "chessboard" and tag_m is None):
        inner = chessboard or (info["inner"] if info and info["kind"] == "chessboard" else None)
        square = square_m or (info["square_m"] if info and info["kind"] == "chessboard" else None)
        if square is None:
            raise ConfigError(f"{src}: --chessboard needs --square-m (the square side in metres): no "
                              f"{PATTERN_FILES[0]} with 'square size: S m' in the folder")
        return import_visp_chessboard(src, dst, *inner, square, mount=mount or "eye_in_hand",
                                      allow_symlinks=allow_symlinks, notes=notes)
    if (info is None or info["kind"] != "apriltag") and tag_m is None:
        raise DataError(f"{src}: no pattern description: looked for {' and '.join(PATTERN_FILES)} (ViSP's data files "
                        "beside the images) and found neither; give --chessboard COLSxROWS --square-m S for a "
                        "chessboard, or --tag-size-m S for an AprilTag")
    if mount not in (None, "fixed"):
        raise ConfigError(f"{src}: an AprilTag folder is ViSP's eye-to-hand one (fixed camera, tag on the flange); "
                          f"--mount {mount} applies to chessboard folders")
    return import_visp_eye_to_hand(src, dst, tag_m=tag_m, tag_id=tag_id, allow_symlinks=allow_symlinks)


def import_visp_eye_to_hand(src, dst, tag_m: float | None = None, tag_id: int | None = None,
                            dictionary: str | None = None, allow_symlinks: bool = False):
    """Convert a ViSP hand-eye folder (``*_camera.xml``, ``*_pose_rPe_N.yaml`` flange poses in the
    base as t + theta-u, ``*_image-N.png``) into a recorded folder (DESIGN.md §5) with flange poses:
    fixed camera, one AprilTag on the flange. tag_m: tag side [m] (default: read from
    ``apriltag-data.txt`` 'size: 0.048 m'); dictionary: OpenCV's (default: the family named there, else
    36h11). Files that are symbolic links leading out of ``src`` are refused unless allow_symlinks; copied
    images keep no looser permissions than their source. Returns the destination Path."""
    src, dst = Path(src), Path(dst)
    intr, poses, images = _collect(src, allow_symlinks)
    info = read_pattern_file(src, allow_symlinks) if tag_m is None or dictionary is None else None
    info = info if info is not None and info["kind"] == "apriltag" else {}
    if tag_m is None:
        tag_m = info.get("tag_m")
        if tag_m is None:
            raise DataError(f"{src}: tag size unknown: give tag_m (--tag-size-m); looked for 'size: <x> m' in "
                            f"{PATTERN_FILES[1]}" + ("" if info else " (not in the folder)"))
    dictionary = dictionary or info.get("dictionary", "DICT_APRILTAG_36h11")
    if not (tag_m > 0 and np.isfinite(tag_m)):
        raise DataError(f"tag size must be > 0 m, got {tag_m}")
    if tag_id is None:
        tag_id = _detect_tag_id(images[min(images)], dictionary) if images else 0
    target = {"kind": "apriltag_grid", "name": f"tag{dictionary.rsplit('_', 1)[-1]}_{tag_id}", "rows": 1, "cols": 1,
              "dictionary": dictionary, "tag_m": float(tag_m), "spacing_m": 0.01, "first_id": int(tag_id),
              "margin_m": 0.01}
    return _write_visp_recording(src, dst, intr, poses, images, "fixed", target)


def transposed_note(first, corners, inner_cols: int, inner_rows: int) -> str:
    """A warning when the detected rows of ``inner_cols`` corners (OpenCV order, (K, 1, 2) or (K, 2) px) run along
    the image height: ViSP's ``-w`` counts the inner corners along the image width, so the size is likely
    transposed (the board is found either way; only its frame's x axis differs). "" otherwise."""
    c = np.asarray(corners, float).reshape(-1, 2)
    row = c[inner_cols - 1] - c[0]
    if inner_cols == inner_rows or abs(row[1]) <= abs(row[0]):
        return ""
    return (f"{first}: --chessboard {inner_cols}x{inner_rows}: the rows of {inner_cols} inner corners run along the image "
            f"height; ViSP's -w x -h counts the corners along the image width first: {inner_rows}x{inner_cols}? "
            "(the target frame's x axis follows the first number)")


def import_visp_chessboard(src, dst, inner_cols: int, inner_rows: int, square_m: float,
                           mount: str = "eye_in_hand", allow_symlinks: bool = False, notes: list | None = None) -> Path:
    """Convert a ViSP hand-eye folder of the chessboard tutorials (``camera.xml``, ``image-N.png``,
    ``pose_fPe_N.yaml`` / ``pose_rPe_N.yaml`` flange poses; ``tutorial-chessboard-pose -w W -h H
    --square_size S``) into a recorded folder with flange poses. inner_cols x inner_rows: ViSP's ``-w`` x
    ``-h``, the *inner* corners (OpenCV's pattern size; ViSP's default 9 x 6); the target written has
    ``rows``/``cols`` = number of squares = inner + 1. square_m: square side [m]. mount: "eye_in_hand"
    (ViSP's tutorial-hand-eye-calibration: camera on the flange, board fixed) or "fixed". The pattern
    size is checked on the first image (the chessboard kind's detectors); DataError names the image. A size that
    looks transposed (:func:`transposed_note`) is noted in recording.yaml ``notes`` and appended to ``notes``."""
    import cv2

    src, dst = Path(src), Path(dst)
    for name, v in (("inner_cols", inner_cols), ("inner_rows", inner_rows)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 2:
            raise ConfigError(f"chessboard {name} (inner corners) must be an integer >= 2, got {v!r}")
    if not (isinstance(square_m, (int, float)) and np.isfinite(square_m) and 0 < square_m <= 1.0):
        raise ConfigError(f"chessboard square size must be in (0, 1] m, got {square_m!r} (millimetres?)")
    if mount not in ("eye_in_hand", "fixed"):
        raise ConfigError(f"mount must be 'eye_in_hand' or 'fixed', got {mount!r}")
    intr, poses, images = _collect(src, allow_symlinks)
    if images:
        first = images[min(images)]
        from ..measure.detect import load_gray  # the one decoder: header and pixel limit checked first

        img, why = load_gray(first)
        if img is None:
            raise DataError(f"{first}: unreadable image ({why})")
        from ..targets.kinds.chessboard import CLASSIC_FLAGS, SB_FLAGS  # the chessboard kind's detectors

        size = (int(inner_cols), int(inner_rows))
        found, corners = cv2.findChessboardCorners(img, size, flags=CLASSIC_FLAGS)
        if not found:
            found, corners = cv2.findChessboardCornersSB(img, size, flags=SB_FLAGS)
        if not found:
            raise DataError(f"{first}: no chessboard of {inner_cols}x{inner_rows} inner corners found; check "
                            "--chessboard COLSxROWS (ViSP's -w x -h: inner corners, not squares)")
        note = transposed_note(first, corners, int(inner_cols), int(inner_rows))
    target = {"kind": "chessboard", "rows": int(inner_rows) + 1, "cols": int(inner_cols) + 1,
              "square_m": float(square_m), "margin_m": float(square_m)}
    note = note if images else ""
    if note and notes is not None:
        notes.append(note)
    return _write_visp_recording(src, dst, intr, poses, images, mount, target, [note] if note else [])
