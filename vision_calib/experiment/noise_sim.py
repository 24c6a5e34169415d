"""The simulator settings that reproduce a camera's frames of a static target (``vision-calib noise``).

The target is rendered by the project's own renderer (``render.TargetRenderer``, polygon backend, the camera's
lens distortion drawn exactly, as ``sim.intrinsics_views`` does) at the pose PnP gives on the mean corners,
and the sensor stage (``sensor.pose_frames``) adds blur, levels and noise, so that the fit and the simulated
check go through the same code as ``simulate``.

- blur and grey levels (:func:`fit_blur_levels`): around every detected corner / dot, a patch of the mean frame
  (half-size 0.45 x the median distance between neighbouring features, 3..25 px) is fitted by least squares with
  ``a + b * G_sigma(ideal)``: a per-patch offset a (the ink's grey level: ``black_level_grey``) and scale b
  (``exposure``, gain 1) for every sigma of a 0.05 px grid (0..4 px; ``cv2.GaussianBlur`` with the sensor
  stage's kernel). The blur is the minimum of the summed cost (on the grid, then parabolas through costs 0.02 px
  apart);
  its standard error is the std of the per-patch minima / sqrt(patches) (with :data:`SE_FLOOR`). Noise is
  zero-mean, so it does not bias this fit; a pose off by a fraction of a pixel adds only second-order blur.
- dot diameter, when the target does not give it (ROS-I sets): the same fit over a grid of d / spacing
  (0.15 .. 0.66; the origin dot twice the others), the pose re-solved for each (the modified grid's corner
  coordinates depend on the diameters); minimum of the summed cost, standard error from the per-patch minima.
- simulated scatter (:func:`simulate_scatter`): ``n`` frames of the fitted settings at that pose, detected
  and measured like the real ones.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from ..camera import CameraIntrinsics
from ..errors import DataError
from ..measure.noise_qualification import common_corners, corner_scatter, pose_scatter
from ..measure.pnp import solve_pnp_planar, target_lookup, undistort_px
from ..sensor.maps import gaussian_ksize

#: blur grid [px] of the fit
SIGMA_GRID = np.round(np.arange(0.0, 4.0001, 0.05), 4)
#: resolution of the image fit, added in quadrature to the patch-scatter standard errors: the mean errors over
#: simulated folders (24 seeds ChArUco, 12 modified circle grid; 640x480, blur 1.3 px, 10 frames) reached
#: +0.0002 px (blur), -0.016 grey (black level), +1.8e-4 (exposure), beyond what the patch scatter gave
SE_FLOOR = {"blur": 5e-4, "black": 0.02, "exposure": 2e-4}
#: dot diameter / spacing grid when the target has no diameter
DIAMETER_GRID = np.round(np.arange(0.15, 0.6601, 0.03), 4)


def render_ideal(target, camera: CameraIntrinsics, T_cam_target: np.ndarray) -> np.ndarray:
    """(ideal grey image (H, W) float32 [0, 255] of the target at T_cam_target, lens distortion drawn exactly;
    the TargetRenderer that drew it, for ``sensor.effects_for_render``)."""
    from ..render import TargetRenderer

    r = TargetRenderer(target, camera, backend="polygon", distort=any(camera.dist))
    return r.render(T_cam_target), r


def mean_pose_of(target, ids: np.ndarray, uv_mean_px: np.ndarray, camera: CameraIntrinsics) -> np.ndarray:
    """T_cam_target (4, 4) by PnP on the mean corners uv_mean_px (K, 2) (distorted px) of ids (K,)."""
    lookup = target_lookup(target)
    p = np.array([lookup[int(i)] for i in ids])
    return solve_pnp_planar(p, undistort_px(uv_mean_px, camera), camera)[0]


def patch_boxes(uv_px: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, int]:
    """(centres (P, 2) int px of the patches inside the image, half-size h px) around features uv_px (K, 2)."""
    d = np.linalg.norm(uv_px[:, None] - uv_px[None], axis=2)
    np.fill_diagonal(d, np.inf)
    h = int(np.clip(np.floor(0.45 * np.median(d.min(axis=1))), 3, 25))
    c = np.rint(uv_px).astype(int)
    w, hgt = size
    inside = (c[:, 0] - h >= 0) & (c[:, 1] - h >= 0) & (c[:, 0] + h < w) & (c[:, 1] + h < hgt)
    if inside.sum() < 1:
        raise DataError("no feature far enough from the image border to measure the blur around it")
    return c[inside], h


def _stack(img: np.ndarray, centres: np.ndarray, h: int) -> np.ndarray:
    """(P, (2h+1)^2) pixel values of the patches."""
    k = 2 * h + 1
    out = np.empty((len(centres), k * k))
    for i, (u, v) in enumerate(centres):
        out[i] = img[v - h:v + h + 1, u - h:u + h + 1].ravel()
    return out


def _blurred(ideal: np.ndarray, sigma: float, box) -> np.ndarray:
    """The sensor stage's Gaussian blur of ideal, computed on the crop box (x0, y0, x1, y1) only (exact there:
    the box holds the kernel's reach around every patch)."""
    x0, y0, x1, y1 = box
    crop = np.ascontiguousarray(ideal[y0:y1, x0:x1], dtype=np.float32)
    if sigma > 0:
        k = gaussian_ksize(sigma)
        crop = cv2.GaussianBlur(crop, (k, k), sigma, sigmaY=sigma, borderType=cv2.BORDER_REPLICATE)
    out = np.zeros(ideal.shape, np.float32)
    out[y0:y1, x0:x1] = crop
    return out


