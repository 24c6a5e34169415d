"""ROS-Industrial ``industrial_calibration`` extrinsic hand-eye data sets <-> recorded folders.

The ROS-I layout (``examples/data/test_set_charuco`` of ros-industrial/industrial_calibration)::

    cal_data.yaml
        data:                          # one entry per observation (image + robot pose)
          - {image: images/0.png, pose: poses/0.yaml}
        intrinsics: {fx, fy, cx, cy}   # [px]; no distortion: ROS-I expects undistorted images
        static_camera: true            # or (newer GUI) eye_in_hand: false
        camera_mount_to_camera_guess: {x, y, z, qx, qy, qz, qw}   # ignored here
        target_mount_to_target_guess: {...}                       # ignored here
        homography_threshold: 2.0                                 # -> corner_noise_px (below)
        target_finder: {type: CharucoGridTargetFinder, rows, cols, chessboard_dim, aruco_marker_dim,
                        dictionary: 10}
    poses/0.yaml                       # {x, y, z, qw, qx, qy, qz}
    images/0.png

``intrinsics`` may also come from ``camera_intr.yaml`` and ``target_finder`` from ``target_finder.yaml``
next to ``cal_data.yaml`` (both exist in ROS-I's examples).

Mapping (ROS-I -> ours):

- pose files: ``x, y, z`` [m] and the quaternion ``qw, qx, qy, qz`` (named keys; written to poses.csv
  scalar-last) are the robot base -> flange transform ``T_base_flange`` (ROS-I's ``to_camera_mount``
  for an eye-in-hand camera, ``to_target_mount`` for a static camera: in both, the mount pose in the
  robot base) -> ``poses.csv`` ``x,y,z,qx,qy,qz,qw`` with ``poses: flange_pose``.
- ``static_camera: true`` / ``eye_in_hand: false`` -> ``camera_mount: fixed`` (target on the flange);
  ``static_camera: false`` / ``eye_in_hand: true`` -> ``eye_in_hand``.
- ``intrinsics`` -> camera fx, fy, cx, cy; width x height from the first image (all images must match);
  ``dist`` zeros (ROS-I's hand-eye has no distortion model).
- ``CharucoGridTargetFinder``: rows, cols (squares along y, x: ROS-I calls
  ``CharucoBoard::create(cols, rows, ...)``), chessboard_dim -> square_m, aruco_marker_dim -> marker_m,
  dictionary (OpenCV's enum value) -> its ``cv2.aruco`` name, ``legacy_pattern: true`` (ROS-I builds
  against OpenCV < 4.6, whose ChArUco layout is the legacy one; it matters only for an even number of
  rows).
- ``ModifiedCircleGridTargetFinder``: rows, cols (dots), spacing -> ``modified_circle_grid`` spacing_m; its
  ``circle_detector_params`` -> the target's ``blob_detector`` (:func:`blob_settings`), tried first on each image
  before our own stages (targets/kinds/dot_grid.py); the origin dot is told by our dark-area test. ROS-I
  gives no dot diameter: detection does without, but the ellipse-centre correction is then off (the
  extension keys ``diameter_m``/``origin_diameter_m``, written by :func:`export_rosi`, restore it). Our target
  frame is not ROS-I's (``ModifiedCircleGridKind`` docstring: same point order, y flipped, origin shifted).
  ArUco-grid targets are refused (no such target kind here).
- Entries that share a pose file become the frames of one pose (pose id = the pose file's stem).
- ``homography_threshold`` [px] (ROS-I skips a view whose homography error exceeds it) -> the recording's
  ``corner_noise_px`` = threshold / ``view_checks.RMS_K`` (at least the default 0.3 px), so that our per-view
  rule rejects a view at a homography residual std of about ROS-I's own threshold (the statistics differ:
  ROS-I's mean error vs our per-coordinate residual std) instead of at our tighter default.

Two extension keys, written by :func:`export_rosi` and ignored by ROS-I (it reads only the keys it
knows): ``distortion: [k1, k2, p1, p2, k3]`` and ``target_finder.legacy_pattern`` (ChArUco) or
``target_finder.diameter_m``/``origin_diameter_m`` (circle grids); a real ROS-I data set has none of them
(zero distortion, legacy layout, unknown dot size).

Checks up front (DataError naming the file and key): a translation beyond 20 m (millimetres?), a
quaternion whose norm is off 1 by more than 1e-3 (smaller: renormalised), an image missing or of
another size than the first one.
"""

