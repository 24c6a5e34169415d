"""The camera intrinsics a recorded folder is processed with: ``process --camera camera.yaml``'s,
recording.yaml's (``camera`` or ``camera_file``), or calibrated from the recording's own images (no
intrinsics given, or ``process --refine-intrinsics``), and the report's ``intrinsics`` block that says which."""

from __future__ import annotations

from dataclasses import replace

from ..errors import DataError
from ..measure.intrinsics import PARAM_NAMES, calibrate_from_images

SOURCE_FILE = "recording.yaml"
SOURCE_CALIBRATED = "calibrated from the recording"
SOURCE_CAMERA_FILE = "camera file"


def recording_intrinsics(rec, refine: bool = False, progress: bool = False, camera_file=None):
    """(Recording with its camera set, report block). camera_file: a camera.yaml (``process --camera``)
    that replaces recording.yaml's intrinsics (size checked against the images; ConfigError naming it).
    The calibration uses the first frame of every pose
    (one view per pose; the other frames of a pose add noise averaging, not geometry). Report block:
    {source, values {fx, fy, cx, cy, k1, k2, p1, p2, k3}, std (None when given), rms_px, n_views_used,
    n_views_rejected, rejected_views [{name, reason}], coverage, warnings, given (recording.yaml's values
    when refined)}. DataError naming the folder when the calibration is impossible."""
    if camera_file is not None:
        from pathlib import Path

        from ..io.camera_file import load_camera_for_images

        rec = replace(rec, camera=load_camera_for_images(camera_file, rec.image_size, "process --camera"),
                      camera_file=Path(camera_file))
    if rec.camera is not None and not refine:
        c = rec.camera
        block = {"source": SOURCE_FILE if rec.camera_file is None else f"{SOURCE_CAMERA_FILE} {rec.camera_file}",
                 "values": dict(zip(PARAM_NAMES, (c.fx, c.fy, c.cx, c.cy, *c.dist))),
                 "std": None, "rms_px": None, "warnings": []}
        return rec, block
    pids = [pid for pid in rec.pose_ids if rec.images.get(pid)]
    try:
        res = calibrate_from_images([rec.images[p][0] for p in pids], rec.target, rec.image_size,
                                    names=[f"pose {p}" for p in pids], progress=progress)
    except DataError as exc:
        why = "has no camera fx/fy/cx/cy" if rec.camera is None else "asks to refine the intrinsics"
        raise DataError(f"{rec.folder}: recording.yaml {why}, and calibrating them from the images failed: "
                        f"{exc}") from None
    d = res.to_dict()
    block = {"source": SOURCE_CALIBRATED, "values": res.values(), "std": dict(res.std), "rms_px": res.rms_px,
             "n_views_used": d["n_views_used"], "n_views_rejected": d["n_views_rejected"],
             "rejected_views": [{"name": v.name, "reason": v.reason} for v in res.views if not v.used],
             "coverage": res.coverage, "warnings": [f"camera intrinsics: {w}" for w in res.warnings]}
    if rec.camera is not None:
        c = rec.camera
        block["given"] = dict(zip(PARAM_NAMES, (c.fx, c.fy, c.cx, c.cy, *c.dist)))
    return replace(rec, camera=res.camera), block