def _costs(mean_img: np.ndarray, ideal: np.ndarray, centres: np.ndarray, h: int, sigmas) -> tuple:
    """Per-patch least-squares fit of mean_img ~ a + b G_sigma(ideal) for each sigma: (cost (S, P), a (S, P),
    b (S, P))."""
    reach = gaussian_ksize(float(max(sigmas))) // 2 + h + 2
    H, W = ideal.shape
    box = (max(centres[:, 0].min() - reach, 0), max(centres[:, 1].min() - reach, 0),
           min(centres[:, 0].max() + reach + 1, W), min(centres[:, 1].max() + reach + 1, H))
    M = _stack(mean_img, centres, h)
    cost, A, B = (np.empty((len(sigmas), len(centres))) for _ in range(3))
    for s, sigma in enumerate(sigmas):
        X = _stack(_blurred(ideal, float(sigma), box), centres, h)
        xm, mm = X.mean(axis=1, keepdims=True), M.mean(axis=1, keepdims=True)
        dx, dm = X - xm, M - mm
        sxx = np.sum(dx * dx, axis=1)
        b = np.where(sxx > 0, np.sum(dx * dm, axis=1) / np.where(sxx > 0, sxx, 1.0), 0.0)
        a = mm[:, 0] - b * xm[:, 0]
        cost[s] = np.sum((dm - b[:, None] * dx) ** 2, axis=1)
        A[s], B[s] = a, b
    return cost, A, B


def _argmin_parabola(grid: np.ndarray, cost: np.ndarray) -> float:
    """Minimum of a sampled cost (parabola through the lowest grid point and its neighbours)."""
    i = int(np.argmin(cost))
    if i == 0 or i == len(grid) - 1:
        return float(grid[i])
    c0, c1, c2 = cost[i - 1], cost[i], cost[i + 1]
    den = c0 - 2 * c1 + c2
    step = grid[i + 1] - grid[i]
    return float(grid[i] + (0.5 * (c0 - c2) / den * step if den > 0 else 0.0))


def _local_min(mean_img, ideal, centres, h, s0: float, step: float = 0.02) -> tuple:
    """Refine a blur minimum s0 [px]: costs at 3 sigmas ``step`` apart around it (from 0 at the lower bound),
    the vertex of the parabola of the summed cost and of each patch's. Returns (sigma, per-patch sigmas (P,),
    a (P,), b (P,)) at the three points' middle."""
    lo = max(s0 - step, 0.0)
    grid = np.array([lo, lo + step, lo + 2 * step])
    cost, A, B = _costs(mean_img, ideal, centres, h, grid)

    def vertex(c):
        den = c[0] - 2 * c[1] + c[2]
        return float(np.clip(grid[1] + 0.5 * (c[0] - c[2]) / den * step, 0.0, None)) if den > 0 else float(grid[1])

    return vertex(cost.sum(axis=1)), np.array([vertex(cost[:, k]) for k in range(cost.shape[1])]), A[1], B[1]


def fit_blur_levels(mean_img: np.ndarray, ideal: np.ndarray, uv_px: np.ndarray, sigmas=SIGMA_GRID) -> dict:
    """Blur sigma [px], black level [grey] and exposure (gain 1) of the mean frame mean_img (H, W) against the
    ideal render (H, W) of the same pose, from patches around the features uv_px (K, 2) (module docstring;
    the grid minimum is refined twice by parabolas through costs 0.02 px apart).
    Returns {blur_sigma_px, blur_se_px, black_level_grey, black_se, exposure, exposure_se, exposure_spread
    (relative std over patches: uneven lighting), patches, patch_half_px, at_grid_edge}."""
    centres, h = patch_boxes(uv_px, (mean_img.shape[1], mean_img.shape[0]))
    cost, _, _ = _costs(mean_img, ideal, centres, h, sigmas)
    sigma = _argmin_parabola(sigmas, cost.sum(axis=1))
    at_edge = bool(sigma >= sigmas[-1] - 1e-9)
    for _ in range(2):
        sigma, per, a, b = _local_min(mean_img, ideal, centres, h, sigma)
    P = len(per)

    def se(x, floor):
        return float(np.hypot(np.std(x, ddof=1) / np.sqrt(len(x)), floor)) if len(x) > 1 else float("nan")

    return {"blur_sigma_px": sigma, "blur_se_px": se(per, SE_FLOOR["blur"]), "black_level_grey": float(np.mean(a)),
            "black_se": se(a, SE_FLOOR["black"]), "exposure": float(np.mean(b)),
            "exposure_se": se(b, SE_FLOOR["exposure"]),
            "exposure_spread": float(np.std(b) / np.mean(b)) if P > 1 else 0.0, "patches": P,
            "patch_half_px": h, "at_grid_edge": at_edge}


