"""Camera noise from repeated frames of a static target: corner scatter, per-frame pose scatter, pixel noise.

Everything here is measured from the frames alone (the simulator settings that reproduce it are fitted in
:mod:`vision_calib.experiment.noise`). Conventions:

- corner scatter: each corner's detected position (distorted px, as detected) minus its mean over the frames;
  the std per coordinate pooled over the K corners seen in every frame, dof = K (N - 1) per coordinate, with a
  chi-square confidence interval (corners assumed independent);
- pose scatter: one planar PnP per frame (undistorted corners); the deviation of frame f is
  ``frames.pose_error(T_mean, T_f)``: the translation of the *target frame's origin* in camera axes [m] and
  the rotation vector of R_f R_mean^T in camera axes [rad]; std per axis with dof N - 1. "predicted": the same
  std from the corner scatter alone, sigma^2 (J^T J)^-1 (J: :func:`.pnp.reprojection_jacobian`);
- a frame "moved" when its pose deviation from the median pose has a squared Mahalanobis distance above the
  chi-square (6 dof) quantile of probability :data:`MOVED_P`, the covariance taken from the noise left after each
  frame's own PnP (so that a moving target does not inflate its own yardstick), scaled up (N >= 5) when the median
  frame's distance exceeds the chi-square median (corner noise correlated between corners);
- pixel noise: per-pixel temporal variance over the frames on flat pixels (no edge nearby), fitted against
  the pixel's mean grey level: var = c0 + c1 mean (a photon-transfer curve). The simulator's model
  (:class:`vision_calib.sensor.SensorEffects` with gain 1) gives var = read^2 + (255 / full_well_e)
  (mean - black_level) + 1/12 (8-bit rounding), so c1 = 255 / full_well_e and read^2 = c0 + c1 black - 1/12.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import stats

from .. import frames
from ..camera import CameraIntrinsics
from ..errors import DataError
from .pnp import pose_cov_from_jacobian, reprojection_jacobian, solve_pnp_planar, target_lookup, undistort_px

#: confidence level of the reported intervals
LEVEL = 0.95
#: probability, for a static target, that a frame's pose deviation exceeds the "moved" threshold
MOVED_P = 1e-6
#: pose axes of the scatter tables: (name, unit, factor from SI)
POSE_AXES = (("tx", "mm", 1e3), ("ty", "mm", 1e3), ("tz", "mm", 1e3),
             ("rx", "mrad", 1e3), ("ry", "mrad", 1e3), ("rz", "mrad", 1e3))


@dataclass(frozen=True)
class Scatter:
    """A std estimated from a sum of squares ``ss`` with ``dof`` degrees of freedom: std = sqrt(ss / dof) and its
    chi-square interval [lo, hi] at :data:`LEVEL` (same unit as std)."""

    std: float
    lo: float
    hi: float
    dof: int

    @classmethod
    def from_ss(cls, ss: float, dof: int, level: float = LEVEL) -> "Scatter":
        if dof < 1:
            return cls(float("nan"), float("nan"), float("nan"), int(dof))
        a = 1.0 - level
        return cls(float(np.sqrt(ss / dof)), float(np.sqrt(ss / stats.chi2.ppf(1 - a / 2, dof))),
                   float(np.sqrt(ss / stats.chi2.ppf(a / 2, dof))), int(dof))

    @property
    def rel_se(self) -> float:
        """Relative standard error of the std (normal approximation, 1 / sqrt(2 dof))."""
        return float(1.0 / np.sqrt(2.0 * self.dof)) if self.dof > 0 else float("nan")

    def scaled(self, k: float) -> "Scatter":
        return Scatter(self.std * k, self.lo * k, self.hi * k, self.dof)

    def to_dict(self, unit: str) -> dict:
        return {f"std_{unit}": self.std, f"ci{int(LEVEL * 100)}_{unit}": [self.lo, self.hi], "dof": self.dof}


def common_corners(detections) -> tuple[np.ndarray, np.ndarray]:
    """(ids (K,), uv_px (N, K, 2)): the corners detected in every one of the N (valid) detections, sorted by id."""
    ids = None
    for d in detections:
        s = set(int(i) for i in d.ids)
        ids = s if ids is None else ids & s
    ids = np.array(sorted(ids or ()), dtype=int)
    uv = np.empty((len(detections), len(ids), 2))
    for f, d in enumerate(detections):
        pos = {int(i): k for k, i in enumerate(d.ids)}
        uv[f] = d.uv_px[[pos[int(i)] for i in ids]] if len(ids) else np.zeros((0, 2))
    return ids, uv


def corner_scatter(uv_px: np.ndarray) -> dict:
    """Scatter of corner positions uv_px (N, K, 2) about each corner's mean: {"x", "y", "xy": :class:`Scatter`
    [px] (xy: per coordinate, both pooled), "per_corner_std_px": (K, 2)}; dof K (N - 1) per coordinate."""
    N, K = uv_px.shape[:2]
    d = uv_px - uv_px.mean(axis=0)
    ss = np.sum(d**2, axis=0)  # (K, 2)
    dof = K * (N - 1)
    per = np.sqrt(ss / (N - 1)) if N > 1 else np.full((K, 2), np.nan)
    return {"x": Scatter.from_ss(ss[:, 0].sum(), dof), "y": Scatter.from_ss(ss[:, 1].sum(), dof),
            "xy": Scatter.from_ss(ss.sum(), 2 * dof), "per_corner_std_px": per}


@dataclass(frozen=True)
class PoseScatter:
    """Per-frame PnP poses and their scatter (module docstring for the convention).

    T_cam_target: (N, 4, 4) per frame; T_mean: (4, 4) their SE(3) mean; deltas: (N, 6) [m, rad] pose_error(T_mean,
    T_f); axes: {tx..rz: Scatter} in mm / mrad (dof N - 1); predicted_std: (6,) [mm, mrad] from the corner scatter;
    residual_noise_px: the corner noise left after each frame's own PnP (systematic part removed), a Scatter;
    moved: [(frame, mahalanobis^2, mean corner shift px)] of the frames flagged as moved; moved_threshold: the
    chi-square quantile used; mahalanobis2: (N,) every frame's value."""

    T_cam_target: np.ndarray
    T_mean: np.ndarray
    deltas: np.ndarray
    axes: dict
    predicted_std: np.ndarray
    residual_noise_px: Scatter
    moved: tuple
    moved_threshold: float
    mahalanobis2: np.ndarray


