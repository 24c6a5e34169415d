"""Detection over the frames of one pose: per frame (:func:`.detect.detect`) or seeded (:mod:`.seeded`)."""

from __future__ import annotations

import numpy as np

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


def refit_detection(det: Detection, intrinsics: CameraIntrinsics | None, min_corners: int = 1) -> Detection | None:
    """``det``'s corners fitted again to its edge samples (``Detection.edges``, AprilTag grids) under
    ``intrinsics`` (their lines in its undistorted pixels; None: in raw pixels), no image read
    (:func:`.tag_edges.corners_from_edges`): the detection those intrinsics give, to the placement of the edge
    profiles. A marker whose sides no longer intersect is dropped; fewer than ``min_corners`` corners left: an
    invalid Detection saying so. An invalid ``det`` is returned as it is; None when ``det`` has no edge samples
    (another kind: detect again)."""
    from .tag_edges import corners_from_edges

    if not det.valid:
        return det
    if det.edges is None:
        return None
    corners, ok = corners_from_edges(det.edges, intrinsics)
    keep = np.repeat(ok, 4)
    ids, uv = det.ids[keep], corners.reshape(-1, 2)[keep]
    diag = {**det.diagnostics, "n_corners": int(len(ids)), "refit": "tag edges under other intrinsics"}
    valid = len(ids) >= min_corners
    return Detection(valid, "" if valid else f"too few corners after the edge refit: {len(ids)} < {min_corners}", ids,
                     uv, det.image_size, det.frame_index, diag, det.edges.take(ok))


def refittable(detections) -> bool:
    """Whether every valid Detection of ``detections`` (an iterable) carries edge samples
    (:func:`refit_detection`), at least one of them valid."""
    valid = [d for d in detections if d.valid]
    return bool(valid) and all(d.edges is not None for d in valid)