from __future__ import annotations

import csv
import io
import shutil
from pathlib import Path

import numpy as np
import yaml

from ..errors import ConfigError, DataError
from ..serialize import write_text_atomic
from .images import check_principal_point, folder_sizes, is_image
from .recording import FORMAT, MAX_ABS_POSITION_M, check_inside

POSE_KEYS = ("x", "y", "z", "qw", "qx", "qy", "qz")
CHARUCO_TYPES = ("CharucoGridTargetFinder", "industrial_calibration::CharucoGridTargetFinderPlugin")
CIRCLE_TYPES = ("ModifiedCircleGridTargetFinder", "industrial_calibration::ModifiedCircleGridTargetFinderPlugin")
QUAT_TOL = 1e-3


def _load(path: Path, what: str):
    from ..config import parse_yaml

    return parse_yaml(path, DataError, what)


def _num(d: dict, key: str, where: str) -> float:
    if not isinstance(d, dict) or key not in d:
        raise DataError(f"{where}: missing key {key!r}")
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
        raise DataError(f"{where}: key {key!r}: expected a finite number, got {v!r}")
    return float(v)


def read_rosi_pose(path) -> tuple[np.ndarray, np.ndarray]:
    """ROS-I pose YAML {x, y, z [m], qw, qx, qy, qz} -> (xyz (3,) m, quaternion (4,) scalar-last, as
    written: renormalised where it is read); DataError naming the file and key for a missing/non-numeric
    key, |t| > 20 m (mm?) or a non-unit quaternion (|norm - 1| > 1e-3)."""
    path = Path(path)
    d = _load(path, "ROS-I pose file")
    if not isinstance(d, dict):
        raise DataError(f"{path}: expected a mapping with keys {', '.join(POSE_KEYS)}")
    v = {k: _num(d, k, str(path)) for k in POSE_KEYS}
    t = np.array([v["x"], v["y"], v["z"]])
    if np.max(np.abs(t)) > MAX_ABS_POSITION_M:
        raise DataError(f"{path}: keys x, y, z: {np.max(np.abs(t)):.4g} m from the robot base (limit "
                        f"{MAX_ABS_POSITION_M:g} m): millimetres written as metres? ROS-I poses are in metres")
    q = np.array([v["qx"], v["qy"], v["qz"], v["qw"]])
    n = float(np.linalg.norm(q))
    if abs(n - 1) > QUAT_TOL:
        raise DataError(f"{path}: keys qw, qx, qy, qz: quaternion norm {n:.6g} is not 1 (tolerance {QUAT_TOL:g})")
    return t, q


def _dictionary_name(value, where: str) -> str:
    import cv2

    if isinstance(value, str) and value.startswith("DICT_") and hasattr(cv2.aruco, value):
        return value
    names = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and getattr(cv2.aruco, n) == value)
    if isinstance(value, bool) or not isinstance(value, int) or not names:
        raise ConfigError(f"{where}: key 'dictionary': {value!r} is not an OpenCV predefined dictionary id")
    return names[0]


