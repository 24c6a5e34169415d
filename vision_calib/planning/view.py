"""Is the target measurable from a pose? The view figures of the camera's pose of the target T_cam_target, vectorised
over poses (numpy), and the limits the planner holds them to (the scene's ``planning`` section, ``rig.cell``).

Figures per pose:

- ``margin_px``: the smallest distance from the projected bounding box of the points the measurement uses (the
  corners; the scene's own pose sampler holds the same box in view) to the image border (negative: a corner
  outside the image), distortion included;
- ``distance_m``: camera centre to board centre;
- ``incidence_deg``: angle between the board's normal and the viewing ray to its centre (0: seen square on);
- ``square_px``: the smallest projected side of one feature cell (a square of a ChArUco board or chessboard, a tag
  pitch, a dot spacing: the pattern's size over its rows / cols) at the pattern's four corners and centre, along
  both board axes, distortion included (the projection is smooth: its extremes lie at the pattern's corners);
- ``front``: the camera sees the printed side (the board's +z axis points away from the camera) and every outline
  corner is at least :data:`MIN_DEPTH_M` in front of it.

A pose is measurable when front, margin_px >= the scene's margin, distance within its limits, incidence <= its
maximum and square_px >= :data:`MIN_SQUARE_PX`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: smallest side of a feature cell in pixels that the detectors find reliably: ChArUco / chessboard corners need
#: a few pixels of each square around them (OpenCV's corner refinement window is 2 x 5 + 1 px at full size but
#: adapts down; below ~6 px per square the markers' bits (square / 7 to / 9) are under one pixel and detection
#: fails), so 6 px per square is the floor we plan against
MIN_SQUARE_PX = 6.0
#: outline corners closer than this to the camera plane [m] count as behind the camera
MIN_DEPTH_M = 0.02
FIGURES = ("margin_px", "distance_m", "incidence_deg", "square_px")


@dataclass(frozen=True)
class ViewLimits:
    """margin_px (board outline to image border), distance_m (min, max) camera to board centre, max_incidence_rad,
    min_square_px."""

    margin_px: float
    distance_m: tuple[float, float]
    max_incidence_rad: float
    min_square_px: float = MIN_SQUARE_PX

    @classmethod
    def of_scene(cls, scene) -> "ViewLimits":
        p = scene.planning
        return cls(p.margin_px, p.distance_m, p.max_incidence_rad)


def _probes(target) -> tuple[np.ndarray, float]:
    """(points (5, 3) [m, target frame]: the pattern's corners and centre, feature cell side [m])."""
    w, h = target.pattern_size_m()
    cell = min(w / target.cols, h / target.rows)
    # the pattern spans [0, w] x [0, h] of the target frame (TargetSpec.texture_extent_m adds the margin around it)
    return np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0], [w / 2, h / 2, 0]], float), cell


def _centre_ray(T: np.ndarray, target) -> tuple[np.ndarray, np.ndarray]:
    """(distance (N,) [m] camera centre to the pattern's centre, cos (N,) of the angle between the board's +z and
    the viewing ray to that centre: > 0 for a board seen from its front) at poses T (N, 4, 4)."""
    centre = np.einsum("nij,j->ni", T[:, :3, :3], _probes(target)[0][4]) + T[:, :3, 3]
    dist = np.linalg.norm(centre, axis=1)
    return dist, np.einsum("ni,ni->n", T[:, :3, 2], centre) / np.maximum(dist, 1e-12)


def incidence_rad(T_cam_target: np.ndarray, target) -> np.ndarray:
    """(N,) [rad] angle between the board's normal and the viewing ray to the pattern's centre (0: seen square on)
    at camera poses of the target T_cam_target (N, 4, 4) [m]: the ``incidence_deg`` of :func:`view_figures`."""
    return np.arccos(np.clip(np.abs(_centre_ray(np.asarray(T_cam_target, float), target)[1]), 0.0, 1.0))


def view_figures(T_cam_target: np.ndarray, camera, target) -> dict:
    """{margin_px, distance_m, incidence_deg, square_px: (N,) float, front: (N,) bool} of camera poses of the target
    T_cam_target (N, 4, 4) [m] with intrinsics ``camera`` (``CameraIntrinsics``) and ``target`` (a TargetSpec)."""
    T = np.asarray(T_cam_target, float)
    N = T.shape[0]
    R, t = T[:, :3, :3], T[:, :3, 3]
    outline = target.measured_outline_m()  # the scenes' pose sampler holds the same box in view
    probes, cell = _probes(target)
    steps = np.concatenate([probes, probes + [cell, 0, 0], probes + [0, cell, 0]])  # (15, 3)
    pts = np.concatenate([outline, steps])  # (19, 3)
    p = np.einsum("nij,kj->nki", R, pts) + t[:, None, :]  # (N, 19, 3) camera frame
    z = p[..., 2]
    front_z = np.all(z[:, :4] >= MIN_DEPTH_M, axis=1) & np.all(z > MIN_DEPTH_M, axis=1)
    zs = np.where(z > MIN_DEPTH_M, z, np.nan)
    uv = camera.project(np.concatenate([p[..., :2], zs[..., None]], axis=2).reshape(-1, 3)).reshape(N, -1, 2)
    ou = uv[:, :4]
    margin = np.min(np.stack([ou[..., 0], camera.width - 1 - ou[..., 0], ou[..., 1], camera.height - 1 - ou[..., 1]],
                             axis=-1), axis=(1, 2))
    su = uv[:, 4:].reshape(N, 3, 5, 2)
    side = np.minimum(np.linalg.norm(su[:, 1] - su[:, 0], axis=-1), np.linalg.norm(su[:, 2] - su[:, 0], axis=-1))
    dist, cosang = _centre_ray(T, target)  # board +z away from the camera for a board seen from its front
    front = front_z & (cosang > 0) & np.isfinite(margin)
    return {"margin_px": np.where(front, margin, np.nan), "distance_m": dist,
            "incidence_deg": np.degrees(np.arccos(np.clip(np.abs(cosang), 0, 1))),
            "square_px": np.where(front, np.min(side, axis=1), np.nan), "front": front}


def measurable(fig: dict, limits: ViewLimits) -> tuple[np.ndarray, dict]:
    """(ok (N,) bool, {reason: (N,) bool failing}) of view figures against the limits; reasons: behind, outside
    (margin), distance, incidence, square (too small)."""
    with np.errstate(invalid="ignore"):
        fails = {
            "behind": ~fig["front"],
            "outside": fig["front"] & ~(fig["margin_px"] >= limits.margin_px),
            "distance": (fig["distance_m"] < limits.distance_m[0]) | (fig["distance_m"] > limits.distance_m[1]),
            "incidence": fig["incidence_deg"] > np.degrees(limits.max_incidence_rad),
            "square": fig["front"] & ~(fig["square_px"] >= limits.min_square_px),
        }
    ok = ~np.any(np.stack(list(fails.values())), axis=0)
    return ok, fails


__all__ = ["MIN_SQUARE_PX", "ViewLimits", "incidence_rad", "view_figures", "measurable", "FIGURES"]
