"""Camera intrinsics (fx, fy, cx, cy, Brown–Conrady k1 k2 p1 p2 k3) from detections of a planar target
in many views, by ``cv2.calibrateCameraExtended`` (OpenCV's Zhang initialisation + Levenberg–Marquardt).

Works for every target kind whose ``detect()`` returns corner ids + ``uv_px``: the 3-D points are
``target.corner_points()`` matched by id (target frame, metres, z = 0).

Uncertainty (:func:`intrinsics_covariance`): from the analytic reprojection Jacobian of
``cv2.projectPoints`` at the solution, the view poses eliminated by a Schur complement, scaled by the
a-posteriori residual variance sigma^2 = SSE / (2 N - p) (N points, p free parameters). OpenCV's own
``stdDeviationsIntrinsics`` also contains the residual variance and agrees on well-posed data, but it
inverts the normal matrix with a pseudo-inverse, which hides a null space: on views all fronto-parallel
it reported std(fx) = 0.023 px for an fx 319 px off the truth (tilt < 0.01 deg, 12 views). Here such a
problem is refused (condition of the scaled normal matrix, std > ``max_std_frac`` x width).
Checked on white noise (``benchmarks/bench_intrinsics.py``, "white-noise check"). RMS values follow
OpenCV: sqrt(mean over points of |uv_detected - uv_projected|^2) [px] (the 2-D error per point; per
coordinate it is RMS / sqrt(2)).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from ..camera import CameraIntrinsics
from ..errors import ConfigError, DataError

PARAM_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


@dataclass(frozen=True)
class CalibrationConfig:
    """min_corners: fewer corners in a view -> view rejected. min_views: fewer usable views -> DataError.
    min_spread: the detected corners' smaller principal spread in the target plane over the larger one
    (0 = collinear) below which a view is rejected (its homography is degenerate).
    outlier_factor, outlier_floor_px: a view whose RMS exceeds max(outlier_factor * median view RMS,
    outlier_floor_px) is dropped and the rest refitted (repeated while views drop, at most 3 rounds).
    max_std_frac: DataError when the std of fx, fy, cx or cy exceeds this fraction of the image width
    (focal length / principal point not determined: views all fronto-parallel, or too few).
    grid: (columns, rows) of image cells for the coverage figure. flags: extra cv2.CALIB_* flags
    (e.g. cv2.CALIB_FIX_K3 for a narrow lens)."""

    min_corners: int = 8
    min_views: int = 4
    min_spread: float = 0.05
    outlier_factor: float = 3.0
    outlier_floor_px: float = 0.5
    max_std_frac: float = 0.02
    grid: tuple[int, int] = (8, 6)
    flags: int = 0

    def __post_init__(self):
        if self.min_corners < 4 or self.min_views < 3:
            raise ConfigError("CalibrationConfig: min_corners must be >= 4 and min_views >= 3")
        if not (self.outlier_factor > 1 and self.outlier_floor_px > 0 and self.max_std_frac > 0):
            raise ConfigError("CalibrationConfig: outlier_factor > 1, outlier_floor_px > 0, max_std_frac > 0 needed")
        if len(self.grid) != 2 or min(self.grid) < 2:
            raise ConfigError(f"CalibrationConfig.grid must be (columns, rows) >= 2, got {self.grid!r}")


@dataclass(frozen=True)
class ViewInfo:
    """One view: name (file or pose id), n_corners, rms_px (nan when not fitted), used, reason (why not)."""

    name: str
    n_corners: int
    rms_px: float = float("nan")
    used: bool = False
    reason: str = ""

    def to_dict(self) -> dict:
        return {"name": self.name, "n_corners": int(self.n_corners),
                "rms_px": None if not np.isfinite(self.rms_px) else float(self.rms_px), "used": bool(self.used),
                "reason": self.reason}


@dataclass(frozen=True)
class IntrinsicsResult:
    """camera: the calibrated CameraIntrinsics. std: {name: 1-sigma} for PARAM_NAMES [px; dist unitless].
    rms_px: overall reprojection RMS of the used views [px, 2-D error per point]. views: every view,
    used or rejected with its reason. coverage: {grid, fraction, radius_frac, warnings}; warnings: all
    warnings (coverage + dropped outlier views). cov: (9, 9) covariance of PARAM_NAMES. distortion:
    :func:`distortion_uncertainty` at the image corners and the farthest detected corner (px)."""

    camera: CameraIntrinsics
    std: dict
    rms_px: float
    views: tuple
    coverage: dict
    warnings: tuple = field(default=())
    cov: np.ndarray | None = None
    distortion: dict | None = None

    @property
    def n_used(self) -> int:
        return sum(v.used for v in self.views)

    def values(self) -> dict:
        c = self.camera
        return dict(zip(PARAM_NAMES, (c.fx, c.fy, c.cx, c.cy, *c.dist)))

    def to_dict(self) -> dict:
        """JSON/YAML-ready: the camera block (width .. dist) + std, rms_px, covariance {names, matrix (9, 9)} of
        PARAM_NAMES (when finite), views, coverage, warnings."""
        return {**self.camera.to_dict(),
                "std": {k: float(self.std[k]) for k in PARAM_NAMES[:4]} | {"dist": [float(self.std[k])
                                                                                  for k in PARAM_NAMES[4:]]},
                "rms_px": float(self.rms_px), "n_views_used": self.n_used,
                "n_views_rejected": len(self.views) - self.n_used,
                **({"distortion_px": distortion_summary(self.distortion)} if self.distortion else {}),
                **({"covariance": {"names": list(PARAM_NAMES), "matrix": [[float(v) for v in row]
                                                                          for row in np.asarray(self.cov)]}}
                   if self.cov is not None and np.all(np.isfinite(self.cov)) else {}),
                "coverage": self.coverage, "warnings": list(self.warnings),
                "views": [v.to_dict() for v in self.views]}


def _view_points(det, lookup: dict, p3: np.ndarray):
    """(object points (K, 3) float32, image points (K, 2) float32) of one detection, matched by id."""
    idx = [lookup[int(i)] for i in det.ids if int(i) in lookup]
    uv = np.asarray(det.uv_px, float)[[k for k, i in enumerate(det.ids) if int(i) in lookup]]
    return p3[idx].astype(np.float32), uv.astype(np.float32)


def _spread(obj: np.ndarray) -> float:
    """Smaller / larger singular value of the centred target-plane points (0 = collinear)."""
    xy = obj[:, :2] - obj[:, :2].mean(axis=0)
    s = np.linalg.svd(xy, compute_uv=False)
    return float(s[1] / s[0]) if s[0] > 0 else 0.0


def _view_rms(obj, img, rvec, tvec, K, dist) -> float:
    proj = cv2.projectPoints(obj, rvec, tvec, K, dist)[0].reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum((proj - img) ** 2, axis=1))))


def coverage(uv_list, size: tuple[int, int], grid=(8, 6), principal=None) -> dict:
    """How much of the image the detected corners reach. uv_list: list of (K, 2) px; size (width, height).
    Returns {grid: [cols, rows], fraction: cells with a corner / all cells, radius_frac: largest corner
    distance from the principal point over the distance to the farthest image corner, warnings: [...]}:
    named warnings for image corners (corner cells) and borders (outer cell rows/columns) never reached,
    where the distortion is extrapolated."""
    w, h = size
    gc, gr = grid
    pts = np.concatenate([np.asarray(u, float).reshape(-1, 2) for u in uv_list]) if uv_list else np.zeros((0, 2))
    hit = np.zeros((gr, gc), bool)
    if len(pts):
        c = np.clip(((pts[:, 0] + 0.5) / w * gc).astype(int), 0, gc - 1)
        r = np.clip(((pts[:, 1] + 0.5) / h * gr).astype(int), 0, gr - 1)
        hit[r, c] = True
    pp = np.array(principal if principal is not None else ((w - 1) / 2, (h - 1) / 2), float)
    corners = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [-0.5, h - 0.5], [w - 0.5, h - 0.5]])
    r_max = np.max(np.linalg.norm(corners - pp, axis=1))
    radius = float(np.max(np.linalg.norm(pts - pp, axis=1)) / r_max) if len(pts) else 0.0
    warnings = []
    names = {(0, 0): "top-left", (0, gc - 1): "top-right", (gr - 1, 0): "bottom-left", (gr - 1, gc - 1): "bottom-right"}
    missed = [n for (r_, c_), n in names.items() if not hit[r_, c_]]
    if missed:
        warnings.append(f"corners never reached the {', '.join(missed)} corner(s) of the image (cells of 1/{gc} x "
                        f"1/{gr} of the image): the distortion there is extrapolated")
    borders = {"left": hit[:, 0], "right": hit[:, -1], "top": hit[0, :], "bottom": hit[-1, :]}
    empty = [n for n, cells in borders.items() if not cells.any()]
    if empty:
        warnings.append(f"no corners in the {', '.join(empty)} border(s) of the image (outer 1/{gc} of the width, "
                        f"1/{gr} of the height): the distortion there is extrapolated")
    if radius < 0.8:
        warnings.append(f"corners reach only {100 * radius:.0f} % of the distance from the principal point to the "
                        "image corners: the radial distortion beyond is extrapolated")
    return {"grid": [gc, gr], "fraction": float(hit.mean()), "radius_frac": radius, "warnings": warnings}


def _fit(objs, imgs, size, flags):
    """One calibrateCameraExtended run -> (rms, K, dist (5,), rvecs, tvecs). Run on one OpenCV thread: its threaded
    sums are not bit-reproducible (the same images gave intrinsics differing at 1e-9 run to run, and every answer
    after them at up to 6e-6 of its std)."""
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        out = cv2.calibrateCameraExtended(objs, imgs, size, None, None, flags=flags, criteria=crit)
    except cv2.error as exc:
        raise DataError(f"camera calibration failed in OpenCV: {str(exc).strip().splitlines()[-1]}") from None
    finally:
        cv2.setNumThreads(threads)
    rms, K, dist, rvecs, tvecs = out[0], out[1], out[2], out[3], out[4]
    return rms, K, np.asarray(dist, float).ravel()[:5], rvecs, tvecs


#: cv2.CALIB_* flags that fix some of PARAM_NAMES (their std is 0); other flags are refused
_FIXING = {cv2.CALIB_FIX_PRINCIPAL_POINT: ("cx", "cy"), cv2.CALIB_ZERO_TANGENT_DIST: ("p1", "p2"),
           cv2.CALIB_FIX_K1: ("k1",), cv2.CALIB_FIX_K2: ("k2",), cv2.CALIB_FIX_K3: ("k3",)}


def _free_mask(flags: int) -> np.ndarray:
    """(9,) bool: which of PARAM_NAMES the cv2 flags leave free; ConfigError for unsupported flags."""
    known = sum(_FIXING) | cv2.CALIB_USE_INTRINSIC_GUESS
    if flags & ~known:
        raise ConfigError(f"CalibrationConfig.flags: only CALIB_FIX_PRINCIPAL_POINT, CALIB_ZERO_TANGENT_DIST, "
                          f"CALIB_FIX_K1/K2/K3 are supported, got {flags}")
    free = np.ones(9, bool)
    for f, names in _FIXING.items():
        if flags & f:
            free[[PARAM_NAMES.index(n) for n in names]] = False
    return free


def intrinsics_covariance(objs, imgs, rvecs, tvecs, K, dist, free) -> tuple[np.ndarray, float, float]:
    """(cov (9, 9) of PARAM_NAMES [px^2 ...] (fixed ones 0; inf on the diagonal when singular), sigma [px
    per coordinate], condition number of the column-scaled reduced normal matrix). objs/imgs: per view
    (K_i, 3) [m] / (K_i, 2) [px]; rvecs/tvecs: the fitted view poses; free: (9,) bool."""
    A = np.zeros((9, 9))
    sse, n = 0.0, 0
    for o, i, rv, tv in zip(objs, imgs, rvecs, tvecs):
        proj, J = cv2.projectPoints(o, rv, tv, K, dist)
        e = proj.reshape(-1, 2) - i
        sse += float(np.sum(e**2))
        n += e.size
        Jp, Ji = J[:, :6], J[:, 6:15][:, free]
        D = Jp.T @ Jp
        B = Ji.T @ Jp
        A_i = Ji.T @ Ji
        try:
            A[np.ix_(free, free)] += A_i - B @ np.linalg.solve(D, B.T)
        except np.linalg.LinAlgError:
            A[np.ix_(free, free)] += A_i  # a degenerate view pose: ignore its coupling (rare)
    p = int(free.sum()) + 6 * len(objs)
    sigma2 = sse / max(n - p, 1)
    Af = A[np.ix_(free, free)]
    s = np.sqrt(np.maximum(np.diag(Af), 1e-300))
    As = Af / np.outer(s, s)
    ev = np.linalg.eigvalsh(As)
    cond = float(ev[-1] / ev[0]) if ev[0] > 0 else float("inf")
    cov = np.zeros((9, 9))
    if not np.isfinite(cond) or cond > 1e14:
        cov[np.ix_(free, free)] = np.inf
    else:
        cov[np.ix_(free, free)] = np.linalg.inv(As) / np.outer(s, s) * sigma2
    return cov, float(np.sqrt(sigma2)), cond


def distortion_displacement(cam: CameraIntrinsics, xy: np.ndarray) -> np.ndarray:
    """(N, 2) [px] displacement the lens distortion of cam gives the ideal points xy (N, 2) [normalised
    image coordinates x/z, y/z]: (fx (x_d - x), fy (y_d - y)), (x_d, y_d) OpenCV's Brown–Conrady model."""
    x, y = np.asarray(xy, float).T
    k1, k2, p1, p2, k3 = cam.dist
    r2 = x * x + y * y
    rad = k1 * r2 + k2 * r2**2 + k3 * r2**3
    dx = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    dy = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.column_stack([cam.fx * dx, cam.fy * dy])


