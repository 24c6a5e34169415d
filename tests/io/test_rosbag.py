"""`vision-calib import-bag`: ROS 1 / ROS 2 bags written with rosbags' own writers from the shipped example
recording (joint states at 50 Hz moving between its poses and standing still at each while its image is
published) import to a recorded folder that `process` turns into the same result as the example folder itself;
damaged bags give named errors (exit 2)."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

pytest.importorskip("rosbags")

from rosbags.typesys import Stores, get_typestore  # noqa: E402

from vision_calib.cli import main  # noqa: E402
from vision_calib.errors import DataError  # noqa: E402
from vision_calib.io.rosbag import StillSettings, import_bag, standstills  # noqa: E402
from vision_calib.shipped import examples_dir  # noqa: E402

EXAMPLE = examples_dir() / "rx90_eye_in_hand"
SCENE = EXAMPLE / "scene" / "rx90_eye_in_hand.yaml"
RATE_HZ = 50
STILL_S = 1.0
MOVE_S = 1.0
T0_NS = 1_700_000_000 * 10**9


def example_poses():
    with open(EXAMPLE / "poses.csv", newline="") as f:
        rows = list(csv.reader(f))
    ids = [r[0] for r in rows[1:]]
    return ids, np.array([[float(v) for v in r[1:]] for r in rows[1:]])


def timeline(q):
    """(stamps ns, joints) at RATE_HZ: still STILL_S at each pose, smooth (cosine) moves of MOVE_S between them;
    and the stamp of the middle of each standstill (where its image is published)."""
    dt = 1.0 / RATE_HZ
    ts, rows, mids, t = [], [], [], 0.0
    for i, qi in enumerate(q):
        n = int(round(STILL_S * RATE_HZ))
        for k in range(n):
            ts.append(t + k * dt)
            rows.append(qi)
        mids.append(t + STILL_S / 2)
        t += n * dt
        if i + 1 < len(q):
            m = int(round(MOVE_S * RATE_HZ))
            for k in range(m):
                s = 0.5 * (1 - np.cos(np.pi * (k + 1) / (m + 1)))
                ts.append(t + k * dt)
                rows.append(qi + s * (q[i + 1] - qi))
            t += m * dt
    ns = lambda x: T0_NS + int(round(x * 1e9))  # noqa: E731
    return [ns(x) for x in ts], np.array(rows), [ns(x) for x in mids]


class BagWriter:
    """rosbags' writers behind one interface: kind 'ros1' (.bag), 'ros2' (sqlite3 folder), 'mcap' (ROS 2 mcap)."""

    def __init__(self, path: Path, kind: str):
        self.kind = kind
        if kind == "ros1":
            from rosbags.rosbag1 import Writer

            self.ts = get_typestore(Stores.ROS1_NOETIC)
            self.w = Writer(path)
        else:
            from rosbags.rosbag2 import StoragePlugin, Writer

            self.ts = get_typestore(Stores.ROS2_HUMBLE)
            self.w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP if kind == "mcap" else
                            StoragePlugin.SQLITE3)
        self.conns, self.msgs = {}, []

    def header(self, t_ns):
        T = self.ts.types
        stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        if self.kind == "ros1":
            return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="cam")
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id="cam")

    def add(self, topic, msgtype, t_ns, msg, log_ns=None):
        self.msgs.append((log_ns if log_ns is not None else t_ns, topic, msgtype, msg))

    def joints(self, topic, t_ns, names, q, log_ns=None):
        T = self.ts.types
        self.add(topic, "sensor_msgs/msg/JointState", t_ns, T["sensor_msgs/msg/JointState"](
            header=self.header(t_ns), name=list(names), position=np.asarray(q, float),
            velocity=np.zeros(0), effort=np.zeros(0)), log_ns)

    def compressed(self, topic, t_ns, data: bytes, fmt="jpeg"):
        T = self.ts.types
        self.add(topic, "sensor_msgs/msg/CompressedImage", t_ns, T["sensor_msgs/msg/CompressedImage"](
            header=self.header(t_ns), format=fmt, data=np.frombuffer(data, np.uint8)))

    def raw(self, topic, t_ns, img: np.ndarray, encoding: str):
        T = self.ts.types
        data = img.astype(img.dtype.newbyteorder("<")).tobytes() if img.dtype.itemsize > 1 else img.tobytes()
        h, w = img.shape[:2]
        self.add(topic, "sensor_msgs/msg/Image", t_ns, T["sensor_msgs/msg/Image"](
            header=self.header(t_ns), height=h, width=w, encoding=encoding, is_bigendian=0,
            step=len(data) // h, data=np.frombuffer(data, np.uint8)))

    def camera_info(self, topic, t_ns, cam: dict, model="plumb_bob"):
        T = self.ts.types
        K = np.array([cam["fx"], 0, cam["cx"], 0, cam["fy"], cam["cy"], 0, 0, 1], float)
        D = np.array(cam["dist"], float)
        roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        arrays = {"d": D, "k": K, "r": np.eye(3).ravel(), "p": np.zeros(12)}
        if self.kind == "ros1":
            arrays = {k.upper(): v for k, v in arrays.items()}
        self.add(topic, "sensor_msgs/msg/CameraInfo", t_ns, T["sensor_msgs/msg/CameraInfo"](
            header=self.header(t_ns), height=cam["height"], width=cam["width"], distortion_model=model,
            binning_x=0, binning_y=0, roi=roi, **arrays))

    def close(self):
        with self.w as w:
            for t, topic, msgtype, msg in sorted(self.msgs, key=lambda m: m[0]):
                if topic not in self.conns:
                    self.conns[topic] = w.add_connection(topic, msgtype, typestore=self.ts)
                ser = self.ts.serialize_ros1 if self.kind == "ros1" else self.ts.serialize_cdr
                w.write(self.conns[topic], t, ser(msg, msgtype))


def write_example_bag(path: Path, kind: str, images: str = "jpeg", names=None, camera_info=True, frames=1,
                      moving_image=True, edit=None) -> Path:
    """A bag of the example recording (module docstring). images: 'jpeg' (the original bytes as
    CompressedImage) or a raw encoding (mono8, bgr8, rgb8, mono16); names: the JointState names (default q1..q6,
    shuffled order and an extra gripper joint when given); frames: images per standstill; moving_image: one more
    image mid-move (to be dropped); edit(writer, stamps, Q) changes the messages before writing."""
    ids, q = example_poses()
    stamps, Q, mids = timeline(q)
    bw = BagWriter(path, kind)
    names = names or [f"q{j + 1}" for j in range(q.shape[1])]
    perm = [2, 0, 5, 1, 4, 3] if names[0] != "q1" else list(range(q.shape[1]))
    for t, row in zip(stamps, Q):
        bw.joints("/joint_states", t, [names[j] for j in perm] + (["gripper"] if names[0] != "q1" else []),
                  list(row[perm]) + ([0.01] if names[0] != "q1" else []))
    cam = yaml.safe_load((EXAMPLE / "recording.yaml").read_text())["camera"]
    if camera_info:
        for t in stamps[::25]:
            bw.camera_info("/camera/camera_info", t, cam)
    for pid, t in zip(ids, mids):
        data = (EXAMPLE / "images" / pid / "00.jpg").read_bytes()
        for f in range(frames):
            tf = t + f * 100_000_000
            if images == "jpeg":
                bw.compressed("/camera/image/compressed", tf, data)
            else:
                grey = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
                img = {"mono8": grey, "bgr8": cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR),
                       "rgb8": cv2.cvtColor(grey, cv2.COLOR_GRAY2RGB), "mono16": grey.astype(np.uint16) << 8}[images]
                bw.raw("/camera/image_raw", tf, img, images)
    if moving_image:  # mid-way between the first two poses: the robot moves
        t = mids[0] + int((STILL_S / 2 + MOVE_S / 2) * 1e9)
        data = (EXAMPLE / "images" / ids[1] / "00.jpg").read_bytes()
        if images == "jpeg":
            bw.compressed("/camera/image/compressed", t, data)
        else:
            bw.raw("/camera/image_raw", t, cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED), "mono8")
    if edit is not None:
        edit(bw, stamps, Q)
    bw.close()
    return path


