"""Opt-in CPU path (``backend="warp"``) of :class:`~vision_calib.render.TargetRenderer` for a scene with one
planar target and no occluders: the ideal image is a homography warp of a pre-filtered (mip-mapped) board
texture. Not the default: its edges carry a texel-phase error up to 0.05 px and its corners are 2-3 x
further from the 8x reference than the default "polygon" backend's (:mod:`vision_calib.render.coverage`;
``benchmarks/bench_render.py``). :func:`supersampled_K` and :func:`planar_warp_ok` serve all backends.

Conventions are those of :mod:`vision_calib.render.renderer` (OpenCV pixel centres, supersampling by s
with hi-res pixel centre u_s = s (u + 0.5) - 0.5, then an exact s x s box average):
- Mip level 0 is ``target.texture``: texel (j, i) covers [x0 + j dx, x0 + (j + 1) dx] x [y0 + i dy, ...]
  of :meth:`TargetSpec.texture_extent_m`; its centre is at x0 + (j + 0.5) dx. Level L + 1 is the exact
  2 x 2 box average of level L (``cv2.resize`` INTER_AREA, factor 2), padded on the right/bottom with the
  *background* grey, so each texel of level L is the exact area average of board + background over its
  footprint of 2^L x 2^L level-0 texels (the board's outline stays where it is, no replicated border).
- The level is chosen per pose from the homography's Jacobian at the board's corners and centre: the
  largest number of level-0 texels per hi-res pixel (most compressed direction, worst point) rho, level
  ``floor(log2(rho) + lod_bias)`` (default bias 0: 1 to 2 texels per hi-res pixel where the board is the
  most compressed, so bilinear sampling skips no texel; less elsewhere, i.e. a little extra blur, symmetric
  so it moves no edge). ``cv2.warpPerspective`` (bilinear, 1/32 px steps) samples it, only over the
  bounding box of the board (aligned to the s x s blocks); the rest of the image is the background.
- The back face (camera on the +z side of the board) is the uniform ``back_grey`` over the board's outline.
:func:`planar_warp_ok` tells when a pose cannot be warped (a board corner at or behind ``znear``); the
renderer then uses pyrender for that pose.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..camera import CameraIntrinsics
from ..targets.spec import TargetSpec

#: Largest texture side [texels] the warp path accepts (same order as GL_MAX_TEXTURE_SIZE of common drivers).
MAX_WARP_TEXTURE_PX = 16384


def supersampled_K(K: CameraIntrinsics, s: int) -> np.ndarray:
    """(3, 3) camera matrix of the s x supersampled image (hi-res pixel centres, see the module docstring)."""
    Ks = K.K.astype(np.float64).copy()
    Ks[:2, :2] *= s
    Ks[0, 2] = s * (K.cx + 0.5) - 0.5
    Ks[1, 2] = s * (K.cy + 0.5) - 0.5
    return Ks


def planar_warp_ok(target: TargetSpec, T_cam_target: np.ndarray, znear: float) -> bool:
    """Whether every corner of the board's outline lies in front of the camera (z > znear [m])."""
    x0, y0, x1, y1 = target.texture_extent_m()
    P = np.array([[x0, y0, 0, 1], [x1, y0, 0, 1], [x1, y1, 0, 1], [x0, y1, 0, 1]], float)
    return bool(np.all((P @ np.asarray(T_cam_target)[2]) > znear))