def displacement_jacobian(cam: CameraIntrinsics, xy: np.ndarray) -> np.ndarray:
    """(N, 2, 9) d displacement [px] (:func:`distortion_displacement`) / d PARAM_NAMES (fx, fy, cx, cy, k1, k2, p1,
    p2, k3) at fixed normalised points xy (N, 2)."""
    x, y = np.asarray(xy, float).T
    r2 = x * x + y * y
    d = distortion_displacement(cam, xy)
    J = np.zeros((len(x), 2, 9))
    J[:, 0, 0], J[:, 1, 1] = d[:, 0] / cam.fx, d[:, 1] / cam.fy
    for j, g in ((4, r2), (5, r2**2), (8, r2**3)):
        J[:, 0, j], J[:, 1, j] = cam.fx * x * g, cam.fy * y * g
    J[:, 0, 6], J[:, 1, 6] = cam.fx * 2 * x * y, cam.fy * (r2 + 2 * y * y)
    J[:, 0, 7], J[:, 1, 7] = cam.fx * (r2 + 2 * x * x), cam.fy * 2 * x * y
    return J


def distortion_uncertainty(cam: CameraIntrinsics, cov: np.ndarray, uv_far) -> dict:
    """How well the distortion is known in pixels, where it matters most. cov: (9, 9) of PARAM_NAMES;
    uv_far: (2,) px, the detected corner farthest from the principal point (None: none).
    Returns {corners_xy (4, 2): normalised ideal points seen at the centres of the image-corner pixels
    (TL, TR, BL, BR), displacement_corners_px (4,) |distortion displacement| there, std_corners_px (4,):
    1-sigma of that displacement vector along its worst direction (sqrt of the largest eigenvalue of its
    2 x 2 covariance, fx .. k3 all propagated), and the same at uv_far: max_radius_px (its distance from
    the principal point), displacement_max_radius_px, std_max_radius_px}. The points are held fixed in
    normalised coordinates: the std is that of the pixel correction undistortion applies there."""
    w, h = cam.width, cam.height
    uv = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]]
                  + ([list(uv_far)] if uv_far is not None else []), float)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
    xy = cv2.undistortPointsIter(uv.reshape(-1, 1, 2), cam.K, cam.dist_array, None, None, crit).reshape(-1, 2)
    J = displacement_jacobian(cam, xy)
    if np.isfinite(cov).all():
        std = np.sqrt(np.maximum(np.linalg.eigvalsh(np.einsum("nai,ij,nbj->nab", J, cov, J))[:, -1], 0.0))
    else:
        std = np.full(len(xy), np.inf)
    mag = np.linalg.norm(distortion_displacement(cam, xy), axis=1)
    out = {"corners_xy": xy[:4], "displacement_corners_px": mag[:4], "std_corners_px": std[:4]}
    if uv_far is not None:
        out |= {"max_radius_px": float(np.hypot(uv[4, 0] - cam.cx, uv[4, 1] - cam.cy)),
                "displacement_max_radius_px": float(mag[4]), "std_max_radius_px": float(std[4])}
    return out


