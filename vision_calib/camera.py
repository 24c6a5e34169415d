"""Camera intrinsics shared by render/, sensor/ and measure/ (OpenCV pinhole + Brown–Conrady).

Pixel convention (OpenCV): pixel (u, v) = (column, row); the centre of the top-left pixel is
at (0, 0), so the image spans [-0.5, width - 0.5] x [-0.5, height - 0.5].
Camera frame: OpenCV (x right, y down, z forward).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ConfigError


@dataclass(frozen=True)
class CameraIntrinsics:
    """width/height: image size [px]. fx, fy: focal lengths [px]. cx, cy: principal point [px].
    dist: (5,) Brown–Conrady coefficients (k1, k2, p1, p2, k3), OpenCV order, zero = ideal."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def __post_init__(self):
        vals = [self.fx, self.fy, self.cx, self.cy, *self.dist]
        if not np.all(np.isfinite(vals)):
            raise ConfigError(f"camera intrinsics contain a non-finite value: {self}")
        if self.width <= 0 or self.height <= 0 or self.fx <= 0 or self.fy <= 0:
            raise ConfigError(
                f"camera intrinsics need positive width, height, fx, fy (got {self.width}x{self.height}, "
                f"fx={self.fx}, fy={self.fy})"
            )
        if len(self.dist) != 5:
            raise ConfigError(f"camera dist must have 5 coefficients (k1, k2, p1, p2, k3), got {len(self.dist)}")
        object.__setattr__(self, "dist", tuple(float(d) for d in self.dist))

    @property
    def K(self) -> np.ndarray:
        """(3, 3) camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_array(self) -> np.ndarray:
        """(5,) distortion coefficients as float64."""
        return np.asarray(self.dist, dtype=float)

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in px, OpenCV order."""
        return (int(self.width), int(self.height))

    def without_distortion(self) -> "CameraIntrinsics":
        return CameraIntrinsics(self.width, self.height, self.fx, self.fy, self.cx, self.cy)

    @classmethod
    def from_fov(cls, width: int, height: int, hfov_deg: float) -> "CameraIntrinsics":
        """Square pixels, centred principal point, horizontal field of view hfov_deg."""
        f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2)
        return cls(width, height, f, f, (width - 1) / 2, (height - 1) / 2)

    @classmethod
    def from_focal_mm(cls, width: int, height: int, focal_mm: float, pixel_um: float) -> "CameraIntrinsics":
        """Square pixels of pixel_um micrometres, lens focal length focal_mm, centred principal point."""
        f = focal_mm * 1e-3 / (pixel_um * 1e-6)
        return cls(width, height, f, f, (width - 1) / 2, (height - 1) / 2)

    def project(self, p_cam: np.ndarray) -> np.ndarray:
        """Project points (N, 3) [m, camera frame] to distorted pixels (N, 2) (same model as cv2.projectPoints)."""
        p = np.asarray(p_cam, dtype=float)
        x = p[:, 0] / p[:, 2]
        y = p[:, 1] / p[:, 2]
        k1, k2, p1, p2, k3 = self.dist
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=1)

    def to_dict(self) -> dict:
        return {
            "width": int(self.width),
            "height": int(self.height),
            "fx": float(self.fx),
            "fy": float(self.fy),
            "cx": float(self.cx),
            "cy": float(self.cy),
            "dist": [float(d) for d in self.dist],
        }

    @classmethod
    def from_dict(cls, d: dict, where: str = "camera", require_dist: bool = False) -> "CameraIntrinsics":
        """From {width, height, fx, fy, cx, cy, dist} [px]; ConfigError naming ``where`` (file: key) and the key.

        Unknown keys are refused with the closest known key suggested (``k9`` is not silently ignored).
        require_dist: ``dist`` must be given (recordings: a real camera's distortion is never assumed
        zero); otherwise a missing ``dist`` means an ideal, undistorted camera."""
        from .config import did_you_mean

        if not isinstance(d, dict):
            raise ConfigError(f"{where}: expected a mapping of camera intrinsics, got {type(d).__name__}")
        known = ("width", "height", "fx", "fy", "cx", "cy", "dist")
        for k in d:
            if k not in known:
                raise ConfigError(f"{where}.{k}: unknown key{did_you_mean(k, known)}; allowed: {', '.join(known)}")
        need = known if require_dist else known[:-1]
        missing = [k for k in need if d.get(k) is None]
        if missing:
            hint = ("; give dist: [0, 0, 0, 0, 0] for an undistorted camera" if "dist" in missing else "")
            raise ConfigError(f"{where}: missing key(s) {', '.join(missing)} (need width, height, fx, fy, cx, cy [px], "
                              f"dist [k1, k2, p1, p2, k3]){hint}")
        vals = {}
        for k in known[:-1]:
            v = d[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ConfigError(f"{where}.{k}: expected a number [px], got {v!r}")
            if not np.isfinite(v):
                raise ConfigError(f"{where}.{k}: expected a finite number [px], got {v!r}")
            if k in ("width", "height") and (not float(v).is_integer() or v < 1):
                raise ConfigError(f"{where}.{k}: expected a positive integer [px], got {v!r}")
            if k in ("fx", "fy") and not v > 0:
                raise ConfigError(f"{where}.{k}: expected a focal length > 0 [px], got {v!r}")
            vals[k] = v
        dist = d.get("dist", (0, 0, 0, 0, 0))
        if (not isinstance(dist, (list, tuple)) or len(dist) != 5
                or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) for v in dist)):
            raise ConfigError(f"{where}.dist: expected 5 finite numbers [k1, k2, p1, p2, k3] (OpenCV order), got {dist!r}")
        return cls(int(vals["width"]), int(vals["height"]), float(vals["fx"]), float(vals["fy"]), float(vals["cx"]),
                   float(vals["cy"]), tuple(float(v) for v in dist))
