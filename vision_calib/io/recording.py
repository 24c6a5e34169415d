"""Recorded folders (DESIGN.md §5): what a real robot session leaves on disk, and what
``simulate --export-recording`` writes.

Layout::

    FOLDER/recording.yaml     format, units, camera intrinsics + distortion, camera mount,
                              target (inline definition), robot reference (scene file), frames
    FOLDER/poses.csv          header ``pose_id,q1..qn`` (joint values, in the file's angle unit)
                              or ``pose_id,x,y,z,qx,qy,qz,qw`` (flange pose in the robot base:
                              metres + unit quaternion, scalar last) when only flange poses are known
    FOLDER/images/<pose_id>/<frame>.png   (or .jpg/.jpeg/.bmp/.tif/.tiff: io/images.py; 8/16 bit, grey/colour)

recording.yaml::

    format: vision_calib.recording/1
    units: {length: m, angle: rad}          # of poses.csv
    camera: {width, height, fx, fy, cx, cy, dist: [k1, k2, p1, p2, k3]}
                                            # width/height optional (read from the images; a given size
                                            # must match them); no fx/fy/cx/cy: `process` calibrates the
                                            # intrinsics from the recording's own images
    camera_file: camera.yaml                # instead of camera: a `calibrate-camera` output (relative to this
                                            # file or absolute), its size checked against the images
    camera_mount: eye_in_hand | fixed | base
    target: {kind: charuco, rows: .., cols: .., dictionary: .., square_m: .., marker_m: .., ...}
    scene: scene/h4_vision.yaml             # robot model + free parameters (relative to this file, or absolute;
                                            # inside the folder or the shipped scenes/: config.confine).
                                            # simulate --export-recording copies the scene, its robot and
                                            # target into FOLDER/scene/ (io.portable): the folder moves whole
    scene_name: h4_vision                   # fallback: the shipped scenes/<scene_name>.yaml
    poses: joints | flange_pose
    frames_per_pose: 10
    averaging: corners                      # how the frames of a pose are averaged (measure.MeasureConfig.mode)
    corner_noise_px: 0.3                    # optional: upper bound of a corner's per-coordinate noise [px]; the
                                            # per-view rule drops corners beyond 5x it from the view's homography
                                            # and views whose residual std exceeds 3x it (measure/view_checks.py)
    robot_pose_std: {translation_mm: 0.2, rotation_deg: 0.02}
                                            # optional, poses: flange_pose only: std per axis of the error of the
                                            # reported flange poses (the robot's accuracy, not its repeatability,
                                            # when they come from its nominal model); both keys required, >= 0.
                                            # Absent: estimated from the data (REML, identify/handeye_fit.py);
                                            # 0, 0: the flange poses are taken as exact
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml

from ..camera import CameraIntrinsics
from ..config import Section, load_yaml
from ..errors import DataError
from ..serialize import write_text_atomic
from .images import IMAGE_EXT, check_image_sizes  # IMAGE_EXT: the formats accepted in images/<pose_id>/

if TYPE_CHECKING:  # annotations only
    from ..targets.kinds.base import TargetSpec

FORMAT = "vision_calib.recording/1"


@dataclass(frozen=True)
class Recording:
    """A recorded folder, validated. poses: (N, n) joints [rad] or (N, 4, 4) T_base_flange.
    images: {pose_id: [paths of its frames, sorted]} (missing poses absent). camera: None when
    recording.yaml gives no intrinsics (calibrate them from the images: ``experiment.camera_step``);
    image_size: (width, height) [px] of the images (None without a readable image). camera_file: the
    camera.yaml the intrinsics come from (recording.yaml ``camera_file``), else None."""

    folder: Path
    camera: CameraIntrinsics
    camera_mount: str
    target: TargetSpec
    scene_path: Path | None
    pose_kind: str
    pose_ids: tuple[str, ...]
    poses: np.ndarray
    images: dict
    frames_per_pose: int
    extra_files: tuple[str, ...] = ()
    averaging: str = "corners"
    notes: tuple[str, ...] = ()
    image_size: tuple[int, int] | None = None
    camera_file: Path | None = None
    corner_noise_px: float = 0.3
    #: (translation m, rotation rad) std per axis of the reported flange poses' error (``robot_pose_std``), or None
    robot_pose_std: tuple[float, float] | None = None

    def measure_config(self):
        """The pose measurement settings of this recording (measure.MeasureConfig: averaging, corner_noise_px)."""
        from ..measure import MeasureConfig

        return MeasureConfig(mode=self.averaging, corner_noise_px=self.corner_noise_px)


def _target_dict(spec) -> dict:
    """The target's own keys (its kind's typed spec: no other kind's keys), numpy scalars as Python numbers."""
    return {k: v.item() if isinstance(v, np.generic) else v for k, v in spec.to_dict().items()}