def target_from_rosi(tf, where: str) -> dict:
    """Our target dict (the keys of targets.spec.target_from_dict) from a ROS-I target_finder mapping;
    ConfigError naming ``where`` and the key."""
    if not isinstance(tf, dict) or "type" not in tf:
        raise ConfigError(f"{where}: expected a mapping with a 'type' key")
    if tf["type"] not in CHARUCO_TYPES + CIRCLE_TYPES:
        raise ConfigError(f"{where}: type {tf['type']!r} is not supported (ChArUco boards: "
                          f"{', '.join(CHARUCO_TYPES)}; modified circle grids: {', '.join(CIRCLE_TYPES)}); "
                          "ArUco grids have no target kind here")
    circles = tf["type"] in CIRCLE_TYPES
    ints = {}
    for k in ("rows", "cols"):
        v = tf.get(k)
        if isinstance(v, bool) or not isinstance(v, int):
            raise ConfigError(f"{where}: key {k!r}: expected an integer ({'dots' if circles else 'squares'}), "
                              f"got {v!r}")
        ints[k] = v
    if circles:
        try:
            s = _num(tf, "spacing", where)
            extra = {k: _num(tf, k, where) for k in ("diameter_m", "origin_diameter_m") if k in tf}
        except DataError as exc:
            raise ConfigError(str(exc)) from None
        if "circle_detector_params" in tf:
            extra["blob_detector"] = blob_settings(tf["circle_detector_params"], f"{where}: circle_detector_params")
        return {"kind": "modified_circle_grid", "name": "rosi_modified_circle_grid", "rows": ints["rows"],
                "cols": ints["cols"], "spacing_m": s, "margin_m": s / 2, **extra}
    try:
        sq, mk = _num(tf, "chessboard_dim", where), _num(tf, "aruco_marker_dim", where)
    except DataError as exc:
        raise ConfigError(str(exc)) from None
    return {"kind": "charuco", "name": "rosi_charuco", "rows": ints["rows"], "cols": ints["cols"],
            "dictionary": _dictionary_name(tf.get("dictionary"), where), "square_m": sq, "marker_m": mk,
            "legacy_pattern": bool(tf.get("legacy_pattern", True)), "margin_m": sq / 2}


#: ROS-I circle_detector_params keys with an OpenCV SimpleBlobDetector_Params field of the same meaning
ROSI_BLOB_SAME = ("minThreshold", "maxThreshold", "minRepeatability", "filterByColor", "filterByArea", "minArea",
                  "maxArea", "filterByCircularity", "minCircularity", "maxCircularity", "filterByInertia",
                  "minInertiaRatio", "maxInertiaRatio", "filterByConvexity", "minConvexity", "maxConvexity",
                  "minDistBetweenBlobs")
#: ROS-I keys of its own circle detector with no OpenCV blob-detector counterpart (ignored)
ROSI_BLOB_OWN = ("circleInclusionRadius", "maxRadiusDiff", "maxAverageEllipseError")


def blob_settings(params, where: str) -> dict:
    """ROS-I ``circle_detector_params`` -> OpenCV SimpleBlobDetector parameters (the target's ``blob_detector``):
    same-named keys copied, ``nThresholds`` -> ``thresholdStep`` = (maxThreshold - minThreshold) / nThresholds,
    ``circleColor`` -> ``blobColor``; ROS-I's own keys (ROSI_BLOB_OWN) ignored; another key is a ConfigError."""
    if not isinstance(params, dict):
        raise ConfigError(f"{where}: expected a mapping of circle detector parameters, got {params!r}")
    out = {}
    for k, v in params.items():
        if k in ROSI_BLOB_SAME:
            out[k] = v
        elif k == "circleColor":
            out["blobColor"] = v
        elif k not in ROSI_BLOB_OWN + ("nThresholds",):
            raise ConfigError(f"{where}: {k}: not a ROS-I circle detector parameter (known: "
                              f"{', '.join(ROSI_BLOB_SAME + ROSI_BLOB_OWN + ('nThresholds', 'circleColor'))})")
    if "nThresholds" in params:
        n = params["nThresholds"]
        lo, hi = out.get("minThreshold", 50.0), out.get("maxThreshold", 220.0)
        if isinstance(n, bool) or not isinstance(n, (int, float)) or not n >= 1:
            raise ConfigError(f"{where}: nThresholds: expected a number >= 1, got {n!r}")
        out["thresholdStep"] = max((hi - lo) / n, 1.0)
    for k in ("minRepeatability", "blobColor"):
        if isinstance(out.get(k), float) and out[k] == int(out[k]):
            out[k] = int(out[k])
    return out


def _mount(doc: dict, where: str) -> str:
    if "eye_in_hand" in doc:
        return "eye_in_hand" if bool(doc["eye_in_hand"]) else "fixed"
    if "static_camera" in doc:
        return "fixed" if bool(doc["static_camera"]) else "eye_in_hand"
    raise ConfigError(f"{where}: neither 'static_camera' nor 'eye_in_hand' is given: where is the camera?")