def distortion_summary(d: dict) -> dict:
    """YAML-ready part of :func:`distortion_uncertainty` (floats; image corners TL, TR, BL, BR)."""
    out = {"image_corners": {"displacement": [round(float(v), 4) for v in d["displacement_corners_px"]],
                             "std": [float(v) for v in d["std_corners_px"]]}}
    if "max_radius_px" in d:
        out["max_radius"] = {"radius": round(d["max_radius_px"], 2),
                             "displacement": round(d["displacement_max_radius_px"], 4),
                             "std": d["std_max_radius_px"]}
    return out


def calibrate_intrinsics(detections, names, target, image_size=None,
                         config: CalibrationConfig = CalibrationConfig()) -> IntrinsicsResult:
    """Calibrate from per-view detections (``measure.detect.Detection``; invalid ones are rejected with
    their reason). names: one label per detection (file or pose id). image_size: (width, height) px;
    default: the size most valid detections have (the majority, not the first); views of another size are
    rejected.
    Raises DataError (too few usable views; OpenCV failure; focal length / principal point not
    determined: std > ``config.max_std_frac`` x width, typical of views all fronto-parallel)."""
    ids3, p3 = target.corner_points()
    lookup = {int(i): k for k, i in enumerate(ids3)}
    from .image_header import majority_size

    size = tuple(int(v) for v in image_size) if image_size is not None else majority_size(
        [tuple(d.image_size) for d in detections if d.valid and d.image_size is not None])[0]
    views, data = [], []  # data: index into views -> (obj, img)
    for det, name in zip(detections, names):
        if not det.valid:
            views.append(ViewInfo(str(name), det.n_corners, reason=det.reason or "no detection"))
            continue
        if size is not None and det.image_size is not None and tuple(det.image_size) != size:
            views.append(ViewInfo(str(name), det.n_corners, reason=f"image size {det.image_size[0]}x"
                                  f"{det.image_size[1]} differs from {size[0]}x{size[1]}"))
            continue
        obj, img = _view_points(det, lookup, p3)
        copy = next((views[k].name for k, o, i in data if i.shape == img.shape and np.array_equal(i, img)), None)
        if copy is not None:  # a copy of an earlier view adds no information and would shrink the std
            views.append(ViewInfo(str(name), len(obj), reason=f"the same corners as view {copy} (a copy of that image)"))
        elif len(obj) < config.min_corners:
            views.append(ViewInfo(str(name), len(obj), reason=f"too few corners: {len(obj)} < {config.min_corners}"))
        elif _spread(obj) < config.min_spread:
            views.append(ViewInfo(str(name), len(obj), reason="corners (nearly) collinear on the target"))
        else:
            views.append(ViewInfo(str(name), len(obj), used=True))
            data.append((len(views) - 1, obj, img))
    free = _free_mask(config.flags)
    warnings = []
    for _round in range(4):
        if len(data) < config.min_views:
            why = "; ".join(f"{v.name}: {v.reason}" for v in views if not v.used)[:600]
            raise DataError(f"camera calibration: {len(data)} usable views of {len(views)}, need at least "
                            f"{config.min_views} (views at varied tilts, >= {config.min_corners} corners each)"
                            + (f"; rejected: {why}" if why else ""))
        rms, K, dist, rvecs, tvecs = _fit([o for _, o, _ in data], [i for _, _, i in data], size,
                                               config.flags)
        view_rms = np.array([_view_rms(o, i, rv, tv, K, dist) for (_, o, i), rv, tv in zip(data, rvecs, tvecs)])
        limit = max(config.outlier_factor * float(np.median(view_rms)), config.outlier_floor_px)
        bad = view_rms > limit
        if not bad.any() or _round == 3 or len(data) - bad.sum() < config.min_views:
            break
        for (k, o, _), r in zip(data, view_rms):
            if r > limit:
                views[k] = ViewInfo(views[k].name, len(o), float(r), False,
                                    f"outlier: view RMS {r:.3f} px > {limit:.3f} px "
                                    f"(max({config.outlier_factor:g} x median, {config.outlier_floor_px:g} px))")
                warnings.append(f"view {views[k].name} dropped as an outlier (RMS {r:.3f} px > {limit:.3f} px) "
                                "and the camera refitted")
        data = [d for d, b in zip(data, bad) if not b]
    for (k, o, _), r in zip(data, view_rms):
        views[k] = ViewInfo(views[k].name, len(o), float(r), True, "")
    cam = CameraIntrinsics(size[0], size[1], float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]),
                           tuple(float(v) for v in dist))
    cov, _sigma, cond = intrinsics_covariance([o for _, o, _ in data], [i for _, _, i in data], rvecs, tvecs, K,
                                              dist, free)
    stds = dict(zip(PARAM_NAMES, (float(v) for v in np.sqrt(np.diag(cov)))))
    worst = max(PARAM_NAMES[:4], key=lambda n: stds[n])
    if not np.isfinite(stds[worst]) or stds[worst] > config.max_std_frac * size[0]:
        raise DataError(f"camera calibration: {worst} not determined by these {len(data)} views (std "
                        f"{stds[worst]:.3g} px > {config.max_std_frac:g} x width; condition number {cond:.3g}); "
                        "the views are too close to fronto-parallel or too few: tilt the target (20-45 deg) "
                        "about different axes")
    uv_all = np.concatenate([i for _, _, i in data]).reshape(-1, 2)
    uv_far = uv_all[np.argmax(np.hypot(uv_all[:, 0] - cam.cx, uv_all[:, 1] - cam.cy))]
    dist_u = distortion_uncertainty(cam, cov, uv_far)
    cov_img = coverage([i for _, _, i in data], size, config.grid, (cam.cx, cam.cy))
    return IntrinsicsResult(cam, stds, float(rms), tuple(views), cov_img, tuple(warnings + cov_img["warnings"]),
                            cov, dist_u)