def write_recording(folder, scene, poses, joints, frames: int, camera=None, source: str | None = None,
                    notes=None) -> Path:
    """Write recording.yaml, poses.csv and a copy of the scene (``folder/scene/``: scene, robot and target
    files, named relatively) for a simulated run or an import (images are written by the caller into
    ``folder/images/<pose_id>/``, pose ids ``000``, ``001``...). joints: (N, n) rad, the encoder readings of
    each pose; camera: the intrinsics (default the scene's); source, notes: recording.yaml's ``source`` and
    ``notes`` (words: where the recording comes from)."""
    from ..targets import load_target

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    setup = scene.setup
    doc = {
        "format": FORMAT,
        **({"source": str(source)} if source else {}),
        **({"notes": [str(n) for n in notes]} if notes else {}),
        "units": {"length": "m", "angle": "rad"},
        "camera": (camera or setup.camera).to_dict(),
        "camera_mount": setup.mount,
        "target": _target_dict(load_target(scene.target_path)),
        "scene": None,  # below: the copied scene, relative to this file
        "scene_name": scene.name,  # fallback when the folder moves to another machine: scenes/<name>.yaml
        "poses": "joints",
        "frames_per_pose": int(frames),
        "averaging": scene.measurement.averaging,
    }
    from .portable import copy_scene_bundle, relative_ref

    doc["scene"] = relative_ref(copy_scene_bundle(scene, folder / "scene"), folder)
    write_text_atomic(folder / "recording.yaml", yaml.safe_dump(doc, sort_keys=False))
    joints = np.asarray(joints, float)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["pose_id"] + [f"q{j + 1}" for j in range(joints.shape[1])])
    for i, q in enumerate(joints):
        w.writerow([f"{i:03d}"] + [repr(float(v)) for v in q])
    write_text_atomic(folder / "poses.csv", buf.getvalue())
    return folder


#: recording.yaml's key tree (config.check_keys): unknown keys are errors, with the closest suggested
_SCHEMA = {
    "format": None, "source": None, "description": None, "notes": None,
    "units": {"length", "angle"},
    "camera": None,  # CameraIntrinsics.from_dict checks its keys
    "camera_file": None,  # a camera.yaml (io.camera_file), instead of camera
    "camera_mount": None, "target": None,  # target_from_dict checks its keys
    "scene": None, "scene_name": None, "poses": None, "frames_per_pose": None, "averaging": None,
    "corner_noise_px": None, "robot_pose_std": {"translation_mm", "rotation_deg"},
}
FLANGE_COLUMNS = ("x", "y", "z", "qx", "qy", "qz", "qw")
#: |joint value| [rad or m] and |flange position| [m] beyond which a pose is refused as implausible
MAX_ABS_JOINT = 100.0
#: flange positions beyond 20 m from a lab robot's base are millimetres declared as metres
MAX_ABS_POSITION_M = 20.0


def check_inside(path: Path, root: Path, allow_symlinks: bool) -> Path:
    """``path`` itself when it resolves inside ``root`` (or allow_symlinks): ``config.confine``, the one rule for
    the paths a file or folder names (a symlink inside a recording must not make the tools read or copy files
    from elsewhere); DataError otherwise."""
    from ..config import confine

    return confine(path, root, str(path), DataError, allow=allow_symlinks,
                   hint="--allow-symlinks, or --allow-path DIR")


