"""Corner detection of calibration targets, never raising on bad input. What is detected and how is
the target kind's (:mod:`vision_calib.targets.kinds`: cv2.aruco for ChArUco boards and AprilTag grids,
``findChessboardCornersSB`` for chessboards, ``findCirclesGrid`` for asymmetric circle grids).

Corner ids follow ``TargetSpec.corner_points()``: ChArUco corners use OpenCV's ChArUco corner
ids; AprilTag-grid corners are ``4 * marker_id + k`` with k the OpenCV marker corner index.
``uv_px`` are *distorted* pixel coordinates as seen in the image (OpenCV pixel-centre convention:
the centre of the top-left pixel is (0, 0)).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from ..camera import CameraIntrinsics
from ..errors import ConfigError
from ..serialize import jsonable


def _kind(kind: str):
    """The registered target kind (its ``auto_refine`` / ``auto_extra_subpix`` defaults)."""
    from ..targets.kinds import get_kind

    return get_kind(kind, "DetectConfig")


@dataclass(frozen=True)
class DetectConfig:
    """refine: marker corner refinement "apriltag" | "subpix" | "contour" | "none" (AprilTag grids;
    ChArUco corners are always refined by OpenCV's interpolation + cornerSubPix).
    apriltag_offset_px: added to u and v of corners refined with "apriltag": OpenCV 4.14's
    AprilTag quad refinement returns corners in the pixel-*corner* convention, +0.46 px (blur
    0..0.6 px) to +0.49 px (blur 1.2 px) off the pixel-centre convention (measured on synthetic
    renders, benchmarks/bench_measure.py); -0.5 restores the OpenCV pixel-centre convention.
    extra_subpix: run cv2.cornerSubPix again on the final corners (window ``subpix_win`` px
    half-size, eps 1e-4 px); None = auto: on for ChArUco (measured on TargetRenderer images,
    1024 x 768, 0.4-0.8 m, blur 0.6 px: corner RMS 0.076 -> 0.062 px with win 5; OpenCV's own
    ChArUco refinement stops at 0.1 px steps and uses small windows), off for AprilTag grids
    (L-corners: cornerSubPix leaves ~0.18 px per-corner bias). min_corners: fewer detected target
    corners -> invalid Detection.
    refine "auto" (default, measured): "apriltag" for AprilTag grids (corner std 0.05 px vs 0.18 px
    for subpix), "none" for ChArUco markers (the ChArUco corners do not change; AprilTag refinement
    of the markers costs 175 ms/frame vs 9 ms at 1024 x 768).
    batch: how ``detect_batch`` treats the frames of one pose. "per_frame": full detection of every
    frame (the path above). "seeded" (default): the markers/board are detected once (on the first
    frame that gives a valid detection), then every other frame's corners are refined from those
    positions: ChArUco by ``cv2.cornerSubPix`` (window ``subpix_win``), AprilTag grids by straight-edge
    fits of each tag's border (:mod:`.tag_edges`; the seed frame itself is refined the same way, so all
    frames share one estimator; marker detection for the seed with refine "auto" -> "none"). A frame is
    refined from the seed only when its 1/8-scale image correlates with the seed's at least
    ``min_view_ncc`` and no corner moves more than ``max_shift_px`` from its seed; otherwise it gets a
    full detection (diagnostics "fallback": why). Measured (benchmarks/bench_detect.py): ChArUco poses
    equal the per-frame path's within 1e-4 mm / 1e-4 deg, same corner bias and scatter; AprilTag grids:
    corner bias and scatter and pose error smaller than with OpenCV's AprilTag refinement."""

    refine: str = "auto"
    apriltag_offset_px: float = -0.5
    extra_subpix: bool | None = None
    subpix_win: int = 5
    min_corners: int = 4
    batch: str = "seeded"
    max_shift_px: float = 1.0
    min_view_ncc: float = 0.9

    def __post_init__(self):
        if self.refine not in ("auto", "apriltag", "subpix", "contour", "none"):
            raise ConfigError(f"DetectConfig.refine must be auto|apriltag|subpix|contour|none, got {self.refine!r}")
        if self.min_corners < 1 or self.subpix_win < 1:
            raise ConfigError("DetectConfig.min_corners and subpix_win must be >= 1")
        if self.batch not in ("seeded", "per_frame"):
            raise ConfigError(f"DetectConfig.batch must be 'seeded' or 'per_frame', got {self.batch!r}")
        if not self.max_shift_px > 0 or not -1.0 <= self.min_view_ncc <= 1.0:
            raise ConfigError("DetectConfig.max_shift_px must be > 0 and min_view_ncc in [-1, 1]")

    def refine_for(self, kind: str) -> str:
        """The marker refinement actually used for a target kind (per-frame detection)."""
        return _kind(kind).auto_refine if self.refine == "auto" else self.refine

    def seed_config(self) -> "DetectConfig":
        """The per-frame config used for full detections in the seeded batch mode: refine "auto" ->
        "none" (the seeded refinement replaces OpenCV's marker corner refinement)."""
        return replace(self, refine="none") if self.refine == "auto" else self

    def extra_subpix_for(self, kind: str) -> bool:
        """Whether the extra cornerSubPix pass runs for a target kind."""
        return _kind(kind).auto_extra_subpix if self.extra_subpix is None else bool(self.extra_subpix)


