"""A recorded folder from a ROS bag (``vision-calib import-bag``), read with the ``rosbags`` library (extra
``[ros]``): ROS 1 ``.bag``, ROS 2 folders (``metadata.yaml``), ``.db3`` and ``.mcap`` files; no ROS install.

Topics read:

- images: ``sensor_msgs/Image`` (encodings :data:`RAW_ENCODINGS`) or ``sensor_msgs/CompressedImage`` (jpeg, png);
  decoded to the pixels the bag holds (a JPEG exactly as OpenCV decodes the file) and written lossless as
  ``images/<pose_id>/<frame>.png``;
- joints: ``sensor_msgs/JointState``, values mapped by name to the cell's joint order
  (``rig.Setup.joint_names``: a URDF chain's joint names, ``q1..qn`` for an MDH robot, or ``joint_names``);
  positions in rad (revolute) or m (prismatic), as the recording's ``units: {length: m, angle: rad}``;
- intrinsics (optional): ``sensor_msgs/CameraInfo`` K and D (``plumb_bob``: k1, k2, p1, p2, k3); else the cell's.

Time: every message's ``header.stamp`` (the bag's log time for a topic whose first stamp is zero) in ns.

Standstills (:func:`standstills`): a joint-state sample is *still* when, over the samples within +-window/2 of
it, every joint's range (max - min) is at most ``speed x window`` (a mean speed below ``speed`` [rad/s or m/s]
over the window). A run of still samples is one pose: its interval spans the runs' windows, its joints are the
median of the samples in it. A tolerance so loose that a standstill spans motion (more than
:data:`MAX_STILL_SPAN` on a joint) is a DataError naming ``--still-speed``; fewer than 3 standstills in a bag
whose joints move, a note naming it (:func:`check_standstills`). An image whose stamp falls in a pose's interval
is a frame of that pose; other images (robot moving, or outside the joint-state span) are dropped and counted.
Each image's size is read from the message (a raw image's width and height, a compressed one's PNG / JPEG
header) before it is decoded, against the pixel limit and the intrinsics' size; a message longer than any image
within the limit is refused before it is deserialized.

Damaged bags (DataError naming the bag, the topic and the time or message; exit 2): a missing topic (the
topics present are listed), a topic of another message type, time going backwards or a gap longer than
``max_gap_s`` in the joint states or the images, joint names that do not match the cell's (the missing and the
present names given), an unsupported image encoding or an undecodable image, images of different sizes or of
another size than the intrinsics, no standstill with an image.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DataError, import_extra

#: raw ``sensor_msgs/Image`` encodings read: (numpy dtype, channels)
RAW_ENCODINGS = {"mono8": ("u1", 1), "bgr8": ("u1", 3), "rgb8": ("u1", 3), "mono16": ("u2", 1)}
#: compressed formats read (``sensor_msgs/CompressedImage.format`` names one of them; magic bytes checked)
COMPRESSED_FORMATS = {"jpeg": b"\xff\xd8", "jpg": b"\xff\xd8", "png": b"\x89PNG"}
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
JOINT_TYPE = "sensor_msgs/msg/JointState"
INFO_TYPE = "sensor_msgs/msg/CameraInfo"
#: fewest joint-state samples a standstill window must hold
MIN_WINDOW_SAMPLES = 3


@dataclass(frozen=True)
class StillSettings:
    """How standstills are found. speed: mean joint speed bound over the window [rad/s, m/s for prismatic
    joints]; window_s: the window [s] (also the shortest standstill); max_gap_s: longest silence of the joint
    or image topic [s] before the bag counts as damaged; max_frames: frames kept per pose (the first ones;
    None: all)."""

    speed: float = 1e-3
    window_s: float = 0.5
    max_gap_s: float = 1.0
    max_frames: int | None = None

    def __post_init__(self):
        for name in ("speed", "window_s", "max_gap_s"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise DataError(f"standstill setting {name} must be a finite number > 0, got {v}")
        if self.max_frames is not None and self.max_frames < 1:
            raise DataError(f"max_frames must be >= 1, got {self.max_frames}")


#: a standstill whose samples span more than this on one joint [rad, or m for a prismatic joint] holds motion:
#: the tolerance (``--still-speed`` x ``--still-window``) is too loose for the bag, and moving data would be merged
#: into one pose (a robot at rest holds its joints within a few encoder counts, ~1e-5 rad)
MAX_STILL_SPAN = 0.01


@dataclass(frozen=True)
class Standstill:
    """One pose: interval [t0_ns, t1_ns] of stamps, joints (n,) [rad, m] (median of its samples), n_samples,
    span (n,) [rad, m]: each joint's range (max - min) over its samples."""

    t0_ns: int
    t1_ns: int
    joints: np.ndarray
    n_samples: int
    span: np.ndarray | None = field(default=None, compare=False)


