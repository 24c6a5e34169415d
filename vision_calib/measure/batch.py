"""Detection over the frames of one pose: per frame (:func:`.detect.detect`) or seeded (:mod:`.seeded`)."""

from __future__ import annotations

from ..camera import CameraIntrinsics
from .detect import DetectConfig, Detection, detect
from .seeded import detect_seeded


def detect_batch(images, target, intrinsics: CameraIntrinsics | None = None,
                 config: DetectConfig = DetectConfig()) -> list[Detection]:
    """Detect in every frame of a pose: images is a (N, H, W) array or a sequence of paths/arrays.
    Returns N Detections (frame_index = position); never raises on a bad frame. ``config.batch``:
    "seeded" detects once and refines the other frames from those corners (:mod:`.seeded`),
    "per_frame" runs :func:`detect` on every frame."""
    if config.batch == "seeded":
        return detect_seeded(images, target, intrinsics, config)
    return [detect(im, target, intrinsics, i, config) for i, im in enumerate(images)]