@dataclass(frozen=True, eq=False)
class Detection:
    """Detected target corners in one frame.

    valid: usable for PnP; reason: why not ("" when valid). ids: (K,) int corner ids.
    uv_px: (K, 2) float64 distorted pixel coordinates. image_size: (width, height) px or None
    (unreadable). frame_index: index of the frame in its pose batch. diagnostics: dict
    (n_markers, marker_ids, time_s, source, ...). edges: the :class:`.tag_edges.EdgeSamples` the corners were
    fitted to (AprilTag grids' seeded detection: corner ids 4 m .. 4 m + 3 of marker m in order), from which
    :func:`.batch.refit_detection` fits them under other intrinsics; None for other kinds (not serialised)."""

    valid: bool
    reason: str
    ids: np.ndarray
    uv_px: np.ndarray
    image_size: tuple[int, int] | None
    frame_index: int = 0
    diagnostics: dict = field(default_factory=dict)
    edges: object = None

    @property
    def n_corners(self) -> int:
        return int(len(self.ids))

    def to_dict(self) -> dict:
        return {
            "valid": bool(self.valid),
            "reason": self.reason,
            "frame_index": int(self.frame_index),
            "image_size": None if self.image_size is None else [int(x) for x in self.image_size],
            "ids": [int(i) for i in self.ids],
            "uv_px": np.asarray(self.uv_px, dtype=float).tolist(),
            "diagnostics": jsonable(self.diagnostics),
        }


def _invalid(reason, frame_index, image_size=None, **diag) -> Detection:
    return Detection(False, reason, np.zeros(0, dtype=int), np.zeros((0, 2)), image_size, frame_index, diag)


# ----------------------------------------------------------------------------- image loading
def load_gray(image) -> tuple[np.ndarray | None, str]:
    """Image path or array -> (uint8 (H, W) grey image, "") or (None, reason naming the file). Never raises.

    Files: any format OpenCV reads (PNG, JPEG, BMP, TIFF, ...), 8 or 16 bit, grey or colour (BGR/BGRA ->
    grey with ``cv2.cvtColor``). A JPEG without its end-of-image marker (truncated: OpenCV would decode the
    top part and leave the rest grey) is refused. 16-bit images are scaled by their *used* bit depth,
    ``b = max(8, bit_length(max pixel))``: ``img >> (b - 8)``, so a 12-bit camera in a 16-bit container
    (max <= 4095) keeps its full contrast (>> 4) and a full-range 16-bit image gets >> 8; the brightest
    pixel never clips. Float arrays are rounded and clipped to 0..255.
    A file is decoded only once its header was read (:func:`vision_calib.measure.image_header.header_size`) and
    its width x height is within the pixel limit (``config.max_image_pixels``): a file declaring more is refused
    with the reason, never decoded; so is one whose header no reader understands."""
    src = ""
    try:
        if isinstance(image, (str, Path)):
            from .image_header import header_size, pixel_refusal

            src = str(image)
            if not Path(src).is_file():
                return None, f"image file not found: {src}"
            size = header_size(src)
            if size is None:
                return None, f"unreadable or corrupt image file: {src}"
            too_big = pixel_refusal(src, size)
            if too_big:
                return None, too_big
            data = np.fromfile(src, dtype=np.uint8)
            # JPEG (starts FF D8) must hold its end-of-image marker FF D9 (some writers pad after it)
            if data.size >= 2 and data[0] == 0xFF and data[1] == 0xD8 and b"\xff\xd9" not in data[-64:].tobytes():
                return None, f"truncated JPEG file (no end-of-image marker): {src}"
            img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
            if img is None:
                return None, f"unreadable or corrupt image file: {src}"
        else:
            img = np.asarray(image)
        if img.size == 0 or img.ndim not in (2, 3):
            return None, f"empty or malformed image (shape {img.shape}) {src}".strip()
        if img.ndim == 3:
            if img.shape[2] == 1:
                img = img[..., 0]
            elif img.shape[2] in (3, 4):
                img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
            else:
                return None, f"image with {img.shape[2]} channels not supported {src}".strip()
        if img.dtype == np.uint16:
            bits = max(8, int(img.max()).bit_length())
            img = (img >> (bits - 8)).astype(np.uint8)
        elif img.dtype != np.uint8:
            f = img.astype(np.float64)
            if not np.all(np.isfinite(f)):
                return None, f"image contains NaN/inf values {src}".strip()
            img = np.clip(np.rint(f), 0, 255).astype(np.uint8)
        return np.ascontiguousarray(img), ""
    except Exception as exc:  # corrupt data must not escape a batch
        return None, f"could not read image {src}: {exc}".strip()