class MipWarp:
    """Mip-mapped board texture + homography warp (see the module docstring).

    target: TargetSpec; intrinsics: pinhole camera (distortion ignored); supersample: s >= 1;
    background, back_grey: grey levels [0, 255]; texture_px_per_m: level-0 texels per metre;
    lod_bias: added to the chosen level's log2 (0: 1-2 texels per hi-res pixel, worst direction)."""

    def __init__(self, target: TargetSpec, intrinsics: CameraIntrinsics, supersample: int, background: float,
                 back_grey: float, texture_px_per_m: float, lod_bias: float = 0.0):
        self.target, self.K, self.s = target, intrinsics, int(supersample)
        self.background, self.back_grey = float(background), float(back_grey)
        self.lod_bias = float(lod_bias)
        self.px_per_m = float(texture_px_per_m)
        self.shape0 = target.texture_shape(self.px_per_m)
        self._levels: dict[tuple[str, int], np.ndarray] = {}
        self._Ks = supersampled_K(intrinsics, self.s)
        x0, y0, x1, y1 = target.texture_extent_m()
        H0, W0 = self.shape0
        self._extent = (x0, y0, x1, y1)
        self._d0 = ((x1 - x0) / W0, (y1 - y0) / H0)  # level-0 texel size [m]
        self.last_level = None
        self.interp = cv2.INTER_LINEAR

    # ------------------------------------------------------------------ texture pyramid
    def level(self, face: str, L: int) -> np.ndarray:
        """Level L (float32) of the front ("front": the printed pattern) or back ("back": uniform) face."""
        key = (face, L)
        hit = self._levels.get(key)
        if hit is not None:
            return hit
        if L == 0:
            if face == "front":
                img = self.target.texture(self.px_per_m).astype(np.float32)
            else:
                img = np.full(self.shape0, self.back_grey, np.float32)
        else:
            prev = self.level(face, L - 1)
            h, w = prev.shape
            if h % 2 or w % 2:  # pad with the background: texels past the outline are partly background
                prev = cv2.copyMakeBorder(prev, 0, h % 2, 0, w % 2, cv2.BORDER_CONSTANT, value=self.background)
            img = cv2.resize(prev, (prev.shape[1] // 2, prev.shape[0] // 2), interpolation=cv2.INTER_AREA)
        self._levels[key] = img
        return img

    def sampled_level(self, face: str, L: int) -> np.ndarray:
        """Level L as sampled by the warp: uint8 (rounded; 8-bit warps are ~1.3x faster, corners measured
        unchanged: sim.render_bench) when the background is an integer grey, else float32."""
        key = (face + "_sampled", L)
        hit = self._levels.get(key)
        if hit is None:
            hit = self.level(face, L)
            if self.background == round(self.background):
                hit = np.round(hit).astype(np.uint8)
            self._levels[key] = hit
        return hit

    def _homography(self, T: np.ndarray, L: int) -> np.ndarray:
        """(3, 3) map from level-L texel indices (j, i, 1) to hi-res pixels."""
        x0, y0, _, _ = self._extent
        f = float(2 ** L)
        dx, dy = self._d0[0] * f, self._d0[1] * f
        A = np.array([[dx, 0.0, x0 + 0.5 * dx], [0.0, dy, y0 + 0.5 * dy], [0.0, 0.0, 1.0]])
        return self._Ks @ np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]]) @ A

    def choose_level(self, T: np.ndarray) -> int:
        """Mip level for pose T (see the module docstring)."""
        H = self._homography(T, 0)
        H0, W0 = self.shape0
        pts = np.array([[0, 0], [W0 - 1, 0], [W0 - 1, H0 - 1], [0, H0 - 1], [(W0 - 1) / 2, (H0 - 1) / 2]], float)
        rho = 0.0
        for j, i in pts:
            p = H @ np.array([j, i, 1.0])
            J = (H[:2, :2] - np.outer(p[:2] / p[2], H[2, :2])) / p[2]  # hi-res px per texel
            smin = np.linalg.svd(J, compute_uv=False)[-1]
            rho = max(rho, 1.0 / max(smin, 1e-12))  # texels per hi-res px, most compressed direction
        L = int(math.floor(math.log2(rho) + self.lod_bias)) if rho > 0 else 0
        return max(0, min(L, int(math.log2(max(self.shape0))) - 1))

    # ------------------------------------------------------------------ rendering
    def render(self, T_cam_target: np.ndarray) -> np.ndarray:
        """Ideal grey image (H, W) float32 [0, 255] of the board at pose T_cam_target (4, 4) [m, OpenCV
        camera frame]; every board corner must satisfy :func:`planar_warp_ok`."""
        T = np.asarray(T_cam_target, float)
        s, K = self.s, self.K
        out = np.full((K.height, K.width), self.background, np.float32)
        front = float(T[:3, 2] @ T[:3, 3]) > 0  # camera on the -z side of the board: printed face
        L = self.choose_level(T)
        self.last_level = L
        tex = self.sampled_level("front" if front else "back", L)
        H = self._homography(T, L)
        h, w = tex.shape
        c = H @ np.array([[-0.5, -0.5, 1], [w - 0.5, -0.5, 1], [w - 0.5, h - 0.5, 1], [-0.5, h - 0.5, 1]], float).T
        uv = c[:2] / c[2]
        # ROI in final pixels (whole blocks of s x s hi-res pixels), one pixel of margin
        u0 = max(0, int(math.floor((uv[0].min() + 0.5) / s)) - 1)
        v0 = max(0, int(math.floor((uv[1].min() + 0.5) / s)) - 1)
        u1 = min(K.width, int(math.ceil((uv[0].max() + 0.5) / s)) + 1)
        v1 = min(K.height, int(math.ceil((uv[1].max() + 0.5) / s)) + 1)
        if u1 <= u0 or v1 <= v0:
            return out
        shift = np.array([[1.0, 0.0, -s * u0], [0.0, 1.0, -s * v0], [0.0, 0.0, 1.0]])
        hi = cv2.warpPerspective(tex, shift @ H, (s * (u1 - u0), s * (v1 - v0)), flags=self.interp,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=self.background)
        hi = hi.astype(np.float32, copy=False)
        out[v0:v1, u0:u1] = hi if s == 1 else cv2.resize(hi, (u1 - u0, v1 - v0), interpolation=cv2.INTER_AREA)
        return out