@dataclass(frozen=True)
class BagImport:
    """What :func:`import_bag` wrote: folder, frames per pose (pose ids ``000``...), standstills found (those
    without an image are not poses), images read / kept / dropped while moving, where the intrinsics come from,
    notes (also written to recording.yaml)."""

    folder: Path
    frames: tuple
    n_standstills: int
    n_images: int
    n_moving: int
    camera_source: str
    notes: tuple = field(default_factory=tuple)

    def summary(self) -> str:
        kept = sum(self.frames)
        return (f"wrote recorded folder {self.folder}: {len(self.frames)} poses, {kept} frames (of {self.n_images} "
                f"images; {self.n_moving} taken while the robot moved or outside the joint states, dropped), "
                f"{self.n_standstills} standstills; intrinsics: {self.camera_source}"
                + "".join(f"\nnote: {n}" for n in self.notes))


# ----------------------------------------------------------------------------------------------- the bag
def open_bag(path):
    """An open ``rosbags.highlevel.AnyReader`` on ``path`` (ROS 1 .bag; ROS 2 folder, .db3 or .mcap; close it, or
    use it in ``contextlib.closing``); DataError naming the path when it is missing or not a bag."""
    import_extra("rosbags", "ros", "reading ROS bags")
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: bag not found")
    meta = path / "metadata.yaml" if path.is_dir() else path.parent / "metadata.yaml"
    if path.suffix != ".bag" and meta.is_file():  # read by rosbags' own YAML loader: ours first (aliases bounded)
        from ..config import parse_yaml

        parse_yaml(meta, DataError, "ROS 2 bag metadata")
    ros1 = path.suffix == ".bag"
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE))
        reader.open()
        return reader
    except (AnyReaderError, FileNotFoundError, ValueError) as exc:
        raise DataError(f"{path}: not a readable ROS bag ({exc}); expected a ROS 1 .bag, a ROS 2 bag folder "
                        "(metadata.yaml), a .db3 or a .mcap file") from None


def topic_connections(reader, topic: str, types, bag, what: str) -> list:
    """The reader's connections of ``topic``; DataError listing the topics present (with their types) when it
    is missing, or naming the type when it is not one of ``types``."""
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        present = ", ".join(f"{t} ({i.msgtype})" for t, i in sorted(reader.topics.items())) or "none"
        raise DataError(f"{bag}: {what} topic {topic!r} is not in the bag; topics present: {present}")
    bad = sorted({c.msgtype for c in conns if c.msgtype not in types})
    if bad:
        raise DataError(f"{bag}: topic {topic!r} holds {', '.join(bad)}, expected {' or '.join(types)} ({what})")
    return conns


