"""Bad inputs beyond a damaged recording (issue 21): measured-pose files with gross errors (a reversed direction,
swapped columns, a joint's sign reversed, a turned mount), non-UTF-8 bytes, paths leading out of a file's
folder, implausible sigmas, duplicated rows; outputs inside inputs; ROS-I data sets naming files outside;
oversized targets; a transposed chessboard size; copied calibration views.

A case is (id, build, expect, pattern): ``build(tmp, ctx)`` writes its inputs under ``tmp`` and returns the CLI
arguments (and, for "correct"/"warned" cases, a check of the written outputs); expect "error" = exit 2 or 3 with
``pattern`` (a regex) on stderr; "correct" = exit 0 and the check holds; "warned" = exit 0 with ``pattern`` on
stderr. ``ctx``: the shared inputs (:func:`context`).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import yaml

from vision_calib import frames as F
from vision_calib.experiment.steps import rngs, scene_truth
from vision_calib.io.measured_poses_writer import write_measured_poses
from vision_calib.rig import SCENES_DIR, load_scene, scene_poses

REPO = Path(__file__).resolve().parents[2]
RX90, UR5E = SCENES_DIR / "rx90_eye_in_hand.yaml", SCENES_DIR / "ur5e_eye_in_hand.yaml"
ST, SR = 1e-4, float(np.radians(0.02))  # 0.1 mm, 0.02 deg per component
N = 40


def context(recording: Path) -> dict:
    """{scene path: (q (N, 6) rad, T_cam_target rows (N, 4, 4) with N(0, ST/SR) noise)} for the RX-90 and UR5e
    truths, and the session's recorded folder ``rec`` (never modified: cases copy it)."""
    out = {"rec": recording}
    for path in (RX90, UR5E):
        scene = load_scene(path)
        rp, rn, _ = rngs(2)
        q = scene_poses(scene, rp, N)
        T = scene.setup.T_cam_target(q, scene_truth(scene))
        d = np.concatenate([rn.normal(scale=ST, size=(N, 3)), rn.normal(scale=SR, size=(N, 3))], axis=1)
        out[path] = (q, F.perturb_pose(T, d))
    return out


def _mp(tmp, ctx, scene=RX90, q=None, T=None, measured="T_cam_target", name="m.yaml", **kw) -> Path:
    q0, T0 = ctx[scene]
    q, T = q0 if q is None else q, T0 if T is None else T
    kw.setdefault("sigmas", np.tile([ST] * 3 + [SR] * 3, (len(q), 1)))
    return write_measured_poses(tmp / name, scene, [f"p{i:03d}" for i in range(len(q))], q, T, measured,
                                units={"length": "mm", "angle": "deg"}, **kw)


def _run(path, tmp, *extra):
    return ["process-poses", str(path), "--out", str(tmp / "out"), "--no-plots", *map(str, extra)]


def _model_written(tmp) -> bool:
    rep = json.loads((tmp / "out" / "report.json").read_text())
    return (tmp / "out" / "calibrated_model.yaml").is_file() and rep["verdict"]["status"] == "ok"


def failed_without_model(tmp) -> bool:
    """A failure: report.json kept with status "failed", no calibrated model."""
    rep = json.loads((tmp / "out" / "report.json").read_text())
    return rep["verdict"]["status"] == "failed" and not (tmp / "out" / "calibrated_model.yaml").exists()


# ----------------------------------------------------------------------------- measured-pose files
def clean(scene):
    def build(tmp, ctx):
        return _run(_mp(tmp, ctx, scene), tmp), _model_written
    return build


def reversed_direction(tmp, ctx):
    q, T = ctx[RX90]
    return _run(_mp(tmp, ctx, T=F.inv_T(T)), tmp), failed_without_model


def _edit_csv(path: Path, fn):
    rows = [r.split(",") for r in path.read_text().splitlines()]
    path.write_text("\n".join(",".join(r) for r in fn(rows)) + "\n")


def swapped_columns(a, b):
    def build(tmp, ctx):
        p = _mp(tmp, ctx)

        def swap(rows):
            i, j = rows[0].index(a), rows[0].index(b)
            rows[0][i], rows[0][j] = b, a
            return rows
        _edit_csv(p.with_suffix(".csv"), swap)
        return _run(p, tmp), failed_without_model
    return build


def scalar_first_quaternion(tmp, ctx):
    p = _mp(tmp, ctx)

    def rename(rows):  # the columns qx, qy, qz, qw then hold (w, x, y, z): a scalar-first writer
        rows[0] = [{"qx": "qy", "qy": "qz", "qz": "qw", "qw": "qx"}.get(h, h) for h in rows[0]]
        return rows
    _edit_csv(p.with_suffix(".csv"), rename)
    return _run(p, tmp), failed_without_model