def _index(src: Path) -> Path:
    if src.is_file():
        return src
    if not src.is_dir():
        raise DataError(f"{src}: ROS-I data set not found")
    cand = src / "cal_data.yaml"
    if cand.is_file():
        return cand
    found = [p for p in sorted(src.glob("*.yaml")) if isinstance(_load(p, "YAML"), dict) and "data" in _load(p, "YAML")]
    if len(found) != 1:
        raise DataError(f"{src}: no cal_data.yaml (a YAML file with a 'data' list of image/pose entries)"
                        + (f"; several candidates: {[p.name for p in found]}" if found else ""))
    return found[0]


def _section(doc: dict, key: str, folder: Path, fallback: str, index: Path):
    """doc[key], else the ``key`` section (or the whole mapping) of ``folder/fallback``."""
    if key in doc:
        return doc[key], f"{index}: {key}"
    p = folder / fallback
    if not p.is_file():
        raise ConfigError(f"{index}: no {key!r} key and no {fallback} next to it")
    d = _load(p, fallback)
    if isinstance(d, dict) and key in d:
        return d[key], f"{p}: {key}"
    return d, str(p)


def import_rosi(src, dst, allow_symlinks: bool = False) -> Path:
    """Convert a ROS-I hand-eye data set (folder with ``cal_data.yaml``, or that file) into a recorded
    folder ``dst`` (flange poses; the mapping is in the module docstring). Images are copied in their own
    format. Returns dst; the written folder is read back with :func:`read_recording`."""
    from ..camera import CameraIntrinsics
    from .recording import read_recording
    from .visp import copy_no_looser

    index = _index(Path(src))
    folder = index.parent
    doc = _load(index, "ROS-I data set index")
    if not isinstance(doc, dict) or not isinstance(doc.get("data"), list) or not doc["data"]:
        raise DataError(f"{index}: key 'data': expected a non-empty list of {{image, pose}} entries")
    mount = _mount(doc, str(index))
    intr, where_i = _section(doc, "intrinsics", folder, "camera_intr.yaml", index)
    k = {key: _num(intr, key, where_i) for key in ("fx", "fy", "cx", "cy")}
    tf, where_t = _section(doc, "target_finder", folder, "target_finder.yaml", index)
    target = target_from_rosi(tf, where_t)
    noise = {}
    if "homography_threshold" in doc:  # ROS-I's acceptance of a view: our view rule at the same residual
        from ..measure.view_checks import RMS_K

        thr = _num(doc, "homography_threshold", str(index))
        if not thr > 0:
            raise DataError(f"{index}: key 'homography_threshold': expected > 0 px, got {thr}")
        noise = {"corner_noise_px": max(thr / RMS_K, 0.3)}
    dist = doc.get("distortion", [0.0] * 5)
    if not (isinstance(dist, list) and len(dist) == 5 and all(isinstance(v, (int, float)) for v in dist)):
        raise ConfigError(f"{index}: key 'distortion': expected [k1, k2, p1, p2, k3], got {dist!r}")

    poses: dict[str, tuple[Path, list[Path]]] = {}
    for i, e in enumerate(doc["data"]):
        where = f"{index}: data[{i}]"
        if not isinstance(e, dict) or not isinstance(e.get("image"), str) or not isinstance(e.get("pose"), str):
            raise DataError(f"{where}: expected {{image: <file>, pose: <file>}}, got {e!r}")
        img, pose = folder / e["image"], folder / e["pose"]
        for p in (img, pose):
            if not p.is_file():
                raise DataError(f"{where}: file not found: {p}")
            check_inside(p, folder, allow_symlinks)
        if not is_image(img):
            raise DataError(f"{where}: {img.name}: not an image format read here ({img.suffix})")
        pid = pose.stem
        if pid in poses and poses[pid][0].resolve() != pose.resolve():
            pid = f"{pid}_{i}"
        poses.setdefault(pid, (pose, []))[1].append(img)

    paths = [p for _, imgs in poses.values() for p in imgs]
    size, sizes, odd = folder_sizes(paths)  # headers only: a file beyond the pixel limit is refused here
    if size is None:
        raise DataError(f"{paths[0]}: unreadable image (the images' size gives the camera width x height)")
    if odd:
        raise DataError(f"{odd[0]}" + (f" (and {len(odd) - 1} more)" if len(odd) > 1 else "") + "; every image of "
                        "a data set comes from one camera at one resolution: remove or fix it")
    check_principal_point(k, size, where_i)
    camera = CameraIntrinsics(size[0], size[1], k["fx"], k["fy"], k["cx"], k["cy"], tuple(float(v) for v in dist))
    T = {pid: read_rosi_pose(p) for pid, (p, _) in poses.items()}

    dst = Path(dst)
    rec_doc = {"format": FORMAT, "source": f"imported from ROS-I industrial_calibration data set {index}",
               "units": {"length": "m", "angle": "rad"}, "camera": camera.to_dict(), "camera_mount": mount,
               "target": target, "poses": "flange_pose",
               "frames_per_pose": max(len(imgs) for _, imgs in poses.values()), "averaging": "corners", **noise}
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["pose_id", "x", "y", "z", "qx", "qy", "qz", "qw"])
    for pid, (xyz, q) in T.items():  # the file's own numbers: a round trip changes no bit
        w.writerow([pid] + [repr(float(v)) for v in (*xyz, *q)])
    for pid, (_, imgs) in poses.items():
        d = dst / "images" / pid
        d.mkdir(parents=True, exist_ok=True)
        for j, p in enumerate(imgs):
            copy_no_looser(p, d / f"{j:02d}{p.suffix.lower()}")
    write_text_atomic(dst / "poses.csv", buf.getvalue())
    write_text_atomic(dst / "recording.yaml", yaml.safe_dump(rec_doc, sort_keys=False))
    read_recording(dst)
    return dst