def _stamp_ns(msg) -> int:
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def _messages(reader, conns, max_bytes: int | None = None, where: str = ""):
    """(stamp ns, log time ns, message) of the connections, in the bag's order, one at a time (an image bag does
    not fit in memory): header stamps, or the log times when the topic's first message has a zero stamp (a
    driver that does not stamp). max_bytes: a message longer than this is a DataError naming ``where`` and its
    index before it is deserialized (an image message beyond the pixel limit)."""
    use_log = None
    for k, (c, t, raw) in enumerate(reader.messages(connections=conns)):
        if max_bytes is not None and len(raw) > max_bytes:
            raise DataError(f"{where} message {k}: {len(raw) / 1e6:.4g} MB, more than any image within the pixel "
                            f"limit takes ({max_bytes / 1e6:.4g} MB: the limit x 3 channels x 2 bytes + 64 kB); a "
                            "damaged or hostile bag, or a camera beyond the limit (raise it with the environment "
                            "variable VISION_CALIB_MAX_IMAGE_MPX=MPX)")
        m = reader.deserialize(raw, c.msgtype)
        s = _stamp_ns(m)
        if use_log is None:
            use_log = s == 0
        yield (t if use_log else s), t, m


def check_clock(stamps_ns, bag, topic: str, max_gap_s: float) -> None:
    """DataError naming the topic, the message index and the times when the stamps (in the bag's order) go
    backwards or leave a gap longer than ``max_gap_s``."""
    t = np.asarray(stamps_ns, np.int64)
    if t.size < 2:
        return
    d = np.diff(t)
    back = np.flatnonzero(d < 0)
    if back.size:
        k = int(back[0]) + 1
        raise DataError(f"{bag}: topic {topic!r}: time goes backwards at message {k} (stamp {t[k] * 1e-9:.6f} s after "
                        f"{t[k - 1] * 1e-9:.6f} s; a clock jump, or a bag merged from two recordings)")
    gap = np.flatnonzero(d > max_gap_s * 1e9)
    if gap.size:
        k = int(gap[0]) + 1
        raise DataError(f"{bag}: topic {topic!r}: gap of {d[k - 1] * 1e-9:.3f} s before message {k} (stamp "
                        f"{t[k] * 1e-9:.6f} s; longest allowed {max_gap_s:g} s: a clock jump or dropped messages; "
                        "--max-gap raises the limit)")


def joint_matrix(msgs, names, bag, topic: str) -> tuple[np.ndarray, np.ndarray]:
    """(stamps (N,) ns, joints (N, n)) of JointState messages ``msgs`` [(stamp, log, msg)] in the order
    ``names``. Messages holding none of the names (another publisher's joints) are skipped; DataError naming
    the missing and the present names when a message holds only some, or none does."""
    names = list(names)
    ts, rows, seen = [], [], set()
    for k, (s, _, m) in enumerate(msgs):
        mine = list(m.name)
        seen.update(mine)
        pos = dict(zip(mine, np.asarray(m.position, float)))
        if len(m.position) != len(mine):
            raise DataError(f"{bag}: topic {topic!r} message {k}: {len(mine)} names but {len(m.position)} positions")
        hit = [n for n in names if n in pos]
        if not hit:
            continue
        if len(hit) < len(names):
            miss = [n for n in names if n not in pos]
            raise DataError(f"{bag}: topic {topic!r} message {k}: joint(s) {', '.join(miss)} missing (the message "
                            f"names {', '.join(mine)}; the cell's joints are {', '.join(names)})")
        rows.append([pos[n] for n in names])
        ts.append(s)
    if not rows:
        raise DataError(f"{bag}: topic {topic!r}: no message names the cell's joints {', '.join(names)}; the bag's "
                        f"joint names are {', '.join(sorted(seen)) or 'none'} (--joint-names maps them, in the "
                        "cell's joint order)")
    Q = np.array(rows, float)
    bad = np.argwhere(~np.isfinite(Q))
    if bad.size:
        k, j = (int(v) for v in bad[0])
        raise DataError(f"{bag}: topic {topic!r}: joint {names[j]} is not finite at stamp {ts[k] * 1e-9:.6f} s")
    return np.array(ts, np.int64), Q