def image_topic(images):
    return "/camera/image/compressed" if images == "jpeg" else "/camera/image_raw"


def _params(report):
    return np.array([p["identified"] for p in report["parameters"]], float)


@pytest.fixture(scope="module")
def example_result(tmp_path_factory):
    from vision_calib.experiment.process import process_folder

    return process_folder(EXAMPLE, tmp_path_factory.mktemp("example_out"), plots=False)


def _same_folder_content(folder: Path):
    """The imported folder holds the example's poses (joints bit-identical) and pixels (identical)."""
    ids, q = example_poses()
    with open(folder / "poses.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["pose_id"] + [f"q{j + 1}" for j in range(6)]
    got = np.array([[float(v) for v in r[1:]] for r in rows[1:]])
    assert got.shape == q.shape and np.array_equal(got, q)
    for k, pid in enumerate(ids):
        files = sorted((folder / "images" / f"{k:03d}").iterdir())
        orig = cv2.imread(str(EXAMPLE / "images" / pid / "00.jpg"), cv2.IMREAD_UNCHANGED)
        for f in files:
            img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
            if img.ndim == 3:
                img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
            if img.dtype == np.uint16:
                img = (img >> 8).astype(np.uint8)
            assert np.array_equal(img, orig), f


@pytest.mark.parametrize("kind", ["ros2", "ros1"])
def test_bag_of_the_example_processes_like_the_example(tmp_path, kind, example_result):
    """ROS 2 (sqlite3, shuffled JointState names + a gripper joint, --joint-names, CameraInfo) and ROS 1 (q1..q6,
    no camera info: the cell's camera): the imported folder's `process` result equals the example's to 1e-9."""
    from vision_calib.experiment.process import process_folder

    ros2 = kind == "ros2"
    names = [f"joint_{j + 1}" for j in range(6)] if ros2 else None
    bag = write_example_bag(tmp_path / ("bag" if ros2 else "rec.bag"), kind, names=names, camera_info=ros2)
    res = import_bag(bag, SCENE, "/camera/image/compressed", "/joint_states", tmp_path / "rec",
                     camera_info_topic="/camera/camera_info" if ros2 else None, joint_names=names)
    assert res.frames == (1,) * 12 and res.n_images == 13 and res.n_moving == 1
    assert res.camera_source.startswith("camera info" if ros2 else "the cell's camera")
    _same_folder_content(tmp_path / "rec")
    rep = process_folder(tmp_path / "rec", tmp_path / "out", plots=False)
    assert rep["verdict"]["converged"] and rep["verdict"]["status"] == example_result["verdict"]["status"]
    a, b = _params(rep), _params(example_result)
    assert a.shape == b.shape and np.max(np.abs(a - b)) < 1e-9, np.max(np.abs(a - b))
    sa = np.array([p["std"] or 0.0 for p in rep["parameters"]])
    sb = np.array([p["std"] or 0.0 for p in example_result["parameters"]])
    assert np.max(np.abs(sa - sb)) < 1e-9


@pytest.mark.parametrize("encoding", ["mono8", "bgr8", "rgb8", "mono16"])
def test_raw_images_decode_to_the_original_pixels(tmp_path, encoding):
    """Raw sensor_msgs/Image in every supported encoding, 2 frames per standstill, an MCAP bag for mono8 (ROS 2
    .db3 otherwise): the folder holds the example's joints and pixels, frames_per_pose 2."""
    kind = "mcap" if encoding == "mono8" else "ros2"
    bag = write_example_bag(tmp_path / "bag", kind, images=encoding, frames=2)
    if kind == "mcap":
        bag = next(bag.glob("*.mcap"))  # the storage file alone is a bag too
    res = import_bag(bag, SCENE, "/camera/image_raw", "/joint_states", tmp_path / "rec",
                     camera_info_topic="/camera/camera_info")
    assert res.frames == (2,) * 12 and res.n_moving == 1
    _same_folder_content(tmp_path / "rec")
    assert yaml.safe_load((tmp_path / "rec" / "recording.yaml").read_text())["frames_per_pose"] == 2
    from vision_calib.io.recording import read_recording

    rec = read_recording(tmp_path / "rec")
    assert len(rec.pose_ids) == 12 and all(len(rec.images[p]) == 2 for p in rec.pose_ids)


def test_cli_import_bag_writes_a_folder_process_reads(tmp_path, capsys):
    bag = write_example_bag(tmp_path / "rec.bag", "ros1")
    assert main(["import-bag", str(bag), "--scene", str(SCENE), "--image-topic", "/camera/image/compressed",
                 "--joints-topic", "/joint_states", "--out", str(tmp_path / "rec")]) == 0
    assert "12 poses" in capsys.readouterr().out
    doc = yaml.safe_load((tmp_path / "rec" / "recording.yaml").read_text())
    assert doc["poses"] == "joints" and doc["camera_mount"] == "eye_in_hand" and doc["source"].startswith("import-bag")
    assert (tmp_path / "rec" / doc["scene"]).is_file()


def test_standstills_of_a_smooth_motion():
    """One pose per standstill, its joints exactly the still value; a slow creep above the speed is no pose."""
    ids, q = example_poses()
    stamps, Q, mids = timeline(q[:3])
    st = standstills(np.array(stamps), Q, StillSettings())
    assert len(st) == 3
    for s, m, qi in zip(st, mids, q[:3]):
        assert s.t0_ns <= m <= s.t1_ns and np.array_equal(s.joints, qi)
        assert (s.t1_ns - s.t0_ns) * 1e-9 >= STILL_S - 0.1
    creep = Q.copy()
    creep[:, 0] += 0.002 * (np.array(stamps) - stamps[0]) * 1e-9  # 2 mrad/s: above the default 1 mrad/s
    assert standstills(np.array(stamps), creep, StillSettings()) == []
    assert len(standstills(np.array(stamps), creep, StillSettings(speed=0.005))) == 3


# ------------------------------------------------------------------------------------------ damaged bags
def _run(tmp_path, bag, *extra):
    return main(["import-bag", str(bag), "--scene", str(SCENE), "--image-topic", "/camera/image/compressed",
                 "--joints-topic", "/joint_states", "--out", str(tmp_path / "rec"), *extra])


def _backwards(bw, stamps, Q):  # a joint state stamped 5 s in the past, logged in order
    bw.joints("/joint_states", stamps[300] - 5 * 10**9, [f"q{j + 1}" for j in range(6)], Q[300], log_ns=stamps[300] + 1)


def _gap(bw, stamps, Q):  # 3 s of joint states lost
    bw.msgs = [m for m in bw.msgs if not (m[1] == "/joint_states" and stamps[200] < m[0] < stamps[200] + 3 * 10**9)]


def _bayer(bw, stamps, Q):
    bw.raw("/camera/image_raw", stamps[10], np.zeros((480, 640), np.uint8), "bayer_rggb8")


def _never_still(bw, stamps, Q):  # the joint states creep all along (5 mrad/s on joint 1)
    for k, m in enumerate(bw.msgs):
        if m[1] == "/joint_states":
            m[3].position[0] += 0.005 * (m[0] - stamps[0]) * 1e-9


@pytest.mark.parametrize("case, edit, extra, message", [
    ("missing topic", None, ["--image-topic", "/cam/img"],
     "image topic '/cam/img' is not in the bag; topics present: /camera/camera_info (sensor_msgs/msg/CameraInfo), "
     "/camera/image/compressed (sensor_msgs/msg/CompressedImage), /joint_states (sensor_msgs/msg/JointState)"),
    ("wrong type", None, ["--joints-topic", "/camera/camera_info"],
     "topic '/camera/camera_info' holds sensor_msgs/msg/CameraInfo, expected sensor_msgs/msg/JointState"),
    ("time backwards", _backwards, [], "topic '/joint_states': time goes backwards at message"),
    ("gap", _gap, [], "topic '/joint_states': gap of 3."),
    ("no standstill", _never_still, [], "no standstill with an image: 0 standstills"),
    ("joint names", None, ["--joint-names", "a1,a2,a3,a4,a5,a6"],
     "no message names the cell's joints a1, a2, a3, a4, a5, a6; the bag's joint names are q1, q2, q3, q4, q5, q6"),
    ("joint count", None, ["--joint-names", "q1,q2"], "--joint-names: 2 names (q1, q2) for the cell's 6 joints"),
    ("encoding", _bayer, ["--image-topic", "/camera/image_raw"],
     "image encoding 'bayer_rggb8' not supported (supported: mono8, bgr8, rgb8, mono16"),
])
def test_damaged_bags_are_named(tmp_path, capsys, case, edit, extra, message):
    """Each damage gives exit 2 and one line naming the bag, the topic and what is wrong."""
    bag = write_example_bag(tmp_path / "rec.bag", "ros1", edit=edit, moving_image=False)
    assert _run(tmp_path, bag, *extra) == 2
    err = capsys.readouterr().err.strip()
    named = "" if case == "joint count" else f"{bag}: "  # an option error names the option
    assert err.startswith(f"vision-calib: error: {named}") and message in err, err
    assert len(err.splitlines()) == 1


def test_partial_joint_names_and_unknown_compressed_format_are_named(tmp_path):
    def partial(bw, stamps, Q):  # one message lacks q6
        bw.joints("/joint_states", stamps[100] + 1, [f"q{j + 1}" for j in range(5)], Q[100, :5])

    bag = write_example_bag(tmp_path / "a.bag", "ros1", edit=partial)
    with pytest.raises(DataError, match=r"joint\(s\) q6 missing \(the message names q1, q2, q3, q4, q5"):
        import_bag(bag, SCENE, "/camera/image/compressed", "/joint_states", tmp_path / "r1")

    def tiff(bw, stamps, Q):
        bw.compressed("/camera/image/compressed", stamps[5], b"II*\x00", fmt="tiff")

    bag = write_example_bag(tmp_path / "b.bag", "ros1", edit=tiff)
    with pytest.raises(DataError, match="compressed image format 'tiff' not supported"):
        import_bag(bag, SCENE, "/camera/image/compressed", "/joint_states", tmp_path / "r2")
    with pytest.raises(DataError, match="bag not found"):
        import_bag(tmp_path / "none.bag", SCENE, "/x", "/y", tmp_path / "r3")
    (tmp_path / "junk.bag").write_bytes(b"not a bag")
    with pytest.raises(DataError, match="not a readable ROS bag"):
        import_bag(tmp_path / "junk.bag", SCENE, "/x", "/y", tmp_path / "r4")


def test_urdf_cells_name_their_joints():
    from vision_calib.rig import load_scene

    setup = load_scene("ur5e_eye_in_hand.yaml").setup
    assert setup.joint_names() == ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
                                   "wrist_2_joint", "wrist_3_joint")
    assert load_scene(SCENE).setup.joint_names() == tuple(f"q{j + 1}" for j in range(6))