def find_images(folder, allow_symlinks: bool = False, hint: str = "--allow-path DIR") -> list[Path]:
    """Image files under folder, recursively (IMAGE_SUFFIXES, case-insensitive), sorted; DataError naming
    the folder when it is missing or holds none, and naming a file that is a symbolic link leading out of the
    folder (``config.confine``, the one rule for paths; ``allow_symlinks``: the user's explicit allowance, ``hint``
    the option that gives it): nothing outside the folder is ever opened."""
    from ..config import confine

    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(f"{folder}: image folder not found")
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise DataError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)}) in the folder or below it")
    for p in files:
        confine(p, folder, str(p), DataError, allow=allow_symlinks, hint=hint)
    return files


#: the detection settings of :func:`calibrate_from_images` (a corner count low enough for oblique views)
CALIBRATION_DETECT = {"min_corners": 4, "batch": "per_frame"}
#: AprilTag grids' corners for the calibration (:func:`calibrate_from_images`): the tag-edge fits of the measurement
#: (``measure.tag_edges``) instead of OpenCV's AprilTag marker refinement, first in raw pixels, whose straight-edge
#: assumption the lens distortion breaks, then refitted to the same edge samples this many times in the undistorted
#: pixels of the calibration before. Measured (``python benchmarks/bench_intrinsics.py --apriltag --seeds
#: 0,1,2,3,4,5 --views 15``: 1024 x 768, k1 -0.1, the 4 x 6 grid of 30 mm tags at 0.25-0.45 m): RMS z of fx, fy
#: 12.0, 12.7 in raw pixels; 1.44, 1.80 with one refit (the others 0.5-0.7; fx error 0.03 px RMS), 1.47, 1.83 with
#: two; OpenCV's refinement 2.32, 2.36 with 0.39 px RMS error on fx and 8-15x the RMS error of one refit on every
#: parameter; 22 ms per image against its 158 (decode, detect, calibrate)
TAG_EDGE_REFIT = 1


