"""Overlay images of what the detector found, for report.html: one frame of a pose with its detected corners,
the target corners reprojected through the measured pose (PnP) and through the calibrated model, and why the
pose was rejected. JPEGs drawn with OpenCV, twice: a small one for the page (at most :data:`MAX_WIDTH_PX` wide)
and a full-size one the page opens on a click (every camera pixel at least one display pixel; crops narrower
than :data:`FULL_MIN_WIDTH_PX` enlarged by a whole factor, at most :data:`FULL_MAX_ENLARGE`, pixels kept
square; at most :data:`FULL_MAX_WIDTH_PX` wide).

Which poses: :func:`overlay_selection` (the worst residuals and the rejected poses of a report); where their
images come from: an :class:`OverlaySource` the pipeline builds (a recorded folder's files, or the simulation's
frames rendered again for those poses only)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

if TYPE_CHECKING:  # annotations only: the module imports neither the target kinds nor OpenCV on load
    from ..camera import CameraIntrinsics
    from ..targets import TargetSpec

#: overlay width limit [px] (the image is downscaled, never enlarged)
MAX_WIDTH_PX = 640
#: the full-size overlay: crops narrower than this [px] are enlarged by a whole factor (nearest pixel) towards it
FULL_MIN_WIDTH_PX = 1280
#: ... by at most this factor
FULL_MAX_ENLARGE = 4
#: ... and wider crops downscaled to this width [px] (a 4K frame's overlay stays a few hundred kB)
FULL_MAX_WIDTH_PX = 2560
#: JPEG quality of an overlay
JPEG_QUALITY = 80
#: colours (BGR) and what they mark, in the order of the legend
COLOURS = {"detected": (40, 200, 40), "measured": (255, 170, 0), "model": (40, 40, 230)}
LEGEND = {"detected": "green +: corners the detector found",
          "measured": "blue dot: target corners reprojected through the measured pose (PnP on this pose's frames)",
          "model": "red circle: target corners reprojected through the calibrated model's pose (from the joints); "
                   "red line: from each detected corner towards its model reprojection, magnified (gain in the "
                   "caption)"}


@dataclass(frozen=True)
class OverlaySource:
    """Where the overlay images of a run come from.

    frames: callable(list of pose ids) -> {pose id: (grey image (H, W) uint8 or None, Detection or None, note)}
    (one frame per pose: the first with a valid detection, else the first; note: why there is no image);
    target: TargetSpec; intrinsics: CameraIntrinsics (distorted pixels); model_pose: callable(pose id) ->
    T_cam_target (4, 4) m the calibrated model predicts for that pose, or None (no usable model)."""

    frames: Callable
    target: TargetSpec
    intrinsics: CameraIntrinsics
    model_pose: Callable | None = None


def overlay_selection(report: dict, n_worst: int = 3, max_rejected: int = 6) -> list[tuple[str, str, str]]:
    """[(pose id, role, reason)] of the poses worth a picture: the rejected ones first (measurement failures,
    then the fit's outliers; at most ``max_rejected``), then the ``n_worst`` largest final residuals
    (report.json's ``pose_residuals``). role: "rejected" | "outlier" | "worst"."""
    out, seen = [], set()
    m = report.get("measurements") or {}
    for role, items in (("rejected", m.get("rejected") or []), ("outlier", report.get("outliers") or [])):
        for it in items:
            pid = str(it["pose_id"])
            if pid not in seen and len(out) < max_rejected:
                seen.add(pid)
                out.append((pid, role, str(it.get("reason") or "")))
    from .text import figure_label

    worst = [p for p in (report.get("pose_residuals") or {}).get("poses", []) if p["pose_id"] not in seen]
    for p in worst[:max(0, int(n_worst))]:
        parts = [f"chi2 {p['chi2']:.3g}" if p.get("chi2") is not None else None]
        for k in ("translation_mm", "rotation_deg", "joint_deg"):
            if p.get(k) is not None:
                label, unit, f = figure_label(k)
                parts.append(f"{label} {p[k] * f:.3g} {unit}".rstrip())
        out.append((p["pose_id"], "worst", "final residual: " + ", ".join(x for x in parts if x)))
    return out


def _project(T, target, intrinsics, ids=None):
    """(ids (K,), uv (K, 2) distorted px) of the target corners (all, or ``ids``) through T_cam_target (4, 4) m;
    corners behind the camera dropped."""
    from ..frames import transform_points
    from ..measure.pnp import target_lookup

    lookup = target_lookup(target)
    ids = [int(i) for i in (lookup if ids is None else ids) if int(i) in lookup]
    if not ids or T is None or not np.all(np.isfinite(T)):
        return np.zeros(0, int), np.zeros((0, 2))
    pc = transform_points(np.asarray(T, float), np.array([lookup[i] for i in ids]))
    front = pc[:, 2] > 0
    return np.asarray(ids)[front], intrinsics.project(pc[front])


def _crop_box(points, w: int, h: int, margin: float = 0.15, min_px: int = 160):
    """(x0, y0, x1, y1) int px: the box of ``points`` (K, 2) px grown by ``margin`` of its size (at least
    ``min_px`` wide and high), inside the (w, h) image; the whole image without points."""
    pts = np.asarray(points, float).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1) & (pts[:, 0] >= 0) & (pts[:, 0] < w) & (pts[:, 1] >= 0)
              & (pts[:, 1] < h)]
    if not len(pts):
        return 0, 0, w, h
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    half = np.maximum((hi - lo) * (0.5 + margin), min_px / 2)
    c = (lo + hi) / 2
    x0, y0 = np.floor(np.maximum(c - half, 0)).astype(int)
    x1, y1 = np.ceil(np.minimum(c + half, [w, h])).astype(int)
    return int(x0), int(y0), int(x1), int(y1)