def test_a_tolerance_that_merges_motion_is_named(tmp_path, capsys):
    """--still-speed 1e9 makes the whole bag one standstill: exit 2 naming the standstill, the joint and the
    setting (it was one pose of median joints, exit 0, no warning); at the default the same bag imports."""
    bag = write_example_bag(tmp_path / "rec.bag", "ros1", moving_image=False)
    assert _run(tmp_path, bag, "--still-speed", "1e9") == 2
    err = capsys.readouterr().err
    _, Q, _ = timeline(example_poses()[1])
    span = Q.max(axis=0) - Q.min(axis=0)  # the one standstill spans the whole motion
    assert f"spans {span.max():.4g} on joint q{int(np.argmax(span)) + 1}" in err, err
    assert "standstill 0 (" in err and "the robot moved during it" in err and "lower --still-speed" in err
    assert "--still-speed 1e+09 x --still-window 0.5 s" in err


def test_too_few_standstills_in_a_moving_bag_are_noted():
    """Two standstills in joint states that move: a note naming the settings; three: none."""
    from vision_calib.io.rosbag import check_standstills

    _, q = example_poses()
    names = [f"q{j + 1}" for j in range(6)]
    for n, noted in ((2, True), (3, False)):
        stamps, Q, _ = timeline(q[:n])
        st = standstills(np.array(stamps), Q, StillSettings())
        note = check_standstills(st, np.array(stamps), Q, names, StillSettings(), "b.bag")
        assert (note is not None) == noted, note
        if noted:
            assert note.startswith("only 2 standstill(s) in a bag whose joints move up to") and "--still-speed" in note