def read_text_utf8(path: Path) -> str:
    """A data text file as str (``config.read_text``: a BOM dropped; DataError naming the file and the line of a
    non-UTF-8 byte)."""
    from ..config import read_text

    return read_text(path, DataError)


def _csv_columns(cpath: Path, header: list[str], pose_kind: str) -> tuple[int, list[int]]:
    """(index of pose_id, indices of the value columns in q1..qn / x..qw order), matched by name."""
    from ..config import did_you_mean

    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise DataError(f"{cpath}: header: duplicate column(s) {', '.join(dup)}")
    if pose_kind == "flange_pose":
        expected = list(FLANGE_COLUMNS)
    else:
        qs = [int(h[1:]) for h in header if h[:1] == "q" and h[1:].isdigit()]
        expected = [f"q{j}" for j in range(1, max(qs, default=0) + 1)]
        if not qs:
            raise DataError(f"{cpath}: header: no joint columns q1..qn (poses: joints), got {','.join(header)}")
    known = ["pose_id", *expected]
    for h in header:
        if h not in known:
            raise DataError(f"{cpath}: header: unknown column {h!r}{did_you_mean(h, known)}; expected pose_id and "
                            f"{', '.join(expected)} (poses: {pose_kind})")
    missing = [h for h in known if h not in header]
    if missing:
        raise DataError(f"{cpath}: header: missing column(s) {', '.join(missing)} (poses: {pose_kind})")
    return header.index("pose_id"), [header.index(h) for h in expected]


def _read_poses_csv(cpath: Path, pose_kind: str, Lf: float, Af: float) -> tuple[list[str], np.ndarray]:
    """(pose ids, (N, n) joints [rad] or (N, 4, 4) T_base_flange [m]) from poses.csv."""
    text = read_text_utf8(cpath)
    rows = [(ln, r) for ln, r in enumerate(csv.reader(io.StringIO(text, newline="")), start=1)
            if r and any(c.strip() for c in r)]
    if len(rows) < 2:
        raise DataError(f"{cpath}: no pose rows")
    header = [h.strip() for h in rows[0][1]]
    i_id, cols = _csv_columns(cpath, header, pose_kind)
    ids, vals = [], []
    for ln, r in rows[1:]:
        if len(r) != len(header):
            raise DataError(f"{cpath}: line {ln}: {len(r)} values, expected {len(header)} ({','.join(header)})")
        pid = r[i_id].strip()
        if not pid or pid in (".", "..") or "/" in pid or "\\" in pid:
            raise DataError(f"{cpath}: line {ln}: invalid pose_id {pid!r}")
        try:
            v = [float(r[c]) for c in cols]
        except ValueError:
            raise DataError(f"{cpath}: line {ln} (pose {pid!r}): non-numeric value in {[r[c] for c in cols]}") from None
        if not np.all(np.isfinite(v)):
            raise DataError(f"{cpath}: line {ln} (pose {pid!r}): NaN or infinite value")
        lim, f = (MAX_ABS_JOINT, Af) if pose_kind == "joints" else (MAX_ABS_POSITION_M, Lf)
        vv = np.abs(v if pose_kind == "joints" else v[:3]) * f
        if np.any(vv > lim):
            hint = (" (degrees declared as radians? set units.angle: deg)" if pose_kind == "joints"
                    else " (millimetres declared as metres? set units.length: mm)")
            raise DataError(f"{cpath}: line {ln} (pose {pid!r}): implausible value {max(vv):.4g} "
                            f"({'joint, SI' if pose_kind == 'joints' else 'position, m'}; limit {lim:g}){hint}")
        ids.append(pid)
        vals.append(v)
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise DataError(f"{cpath}: duplicate pose ids {dup}")
    vals = np.array(vals)
    if pose_kind == "joints":
        return ids, vals * Af
    from ..frames import T_from_xyz_quat

    q = vals[:, 3:]
    nq = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(np.abs(nq - 1) > 1e-3)
    if bad.size:
        raise DataError(f"{cpath}: pose {ids[bad[0]]!r}: quaternion norm {nq[bad[0]]:.4f} is not 1")
    return ids, T_from_xyz_quat(vals[:, :3] * Lf, q / nq[:, None])