def standstills(t_ns, Q, settings: StillSettings) -> list[Standstill]:
    """The standstills of joint samples (module docstring). t_ns (N,) increasing stamps [ns]; Q (N, n) joints.
    DataError when the samples are too sparse for the window."""
    t = (np.asarray(t_ns, np.int64) - int(t_ns[0])) * 1e-9
    Q = np.asarray(Q, float)
    w = settings.window_s
    if len(t) < MIN_WINDOW_SAMPLES:
        raise DataError(f"{len(t)} joint-state samples: too few to find a standstill")
    dt = float(np.median(np.diff(t)))
    if dt > w / (MIN_WINDOW_SAMPLES - 1):
        raise DataError(f"joint states every {dt:.3g} s: too sparse for a standstill window of {w:g} s (needs "
                        f"{MIN_WINDOW_SAMPLES} samples in it; --still-window raises it)")
    lo = np.searchsorted(t, t - w / 2, side="left")
    hi = np.searchsorted(t, t + w / 2, side="right")
    complete = (t - w / 2 >= t[0] - 1e-9) & (t + w / 2 <= t[-1] + 1e-9)
    still = np.zeros(len(t), bool)
    tol = settings.speed * w
    for i in np.flatnonzero(complete & (hi - lo >= MIN_WINDOW_SAMPLES)):
        seg = Q[lo[i]:hi[i]]
        still[i] = bool(np.all(seg.max(axis=0) - seg.min(axis=0) <= tol))
    out = []
    edges = np.flatnonzero(np.diff(np.r_[0, still.astype(int), 0]))
    for a, b in zip(edges[::2], edges[1::2]):  # still samples a..b-1
        i0, i1 = int(lo[a]), int(hi[b - 1])
        seg = Q[i0:i1]
        out.append(Standstill(int(t_ns[i0]), int(t_ns[i1 - 1]), np.median(seg, axis=0), i1 - i0,
                              seg.max(axis=0) - seg.min(axis=0)))
    return out


def check_standstills(stills, t_ns, Q, names, settings: StillSettings, bag) -> str | None:
    """DataError naming ``--still-speed`` / ``--still-window`` when a standstill spans more than
    :data:`MAX_STILL_SPAN` on a joint (the tolerance merges moving data into one pose); a note (or None) when
    the bag's joints move by more than that but hold fewer than 3 standstills (too few poses to calibrate)."""
    def setting() -> str:
        return (f"--still-speed {settings.speed:g} x --still-window {settings.window_s:g} s lets the joints move "
                f"{settings.speed * settings.window_s:.3g} per window (default {StillSettings.speed:g} x "
                f"{StillSettings.window_s:g} s)")

    for k, st in enumerate(stills):
        j = int(np.argmax(st.span))
        if st.span[j] > MAX_STILL_SPAN:
            t0 = (st.t0_ns - int(t_ns[0])) * 1e-9
            raise DataError(f"{bag}: standstill {k} ({t0:.3f}-{t0 + (st.t1_ns - st.t0_ns) * 1e-9:.3f} s into the "
                            f"joint states, {st.n_samples} samples) spans {st.span[j]:.4g} on joint {names[j]} (more "
                            f"than {MAX_STILL_SPAN:g} rad or m): the robot moved during it, and its images would be "
                            f"merged into one pose; {setting()}: lower --still-speed")
    moved = np.max(Q, axis=0) - np.min(Q, axis=0) if len(Q) else np.zeros(0)
    if len(stills) < 3 and moved.size and float(moved.max()) > MAX_STILL_SPAN:
        return (f"only {len(stills)} standstill(s) in a bag whose joints move up to {float(moved.max()):.3g} "
                f"(joint {names[int(np.argmax(moved))]}): a calibration needs many poses; {setting()}")
    return None


# ---------------------------------------------------------------------------------------------- images
def max_image_bytes() -> int:
    """the pixel limit x 3 channels x 2 bytes + 64 kB of header: the longest image message read"""
    from ..config import max_image_pixels

    return int(max_image_pixels()) * 6 + 2**16


def message_size(msg, msgtype: str) -> tuple[int, int] | None:
    """(width, height) [px] an image message declares, without decoding: a raw Image's width and height fields,
    a CompressedImage's PNG / JPEG header (``measure.image_header.buffer_size``; None when unreadable)."""
    from ..measure.image_header import buffer_size

    if msgtype.endswith("CompressedImage"):
        return buffer_size(msg.data)
    return int(msg.width), int(msg.height)