def _png_declaring(width: int, height: int) -> bytes:
    """A grey PNG whose header declares width x height px with almost no pixel data."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\x00" * 16))
            + chunk(b"IEND", b""))


@pytest.mark.parametrize("first, message", [
    (lambda: _png_declaring(30000, 30000), "message 0 (stamp {t}): image 30000x30000 px (900 Mpx) exceeds the limit"),
    (lambda: cv2.imencode(".png", np.zeros((600, 800), np.uint8))[1].tobytes(),
     "message 0 (stamp {t}): image size 800x600 px, but the intrinsics (camera info /camera/camera_info (K, D)) are "
     "for 640x480"),
])
def test_image_sizes_read_from_headers_before_decoding(tmp_path, capsys, first, message):
    """The first image of the first standstill declares 30000 x 30000 px (a 69-byte PNG: refused from its header,
    nothing decoded) or is 800 x 600: the odd image is the one named, against the intrinsics' size (the bag's
    other images, 640 x 480, are not blamed)."""
    data = first()
    stamp = {}

    def odd_first(bw, stamps, Q):
        stamp["t"] = stamps[20]  # 0.4 s into the first standstill, before its own image
        bw.compressed("/camera/image/compressed", stamps[20], data, fmt="png")

    bag = write_example_bag(tmp_path / "rec.bag", "ros1", edit=odd_first, moving_image=False)
    assert _run(tmp_path, bag, "--camera-info-topic", "/camera/camera_info") == 2
    err = capsys.readouterr().err
    assert message.format(t=f"{stamp['t'] * 1e-9:.6f} s") in err, err


def test_image_message_beyond_the_pixel_limit_refused_before_deserializing(tmp_path, capsys, monkeypatch):
    """With the pixel limit at 0.01 Mpx, a raw 640 x 480 bgr8 message (0.92 MB) is longer than any image within it
    may take (0.01 Mpx x 6 bytes + 64 kB): refused from its length, naming the message, before it is
    deserialized."""
    monkeypatch.setenv("VISION_CALIB_MAX_IMAGE_MPX", "0.01")
    bag = write_example_bag(tmp_path / "rec.bag", "ros1", images="bgr8", moving_image=False)
    assert main(["import-bag", str(bag), "--scene", str(SCENE), "--image-topic", "/camera/image_raw",
                 "--joints-topic", "/joint_states", "--out", str(tmp_path / "rec")]) == 2
    err = capsys.readouterr().err
    assert "topic '/camera/image_raw' message 0: 0.92" in err
    assert "MB, more than any image within the pixel limit" in err


def test_ros2_metadata_alias_tree_refused_before_rosbags_reads_it(tmp_path, capsys):
    """A ROS 2 bag folder whose metadata.yaml holds an alias tree (read by rosbags' own YAML loader): refused by
    ours first, naming the file (config.BoundedLoader)."""
    bag = write_example_bag(tmp_path / "b2", "ros2", moving_image=False)
    meta = bag / "metadata.yaml"
    tree = "[&a0 [" + ", ".join(['"x"'] * 9) + "]" + "".join(
        f", &a{k} [" + ", ".join([f"*a{k - 1}"] * 9) + "]" for k in range(1, 9)) + "]"
    meta.write_text(meta.read_text() + f"hostile: {tree}\n")
    assert _run(tmp_path, bag) == 2
    assert f"{meta}: invalid YAML in ROS 2 bag metadata (aliases expand beyond the limit" in capsys.readouterr().err