def fit_dot_diameter(target, camera: CameraIntrinsics, ids, uv_mean_px, mean_img) -> dict:
    """Dot diameter [m] of a circle-grid target that does not give it (module docstring): the grid minimum of
    the summed patch cost (blur on a 0.2 px grid), refined by a bounded scalar search with the blur fitted at
    each diameter; the standard error from the per-patch minima (parabolas 0.002 spacing apart, blur fixed).
    Returns {diameter_m, diameter_se_m, ratio (d / spacing), at_grid_edge}."""
    from scipy.optimize import minimize_scalar

    centres, h = patch_boxes(uv_mean_px, (mean_img.shape[1], mean_img.shape[0]))

    def ideal_at(r):
        spec = replace(target, diameter_m=float(r * target.spacing_m), origin_diameter_m=0.0)
        return render_ideal(spec, camera, mean_pose_of(spec, ids, uv_mean_px, camera))[0]

    coarse = SIGMA_GRID[::4]
    totals = [_costs(mean_img, ideal_at(r), centres, h, coarse)[0].sum(axis=1).min() for r in DIAMETER_GRID]
    r0 = _argmin_parabola(DIAMETER_GRID, np.array(totals))
    step = float(DIAMETER_GRID[1] - DIAMETER_GRID[0])

    def total(r):
        ideal = ideal_at(r)
        sigma = fit_blur_levels(mean_img, ideal, uv_mean_px)["blur_sigma_px"]
        return float(_costs(mean_img, ideal, centres, h, [sigma])[0].sum())

    lo, hi = max(r0 - step, DIAMETER_GRID[0]), min(r0 + step, DIAMETER_GRID[-1])
    r = float(minimize_scalar(total, bounds=(lo, hi), method="bounded", options={"xatol": 1e-5}).x)
    sigma = fit_blur_levels(mean_img, ideal_at(r), uv_mean_px)["blur_sigma_px"]
    dr = 0.002
    c = np.array([_costs(mean_img, ideal_at(x), centres, h, [sigma])[0][0] for x in (r - dr, r, r + dr)])  # (3, P)
    den = c[0] - 2 * c[1] + c[2]
    ok = den > 0
    per = r + 0.5 * (c[0] - c[2])[ok] / den[ok] * dr
    se = float(np.std(per, ddof=1) / np.sqrt(len(per))) if len(per) > 1 else float("nan")
    return {"diameter_m": float(r * target.spacing_m), "diameter_se_m": se * target.spacing_m, "ratio": r,
            "at_grid_edge": bool(r0 <= DIAMETER_GRID[0] + 1e-9 or r0 >= DIAMETER_GRID[-1] - 1e-9)}


def simulate_frames(target, camera: CameraIntrinsics, T_cam_target, effects, n_frames: int, seed: int) -> np.ndarray:
    """(n, H, W) uint8 frames of the target at T_cam_target with the sensor effects (CPU sensor stage)."""
    from ..sensor import effects_for_render, pose_frames

    ideal, r = render_ideal(target, camera, T_cam_target)
    return pose_frames(ideal, effects_for_render(r, effects), int(n_frames), int(seed), camera).stack()


def simulate_scatter(target, camera: CameraIntrinsics, T_cam_target, effects, n_frames: int, seed: int,
                     detect_config) -> dict:
    """Corner and pose scatter of ``n_frames`` simulated frames (same measurement as the real frames):
    {"corners": :func:`corner_scatter` dict, "pose": PoseScatter, "n_corners": K}. DataError when the
    target is not detected in a simulated frame."""
    from ..measure.batch import detect_batch

    imgs = simulate_frames(target, camera, T_cam_target, effects, n_frames, seed)
    dets = detect_batch(list(imgs), target, camera, detect_config)
    bad = [d for d in dets if not d.valid]
    if bad:
        raise DataError(f"the simulator's frame {bad[0].frame_index} with the fitted settings: target not detected "
                        f"({bad[0].reason})")
    ids, uv = common_corners(dets)
    cs = corner_scatter(uv)
    return {"corners": cs, "pose": pose_scatter(ids, uv, target, camera, cs["xy"].std), "n_corners": len(ids)}


__all__ = ["render_ideal", "mean_pose_of", "fit_blur_levels", "fit_dot_diameter", "simulate_frames",
           "simulate_scatter", "SIGMA_GRID"]