def pose_scatter(ids: np.ndarray, uv_px: np.ndarray, target, camera: CameraIntrinsics,
                 corner_std_px: float) -> PoseScatter:
    """PnP of every frame of uv_px (N, K, 2) (corner ids (K,), distorted px) and the scatter of the poses;
    corner_std_px: the pooled corner scatter (for the predicted pose std). DataError if a frame's PnP fails."""
    lookup = target_lookup(target)
    p = np.array([lookup[int(i)] for i in ids])
    N = len(uv_px)
    Ts, res = np.empty((N, 4, 4)), np.empty(uv_px.shape)
    und = np.empty(uv_px.shape)
    for f in range(N):
        und[f] = undistort_px(uv_px[f], camera)
        try:
            Ts[f], res[f] = solve_pnp_planar(p, und[f], camera)
        except (cv2.error, ValueError) as exc:
            raise DataError(f"frame {f}: PnP failed ({str(exc).splitlines()[0]})") from None
    T_mean = frames.mean_pose(Ts)
    deltas = frames.pose_error(T_mean, Ts)
    axes = {}
    for j, (name, unit, k) in enumerate(POSE_AXES):
        axes[name] = Scatter.from_ss(float(np.sum(deltas[:, j] ** 2)), N - 1).scaled(k)
    J = reprojection_jacobian(T_mean, p, camera)
    cov1 = pose_cov_from_jacobian(J, 1.0)  # per unit corner noise
    predicted = np.sqrt(np.diag(cov1)) * corner_std_px * 1e3
    # noise after each frame's own pose, its per-corner systematic part (same in every frame) removed
    e = res - res.mean(axis=0)
    K = uv_px.shape[1]
    noise = Scatter.from_ss(float(np.sum(e**2)), max((2 * K - 6) * (N - 1), 0))
    med = np.median(deltas, axis=0)
    dd = deltas - med
    info = np.linalg.pinv(cov1) / noise.std**2 if noise.std > 0 else np.zeros((6, 6))
    m2 = np.einsum("fi,ij,fj->f", dd, info, dd) if N > 1 else np.zeros(N)
    if N >= 5:  # the yardstick never below what most frames show (correlated corner noise, median reference)
        m2 = m2 / max(1.0, float(np.median(m2)) / float(stats.chi2.median(6)))
    thr = float(stats.chi2.isf(MOVED_P, 6))
    shift = np.linalg.norm((uv_px - np.median(uv_px, axis=0)).mean(axis=1), axis=1)
    moved = tuple((int(f), float(m2[f]), float(shift[f])) for f in range(N) if m2[f] > thr)
    return PoseScatter(Ts, T_mean, deltas, axes, predicted, noise, moved, thr, m2)


# ----------------------------------------------------------------------------------------------- pixel noise
class PixelAccumulator:
    """Per-pixel sums over frames (float64) for the temporal mean and variance; frames added one at a time."""

    def __init__(self):
        self.n = 0
        self.s1 = self.s2 = None
        self.identical_to_first = []

    def add(self, img: np.ndarray) -> None:
        x = np.asarray(img, dtype=np.float64)
        if self.s1 is None:
            self.s1, self.s2, self.first = x.copy(), x * x, np.asarray(img).copy()
        else:
            if x.shape != self.s1.shape:
                raise ValueError(f"frame shape {x.shape} != {self.s1.shape}")
            self.s1 += x
            self.s2 += x * x
            if np.array_equal(img, self.first):
                self.identical_to_first.append(self.n)
        self.n += 1

    @property
    def mean(self) -> np.ndarray:
        """(H, W) temporal mean [grey levels]."""
        return self.s1 / self.n

    @property
    def var(self) -> np.ndarray:
        """(H, W) unbiased temporal variance [grey^2] (n >= 2)."""
        return np.maximum(self.s2 - self.s1**2 / self.n, 0.0) / (self.n - 1)