def check_encoding(msg, msgtype: str, where: str) -> str:
    """The image's encoding (RAW_ENCODINGS) or compressed kind (COMPRESSED_FORMATS key), without decoding;
    DataError naming ``where`` for one not supported."""
    if msgtype.endswith("CompressedImage"):
        fmt = str(msg.format).lower()
        kind = next((k for k in COMPRESSED_FORMATS if k in fmt.replace(";", " ").split()), None)
        if kind is None or "compresseddepth" in fmt:
            raise DataError(f"{where}: compressed image format {msg.format!r} not supported (supported: jpeg, png)")
        return kind
    enc = str(msg.encoding).lower()
    if enc not in RAW_ENCODINGS:
        raise DataError(f"{where}: image encoding {msg.encoding!r} not supported (supported: "
                        f"{', '.join(RAW_ENCODINGS)}; CompressedImage jpeg/png)")
    return enc


def decode_image(msg, msgtype: str, where: str) -> np.ndarray:
    """Pixels of an Image (RAW_ENCODINGS; rgb8 returned as BGR, mono16 in native byte order) or CompressedImage
    (jpeg, png; decoded with ``cv2.IMREAD_UNCHANGED``, as ``measure.load_gray`` decodes a file): (H, W) or
    (H, W, 3) uint8/uint16. DataError naming ``where`` for an unsupported encoding or undecodable data."""
    import cv2

    data = np.frombuffer(bytes(msg.data), np.uint8)
    kind = check_encoding(msg, msgtype, where)
    if msgtype.endswith("CompressedImage"):
        if not data[:len(COMPRESSED_FORMATS[kind])].tobytes() == COMPRESSED_FORMATS[kind]:
            raise DataError(f"{where}: format {msg.format!r} but the data is not a {kind.upper()} stream")
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        if img is None:
            raise DataError(f"{where}: the {kind.upper()} data cannot be decoded (corrupt or truncated)")
        return img
    enc = kind
    dt, ch = RAW_ENCODINGS[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    item = np.dtype(dt).itemsize
    if h <= 0 or w <= 0 or step < w * ch * item or data.size < step * h:
        raise DataError(f"{where}: {w}x{h} {enc} image with step {step} and {data.size} bytes: inconsistent sizes")
    rows = data[:step * h].reshape(h, step)[:, :w * ch * item]
    img = np.ascontiguousarray(rows).view(np.dtype(dt).newbyteorder(">" if msg.is_bigendian else "<"))
    img = img.astype(np.dtype(dt).newbyteorder("="), copy=False).reshape((h, w, ch) if ch > 1 else (h, w))
    return img[..., ::-1].copy() if enc == "rgb8" else img


def camera_from_info(msg, where: str):
    """CameraIntrinsics from a CameraInfo message (K, D ``plumb_bob``; no D: no distortion); DataError naming
    ``where`` for another distortion model or an empty K."""
    from ..camera import CameraIntrinsics
    from ..errors import ConfigError

    ros2 = "k" in type(msg).__dataclass_fields__  # ROS 2 names the arrays k, d; ROS 1 K, D
    K = np.asarray(msg.k if ros2 else msg.K, float).reshape(-1)
    D = np.asarray(msg.d if ros2 else msg.D, float).reshape(-1)
    model = str(msg.distortion_model)
    if K.size != 9 or not np.all(np.isfinite(K)) or K[0] <= 0 or K[4] <= 0:
        raise DataError(f"{where}: K {K.tolist()} is not a camera matrix (fx, fy > 0)")
    if D.size and model not in ("plumb_bob", ""):
        raise DataError(f"{where}: distortion model {model!r} not supported (plumb_bob: k1, k2, p1, p2, k3)")
    if D.size not in (0, 5):
        raise DataError(f"{where}: plumb_bob D has {D.size} coefficients, expected 5 (k1, k2, p1, p2, k3)")
    try:
        return CameraIntrinsics(int(msg.width), int(msg.height), float(K[0]), float(K[4]), float(K[2]), float(K[5]),
                                tuple(D) if D.size else (0.0,) * 5)
    except ConfigError as exc:
        raise DataError(f"{where}: {exc}") from None


# --------------------------------------------------------------------------------------------- import
def _out_folder(out) -> Path:
    from .lock import LOCK_NAME

    out = Path(out)
    if out.exists() and (not out.is_dir() or any(p.name != LOCK_NAME for p in out.iterdir())):
        raise DataError(f"{out}: import-bag needs a new or empty folder (images of another recording would mix in)")
    return out


def _camera(reader, info_topic, setup, bag, notes: list):
    """(CameraIntrinsics, source words): the first CameraInfo of ``info_topic``, else the cell's camera."""
    if info_topic is None:
        if setup.camera is None:
            raise DataError(f"{bag}: no --camera-info-topic and the cell has no camera intrinsics: give one of them")
        return setup.camera, "the cell's camera (no camera info topic)"
    conns = topic_connections(reader, info_topic, (INFO_TYPE,), bag, "camera info")
    msgs = list(_messages(reader, conns))
    if not msgs:
        raise DataError(f"{bag}: camera info topic {info_topic!r} holds no message")
    first = camera_from_info(msgs[0][2], f"{bag}: topic {info_topic!r} message 0")
    last = camera_from_info(msgs[-1][2], f"{bag}: topic {info_topic!r} message {len(msgs) - 1}")
    if last != first:
        notes.append(f"the camera info on {info_topic} changes during the bag: the first message's intrinsics used")
    return first, f"camera info {info_topic} (K, D)"


def _check_declared(size, camera, cam_source: str, where: str) -> None:
    """DataError naming the image ``where`` when its declared (width, height) exceeds the pixel limit or differs
    from the intrinsics' (the odd image is the one named, whichever comes first)."""
    from ..measure.image_header import pixel_refusal

    why = pixel_refusal(None, size)
    if why:
        raise DataError(f"{where}: {why}")
    if tuple(size) != camera.size:
        raise DataError(f"{where}: image size {size[0]}x{size[1]} px, but the intrinsics ({cam_source}) are for "
                        f"{camera.width}x{camera.height}")


def import_bag(bag, scene, image_topic: str, joints_topic: str, out, camera_info_topic: str | None = None,
               joint_names=None, settings: StillSettings | None = None) -> BagImport:
    """Write the recorded folder ``out`` (recording.yaml, poses.csv, images/<pose_id>/<frame>.png; the cell's
    scene copied into ``out/scene``, ``io.recording.write_recording``) from ``bag`` (module docstring).

    scene: a scene file (the cell) or a cell folder holding ``scene.yaml``; joint_names: the bag's names of the
    cell's joints, in its order (default ``setup.joint_names()``); settings: :class:`StillSettings`."""
    from ..rig import load_scene
    from ..serialize import write_bytes_atomic
    from .recording import write_recording

    import cv2

    settings = settings or StillSettings()
    bag = Path(bag)
    out = _out_folder(out)
    sp = Path(scene)
    scene = load_scene(sp / "scene.yaml" if sp.is_dir() else sp)
    setup = scene.setup
    names = list(setup.joint_names()) if joint_names is None else [str(n).strip() for n in joint_names]
    if len(names) != setup.n_joints or len(set(names)) != len(names) or not all(names):
        raise DataError(f"--joint-names: {len(names)} names ({', '.join(names)}) for the cell's {setup.n_joints} "
                        "joints: give each joint's name once, in the cell's joint order")
    notes = []
    reader = open_bag(bag)
    from contextlib import closing

    from rosbags.highlevel import AnyReaderError

    try:
        with closing(reader):
            iconns = topic_connections(reader, image_topic, IMAGE_TYPES, bag, "image")
            jconns = topic_connections(reader, joints_topic, (JOINT_TYPE,), bag, "joint states")
            camera, cam_source = _camera(reader, camera_info_topic, setup, bag, notes)
            jm = list(_messages(reader, jconns))
            check_clock([s for s, _, _ in jm], bag, joints_topic, settings.max_gap_s)
            t_j, Q = joint_matrix(jm, names, bag, joints_topic)
            stills = standstills(t_j, Q, settings)
            few = check_standstills(stills, t_j, Q, names, settings, bag)
            notes += [few] if few else []
            frames, n_img, n_moving, stamps, size = {}, 0, 0, [], None
            for k, (s, _, m) in enumerate(_messages(reader, iconns, max_image_bytes(), f"{bag}: topic "
                                                                                          f"{image_topic!r}")):
                stamps.append(s)
                n_img += 1
                where = f"{bag}: topic {image_topic!r} message {k} (stamp {s * 1e-9:.6f} s)"
                check_encoding(m, m.__msgtype__, where)  # every image: a bad encoding is named, not skipped
                hit = next((i for i, st in enumerate(stills) if st.t0_ns <= s <= st.t1_ns), None)
                if hit is None:
                    n_moving += 1
                    continue
                declared = message_size(m, m.__msgtype__)  # before decoding: the pixel limit, the camera's size
                if declared is not None:
                    _check_declared(declared, camera, cam_source, where)
                img = decode_image(m, m.__msgtype__, where)
                shape = (int(img.shape[1]), int(img.shape[0]))
                if size is None:
                    size = shape
                elif shape != size:
                    raise DataError(f"{where}: image size {shape[0]}x{shape[1]}, the first image is "
                                    f"{size[0]}x{size[1]}")
                ok, buf = cv2.imencode(".png", img)  # lossless; written once the whole bag is read
                frames.setdefault(hit, []).append(buf.tobytes())
            check_clock(stamps, bag, image_topic, float("inf"))  # images come only at standstills: no gap limit
    except AnyReaderError as exc:
        raise DataError(f"{bag}: cannot read the bag ({exc})") from None
    if n_img == 0:
        raise DataError(f"{bag}: image topic {image_topic!r} holds no message")
    if not frames:
        raise DataError(f"{bag}: no standstill with an image: {len(stills)} standstills of the joints "
                        f"(speed <= {settings.speed:g} over {settings.window_s:g} s) and {n_img} images, none taken "
                        "while the robot stood still (--still-speed / --still-window, or the image and joint clocks "
                        "differ)")
    if size != camera.size:
        raise DataError(f"{bag}: the images are {size[0]}x{size[1]} px but the intrinsics ({cam_source}) are for "
                        f"{camera.width}x{camera.height}")
    order = sorted(frames)
    joints = np.array([stills[i].joints for i in order])
    setup.check_joints(joints, f"{bag}: topic {joints_topic!r}", [f"{p:03d}" for p in range(len(order))])
    kept = []
    for p, i in enumerate(order):
        pngs = frames[i][:settings.max_frames] if settings.max_frames else frames[i]
        for f, data in enumerate(pngs):
            write_bytes_atomic(out / "images" / f"{p:03d}" / f"{f:02d}.png", data)
        kept.append(len(pngs))
    lost = len(stills) - len(order)
    if lost:
        notes.append(f"{lost} standstill(s) without an image (not poses)")
    source = (f"import-bag {bag.name}: images {image_topic}, joints {joints_topic} ({', '.join(names)})"
              + (f", camera info {camera_info_topic}" if camera_info_topic else ""))
    write_recording(out, scene, joints, joints, max(kept), camera=camera, source=source, notes=notes)
    return BagImport(out, tuple(kept), len(stills), n_img, n_moving, cam_source, tuple(notes))


__all__ = ["StillSettings", "Standstill", "BagImport", "RAW_ENCODINGS", "open_bag", "topic_connections",
           "check_clock", "joint_matrix", "standstills", "check_standstills", "max_image_bytes", "message_size",
           "check_encoding", "decode_image", "camera_from_info",
           "import_bag"]