def read_flange_csv(path, length_factor: float = 1.0) -> tuple[list[str], np.ndarray]:
    """(pose ids, (N, 4, 4) T_base_flange [m]) of a flange-pose CSV ``pose_id,x,y,z,qx,qy,qz,qw`` (a flange-pose
    recording's poses.csv; positions times ``length_factor`` [m per file unit]); DataError naming the file and
    line (columns, numbers, duplicate ids, quaternion norm, implausible positions)."""
    return _read_poses_csv(Path(path), "flange_pose", float(length_factor), 1.0)


def _find_images(folder: Path, ids, frames: int, allow_symlinks: bool) -> tuple[dict, list[str]]:
    """({pose_id: sorted image paths}, extra files) under folder/images; symlinks checked."""
    images, extra = {}, []
    idir = folder / "images"
    if not idir.is_dir():
        return images, extra
    check_inside(idir, folder, allow_symlinks)
    known = set(ids)
    for d in sorted(idir.iterdir()):
        if d.is_dir() and d.name in known:
            check_inside(d, folder, allow_symlinks)
            files = sorted(p for p in d.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_EXT)
            for f in files:
                check_inside(f, folder, allow_symlinks)
            extra += [str(p.relative_to(folder)) for p in d.iterdir() if p.is_file() and p.suffix.lower() not in IMAGE_EXT]
            if len(files) > frames:
                raise DataError(f"{d}: {len(files)} images but recording.yaml frames_per_pose is {frames} "
                                "(fix frames_per_pose: it sets how the frames are averaged)")
            if files:
                images[d.name] = files
        else:
            extra.append(str(d.relative_to(folder)))
    return images, extra