def flat_mask(mean: np.ndarray, var: np.ndarray, n_frames: int, margin_px: int = 2) -> np.ndarray:
    """(H, W) bool: pixels at least ``margin_px`` from any pixel whose mean-image gradient (central differences)
    exceeds 4 times what the noise of the mean alone gives (edges: any sub-pixel motion inflates their variance)."""
    gy, gx = np.gradient(mean)
    g = np.hypot(gx, gy)
    noise = np.sqrt(np.median(var) / n_frames)  # std of the mean image; gradient of noise ~ noise / sqrt(2) per axis
    edge = (g > 4.0 * noise + 0.5).astype(np.uint8)
    k = 2 * margin_px + 1
    return cv2.dilate(edge, np.ones((k, k), np.uint8)) == 0


def photon_transfer(mean: np.ndarray, var: np.ndarray, mask: np.ndarray, n_frames: int,
                    bin_grey: float = 4.0, min_pixels: int = 50) -> dict:
    """Fit var = c0 + c1 mean over the pixels of ``mask`` binned by mean grey level (weighted by each bin's
    standard error: the std of its pixels' variances / sqrt(n_bin); bins within 3 std of 0 or 255 dropped:
    clipping). Returns {"c0" [grey^2], "c1" [grey], "cov" (2, 2), "reduced_chi2", "bins": [[mean, var, n, se],
    ...],
    "photon": bool}; the covariance is scaled by the reduced chi-square when above 1. With a mean range under
    20 grey levels or a fitted c1 <= 0 the photon term is dropped (c1 = 0, "photon": False)."""
    m, v = mean[mask], var[mask]
    if m.size == 0:
        raise DataError("no flat pixels to measure the pixel noise on (the whole image is edges?)")
    edges = np.arange(np.floor(m.min()), np.ceil(m.max()) + bin_grey, bin_grey)
    idx = np.digitize(m, edges)
    rows = []
    for b in np.unique(idx):
        sel = idx == b
        nb = int(sel.sum())
        if nb < min_pixels:
            continue
        mb, vb = float(m[sel].mean()), float(v[sel].mean())
        sd = np.sqrt(vb)
        if mb - 3 * sd < 0 or mb + 3 * sd > 255:
            continue
        rows.append((mb, vb, nb, float(np.std(v[sel], ddof=1) / np.sqrt(nb))))
    if not rows:
        raise DataError("no grey level away from 0 and 255 with enough flat pixels to measure the pixel noise "
                        "(over- or under-exposed frames?)")
    B = np.array(rows)
    w = 1.0 / B[:, 3] ** 2

    def wls(A):
        Aw = A * w[:, None]
        cov = np.linalg.pinv(A.T @ Aw)
        c = cov @ (Aw.T @ B[:, 1])
        r = B[:, 1] - A @ c
        dof = len(B) - A.shape[1]
        red = float(np.sum(w * r**2) / dof) if dof > 0 else float("nan")
        return c, cov * max(red, 1.0) if np.isfinite(red) else cov, red

    photon = np.ptp(B[:, 0]) >= 20 and len(B) >= 3
    if photon:
        c, cov, red = wls(np.stack([np.ones(len(B)), B[:, 0]], axis=1))
        photon = c[1] > 0
    if not photon:
        c1, cov1, red = wls(np.ones((len(B), 1)))
        c, cov = np.array([c1[0], 0.0]), np.diag([cov1[0, 0], 0.0])
    return {"c0": float(c[0]), "c1": float(c[1]), "cov": cov, "reduced_chi2": red, "bins": B.tolist(),
            "photon": bool(photon)}


def sensor_noise_settings(pt: dict, black_grey: float, black_se: float = 0.0) -> dict:
    """SensorEffects noise settings (gain 1) from a :func:`photon_transfer` fit and the image's black level
    [grey]: {"read_noise_grey", "read_noise_se", "full_well_e", "full_well_se"} (full_well_e 0 = no photon noise)."""
    c0, c1, cov = pt["c0"], pt["c1"], pt["cov"]
    r2 = c0 + c1 * black_grey - 1.0 / 12
    var_r2 = cov[0, 0] + black_grey**2 * cov[1, 1] + 2 * black_grey * cov[0, 1] + (c1 * black_se) ** 2
    read = float(np.sqrt(max(r2, 0.0)))
    read_se = float(np.sqrt(var_r2) / (2 * read)) if read > 0 else float(np.sqrt(np.sqrt(var_r2)))
    if c1 > 0:
        fw, fw_se = 255.0 / c1, 255.0 * np.sqrt(cov[1, 1]) / c1**2
    else:
        fw, fw_se = 0.0, 0.0
    return {"read_noise_grey": read, "read_noise_se": read_se, "full_well_e": float(fw), "full_well_se": float(fw_se)}


__all__ = ["Scatter", "PoseScatter", "PixelAccumulator", "common_corners", "corner_scatter", "pose_scatter",
           "flat_mask", "photon_transfer", "sensor_noise_settings", "POSE_AXES", "MOVED_P", "LEVEL"]