def joint_negated(j, scene=RX90):
    def build(tmp, ctx):
        q, _ = ctx[scene]
        q = q.copy()
        q[:, j - 1] *= -1
        return _run(_mp(tmp, ctx, scene, q=q), tmp), failed_without_model
    return build


def _scene_copy(dst: Path, **edit) -> Path:
    """The shipped RX-90 scene written to ``dst`` with absolute paths to the shipped robot and target (allowed:
    shipped data) and ``edit`` applied to its mounts."""
    d = yaml.safe_load(RX90.read_text())
    d["robot"] = str(SCENES_DIR / d["robot"])
    d["target"] = str((SCENES_DIR / d["target"]).resolve())
    for k, v in edit.items():
        d["mounts"][k] = v
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_text(yaml.safe_dump(d, sort_keys=False))
    return dst


def mount_turned(tmp, ctx):
    """The file's scene says the camera is turned 90 deg about the flange's x axis from where it is."""
    scene = _scene_copy(tmp / "scene.yaml", camera_in_flange={"xyz": [0.0, 0.05, 0.08], "rpy": [90.0, 0.0, 90.0]})
    q, T = ctx[RX90]
    p = write_measured_poses(tmp / "m.yaml", scene.name, [f"p{i:03d}" for i in range(N)], q, T, "T_cam_target",
                             units={"length": "mm", "angle": "deg"}, sigmas=np.tile([ST] * 3 + [SR] * 3, (N, 1)))
    return _run(p, tmp), failed_without_model


def latin1(which):
    def build(tmp, ctx):
        p = _mp(tmp, ctx)
        f = p.with_suffix(".csv") if which == "csv" else p
        b = f.read_bytes()
        f.write_bytes(b.replace(b"pose_id", b"pose_id\xe9", 1) if which == "csv" else b + b"# caf\xe9\n")
        return _run(p, tmp), None
    return build


def named_path(value, link=False, allow=False):
    """The YAML's ``csv:`` (the files in tmp/data) set to ``value`` (a symlink to it when ``link``)."""
    def build(tmp, ctx):
        (tmp / "data").mkdir()
        p = _mp(tmp, ctx, name="data/m.yaml")
        target = value.replace("{tmp}", str(tmp))
        if "{tmp}" in value:
            (tmp / "elsewhere").mkdir(exist_ok=True)
            shutil.copyfile(p.with_suffix(".csv"), target)
        if link:
            (tmp / "data" / "link.csv").symlink_to(target)
            target = "link.csv"
        p.write_text(p.read_text().replace("csv: m.csv", f"csv: {target}"))
        return _run(p, tmp, *(["--allow-path", tmp / "elsewhere"] if allow else [])), _model_written if allow else None
    return build


def scene_outside(tmp, ctx):
    scene = _scene_copy(tmp / "elsewhere" / "scene.yaml")
    (tmp / "data").mkdir()
    q, T = ctx[RX90]
    p = write_measured_poses(tmp / "data" / "m.yaml", scene, [f"p{i:03d}" for i in range(N)], q, T, "T_cam_target",
                             units={"length": "mm", "angle": "deg"}, sigmas=np.tile([ST] * 3 + [SR] * 3, (N, 1)))
    return _run(p, tmp), None


def sigma_cell(value, column="sigma_x", row=1):
    def build(tmp, ctx):
        p = _mp(tmp, ctx)

        def edit(rows):
            rows[row + 1][rows[0].index(column)] = value
            return rows
        _edit_csv(p.with_suffix(".csv"), edit)
        return _run(p, tmp), None
    return build


def cov_not_pd(tmp, ctx):
    q, T = ctx[RX90]
    C = np.tile(np.diag([ST**2] * 3 + [SR**2] * 3), (N, 1, 1))
    C[5, 0, 1] = C[5, 1, 0] = 2 * ST**2  # correlation 2
    return _run(_mp(tmp, ctx, sigmas=None, cov=C), tmp), None


def duplicated_rows(tmp, ctx):
    p = _mp(tmp, ctx)
    _edit_csv(p.with_suffix(".csv"), lambda rows: rows + [[f"copy{k}"] + rows[k + 1][1:] for k in range(5)])

    def check(tmp):
        rep = json.loads((tmp / "out" / "report.json").read_text())
        return (_model_written(tmp) and rep["measurements"]["n_valid"] == N  # the copies counted once (issue 28)
                and any("copies of another pose" in w and "copy4 = p004" in w for w in rep["warnings"]))
    return _run(p, tmp), check


