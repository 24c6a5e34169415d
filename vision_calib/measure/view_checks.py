"""Per-view (per-frame) acceptance rule applied before a view enters the pose measurement.

A planar PnP pose from a handful of corners in a corner of the board is accepted by PnP (4 corners
suffice) but its error is dominated by what the corner-noise covariance does not model (residual lens
error, a corner biased by blur or a marker misread), so it inflates the pose disagreement downstream.
Each view must therefore:

1. **show enough corners**: at least ``min_view_corners`` (default 6, or every corner of a target that
   has fewer, e.g. one AprilTag). Why 6: the target-plane -> image homography has 8 degrees of freedom,
   so 4 corners fit it exactly and nothing can be checked; 6 corners leave 4 redundant equations (the
   check of step 3 can then see an outlier) and 12 equations for the 6 pose parameters.
2. **span the board**: the convex hull of the seen corners (target plane) must cover at least
   ``min_area_fraction`` (default 0.1) of the hull of all the target's corners: collinear corners
   (area 0) or a small cluster leave the tilt of the board poorly determined.
3. **be consistent with one plane seen by a pinhole**: a robust homography fit on the undistorted corners
   (RANSAC with the outlier threshold below, refined on its inliers; it stops after a few samples when
   nearly all corners agree: 0.19 ms vs 1.4 ms for least-median on 80 corners); a corner farther than ``OUTLIER_K`` x ``corner_noise_px`` from it is dropped
   (listed in the frame diagnostics with its residual; more than MAX_DROPPED_FRACTION of the corners:
   the view is rejected), then the homography is refitted on the rest
   and the view is rejected when its residual std (sqrt(sum |r|^2 / (2K - 8)) px per coordinate)
   exceeds ``RMS_K`` x ``corner_noise_px``.

``corner_noise_px`` (MeasureConfig, default 0.3 px) is an upper bound of the per-coordinate noise of a
sub-pixel corner: the thresholds are 5 sigma for one corner (1.5 px, the pose's ``max_rms_px``) and 3
sigma for the view's residual std (0.9 px).
"""

from __future__ import annotations

import cv2
import numpy as np

#: a corner this many corner-noise sigmas (2-D distance) from the robust homography is an outlier
OUTLIER_K = 5.0
#: a view whose homography residual std exceeds this many corner-noise sigmas is rejected
RMS_K = 3.0
#: more outliers than this fraction of the view's corners: the view is noisy, not a few corners bad (rejected,
#: not trimmed: trimming a noisy view to its best corners would make it look consistent)
MAX_DROPPED_FRACTION = 0.2


def hull_area(xy: np.ndarray) -> float:
    """Area (units of xy squared) of the convex hull of points xy (K, 2); 0 for K < 3."""
    if len(xy) < 3:
        return 0.0
    return float(cv2.contourArea(cv2.convexHull(np.ascontiguousarray(xy, dtype=np.float32))))


def _homography_residuals(xy, uv, method, threshold_px=3.0):
    H, _ = cv2.findHomography(xy, uv, method, threshold_px)
    if H is None or not np.all(np.isfinite(H)):
        return None
    pr = cv2.perspectiveTransform(xy.reshape(-1, 1, 2), H).reshape(-1, 2)
    return np.linalg.norm(uv - pr, axis=1)


def check_view(ids: np.ndarray, p_target: np.ndarray, uv_undist: np.ndarray, min_corners: int,
               min_area_fraction: float, board_area: float, corner_noise_px: float) -> tuple[np.ndarray, str, dict]:
    """The rule of the module docstring on one view.

    ids: (K,) corner ids; p_target: (K, 3) their target coordinates [m] (z = 0); uv_undist: (K, 2)
    undistorted px; min_corners: corners needed (already clipped to the target's count); board_area:
    hull area of all target corners [m^2]. Returns (keep (K,) bool: the corners to use, reason: "" when the
    view is accepted else why not, diag: {area_fraction, homography_rms_px, dropped_corners: [{id,
    residual_px}]})."""
    K = len(ids)
    keep = np.ones(K, bool)
    diag: dict = {}
    if K < min_corners:
        return keep, f"too few corners: {K} < {min_corners}", diag
    xy = np.ascontiguousarray(p_target[:, :2], dtype=np.float64)
    frac = hull_area(xy) / board_area if board_area > 0 else 1.0
    diag["area_fraction"] = float(frac)
    if frac < min_area_fraction:
        return keep, (f"corners span {100 * frac:.1f} % of the board < {100 * min_area_fraction:.0f} % "
                      "(collinear or clustered corners: board tilt poorly determined)"), diag
    if K < 5:  # 4 corners (e.g. one tag): the homography fits them exactly, nothing to check
        return keep, "", diag
    uv = np.ascontiguousarray(uv_undist, dtype=np.float64)
    r = _homography_residuals(xy, uv, cv2.RANSAC if K >= 6 else 0, OUTLIER_K * corner_noise_px)
    if r is None:
        return keep, "no homography fits the corners (degenerate view)", diag
    keep = r <= OUTLIER_K * corner_noise_px
    if not keep.all():
        diag["dropped_corners"] = [{"id": int(i), "residual_px": float(e)} for i, e in zip(ids[~keep], r[~keep])]
    if (~keep).sum() > MAX_DROPPED_FRACTION * K:
        return keep, (f"corners inconsistent with one plane: {int((~keep).sum())} of {K} off the homography "
                      f"by > {OUTLIER_K * corner_noise_px:.2g} px ({OUTLIER_K:g} x corner noise "
                      f"{corner_noise_px:g} px)"), diag
    if keep.sum() < min_corners:
        return keep, (f"too few corners consistent with one plane: {int(keep.sum())} < {min_corners} "
                      f"({int((~keep).sum())} off the homography by > {OUTLIER_K * corner_noise_px:.2g} px)"), diag
    r_in = _homography_residuals(xy[keep], uv[keep], 0)
    n_in = int(keep.sum())
    rms = float(np.sqrt(np.sum(r_in**2) / (2 * n_in - 8))) if r_in is not None and n_in > 4 else 0.0
    diag["homography_rms_px"] = rms
    if r_in is None or rms > RMS_K * corner_noise_px:
        return keep, (f"corners inconsistent with one plane: homography residual std {rms:.3g} px > "
                      f"{RMS_K * corner_noise_px:.2g} px ({RMS_K:g} x corner noise {corner_noise_px:g} px)"), diag
    return keep, "", diag