def calibrate_from_images(paths, target, image_size=None, names=None, config: CalibrationConfig = CalibrationConfig(),
                          progress: bool = False, detected: dict | None = None) -> IntrinsicsResult:
    """Detect the target in every image (paths; unreadable ones are rejected views, read with
    ``measure.detect.load_gray``) and calibrate (:func:`calibrate_intrinsics`). names: view labels
    (default: the paths). Before anything is decoded, every file's header size is read
    (:mod:`.image_header`): a file beyond the pixel limit, and one whose size differs from ``image_size`` (default:
    the size most of the files have -- the majority wins, not the first file), is a rejected view named in the
    result's warnings, never decoded. detected: {index: valid Detection} already made of those files with
    ``DetectConfig(**CALIBRATION_DETECT)`` and no intrinsics (``batch.reusable_detections``): not detected again.
    A target with fewer corners than a usable view needs (``config.min_corners``): DataError before any image is
    read (no view of it can calibrate). AprilTag grids (the kinds whose corners are straight-edge fits,
    ``seeded_mode`` "tag_edges"): the edges fitted in raw pixels, a calibration, then the edges of every detected
    view refitted in the undistorted pixels of that calibration (their edge samples: no image read again,
    ``batch.refit_detection``) and the calibration made again from them (:data:`TAG_EDGE_REFIT`); ``detected``
    may then hold detections made with any intrinsics (their edge samples are refitted in raw pixels first)."""
    from .batch import detect_batch, refit_detection
    from .detect import DetectConfig, Detection, detect
    from .image_header import header_size, majority_size, pixel_refusal

    if target.n_corners < config.min_corners:
        raise DataError(f"camera calibration: the target {target.name!r} has {target.n_corners} corners, a usable "
                        f"view needs at least {config.min_corners}: no image of it can calibrate the intrinsics")
    paths = list(paths)
    names = names or [str(p) for p in paths]
    heads = [header_size(p) for p in paths]
    skip = {}
    for i, s in enumerate(heads):
        why = None if s is None else pixel_refusal(None, s)
        if why:
            skip[i] = why
    fits = [s for i, s in enumerate(heads) if i not in skip and s is not None]
    size, count = (tuple(int(v) for v in image_size), None) if image_size is not None else majority_size(fits)
    for i, s in enumerate(heads):
        if i not in skip and s is not None and size is not None and s != size:
            skip[i] = (f"image size {s[0]}x{s[1]} differs from " + (f"the majority {size[0]}x{size[1]} ({count} of "
                       f"{len(fits)} images)" if count else f"the given {size[0]}x{size[1]}"))
    known = {i: d for i, d in (detected or {}).items() if i not in skip and d.valid}
    todo = [i for i in range(len(paths)) if i not in skip and i not in known]
    it = todo
    if progress:
        from tqdm import tqdm

        it = tqdm(todo, desc="calibrate camera: detect", unit="image", leave=False)
    edges = target.kind_impl.seeded_mode(DetectConfig()) == "tag_edges"
    n_min = CALIBRATION_DETECT["min_corners"]
    if edges:  # the tag-edge fits, first in raw pixels (no intrinsics), then (below) in the calibration's own
        known = {i: refit_detection(d, None, n_min) for i, d in known.items()}  # (detected with edge samples)
        known = {i: d for i, d in known.items() if d is not None}

        def detect_one(i):
            return detect_batch([str(paths[i])], target, None, DetectConfig(min_corners=n_min))[0]
    else:
        dcfg = DetectConfig(**CALIBRATION_DETECT)

        def detect_one(i):
            return detect(str(paths[i]), target, None, config=dcfg)
    found = {**known, **{i: detect_one(i) for i in it}}

    def views(found):
        return [found[i] if i in found else Detection(False, skip[i], np.zeros(0, int), np.zeros((0, 2)), heads[i])
                for i in range(len(paths))]

    res = calibrate_intrinsics(views(found), names, target, size, config)
    for _ in range(TAG_EDGE_REFIT if edges else 0):  # straight tag edges hold in undistorted pixels: refit there
        found = {i: refit_detection(d, res.camera, n_min) or d for i, d in found.items()}  # (no image read)
        res = calibrate_intrinsics(views(found), names, target, size, config)
    if not skip:
        return res
    shown = "; ".join(f"{names[i]}: {skip[i]}" for i in sorted(skip)[:10]) + ("; ..." if len(skip) > 10 else "")
    return replace(res, warnings=(f"{len(skip)} image{'s' if len(skip) > 1 else ''} of {len(paths)} skipped, not "
                                  f"decoded: {shown}",) + tuple(res.warnings))