def _csv_poses(path: Path) -> dict:
    """{pose_id: (xyz, quaternion scalar-last)} as written in a (validated) flange-pose poses.csv."""
    from .recording import read_text_utf8

    rows = [r for r in csv.reader(io.StringIO(read_text_utf8(path), newline="")) if r and any(c.strip() for c in r)]
    head = [h.strip() for h in rows[0]]
    col = {h: head.index(h) for h in head}
    out = {}
    for r in rows[1:]:
        v = [float(r[col[k]]) for k in ("x", "y", "z", "qx", "qy", "qz", "qw")]
        out[r[col["pose_id"]].strip()] = (np.array(v[:3]), np.array(v[3:]))
    return out


def export_rosi(rec_folder, dst) -> Path:
    """Write a recorded folder with flange poses (and a ChArUco or modified-circle-grid target) as a ROS-I
    hand-eye data set:
    ``dst/cal_data.yaml``, ``dst/poses/<pose_id>.yaml``, ``dst/images/<pose_id>_<frame><ext>`` (one
    ``data`` entry per frame, the frames of a pose sharing its pose file). Camera distortion, the ChArUco
    layout and the dot diameters go to extension keys (module docstring)."""
    import cv2

    from ..measure.view_checks import RMS_K
    from .recording import read_recording

    rec = read_recording(rec_folder)
    if rec.pose_kind != "flange_pose":
        raise DataError(f"{rec.folder / 'recording.yaml'}: poses: {rec.pose_kind!r}; a ROS-I data set holds "
                        "flange poses (poses: flange_pose)")
    t = rec.target
    if t.kind == "charuco":
        finder = {"type": "CharucoGridTargetFinder", "rows": int(t.rows), "cols": int(t.cols),
                  "chessboard_dim": float(t.square_m), "aruco_marker_dim": float(t.marker_m),
                  "dictionary": int(getattr(cv2.aruco, t.dictionary)), "legacy_pattern": bool(t.legacy_pattern)}
    elif t.kind == "modified_circle_grid":
        finder = {"type": "ModifiedCircleGridTargetFinder", "rows": int(t.rows), "cols": int(t.cols),
                  "spacing": float(t.spacing_m)}
        finder |= {k: float(getattr(t, k)) for k in ("diameter_m", "origin_diameter_m") if getattr(t, k) > 0}
        if t.blob_detector:  # back to ROS-I's names (blob_settings' inverse)
            b = dict(t.blob_detector)
            cdp = {k: v for k, v in b.items() if k in ROSI_BLOB_SAME}
            if "blobColor" in b:
                cdp["circleColor"] = b["blobColor"]
            if "thresholdStep" in b:
                cdp["nThresholds"] = max(1, round((b.get("maxThreshold", 220.0) - b.get("minThreshold", 50.0))
                                                   / b["thresholdStep"]))
            finder["circle_detector_params"] = cdp
    else:
        raise ConfigError(f"{rec.folder / 'recording.yaml'}: target.kind {t.kind!r}: ROS-I's finders here are "
                          "ChArUco and modified circle grids only")
    dst = Path(dst)
    (dst / "poses").mkdir(parents=True, exist_ok=True)
    (dst / "images").mkdir(parents=True, exist_ok=True)
    data = []
    raw = _csv_poses(rec.folder / "poses.csv")
    for pid in rec.pose_ids:
        xyz, q = raw[pid]
        pose = dict(zip(("x", "y", "z"), map(float, xyz))) | {"qw": float(q[3]), "qx": float(q[0]),
                                                                "qy": float(q[1]), "qz": float(q[2])}
        write_text_atomic(dst / "poses" / f"{pid}.yaml", yaml.safe_dump(pose, sort_keys=False))
        for j, img in enumerate(rec.images.get(pid, ())):
            name = f"images/{pid}_{j:02d}{img.suffix.lower()}"
            shutil.copyfile(img, dst / name)
            data.append({"image": name, "pose": f"poses/{pid}.yaml"})
    c = rec.camera
    identity = {"x": 0.0, "y": 0.0, "z": 0.0, "qx": 0.0, "qy": 0.0, "qz": 0.0, "qw": 1.0}
    doc = {"data": data, "intrinsics": {"fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy},
           "camera_mount_to_camera_guess": identity, "target_mount_to_target_guess": identity,
           "homography_threshold": float(RMS_K * rec.corner_noise_px),
           "static_camera": rec.camera_mount != "eye_in_hand",
           "eye_in_hand": rec.camera_mount == "eye_in_hand",
           "target_finder": finder}
    if any(float(v) != 0.0 for v in c.dist):
        doc["distortion"] = [float(v) for v in c.dist]
    write_text_atomic(dst / "cal_data.yaml", yaml.safe_dump(doc, sort_keys=False))
    return dst


def read_rosi_image_set(src, allow_symlinks: bool = False, with_target: bool = True) -> dict:
    """A ROS-I data set read for its images only (the noise-qualification layout: ``cal_data.yaml`` with
    ``data: [{image: images/0.png}, ...]``, ``intrinsics`` and ``target_finder``, no poses; a hand-eye set's
    ``pose`` keys are ignored). Returns {"index": Path of cal_data.yaml, "images": [Path] in the file's order
    (an image listed twice appears twice), "intrinsics": {fx, fy, cx, cy} px, "dist": [k1, k2, p1, p2, k3]
    (zeros unless the extension key is given), "target": our target dict (as :func:`import_rosi`; None when
    ``with_target`` is False: the caller has its own target file and the finder is not read)}.
    DataError/ConfigError naming the file and key (missing image, no data list, unsupported finder)."""
    index = _index(Path(src))
    folder = index.parent
    doc = _load(index, "ROS-I data set index")
    if not isinstance(doc, dict) or not isinstance(doc.get("data"), list) or not doc["data"]:
        raise DataError(f"{index}: key 'data': expected a non-empty list of {{image: <file>}} entries")
    intr, where_i = _section(doc, "intrinsics", folder, "camera_intr.yaml", index)
    k = {key: _num(intr, key, where_i) for key in ("fx", "fy", "cx", "cy")}
    target = target_from_rosi(*_section(doc, "target_finder", folder, "target_finder.yaml", index)) if with_target else None
    dist = doc.get("distortion", [0.0] * 5)
    if not (isinstance(dist, list) and len(dist) == 5 and all(isinstance(v, (int, float)) for v in dist)):
        raise ConfigError(f"{index}: key 'distortion': expected [k1, k2, p1, p2, k3], got {dist!r}")
    images = []
    for i, e in enumerate(doc["data"]):
        where = f"{index}: data[{i}]"
        if not isinstance(e, dict) or not isinstance(e.get("image"), str):
            raise DataError(f"{where}: expected {{image: <file>}}, got {e!r}")
        img = folder / e["image"]
        if not img.is_file():
            raise DataError(f"{where}: file not found: {img}")
        check_inside(img, folder, allow_symlinks)
        images.append(img)
    return {"index": index, "images": images, "intrinsics": k, "intrinsics_where": where_i,
            "dist": [float(v) for v in dist], "target": target}


__all__ = ["import_rosi", "export_rosi", "read_rosi_pose", "read_rosi_image_set"]
