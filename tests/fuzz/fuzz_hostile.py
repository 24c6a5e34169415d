"""Hostile files and runaway work (issue 28): images that declare huge sizes, symbolic links out of an image
folder, an odd-sized first image, measured poses duplicated under new ids, Dask scheduler files and schedulers
without workers, studies and pose counts beyond the machine, a full disk, hostile URDF files.

Each case runs the CLI in a child process (``run_hostile``) bounded in memory (RLIMIT_DATA, :data:`MEMORY_LIMIT`)
and time (its ``timeout``), with the folder ``tmp/outside`` watched by inotify: a case whose inputs lead there
(symbolic links, mesh paths) must not open anything in it. Outcomes (the fuzz tally):

- ``named_error``: exit 2 or 3 and the case's pattern on stderr (expect "error");
- ``correct`` / ``warned``: exit 0, the case's check holds (and, for "warned", the pattern is on stdout/stderr);
- ``silent_wrong``: exit 0 where an error was expected, or a failed check;
- ``unnamed_error``: exit 2/3 without the pattern; ``unexpected_error``: an error where a result was expected;
- ``traceback``: a Python traceback on stderr; ``hang``: the time limit of a case that waits; ``runaway``: the
  memory limit reached, or the time limit of a case that works; ``outside_access``: a file outside opened.

A case: :class:`Hostile` (``build(tmp, ctx) -> (argv, check or None)``; ``prelude``: Python run in the child
before ``main``, e.g. a writer monkeypatched to fail with ENOSPC for one file; ``env``: extra environment).
"""

from __future__ import annotations

import ctypes
import json
import os
import shutil
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from fuzz_inputs import REPO, RX90, ST, SR, _mp, _rosi, visp_folder  # noqa: F401  (shared builders)
from urdf_arm import measured_pose_cell, urdf_text

#: the child's data segment limit (RLIMIT_DATA): a run that needs more is a runaway (the fuzzing session saw
#: 12-24 GB); every well-behaved case here stays far below
MEMORY_LIMIT = 3 * 1024**3
N_CLEAN = 40


