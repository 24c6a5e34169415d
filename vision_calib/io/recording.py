"""Recorded folders (DESIGN.md §5): what a real robot session leaves on disk, and what
``simulate --export-recording`` writes.

Layout::

    FOLDER/recording.yaml     format, units, camera intrinsics + distortion, camera mount,
                              target (inline definition), robot reference (scene file), frames
    FOLDER/poses.csv          header ``pose_id,q1..qn`` (joint values, in the file's angle unit)
                              or ``pose_id,x,y,z,qx,qy,qz,qw`` (flange pose in the robot base:
                              metres + unit quaternion, scalar last) when only flange poses are known
    FOLDER/images/<pose_id>/<frame>.png

recording.yaml::

    format: vision_calib.recording/1
    units: {length: m, angle: rad}          # of poses.csv
    camera: {width, height, fx, fy, cx, cy, dist: [k1, k2, p1, p2, k3]}
    camera_mount: eye_in_hand | fixed | base
    target: {kind: charuco, rows: .., cols: .., dictionary: .., square_m: .., marker_m: .., ...}
    scene: /path/to/scene.yaml              # robot model + free parameters (relative to this file or absolute)
    scene_name: h4_vision                   # fallback: the shipped scenes/<scene_name>.yaml
    poses: joints | flange_pose
    frames_per_pose: 10
    averaging: corners                      # how the frames of a pose are averaged (measure.MeasureConfig.mode)
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import yaml

from ..camera import CameraIntrinsics
from ..config import ANGLE_UNITS, LENGTH_UNITS, Section, load_yaml
from ..errors import ConfigError, DataError
from .atomic import write_text_atomic

FORMAT = "vision_calib.recording/1"
IMAGE_EXT = (".png",)


@dataclass(frozen=True)
class Recording:
    """A recorded folder, validated. poses: (N, n) joints [rad] or (N, 4, 4) T_base_flange.
    images: {pose_id: [paths of its frames, sorted]} (missing poses absent)."""

    folder: Path
    camera: CameraIntrinsics
    camera_mount: str
    target: object
    scene_path: Path | None
    pose_kind: str
    pose_ids: tuple[str, ...]
    poses: np.ndarray
    images: dict
    frames_per_pose: int
    extra_files: tuple[str, ...] = ()
    averaging: str = "corners"
    notes: tuple[str, ...] = ()


def _target_dict(spec) -> dict:
    d = {}
    for f in fields(spec):
        v = getattr(spec, f.name)
        d[f.name] = v.item() if hasattr(v, "item") else v
    return d


def write_recording(folder, scene, poses, joints, frames: int) -> Path:
    """Write recording.yaml and poses.csv for a simulated run (images are written by the workers
    into ``folder/images``). joints: (N, n) rad, the encoder readings of each pose."""
    from ..targets import load_target

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    setup = scene.setup
    doc = {
        "format": FORMAT,
        "units": {"length": "m", "angle": "rad"},
        "camera": setup.camera.to_dict(),
        "camera_mount": setup.mount,
        "target": _target_dict(load_target(scene.target_path)),
        "scene": str(Path(scene.path).resolve()),
        "scene_name": scene.name,  # fallback when the folder moves to another machine: scenes/<name>.yaml
        "poses": "joints",
        "frames_per_pose": int(frames),
        "averaging": scene.measurement.averaging,
    }
    write_text_atomic(folder / "recording.yaml", yaml.safe_dump(doc, sort_keys=False))
    joints = np.asarray(joints, float)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["pose_id"] + [f"q{j + 1}" for j in range(joints.shape[1])])
    for i, q in enumerate(joints):
        w.writerow([f"{i:03d}"] + [repr(float(v)) for v in q])
    write_text_atomic(folder / "poses.csv", buf.getvalue())
    return folder


def read_recording(folder) -> Recording:
    """Read and validate a recorded folder. Missing/corrupt images are NOT errors here (the
    measurement stage rejects those poses with a reason); a missing recording.yaml or poses.csv,
    a malformed CSV, NaN values or duplicate pose ids are (DataError/ConfigError naming the file)."""
    from ..targets import target_from_dict

    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(f"{folder}: recorded folder not found")
    ypath = folder / "recording.yaml"
    top = Section(load_yaml(ypath), ypath)
    fmt = top.get("format", str, FORMAT)
    if fmt != FORMAT:
        raise top.error("format", f"expected {FORMAT!r}, got {fmt!r}")
    Lf, Af = top.units(default_length="m", default_angle="rad")
    camera = CameraIntrinsics.from_dict(top.section("camera").data, where=top.where("camera"))
    mount = top.get("camera_mount", str, choices=("eye_in_hand", "fixed", "base"))
    tsec = top.section("target")
    target = target_from_dict(tsec.data, where=tsec.where())
    scene_path = None
    notes = []
    if "scene" in top:
        p = Path(top.get("scene", str))
        p = p if p.is_absolute() else ypath.parent / p
        if not p.is_file():
            from ..rig.scene import SCENES_DIR

            alt = SCENES_DIR / f"{top.get('scene_name', str, '')}.yaml"
            if not alt.is_file():
                raise top.error("scene", f"file not found: {p} (nor {alt})")
            notes.append(f"recording.yaml scene {p} not found: used the shipped scene {alt} (same name)")
            p = alt
        scene_path = p
    pose_kind = top.get("poses", str, "joints", choices=("joints", "flange_pose"))
    frames = top.positive("frames_per_pose", int, 10)
    averaging = top.get("averaging", str, "corners", choices=("corners", "poses"))

    cpath = folder / "poses.csv"
    if not cpath.is_file():
        raise DataError(f"{cpath}: file not found (one row per robot pose: pose_id then joint values)")
    with open(cpath, newline="", encoding="utf-8-sig") as fh:  # -sig: spreadsheets write a BOM
        rows = [r for r in csv.reader(fh) if r and any(c.strip() for c in r)]
    if len(rows) < 2:
        raise DataError(f"{cpath}: no pose rows")
    header = [h.strip() for h in rows[0]]
    if header[0] != "pose_id":
        raise DataError(f"{cpath}: first column must be 'pose_id', got {header[0]!r}")
    if pose_kind == "flange_pose" and header[1:] != ["x", "y", "z", "qx", "qy", "qz", "qw"]:
        raise DataError(f"{cpath}: flange poses need columns pose_id,x,y,z,qx,qy,qz,qw, got {','.join(header)}")
    ids, vals = [], []
    for ln, r in enumerate(rows[1:], start=2):
        if len(r) != len(header):
            raise DataError(f"{cpath}: line {ln}: {len(r)} values, expected {len(header)} ({','.join(header)})")
        try:
            v = [float(c) for c in r[1:]]
        except ValueError:
            raise DataError(f"{cpath}: line {ln} (pose {r[0].strip()!r}): non-numeric value in {r[1:]}") from None
        if not np.all(np.isfinite(v)):
            raise DataError(f"{cpath}: line {ln} (pose {r[0].strip()!r}): NaN or infinite value")
        ids.append(r[0].strip())
        vals.append(v)
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise DataError(f"{cpath}: duplicate pose ids {dup}")
    vals = np.array(vals)
    if pose_kind == "joints":
        poses = vals * Af
    else:
        from ..frames import T_from_xyz_quat

        q = vals[:, 3:]
        nq = np.linalg.norm(q, axis=1)
        bad = np.flatnonzero(np.abs(nq - 1) > 1e-3)
        if bad.size:
            raise DataError(f"{cpath}: pose {ids[bad[0]]!r}: quaternion norm {nq[bad[0]]:.4f} is not 1")
        poses = T_from_xyz_quat(vals[:, :3] * Lf, q / nq[:, None])

    images = {}
    extra = []
    idir = folder / "images"
    if idir.is_dir():
        known = set(ids)
        for d in sorted(idir.iterdir()):
            if d.is_dir() and d.name in known:
                files = sorted(p for p in d.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_EXT)
                extra += [str(p.relative_to(folder)) for p in d.iterdir() if p.is_file() and p.suffix.lower() not in IMAGE_EXT]
                if files:
                    images[d.name] = files
            else:
                extra.append(str(d.relative_to(folder)))
    assert Lf in LENGTH_UNITS.values() and Af in ANGLE_UNITS.values()
    return Recording(folder, camera, mount, target, scene_path, pose_kind, tuple(ids), poses, images, frames,
                     tuple(extra), averaging, tuple(notes))