# ----------------------------------------------------------------------------- detectors (thread-local cache)
_local = threading.local()


def _detector(target, config: DetectConfig):
    """(kind's detector object, frozenset of the target's corner ids), cached per thread."""
    cache = getattr(_local, "cache", None)
    if cache is None:
        cache = _local.cache = {}
    key = (target, config)
    hit = cache.get(key)
    if hit is not None:
        return hit
    det = target.kind_impl.make_detector(target, config)
    ids, _ = target.corner_points()
    cache[key] = (det, frozenset(int(i) for i in ids))
    return cache[key]


# ----------------------------------------------------------------------------- detection
def load_checked(image, intrinsics, frame_index):
    """A frame loaded grey and checked against the intrinsics' size: (grey image, size (w, h) px, source, None),
    or (None, size, source, invalid Detection) naming why."""
    source = str(image) if isinstance(image, (str, Path)) else "array"
    if intrinsics is not None and isinstance(image, (str, Path)):  # the header's size first: nothing decoded
        from .image_header import header_size

        size = header_size(image)
        if size is not None and size != intrinsics.size:
            return None, size, source, _invalid(f"image size {size[0]}x{size[1]} does not match the camera "
                                                f"intrinsics {intrinsics.width}x{intrinsics.height} ({source})",
                                                frame_index, size, source=source)
    img, why = load_gray(image)
    if img is None:
        return None, None, source, _invalid(why, frame_index, source=source)
    size = (int(img.shape[1]), int(img.shape[0]))
    if intrinsics is not None and size != intrinsics.size:
        return None, size, source, _invalid(f"image size {size[0]}x{size[1]} does not match the camera intrinsics "
                                            f"{intrinsics.width}x{intrinsics.height} ({source})", frame_index, size,
                                            source=source)
    return img, size, source, None


def detect(image, target, intrinsics: CameraIntrinsics | None = None, frame_index: int = 0,
           config: DetectConfig = DetectConfig()) -> Detection:
    """Detect the target's corners in one image (path or (H, W)[, C] array). Never raises on bad
    images: returns ``Detection(valid=False, reason=...)``. intrinsics: when given, the image
    size must match (width, height)."""
    t0 = time.perf_counter()
    img, size, source, bad = load_checked(image, intrinsics, frame_index)
    if bad is not None:
        return bad
    return detect_gray(img, size, source, target, frame_index, config, t0, intrinsics=intrinsics)


def _find_corners(img, target, config: DetectConfig, diag: dict, intrinsics=None):
    """The target kind's corner finder on a grey image: (ids, uv) or (None, reason)."""
    det, _ = _detector(target, config)
    return target.kind_impl.find_corners(target, det, img, config, diag, intrinsics)


def subpix(img, uv, win):
    """uv (K, 2) px refined by cv2.cornerSubPix on the grey image (window win x win px, eps 1e-4 px)."""
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    pts = uv.astype(np.float32).reshape(-1, 1, 2)
    cv2.cornerSubPix(img, pts, (int(win), int(win)), (-1, -1), crit)
    return pts.reshape(-1, 2).astype(np.float64)


def detect_gray(img, size, source, target, frame_index, config: DetectConfig, t0,
                 post=None, intrinsics=None) -> Detection:
    """Detection on a loaded grey image. post: optional (img, ids, uv) -> (ids, uv, edges) refinement replacing
    the extra cornerSubPix pass (the seeded batch mode's per-frame estimator; edges: ``Detection.edges`` or None).
    intrinsics: passed to the kind's corner finder (circle grids correct the perspective offset of the dot centres
    with it)."""
    _, target_ids = _detector(target, config)
    diag = {"source": source}
    try:
        ids, uv = _find_corners(img, target, config, diag, intrinsics)
        if ids is None:
            diag["time_s"] = time.perf_counter() - t0
            return _invalid(uv, frame_index, size, **diag)
        keep = np.array([int(i) in target_ids for i in ids], dtype=bool)
        ids, uv = ids[keep], uv[keep]
        order = np.argsort(ids, kind="stable")
        ids, uv = ids[order], uv[order]
        edges = None
        if post is not None and len(ids):
            ids, uv, edges = post(img, ids, uv)
        elif config.extra_subpix_for(target.kind) and len(ids):
            uv = subpix(img, uv, config.subpix_win)
    except cv2.error as exc:
        return _invalid(f"OpenCV detection error: {exc}".splitlines()[0], frame_index, size, **diag)
    diag["n_corners"] = int(len(ids))
    diag["time_s"] = time.perf_counter() - t0
    if len(ids) < config.min_corners:
        return Detection(False, f"too few corners: {len(ids)} < {config.min_corners}", ids, uv, size, frame_index, diag,
                         edges)
    return Detection(True, "", ids, uv, size, frame_index, diag, edges)