# ----------------------------------------------------------------------------- hostile images
def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_declaring(width: int, height: int) -> bytes:
    """A grey PNG whose header declares width x height px with almost no pixel data (~69 bytes)."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", zlib.compress(b"\x00" * 16)) + \
        _chunk(b"IEND", b"")


_PNG_CACHE: dict = {}


def png_zeros(width: int, height: int) -> bytes:
    """A complete, valid black grey PNG of width x height px (deflate: ~1 KB per Mpx), cached."""
    key = (width, height)
    if key not in _PNG_CACHE:
        z = zlib.compressobj(9)
        row = b"\x00" * (width + 1)
        idat = b"".join(z.compress(row) for _ in range(height)) + z.flush()
        ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
        _PNG_CACHE[key] = b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", idat) + _chunk(b"IEND", b"")
    return _PNG_CACHE[key]


BOMB = png_declaring(30000, 30000)


# ----------------------------------------------------------------------------- inotify: nothing outside opened
class Watch:
    """inotify watch of the files directly in ``folder`` (IN_OPEN | IN_ACCESS): :meth:`opened` lists the names
    opened since the watch began (by any process: the child reading through a symbolic link)."""

    IN_ACCESS, IN_OPEN = 0x1, 0x20

    def __init__(self, folder: Path):
        self.libc = ctypes.CDLL(None, use_errno=True)
        self.fd = self.libc.inotify_init1(os.O_NONBLOCK)
        if self.fd < 0 or self.libc.inotify_add_watch(self.fd, str(folder).encode(), self.IN_OPEN | self.IN_ACCESS) < 0:
            raise OSError(ctypes.get_errno(), "inotify not available")

    def opened(self) -> list[str]:
        names = []
        try:
            buf = os.read(self.fd, 1 << 16)
        except BlockingIOError:
            buf = b""
        i = 0
        while i + 16 <= len(buf):
            _, _, _, n = struct.unpack_from("iIII", buf, i)
            names.append(buf[i + 16:i + 16 + n].rstrip(b"\0").decode(errors="replace"))
            i += 16 + n
        return sorted(set(names))

    def close(self):
        os.close(self.fd)


# ----------------------------------------------------------------------------- cases
@dataclass(frozen=True)
class Hostile:
    id: str
    build: Callable
    expect: str  # "error" | "correct" | "warned"
    pattern: str | None = None
    timeout: float = 120.0
    on_timeout: str = "runaway"  # what the time limit means for this case: "hang" (waits) or "runaway" (works)
    prelude: str = ""
    env: dict = field(default_factory=dict)


def _views(tmp: Path, ctx, n=10) -> Path:
    """A folder of n good calibration views (the session recording's first frames, 1024x768)."""
    d = tmp / "views"
    d.mkdir()
    for k in range(n):
        shutil.copyfile(ctx["rec"] / "images" / f"{k:03d}" / "00.png", d / f"v{k:02d}.png")
    return d


def _calib(d: Path, tmp: Path, *extra):
    return ["calibrate-camera", str(d), "--target", str(REPO / "targets" / "charuco_a5.yaml"), "--out",
            str(tmp / "cam.yaml"), *extra]


def _rec(tmp, ctx) -> Path:
    rec = tmp / "rec"
    shutil.copytree(ctx["rec"], rec, symlinks=True)
    return rec


def process_frame(data: bytes):
    def build(tmp, ctx):
        rec = _rec(tmp, ctx)
        (rec / "images" / "003" / "01.png").write_bytes(data)
        return ["process", str(rec), "--out", str(tmp / "out"), "--no-plots"], None
    return build


def visp_frame(data: bytes):
    def build(tmp, ctx):
        d = visp_folder(tmp / "visp", np.full((240, 320), 128, np.uint8))
        (d / "image-1.png").write_bytes(data)
        return ["import-visp", str(d), "--out", str(tmp / "rec"), "--chessboard", "9x6", "--square-m", "0.02"], None
    return build


def rosi_frame(data: bytes):
    def build(tmp, ctx):
        src = _rosi(tmp / "rosi")
        (src / "images" / "1.png").write_bytes(data)
        return ["import-rosi", str(src), "--out", str(tmp / "rec")], None
    return build


def _frames(ctx, n: int) -> list:
    """n distinct frames of one static view: the session recording's first pose, each with its own grey noise."""
    import cv2

    base = cv2.imread(str(ctx["rec"] / "images" / "000" / "00.png"), cv2.IMREAD_GRAYSCALE).astype(float)
    rng = np.random.default_rng(7)
    return [np.clip(base + rng.normal(scale=2.0, size=base.shape), 0, 255).astype(np.uint8) for _ in range(n)]


def _noise_set(tmp: Path, ctx, n=4, cx=515.3) -> Path:
    """A ROS-I noise-qualification set of n frames of one static view (distinct by their noise)."""
    import cv2

    d = tmp / "noise"
    (d / "images").mkdir(parents=True)
    for k, img in enumerate(_frames(ctx, n)):
        cv2.imwrite(str(d / "images" / f"{k}.png"), img)
    doc = {"data": [{"image": f"images/{k}.png"} for k in range(n)],
           "intrinsics": {"fx": 1100.0, "fy": 1100.0, "cx": cx, "cy": 380.2},
           "target_finder": {"type": "CharucoGridTargetFinder", "rows": 5, "cols": 7, "chessboard_dim": 0.025,
                             "aruco_marker_dim": 0.018, "dictionary": 10}}
    (d / "cal_data.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return d


def _noise_argv(d, tmp, *extra):
    return ["noise", str(d), "--out", str(tmp / "out"), "--sim-frames", "2",
            "--target", str(REPO / "targets" / "charuco_a5.yaml"), *extra]


def noise_frame(data: bytes, frame=1):
    def build(tmp, ctx):
        d = _noise_set(tmp, ctx)
        (d / "images" / f"{frame}.png").write_bytes(data)
        return _noise_argv(d, tmp), None
    return build


def noise_all(data: bytes, n=3):
    def build(tmp, ctx):
        d = _noise_set(tmp, ctx, n)
        for k in range(n):
            (d / "images" / f"{k}.png").write_bytes(data)
        return _noise_argv(d, tmp), None
    return build


def noise_principal_point(tmp, ctx):
    return _noise_argv(_noise_set(tmp, ctx, cx=1900.0), tmp), None


def calib_with(data: bytes, name="v99.png"):
    def build(tmp, ctx):
        d = _views(tmp, ctx)
        (d / name).write_bytes(data)

        def check(tmp):
            cam = yaml.safe_load((tmp / "cam.yaml").read_text())
            return cam["width"] == 1024 and cam["height"] == 768 and cam["n_views_used"] >= 8
        return _calib(d, tmp), check
    return build


def calib_only(data: bytes, n=2):
    def build(tmp, ctx):
        d = tmp / "views"
        d.mkdir()
        for k in range(n):
            (d / f"big{k}.png").write_bytes(data)
        return _calib(d, tmp), None
    return build


def calib_first_odd(tmp, ctx):
    import cv2

    d = _views(tmp, ctx)
    img = cv2.imread(str(d / "v03.png"), cv2.IMREAD_GRAYSCALE)
    cv2.imwrite(str(d / "a_first.png"), cv2.resize(img, (640, 480)))  # sorted first

    def check(tmp):
        cam = yaml.safe_load((tmp / "cam.yaml").read_text())
        return (cam["width"], cam["height"]) == (1024, 768) and cam["n_views_used"] >= 8
    return _calib(d, tmp), check


def calib_symlink(target: str):
    def build(tmp, ctx):
        d = _views(tmp, ctx)
        if target == "outside":
            shutil.copyfile(ctx["rec"] / "images" / "005" / "01.png", tmp / "outside" / "secret.png")
            (d / "frame.png").symlink_to(tmp / "outside" / "secret.png")
        else:
            (d / "frame.png").symlink_to(target)
        return _calib(d, tmp), None
    return build


def noise_symlink(tmp, ctx):
    """A plain image folder (--target, --camera) with a frame linked to a file outside it."""
    import cv2

    d = tmp / "frames"
    d.mkdir()
    imgs = _frames(ctx, 4)
    for k in range(3):
        cv2.imwrite(str(d / f"{k}.png"), imgs[k])
    cv2.imwrite(str(tmp / "outside" / "secret.png"), imgs[3])
    (d / "3.png").symlink_to(tmp / "outside" / "secret.png")
    cam = {"format": "vision_calib.camera/1", "width": 1024, "height": 768, "fx": 1100.0, "fy": 1100.0, "cx": 515.3,
           "cy": 380.2, "dist": [-0.05, 0.02, 0.0, 0.0, 0.0]}
    (tmp / "camera.yaml").write_text(yaml.safe_dump(cam))
    return _noise_argv(d, tmp, "--camera", str(tmp / "camera.yaml")), None


def noise_first_odd(tmp, ctx):
    import cv2

    d = _noise_set(tmp, ctx, n=5)
    img = cv2.imread(str(d / "images" / "0.png"), cv2.IMREAD_GRAYSCALE)
    cv2.imwrite(str(d / "images" / "0.png"), cv2.resize(img, (640, 480)))

    def check(tmp):
        doc = json.loads((tmp / "out" / "noise.json").read_text())
        return doc["n_frames"] == 4 and doc["camera"]["width"] == 1024
    return _noise_argv(d, tmp), check


# --- measured poses
def _rows(path: Path) -> list[list[str]]:
    return [r.split(",") for r in path.read_text().splitlines()]


def _write_rows(path: Path, rows) -> None:
    path.write_text("\n".join(",".join(r) for r in rows) + "\n")


def _poses_report(tmp, sub="out") -> dict:
    return json.loads((tmp / sub / "report.json").read_text())


def _stds(rep) -> dict:
    return {p["name"]: p["std"] for p in rep["parameters"] if p["free"]}


def _clean_reference(tmp, ctx) -> dict:
    """report.json of the clean file (same rows, no copies), run here in-process."""
    from vision_calib.cli import main

    ref = tmp / "ref"
    ref.mkdir()
    p = _mp(ref, ctx)
    assert main(["process-poses", str(p), "--out", str(ref / "out"), "--no-plots", "--json"]) == 0
    return _poses_report(ref)


def duplicated(jitter: float, n_copies: int | None = None):
    """Rows copied under new ids ``copyK`` (every row, or the first n_copies), each number + jitter."""
    def build(tmp, ctx):
        p = _mp(tmp, ctx)
        rows = _rows(p.with_suffix(".csv"))
        body = rows[1:] if n_copies is None else rows[1:1 + n_copies]
        extra = [[f"copy{k}"] + [repr(float(v) + jitter * (1 if (k + j) % 2 else -1)) for j, v in enumerate(r[1:14])]
                 + r[14:] for k, r in enumerate(body)]
        _write_rows(p.with_suffix(".csv"), rows + extra)

        def check(tmp):
            rep, ref = _poses_report(tmp), _clean_reference(tmp, ctx)
            s, s0 = _stds(rep), _stds(ref)
            ratio = min(s[k] / s0[k] for k in s0)
            named = any("copy0" in w and "p000" in w for w in rep["warnings"])
            held = rep["holdout"]["overall"]["n_poses"]
            return named and ratio > 0.95 and held == N_CLEAN
        return ["process-poses", str(p), "--out", str(tmp / "out"), "--no-plots"], check
    return build


def remeasured(tmp, ctx):
    """Ten poses measured twice at the same joints (independent noise: genuine repeats): both kept, in one fold."""
    from vision_calib import frames as F

    q, T = ctx[RX90]
    rng = np.random.default_rng(11)
    d = np.concatenate([rng.normal(scale=ST, size=(10, 3)), rng.normal(scale=SR, size=(10, 3))], axis=1)
    q2, T2 = np.concatenate([q, q[:10]]), np.concatenate([T, F.perturb_pose(T[:10], d)])
    p = _mp(tmp, ctx, q=q2, T=T2)

    def check(tmp):
        rep = _poses_report(tmp)
        return (rep["verdict"]["status"] == "ok" and rep["holdout"]["overall"]["n_poses"] == N_CLEAN + 10
                and any("same joints" in w and "one held-out fold" in w for w in rep["warnings"]))
    return ["process-poses", str(p), "--out", str(tmp / "out"), "--no-plots"], check


# --- studies
def _study(tmp, reps=1, **kw) -> Path:
    d = {"name": "hostile", "scene": str(REPO / "scenes" / "h4_vision.yaml"), "repetitions": reps, "seed": 1,
         "sweep": {"n_poses": [12]}, **kw}
    p = tmp / "study.yaml"
    p.write_text(yaml.safe_dump(d, sort_keys=False))
    return p


def study_with_scheduler(kind: str):
    def build(tmp, ctx):
        spec = _study(tmp)
        if kind == "garbage":
            (tmp / "sched.json").write_text("not json at all\n")
            sched = str(tmp / "sched.json")
        elif kind == "dead":
            (tmp / "sched.json").write_text(json.dumps({"type": "Scheduler", "address": "tcp://127.0.0.1:9"}))
            sched = str(tmp / "sched.json")
        else:
            addr, file = ctx["scheduler"]()
            sched = file if kind == "file-no-workers" else addr
        return ["study", str(spec), "--out", str(tmp / "out"), "--scheduler", sched, "--no-plots"], None
    return build


def study_runs(reps: int, *extra, **kw):
    def build(tmp, ctx):
        return ["study", str(_study(tmp, reps, **kw)), "--out", str(tmp / "out"), "--no-plots", *extra], None
    return build


def pose_count(command: str, n: int):
    def build(tmp, ctx):
        return [command, str(REPO / "scenes" / "rx90_eye_in_hand.yaml"), "--poses", str(n), "--json"], None
    return build


# --- a full disk: one output refused with ENOSPC (a monkeypatched writer)
def enospc_prelude(name: str) -> str:
    """Python for the child: every write of a file called ``name`` (atomic writers' os.replace, open() for
    writing, matplotlib's savefig through open) fails with ENOSPC, as on a full disk."""
    return f"""
import builtins, errno, os
_NAME = {name!r}
_replace, _open = os.replace, builtins.open
def _full(*a, **k):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
def replace(src, dst, *a, **k):
    if os.path.basename(str(dst)) == _NAME:
        _full()
    return _replace(src, dst, *a, **k)
def open_(file, mode="r", *a, **k):
    if isinstance(file, (str, os.PathLike)) and os.path.basename(str(file)) == _NAME and any(c in mode for c in "wax+"):
        _full()
    return _open(file, mode, *a, **k)
os.replace, builtins.open = replace, open_
"""


def disk_full(plots=False):
    def build(tmp, ctx):
        p = _mp(tmp, ctx)

        def check(tmp):  # the failed run leaves no calibrated model without its report
            return not (tmp / "out" / "calibrated_model.yaml").exists()
        return ["process-poses", str(p), "--out", str(tmp / "out"), *([] if plots else ["--no-plots"])], check
    return build


def study_disk_full(tmp, ctx):
    return ["study", str(_study(tmp, 2)), "--out", str(tmp / "out"), "--no-plots", "--workers", "1"], None


# --- URDF (the arm: tests/urdf_arm.py)


def urdf_init(text: str):
    def build(tmp, ctx):
        (tmp / "arm.urdf").write_text(text)
        return ["init", str(tmp / "cell"), "--urdf", str(tmp / "arm.urdf")], None
    return build


HOSTILE_MESHES = ("/etc/passwd", "../../../../etc/shadow", "file:///etc/passwd", "package://x/../../../etc/passwd")


def urdf_meshes(tmp, ctx):
    """process-poses on a URDF robot whose meshes name files outside (the watched folder among them, by an
    absolute and a relative path): the calibrated URDF is written, its mesh paths unchanged, nothing opened."""
    (tmp / "outside" / "mesh.stl").write_bytes(b"solid x\nendsolid x\n")
    meshes = HOSTILE_MESHES + (str(tmp / "outside" / "mesh.stl"), "../outside/mesh.stl",
                               f"file://{tmp}/outside/mesh.stl")
    p = measured_pose_cell(tmp / "cell", meshes)

    def check(tmp):
        out = list((tmp / "out").glob("*.urdf"))
        return len(out) == 1 and all(f'filename="{m}"' in out[0].read_text() for m in meshes)
    return ["process-poses", str(p), "--out", str(tmp / "out"), "--no-plots"], check


# --- hand-eye route (flange poses known; issue 28 item 3): the session recording as a flange-pose recording
def _flange(tmp, ctx, csv_edit=None, yaml_edit=None) -> Path:
    """The session recording rewritten with its true flange poses + 0.1 mm / 0.01 deg per axis
    (tests/flange_folder.py), then poses.csv's data rows edited (``csv_edit``: rows -> rows) and recording.yaml
    edited in place (``yaml_edit``: doc -> None)."""
    from flange_folder import flange_pose_folder

    rec, _, _ = flange_pose_folder(ctx["rec"], tmp / "flange", robot_std_mm=0.1, robot_std_deg=0.01, seed=2)
    if csv_edit is not None:
        lines = (rec / "poses.csv").read_text().splitlines()
        (rec / "poses.csv").write_text("\n".join([lines[0]] + csv_edit(lines[1:])) + "\n")
    if yaml_edit is not None:
        doc = yaml.safe_load((rec / "recording.yaml").read_text())
        yaml_edit(doc)
        (rec / "recording.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return rec


def _wxyz(row: str) -> str:  # qx,qy,qz,qw columns holding w,x,y,z: a scalar-first writer
    f = row.split(",")
    return ",".join(f[:4] + [f[7], f[4], f[5], f[6]])


def _board_x2(doc):
    doc["target"]["square_m"] *= 2
    doc["target"]["marker_m"] *= 2


def _swap_rows(rows, a=2, b=6):
    x, y = rows[a].split(",", 1), rows[b].split(",", 1)
    return [f"{x[0]},{y[1]}" if i == a else f"{y[0]},{x[1]}" if i == b else r for i, r in enumerate(rows)]


def _one_row_off(rows):  # each pose id with the NEXT row's flange pose
    return [f"{r.split(',', 1)[0]},{n.split(',', 1)[1]}" for r, n in zip(rows[:-1], rows[1:])]


def flange_damage(csv_edit=None, yaml_edit=None, named=()):
    """``process`` of the damaged flange-pose recording; named: the pose ids the report must name as outliers
    (a result that is correct only with them rejected)."""
    def build(tmp, ctx):
        rec = _flange(tmp, ctx, csv_edit, yaml_edit)

        def check(tmp):
            rep = json.loads((tmp / "out" / "report.json").read_text())
            return {o["pose_id"] for o in rep.get("outliers", [])} == set(named)
        return ["process", str(rec), "--out", str(tmp / "out"), "--no-plots"], check
    return build


def flange_copied(n_copies: int):
    """``process`` of the flange-pose recording with its first ``n_copies`` pose folders copied under new ids
    (``cK``: the row and the image folder): the copies named and counted once, no outlier."""
    def build(tmp, ctx):
        rec = _flange(tmp, ctx)
        lines = (rec / "poses.csv").read_text().splitlines()
        extra = []
        for k, row in enumerate(lines[1:1 + n_copies]):
            pid, rest = row.split(",", 1)
            shutil.copytree(rec / "images" / pid, rec / "images" / f"c{k}")
            extra.append(f"c{k},{rest}")
        (rec / "poses.csv").write_text("\n".join(lines + extra) + "\n")

        def check(tmp):
            rep = json.loads((tmp / "out" / "report.json").read_text())
            return ([c["pose_id"] for c in rep["measurements"].get("copies", [])] == [f"c{k}" for k in range(n_copies)]
                    and not rep.get("outliers"))
        return ["process", str(rec), "--out", str(tmp / "out"), "--no-plots"], check
    return build


def one_flange_pose(tmp, ctx):
    """``process`` of the flange-pose recording with every row given the first row's flange pose: refused before
    any fit, nothing written but measurements.json."""
    rec = _flange(tmp, ctx, lambda rows: [f"{r.split(',', 1)[0]},{rows[0].split(',', 1)[1]}" for r in rows])
    return ["process", str(rec), "--out", str(tmp / "out"), "--no-plots"], \
        lambda tmp: not (tmp / "out" / "report.json").exists()


def pairs_of(copies: int | None):
    """import-pairs + process-poses in one child (the CLI's ``main`` twice): 10 copies of one simulated pair
    (``copies=10``), or 20 pairs each written twice (``None``)."""
    def build(tmp, ctx):
        from vision_calib.experiment.handeye_sim import simulate_pose_pairs
        from vision_calib.io.transform_pairs import write_transform_pairs

        d = simulate_pose_pairs(20, 4, "fixed")
        F, M = ((np.repeat(d.T_base_flange[:1], copies, 0), np.repeat(d.T_cam_target[:1], copies, 0)) if copies
                else (np.concatenate([d.T_base_flange] * 2), np.concatenate([d.T_cam_target] * 2)))
        src = write_transform_pairs(tmp / "pairs.yml", F, M)
        from vision_calib.cli import main

        assert main(["import-pairs", str(src), "--mount", "fixed", "--out", str(tmp / "pp" / "pairs.yaml")]) == 0

        def check(tmp):
            if copies:  # refused before any fit: nothing written
                return not (tmp / "out" / "report.json").exists()
            rep = json.loads((tmp / "out" / "report.json").read_text())
            return len(rep["measurements"]["copies"]) == 20 and rep["measurements"]["n_poses"] == 20
        return ["process-poses", str(tmp / "pp" / "pairs.yaml"), "--out", str(tmp / "out"), "--no-plots"], check
    return build


def _alias_tree(levels: int = 9, width: int = 9) -> str:
    """A flow list &a0 [9 strings], &a1 [9 x *a0], ...: width^levels strings once expanded (a "billion laughs")."""
    parts = ["&a0 [" + ", ".join(['"lol"'] * width) + "]"]
    parts += [f"&a{k} [" + ", ".join([f"*a{k - 1}"] * width) + "]" for k in range(1, levels)]
    return "[" + ", ".join(parts) + "]"


def yaml_alias(what: str):
    """identifiability on a scene whose ``name`` (what="scene"), target ``dictionary`` ("target") or robot
    ``kind`` ("robot") holds :func:`_alias_tree`; the other files the shipped ones, by absolute path."""
    import re

    def build(tmp, ctx):
        scenes, targets = REPO / "scenes", REPO / "targets"
        src = scenes / ("h4_vision.yaml" if what == "robot" else "rx90_eye_in_hand.yaml")
        text = re.sub(r"^robot: robots/", f"robot: {scenes}/robots/", src.read_text(), flags=re.M)
        text = text.replace("../targets/", f"{targets}/")
        key, orig = {"scene": ("name", None), "target": ("dictionary", targets / "charuco_a5.yaml"),
                     "robot": ("kind", scenes / "robots" / "h4.yaml")}[what]
        def tree(t):
            return re.sub(rf"^{key}:.*$", lambda m: f"{key}: {_alias_tree()}", t, count=1, flags=re.M)

        if orig is None:
            text = tree(text)
        else:
            (tmp / f"{what}.yaml").write_text(tree(orig.read_text()))
            text = text.replace(str(orig), str(tmp / f"{what}.yaml"))
        (tmp / "scene.yaml").write_text(text)
        return ["identifiability", str(tmp / "scene.yaml"), "--allow-path", str(REPO)], None
    return build


ERR, OK, WARN = "error", "correct", "warned"
#: the child waits 2 s (not study.run.WORKER_WAIT_S) for a Dask worker
WAIT_2S = "import importlib\nimportlib.import_module(\"vision_calib.study.run\").WORKER_WAIT_S = 2.0\n"
LIMIT = r"exceeds the limit of 50 Mpx"

CASES = [
    # --- images declaring huge sizes: refused from the header, before anything is decoded
    Hostile("img-bomb30k-process", process_frame(BOMB), ERR, r"images/003/01.png: image 30000x30000 px .*" + LIMIT),
    Hostile("img-13k-process", process_frame(png_zeros(13000, 13000)), ERR, r"images/003/01.png: image 13000x13000 px"),
    Hostile("img-bomb30k-import-visp", visp_frame(BOMB), ERR, r"image-1.png: image 30000x30000 px .*" + LIMIT),
    Hostile("img-bomb30k-import-rosi", rosi_frame(BOMB), ERR, r"images/1.png: image 30000x30000 px .*" + LIMIT),
    Hostile("img-bomb30k-noise", noise_frame(BOMB), ERR, r"images/1.png: image 30000x30000 px .*" + LIMIT),
    Hostile("img-13k-noise", noise_all(png_zeros(13000, 13000)), ERR, r"images/\d.png: image 13000x13000 px .*" + LIMIT),
    Hostile("img-noise-principal-point", noise_principal_point, ERR,
            r"cal_data.yaml: intrinsics: principal point \(1900, 380.2\) px lies outside the middle of the 1024x768 px "
            r"images"),
    Hostile("img-bomb30k-calibrate-camera", calib_with(BOMB), WARN, r"v99.png: image 30000x30000 px .*" + LIMIT),
    Hostile("img-13k-only-calibrate-camera", calib_only(png_zeros(13000, 13000)), ERR,
            r"0 usable views of 2.*big0.png: image 13000x13000 px .*" + LIMIT),
    Hostile("img-limit-raised-by-env", calib_only(png_declaring(8000, 8000), 1), ERR,
            r"big0.png: unreadable or corrupt image", env={"VISION_CALIB_MAX_IMAGE_MPX": "100"}),
    Hostile("img-first-odd-calibrate-camera", calib_first_odd, WARN,
            r"a_first.png: image size 640x480 differs from the majority 1024x768 \(10 of 11 images\)"),
    Hostile("img-first-odd-noise", noise_first_odd, WARN,
            r"images/0.png: image size 640x480 differs from the majority 1024x768 \(4 of 5 frames\)"),
    # --- symbolic links out of an image folder
    Hostile("calib-symlink-outside", calib_symlink("outside"), ERR, r"frame.png: a symbolic link leading out of the folder"),
    Hostile("calib-symlink-etc-passwd", calib_symlink("/etc/passwd"), ERR, r"frame.png: a symbolic link leading out"),
    Hostile("noise-folder-symlink-outside", noise_symlink, ERR, r"3.png: a symbolic link leading out of the folder"),
    # --- measured poses copied under new ids: named, counted once, the std not flattered
    Hostile("mp-all-rows-copied-1e-6-jitter", duplicated(1e-6), WARN, r"copies? of another pose"),
    Hostile("mp-5-rows-copied-exactly", duplicated(0.0, 5), WARN, r"copies? of another pose"),
    Hostile("mp-remeasured-same-joints", remeasured, OK),
    # --- hand-eye sets without enough distinct motions, or copied (issue 32): named before any fit, counted once
    Hostile("pairs-10-copies-of-one", pairs_of(10), ERR, r"degenerate motion: the 10 pose pairs hold 1 distinct"),
    Hostile("pairs-each-written-twice", pairs_of(None), WARN, r"20 poses are copies of another pose"),
    Hostile("handeye-3-pose-folders-copied", flange_copied(3), WARN, r"3 poses are copies of another pose"),
    Hostile("handeye-one-flange-pose", one_flange_pose, ERR,
            r"degenerate motion: the \d+ pose pairs hold 1 distinct flange pose"),
    # --- YAML alias trees in a key the loader knows: refused while composing (issue 32)
    Hostile("yaml-alias-tree-scene-name", yaml_alias("scene"), ERR, r"scene.yaml: invalid YAML \(aliases expand",
            timeout=30),
    Hostile("yaml-alias-tree-target-dictionary", yaml_alias("target"), ERR,
            r"target.yaml: invalid YAML \(aliases expand", timeout=30),
    Hostile("yaml-alias-tree-robot-kind", yaml_alias("robot"), ERR, r"robot.yaml: invalid YAML \(aliases expand",
            timeout=30),
    # --- studies: scheduler files, schedulers without workers, runaway sizes
    Hostile("study-scheduler-file-garbage", study_with_scheduler("garbage"), ERR,
            r"--scheduler: .*sched.json: not a Dask scheduler file", timeout=60),
    Hostile("study-scheduler-file-dead", study_with_scheduler("dead"), ERR,
            r"Dask scheduler tcp://127.0.0.1:9 \(from .*sched.json\): cannot connect", timeout=90, on_timeout="hang"),
    Hostile("study-scheduler-no-workers", study_with_scheduler("no-workers"), ERR,
            r"Dask scheduler tcp://127.0.0.1:\d+: no worker connected within 2 s", timeout=60, on_timeout="hang",
            prelude=WAIT_2S),
    Hostile("study-scheduler-file-no-workers", study_with_scheduler("file-no-workers"), ERR,
            r"Dask scheduler tcp://127.0.0.1:\d+ \(from .*\.json\): no worker connected within 2 s", timeout=60,
            on_timeout="hang", prelude=WAIT_2S),
    Hostile("study-1e6-runs", study_runs(1_000_000), ERR,
            r"1000000 runs: estimated .* h .*--yes", timeout=60),
    Hostile("study-1e6-runs-bound-too-low", study_runs(1_000_000, max_hours=2), ERR,
            r"1000000 runs: estimated .* h .*max_hours: 2", timeout=60),
    Hostile("synthetic-1e8-poses", pose_count("identify-synthetic", 100_000_000), ERR,
            r"--poses 100000000: estimated .* GB of memory .*--yes", timeout=60),
    Hostile("identifiability-1e8-poses", pose_count("identifiability", 100_000_000), ERR,
            r"--poses 100000000: estimated .* GB of memory .*--yes", timeout=60),
    # --- a full disk: the output that could not be written is an error naming it, no model without its report
    Hostile("disk-full-report-html", disk_full(), ERR, r"out/report.html: No space left on device",
            prelude=enospc_prelude("report.html")),
    Hostile("disk-full-report-json", disk_full(), ERR, r"out/report.json: No space left on device",
            prelude=enospc_prelude("report.json")),
    Hostile("disk-full-plot", disk_full(plots=True), ERR, r"out/residuals.png: No space left on device",
            prelude=enospc_prelude("residuals.png")),
    Hostile("disk-full-study-summary", study_disk_full, ERR, r"out/summary.csv: No space left on device",
            prelude=enospc_prelude("summary.csv")),
    # --- URDF: one tree, exact numbers, and no file it names ever touched
    Hostile("urdf-cycle-tool0-base", urdf_init(urdf_text(
        extra='  <joint name="loop" type="fixed"><parent link="tool0"/><child link="base_link"/></joint>')), ERR,
        r"arm.urdf: .*(one root link|loop)"),
    Hostile("urdf-xyz-4-values", urdf_init(urdf_text(flange_xyz="0 0 0.02 1")), ERR,
            r"arm.urdf: joint 'flange': origin xyz='0 0 0.02 1' must hold exactly 3 numbers, got 4"),
    Hostile("urdf-joint-without-parent", urdf_init(urdf_text(j3_parent=False)), ERR,
            r"arm.urdf: joint 'j3': needs <parent link=...>"),
    Hostile("urdf-hostile-mesh-paths", urdf_meshes, OK),
    # --- hand-eye route: each damage named as the reading that fits, or the bad rows named as outliers
    Hostile("handeye-clean", flange_damage(), OK),
    Hostile("handeye-quaternions-scalar-first", flange_damage(lambda rows: [_wxyz(r) for r in rows]), ERR,
            r"the flange quaternions read scalar-first .*: that reading of the input fits"),
    Hostile("handeye-mount-declared-fixed", flange_damage(yaml_edit=lambda d: d.update(camera_mount="fixed")), ERR,
            r"the camera mount eye_in_hand .*: that reading of the input fits"),
    Hostile("handeye-board-size-x2", flange_damage(yaml_edit=_board_x2), ERR, r"the board's size off by 2"),
    Hostile("handeye-rows-one-off", flange_damage(_one_row_off), ERR,
            r"the images paired one row off \(each with the PREVIOUS row's flange pose\): that reading of the input fits"),
    Hostile("handeye-one-row-scalar-first", flange_damage(lambda rows: [_wxyz(r) if i == 4 else r
                                                                        for i, r in enumerate(rows)], named={"004"}), OK),
    Hostile("handeye-two-rows-swapped", flange_damage(_swap_rows, named={"002", "006"}), OK),
]
