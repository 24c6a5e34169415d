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


def reusable_detections(target, config: DetectConfig = DetectConfig()) -> bool:
    """Whether :func:`detect_batch`'s Detections of a pose hold for any intrinsics of the same image size (the kind's
    detection reads no intrinsics, ``TargetKind.detect_uses_intrinsics``) and its first frame's is the one
    :func:`.detect.detect` gives that file with ``replace(config, batch="per_frame")`` and no intrinsics (the seeded
    mode's full detection adds no refinement of its own), so one detection per image serves the given and the
    refined intrinsics, and the camera calibration from the first frames."""
    kind = target.kind_impl
    if kind.detect_uses_intrinsics:
        return False
    return config.batch == "per_frame" or (kind.seeded_mode(config) != "tag_edges"
                                           and config.seed_config().refine_for(target.kind)
                                           == config.refine_for(target.kind))