def read_recording(folder, allow_symlinks: bool = False) -> Recording:
    """Read and validate a recorded folder. Missing/corrupt images are NOT errors here (the
    measurement stage rejects those poses with a reason); a missing recording.yaml or poses.csv,
    an unknown key (closest key suggested), a missing ``camera.dist``, a malformed or non-UTF-8 CSV,
    unknown/missing/duplicate CSV columns, NaN or implausible values, duplicate pose ids, more images
    per pose than ``frames_per_pose``, an image whose header size differs from the camera's width x height
    are (DataError/ConfigError naming the file, key, line or pose).
    allow_symlinks: follow symbolic links that lead out of the folder (refused by default)."""
    from ..config import check_keys
    from ..targets import target_from_dict

    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(f"{folder}: recorded folder not found")
    ypath = check_inside(folder / "recording.yaml", folder, allow_symlinks)
    top = Section(load_yaml(ypath), ypath)
    check_keys(top, _SCHEMA)
    fmt = top.get("format", str, FORMAT)
    if fmt != FORMAT:
        raise top.error("format", f"expected {FORMAT!r}, got {fmt!r}")
    Lf, Af = top.units(default_length="m", default_angle="rad")
    cam_data = dict(top.section("camera", {}).data)
    mount = top.get("camera_mount", str, choices=("eye_in_hand", "fixed", "base"))
    tsec = top.section("target")
    target = target_from_dict(tsec.data, where=tsec.where())
    scene_path = None
    notes = []
    if "scene" in top:
        from ..config import confine

        p = Path(top.get("scene", str))
        p = p if p.is_absolute() else ypath.parent / p
        if p.exists():  # the same rule as every named path (a missing one falls back to the shipped scene_name)
            confine(p, folder, f"{top.where('scene')}: {top.get('scene', str)!r}")
        if not p.is_file():
            from ..rig.scene import SCENES_DIR

            alt = SCENES_DIR / f"{top.get('scene_name', str, '')}.yaml"
            if not alt.is_file():
                raise top.error("scene", f"file not found: {p} (nor {alt})")
            notes.append(f"recording.yaml scene {p} not found: used the shipped scene {alt} (same name)")
            p = alt
        scene_path = p
    pose_kind = top.get("poses", str, "joints", choices=("joints", "flange_pose"))
    frames = top.number("frames_per_pose", int, 10, min=1)
    averaging = top.get("averaging", str, "corners", choices=("corners", "poses"))
    corner_noise = top.number("corner_noise_px", float, 0.3, min=0.0, min_open=True, max=50.0, unit="px")
    robot_std = None
    if "robot_pose_std" in top:
        if pose_kind != "flange_pose":
            raise top.error("robot_pose_std", "applies to flange-pose recordings (poses: flange_pose) only; a joint "
                                              "recording identifies the robot's own geometry")
        rs = top.section("robot_pose_std")
        robot_std = (rs.number("translation_mm", float, min=0.0, max=100.0, unit="mm") * 1e-3,
                     float(np.radians(rs.number("rotation_deg", float, min=0.0, max=10.0, unit="deg"))))

    cpath = folder / "poses.csv"
    if not cpath.is_file():
        raise DataError(f"{cpath}: file not found (one row per robot pose: pose_id then joint values)")
    check_inside(cpath, folder, allow_symlinks)
    ids, poses = _read_poses_csv(cpath, pose_kind, Lf, Af)
    images, extra = _find_images(folder, ids, frames, allow_symlinks)
    camera, size = _recording_camera(cam_data, top.section("camera", {}), images)
    if size is not None:  # every image header against the declared (or the majority's) size
        from types import SimpleNamespace

        check_image_sizes([f for pid in ids for f in images.get(pid, ())], SimpleNamespace(width=size[0], height=size[1]),
                          f"{ypath} camera")
    camera_file = None
    if "camera_file" in top:
        from .camera_file import load_camera_for_images

        if camera is not None:
            raise top.error("camera_file", "given together with camera fx/fy/cx/cy: give one of them")
        from ..config import confine

        camera_file = Path(top.get("camera_file", str))
        camera_file = camera_file if camera_file.is_absolute() else ypath.parent / camera_file
        confine(camera_file, folder, f"{top.where('camera_file')}: {top.get('camera_file', str)!r}")
        camera = load_camera_for_images(camera_file, size, f"{ypath}: camera_file")
    return Recording(folder, camera, mount, target, scene_path, pose_kind, tuple(ids), poses, images, frames,
                     tuple(extra), averaging, tuple(notes), size, camera_file, float(corner_noise), robot_std)


def _recording_camera(d: dict, sec: Section, images: dict) -> tuple[CameraIntrinsics | None, tuple | None]:
    """(intrinsics or None when no fx/fy/cx/cy are given, (width, height) of the images: the size most image
    headers declare, nothing decoded). width/height default to the images' size; a given size that differs is a
    ConfigError naming the key and an image of that size. An image beyond the pixel limit: DataError naming it."""
    from .images import folder_sizes

    size, sizes, _ = folder_sizes([f for files in images.values() for f in files])
    first = next((f for f, s in sizes.items() if s == size), None)
    for i, key in enumerate(("width", "height")):
        v = d.get(key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v <= 0):
            raise sec.error(key, f"expected a positive integer (pixels), got {v!r}")
        if v is None:
            if size is None:
                raise sec.error(key, "not given and no readable image to read it from")
            d[key] = size[i]
        elif size is not None and v != size[i]:
            raise sec.error(key, f"{v!r} px but the images are {size[0]}x{size[1]} px ({first})")
    if all(d.get(k) is None for k in ("fx", "fy", "cx", "cy")):
        if d.get("dist") is not None:
            raise sec.error("dist", "given without fx, fy, cx, cy (give all of them, or none to calibrate the "
                                    "intrinsics from the recording's images)")
        from ..config import did_you_mean

        for k in d:
            if k not in ("width", "height"):
                raise sec.error(str(k), f"unknown key{did_you_mean(k, ('width', 'height', 'fx', 'fy', 'cx', 'cy', 'dist'))}")
        return None, size
    return CameraIntrinsics.from_dict(d, where=sec.where(), require_dist=True), size