def out_into_input(where):
    def build(tmp, ctx):
        p = _mp(tmp, ctx)
        return ["process-poses", str(p), "--out", str(tmp if where == "folder" else p)], None
    return build


# ----------------------------------------------------------------------------- recordings (process)
def _rec(tmp, ctx) -> Path:
    rec = tmp / "rec"
    shutil.copytree(ctx["rec"], rec, symlinks=True)
    return rec


def process_out(rel):
    def build(tmp, ctx):
        rec = _rec(tmp, ctx)
        return ["process", str(rec), "--out", str(rec / rel if rel else rec), "--no-plots"], None
    return build


def recording_key(key, value):
    def build(tmp, ctx):
        rec = _rec(tmp, ctx)
        (tmp / "elsewhere").mkdir()
        if key == "scene":
            value_ = str(_scene_copy(tmp / "elsewhere" / "scene.yaml"))
        else:
            value_ = value
        doc = yaml.safe_load((rec / "recording.yaml").read_text())
        doc[key] = value_
        if key == "camera_file":
            doc.pop("camera")
        (rec / "recording.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
        return ["process", str(rec), "--out", str(tmp / "out"), "--no-plots"], None
    return build


# ----------------------------------------------------------------------------- ROS-I, targets, ViSP, cameras
def _rosi(d: Path, n=3) -> Path:
    """A ROS-I data set like examples/data/test_set_charuco (static camera, DICT_6X6_250 = 10), tiny images."""
    (d / "images").mkdir(parents=True)
    (d / "poses").mkdir()
    data = []
    for i in range(n):
        cv2.imwrite(str(d / "images" / f"{i}.png"), np.full((48, 64), 100 + i, np.uint8))
        q = np.array([0.1 * i, -0.2, 0.3, 0.9]) / np.linalg.norm([0.1 * i, -0.2, 0.3, 0.9])
        (d / "poses" / f"{i}.yaml").write_text(yaml.safe_dump({"x": 0.1 * i, "y": -0.5, "z": 0.8, "qw": float(q[3]),
                                                               "qx": float(q[0]), "qy": float(q[1]), "qz": float(q[2])}))
        data.append({"image": f"images/{i}.png", "pose": f"poses/{i}.yaml"})
    doc = {"data": data, "intrinsics": {"fx": 60.0, "fy": 61.0, "cx": 32.0, "cy": 24.0}, "static_camera": True,
           "target_finder": {"type": "CharucoGridTargetFinder", "rows": 7, "cols": 5, "chessboard_dim": 0.036195,
                             "aruco_marker_dim": 0.018256, "dictionary": 10}}
    (d / "cal_data.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return d


def rosi_dst(rel):
    def build(tmp, ctx):
        src = _rosi(tmp / "rosi")
        return ["import-rosi", str(src), str(src / rel if rel else src)], None
    return build


def rosi_image(how):
    def build(tmp, ctx):
        src = _rosi(tmp / "rosi")
        shutil.move(str(src / "images" / "1.png"), str(tmp / "outside.png"))
        if how == "link":
            (src / "images" / "1.png").symlink_to(tmp / "outside.png")
        else:
            doc = yaml.safe_load((src / "cal_data.yaml").read_text())
            doc["data"][1]["image"] = "../outside.png"
            (src / "cal_data.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
        return ["import-rosi", str(src), str(tmp / "rec")], None
    return build


def rosi_latin1(tmp, ctx):
    src = _rosi(tmp / "rosi")
    (src / "cal_data.yaml").write_bytes((src / "cal_data.yaml").read_bytes() + b"# caf\xe9\n")
    return ["import-rosi", str(src), str(tmp / "rec")], None


def huge_target(tmp, ctx):
    (tmp / "t.yaml").write_text(yaml.safe_dump({"name": "huge", "kind": "modified_circle_grid", "rows": 10000,
                                                "cols": 10000, "spacing_m": 1e-4, "diameter_m": 5e-5}))
    return ["target", str(tmp / "t.yaml"), "--out", str(tmp / "t.png"), "--dpi", "1"], None


def visp_folder(d: Path, image: np.ndarray) -> Path:
    """A ViSP eye-to-hand folder ``d``: camera.xml (320x240, px = py = 300, no distortion), three pose_fPe_N.yaml
    (theta-u poses) and three image-N.png of ``image``."""
    d.mkdir()
    (d / "camera.xml").write_text(
        "<root><camera><name>Camera</name><image_width>320</image_width><image_height>240</image_height>"
        "<model><type>perspectiveProjWithoutDistortion</type><px>300</px><py>300</py><u0>160</u0><v0>120</v0>"
        "</model></camera></root>")
    for i in range(1, 4):
        (d / f"pose_fPe_{i}.yaml").write_text("rows: 6\ncols: 1\ndata:\n" + "".join(
            f"  - [{v}]\n" for v in (0.3, 0.1 * i, 0.5, 0.0, 0.1 * i, 0.0)))
        cv2.imwrite(str(d / f"image-{i}.png"), image)
    return d


def visp_chessboard(size):
    def build(tmp, ctx):
        img = np.full((240, 320), 255, np.uint8)
        for r in range(7):  # 9 x 6 inner corners: 10 x 7 squares of 20 px, the long side along the image width
            for c in range(10):
                if (r + c) % 2 == 0:
                    img[40 + r * 20:60 + r * 20, 40 + c * 20:60 + c * 20] = 0
        d = visp_folder(tmp / "visp", cv2.GaussianBlur(img, (3, 3), 0.8))
        return ["import-visp", str(d), "--out", str(tmp / "rec"), "--chessboard", size, "--square-m", "0.02"], \
            (lambda tmp: (tmp / "rec" / "recording.yaml").is_file())
    return build


def copied_views(tmp, ctx):
    imgs = tmp / "imgs"
    imgs.mkdir()
    for k in range(10):
        shutil.copyfile(ctx["rec"] / "images" / "000" / "00.png", imgs / f"{k:02d}.png")
    return ["calibrate-camera", str(imgs), "--target", str(REPO / "targets" / "charuco_a5.yaml"), "--out",
            str(tmp / "cam.yaml")], None


def camera_out_in_images(tmp, ctx):
    imgs = tmp / "imgs"
    imgs.mkdir()
    return ["calibrate-camera", str(imgs), "--target", str(REPO / "targets" / "charuco_a5.yaml"), "--out",
            str(imgs / "cam.yaml")], None


ERR, OK, WARN = "error", "correct", "warned"
FITS = r"-- this fits"

CASES = [
    # --- clean files: the scenes keep passing the new tests
    ("mp-rx90-clean", clean(RX90), OK, None),
    ("mp-ur5e-clean", clean(UR5E), OK, None),
    # --- gross misfits: exit 3, report kept, no model, the refit that fits named
    ("mp-direction-reversed", reversed_direction, ERR,
     r"far beyond the noise model: chi2/dof .*the rows read as T_target_cam \(measured: direction reversed\): "
     r"chi2/dof \S+ " + FITS),
    ("mp-columns-x-y-swapped", swapped_columns("x", "y"), ERR, r"far beyond the noise model.*columns x and y swapped: chi2/dof \S+ " + FITS),
    ("mp-columns-y-z-swapped", swapped_columns("y", "z"), ERR, r"far beyond the noise model.*columns y and z swapped: chi2/dof \S+ " + FITS),
    ("mp-quaternion-scalar-first", scalar_first_quaternion, ERR, r"the quaternion written scalar first \(qw,qx,qy,qz\): chi2/dof \S+ " + FITS),
    # --- convention errors at a good fit: exit 3 naming the joint / mount
    ("mp-joint1-negated", joint_negated(1), ERR,
     r"more than any calibration correction: .*mount T_target_base rotated by 180.*joint 1's readings negated .*" + FITS),
    # (the fit from the nominal may also end in a local minimum: then a gross misfit, the same refit named)
    ("mp-joint3-negated", joint_negated(3), ERR, r"(more than any calibration correction|far beyond the noise model|"
     r"the model absorbed it).*"
     r"refitted on \d+ poses: joint 3's readings negated \(its sign reversed in the input\): chi2/dof \S+ -- this fits\."),
    # (or, from a solver that reaches the global minimum, a fit the model absorbed, the motion check naming it)
    ("mp-ur5e-joint2-negated", joint_negated(2, UR5E), ERR, r"(more than any calibration correction|far beyond the "
     r"noise model|the model absorbed it).*refitted on \d+ poses: joint 2's readings negated \(its sign reversed in the input\): chi2/dof \S+ "
     r"-- this fits\."),
    ("mp-camera-mount-turned", mount_turned, ERR, r"more than any calibration correction: .*mount T_flange_cam rotated by 90"),
    # --- text decoding: one decoder, named
    ("mp-csv-latin1", latin1("csv"), ERR, r"m.csv: line 1: not UTF-8 text \(byte 0xe9 at column 8\)"),
    ("mp-yaml-latin1", latin1("yaml"), ERR, r"m.yaml: line \d+: not UTF-8 text \(byte 0xe9"),
    # --- paths named in files: inside the file's folder unless allowed
    ("mp-csv-etc-passwd", named_path("/etc/passwd"), ERR, r"m.yaml: csv: '/etc/passwd': /etc/passwd is outside the folder"),
    ("mp-csv-dotdot", named_path("../../../../../../etc/passwd"), ERR, r"csv: '(\.\./)+etc/passwd': /etc/passwd is outside the folder"),
    ("mp-csv-symlink-out", named_path("{tmp}/elsewhere/m.csv", link=True), ERR, r"csv: 'link.csv': a symbolic link leading out of the folder .*data \(to .*elsewhere/m.csv\)"),
    ("mp-csv-outside-allowed", named_path("{tmp}/elsewhere/m.csv", allow=True), OK, None),
    ("mp-scene-outside", scene_outside, ERR, r"m.yaml: scene: '.*elsewhere/scene.yaml': .* is outside the folder .*--allow-path"),
    # --- sigmas, covariances: file, line and pose id; no numpy warning
    ("mp-sigma-1e-300", sigma_cell("1e-300"), ERR, r"m.csv: line 3 \(pose 'p001'\): column sigma_x: std 1e-300 mm is outside the plausible"),
    ("mp-sigma-1e300", sigma_cell("1e300"), ERR, r"m.csv: line 3 \(pose 'p001'\): column sigma_x: std 1e\+300 mm is outside"),
    ("mp-sigma-rz-1e-30", sigma_cell("1e-30", "sigma_rz", 7), ERR, r"line 9 \(pose 'p007'\): column sigma_rz: std 1e-30 deg"),
    ("mp-cov-not-pd", cov_not_pd, ERR, r"m.csv: line 7 \(pose 'p005'\): cov_\* columns: covariance is not positive definite"),
    ("mp-duplicated-rows", duplicated_rows, OK, None),
    # --- outputs never into inputs
    ("mp-out-is-input-folder", out_into_input("folder"), ERR, r"--out .*: is the folder of the input file .*m.yaml"),
    ("mp-out-is-input-file", out_into_input("file"), ERR, r"--out .*m.yaml: is the input file"),
    ("rec-out-inside", process_out("out"), ERR, r"--out .*rec/out: lies inside the input folder .*rec"),
    ("rec-out-is-rec", process_out(""), ERR, r"--out .*rec: is the input folder"),
    ("rec-out-in-pose-frames", process_out("images/000"), ERR, r"--out .*rec/images/000: lies inside the input folder"),
    ("rec-camera_file-etc", recording_key("camera_file", "/etc/passwd"), ERR, r"recording.yaml: camera_file: '/etc/passwd': /etc/passwd is outside"),
    ("rec-scene-outside", recording_key("scene", None), ERR, r"recording.yaml: scene: .*elsewhere/scene.yaml.* is outside the folder"),
    ("rosi-dst-is-src", rosi_dst(""), ERR, r"DST .*rosi: is the input folder"),
    ("rosi-dst-inside-src", rosi_dst("rec"), ERR, r"DST .*rosi/rec: lies inside the input folder"),
    ("calib-out-in-images", camera_out_in_images, ERR, r"--out .*imgs/cam.yaml: lies inside the input folder"),
    # --- ROS-I paths and bytes
    ("rosi-image-dotdot", rosi_image("dotdot"), ERR, r"outside.png is outside the folder .*rosi"),
    ("rosi-image-symlink", rosi_image("link"), ERR, r"images/1.png: a symbolic link leading out of the folder"),
    ("rosi-latin1", rosi_latin1, ERR, r"cal_data.yaml: line \d+: not UTF-8 text"),
    # --- targets, ViSP, cameras
    ("target-1e8-dots", huge_target, ERR, r"t.yaml: target 'huge': keys 'rows' x 'cols' = 10000 x 10000 = 1e\+08 features"),
    ("visp-chessboard-9x6", visp_chessboard("9x6"), OK, None),
    ("visp-chessboard-transposed", visp_chessboard("6x9"), WARN, r"warning: .*--chessboard 6x9: the rows of 6 inner corners run along the image height.*9x6\?"),
    ("calib-copied-views", copied_views, ERR, r"rejected: .*01.png: the same corners as view .*00.png \(a copy of that image\)"),
]