__all__ = ["CalibrationConfig", "IntrinsicsResult", "ViewInfo", "calibrate_intrinsics", "calibrate_from_images",
           "intrinsics_covariance", "summary_text", "displacement_jacobian", "distortion_displacement",
           "distortion_uncertainty", "distortion_summary",
           "coverage", "find_images", "PARAM_NAMES", "IMAGE_SUFFIXES"]


def summary_text(res: IntrinsicsResult) -> str:
    """Human summary: values ± std, RMS, views, coverage and its warnings."""
    v, s = res.values(), res.std
    lines = [f"camera {res.camera.width}x{res.camera.height}: reprojection RMS {res.rms_px:.3f} px over "
             f"{res.n_used} views ({len(res.views) - res.n_used} rejected)"]
    lines += [f"  {k} = {v[k]:.3f} ± {s[k]:.3f} px" for k in PARAM_NAMES[:4]]
    lines += [f"  {k} = {v[k]:.5g} ± {s[k]:.2g}" for k in PARAM_NAMES[4:]]
    if res.distortion:
        d = res.distortion
        lines.append("  distortion displacement at the image corners (TL, TR, BL, BR): " + ", ".join(
            f"{m:.2f} ± {e:.3f}" for m, e in zip(d["displacement_corners_px"], d["std_corners_px"])) + " px")
        if "max_radius_px" in d:
            lines.append(f"  ... at the farthest detected corner (r = {d['max_radius_px']:.0f} px): "
                         f"{d['displacement_max_radius_px']:.2f} ± {d['std_max_radius_px']:.3f} px")
    c = res.coverage
    lines.append(f"coverage: {100 * c['fraction']:.0f} % of {c['grid'][0]}x{c['grid'][1]} image cells, corners up to "
                 f"{100 * c['radius_frac']:.0f} % of the principal point-to-corner distance")
    lines += [f"  view {x.name}: {x.reason}" for x in res.views if not x.used][:20]
    lines += [f"warning: {w}" for w in res.warnings]
    return "\n".join(lines)