def draw_overlay(image, detection=None, T_measured=None, T_model=None, target=None, intrinsics=None,
                 label: str = "", max_width: int = MAX_WIDTH_PX, vector_px: float = 25.0,
                 min_width: int = 0) -> tuple[bytes, dict]:
    """JPEG bytes of ``image`` ((H, W) uint8 grey) cropped to the target (the detected and reprojected corners,
    with a margin; the whole image when there are none) and downscaled to at most ``max_width`` px wide (or,
    narrower than ``min_width``, enlarged by the whole factor k <= :data:`FULL_MAX_ENLARGE` that keeps it within
    both widths: each image pixel a k x k square), with
    the detected corners (``detection``: measure.Detection, distorted px), the target corners through
    ``T_measured`` and ``T_model`` (T_cam_target (4, 4) m or None), the model - detected vector of each corner
    magnified so that the longest is ``vector_px`` display px (never shrunk), and ``label`` top-left. Also returns
    what was drawn: {crop [x0, y0, x1, y1] px, width, height, scale (display px per image px), n_detected,
    n_measured, n_model, model_rms_px and model_max_px (detected vs model corners of the same ids, image px;
    None without both), vector_gain}."""
    import cv2

    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    h, w = img.shape[:2]
    det_uv = {}
    if detection is not None and len(detection.ids):
        det_uv = {int(i): uv for i, uv in zip(detection.ids, np.asarray(detection.uv_px, float))}
    proj = {}
    if target is not None and intrinsics is not None:
        for key, T in (("measured", T_measured), ("model", T_model)):
            ids, uv = _project(T, target, intrinsics)
            ok = np.all(np.isfinite(uv), axis=1) & (uv[:, 0] > -w) & (uv[:, 0] < 2 * w) & (uv[:, 1] > -h) \
                & (uv[:, 1] < 2 * h) if len(uv) else np.zeros(0, bool)
            proj[key] = (ids[ok], uv[ok])
    allpts = [np.zeros((0, 2))] + [np.array(list(det_uv.values()))] * bool(det_uv) + [uv for _, uv in proj.values()]
    x0, y0, x1, y1 = _crop_box(np.concatenate(allpts), w, h)
    s = min(1.0, float(max_width) / (x1 - x0))
    if s == 1.0 and min_width > x1 - x0:  # enlarged by a whole factor, within both widths
        s = float(max(1, min(FULL_MAX_ENLARGE, int(min_width // (x1 - x0)), int(max_width // (x1 - x0)))))
    crop = img[y0:y1, x0:x1]
    small = cv2.resize(crop, (max(1, round((x1 - x0) * s)), max(1, round((y1 - y0) * s))),
                       interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_NEAREST) if s != 1 else crop.copy()
    out = cv2.cvtColor(small, cv2.COLOR_GRAY2BGR)
    shift = 4  # sub-pixel drawing: coordinates in 1/16 px

    def pt(uv):  # image px (integer = pixel centre) -> display px of the resized crop (pixel edges aligned)
        return (int(round(((uv[0] - x0 + 0.5) * s - 0.5) * (1 << shift))),
                int(round(((uv[1] - y0 + 0.5) * s - 0.5) * (1 << shift))))

    info = {"crop": [x0, y0, x1, y1], "width": int(out.shape[1]), "height": int(out.shape[0]), "scale": s,
            "n_detected": len(det_uv), "n_measured": 0, "n_model": 0, "model_rms_px": None, "model_max_px": None,
            "vector_gain": None}
    ids_m, uv_m = proj.get("measured", (np.zeros(0, int), np.zeros((0, 2))))
    for p in uv_m:
        cv2.circle(out, pt(p), 2 << shift, COLOURS["measured"], -1, cv2.LINE_AA, shift)
    info["n_measured"] = len(uv_m)
    ids_r, uv_r = proj.get("model", (np.zeros(0, int), np.zeros((0, 2))))
    for p in uv_r:
        cv2.circle(out, pt(p), 5 << shift, COLOURS["model"], 1, cv2.LINE_AA, shift)
    info["n_model"] = len(uv_r)
    pairs = [(det_uv[int(i)], p) for i, p in zip(ids_r, uv_r) if int(i) in det_uv]
    if pairs:
        d = np.array([p - q for q, p in pairs])
        n = np.linalg.norm(d, axis=1)
        info["model_rms_px"], info["model_max_px"] = float(np.sqrt(np.mean(n ** 2))), float(n.max())
        gain = max(1.0, vector_px / max(float(n.max()) * s, 1e-9))
        info["vector_gain"] = gain
        for (q, _), dv in zip(pairs, d):
            cv2.line(out, pt(q), pt(q + dv * gain), COLOURS["model"], 1, cv2.LINE_AA, shift)
    for uv in det_uv.values():
        q = pt(uv)
        cv2.drawMarker(out, (q[0] >> shift, q[1] >> shift), COLOURS["detected"], cv2.MARKER_CROSS, 9, 1)
    if label:
        (tw, th), base = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
        cv2.rectangle(out, (0, 0), (tw + 8, th + base + 8), (0, 0, 0), -1)
        cv2.putText(out, label, (4, th + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ValueError("overlay: JPEG encoding failed")
    return buf.tobytes(), info


def _measured_poses(report: dict) -> dict:
    """{pose id: T_cam_target (4, 4)} of the valid measured poses in report.json's ``measurements``."""
    out = {}
    for p in (report.get("measurements") or {}).get("poses", []):
        if p.get("valid") and p.get("T_cam_target") is not None:
            out[str(p["pose_id"])] = np.asarray(p["T_cam_target"], float)
    return out


def build_overlays(report: dict, source: OverlaySource, n_worst: int = 3, max_rejected: int = 6) -> list[dict]:
    """Overlays of :func:`overlay_selection`'s poses: [{pose_id, role, reason, jpeg (bytes) or None, note,
    drawn (``draw_overlay``'s info), full_jpeg and full_drawn (the same drawn at full size: module docstring)}]
    in that order; a pose without an image keeps its note (why)."""
    sel = overlay_selection(report, n_worst, max_rejected)
    if not sel:
        return []
    frames = source.frames([pid for pid, _, _ in sel])
    measured = _measured_poses(report)
    out = []
    for pid, role, reason in sel:
        img, det, note = frames.get(pid, (None, None, "no image"))
        entry = {"pose_id": pid, "role": role, "reason": reason, "jpeg": None, "note": note, "drawn": None,
                 "full_jpeg": None, "full_drawn": None}
        if img is not None:
            T_model = source.model_pose(pid) if source.model_pose is not None else None
            frame = "" if det is None else f" frame {det.frame_index}"
            args = (img, det, measured.get(pid), T_model, source.target, source.intrinsics)
            entry["jpeg"], entry["drawn"] = draw_overlay(*args, label=f"pose {pid}{frame} ({role})")
            entry["full_jpeg"], entry["full_drawn"] = draw_overlay(*args, label=f"pose {pid}{frame} ({role})",
                                                                   max_width=FULL_MAX_WIDTH_PX,
                                                                   min_width=FULL_MIN_WIDTH_PX)
        out.append(entry)
    return out


def recording_frames(images: dict, detections: dict) -> Callable:
    """``OverlaySource.frames`` of a recorded folder: images {pose id: [file path, ...]}, detections {pose id:
    [Detection per frame]} (``experiment.process.measure_recording``). The frame shown: the first with a valid
    detection, else the first readable one."""
    from ..measure.detect import load_gray

    def frames(pose_ids):
        out = {}
        for pid in pose_ids:
            files = list(images.get(pid) or [])
            dets = list(detections.get(pid) or [])
            if not files:
                out[pid] = (None, None, f"no images in images/{pid}/")
                continue
            k = next((j for j, d in enumerate(dets) if d.valid), 0)
            img, why = load_gray(str(files[min(k, len(files) - 1)]))
            out[pid] = (img, dets[k] if k < len(dets) else None, why)
        return out

    return frames
