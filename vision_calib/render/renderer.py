"""Rendering of a calibration target: the ideal grey image a pinhole camera sees.

Backends (``TargetRenderer(..., backend=...)``; the one in use is ``TargetRenderer.backend``, the one that
drew the last image ``TargetRenderer.last_backend``):
- ``"polygon"`` (the default, ``"auto"``, for one planar target and no occluders): the exact pixel-area
  coverage of the board's black rectangles projected by the pose's homography
  (:mod:`vision_calib.render.coverage`), on the CPU, no texture and no supersampling (``supersample`` is
  not used: the image is the s -> infinity limit). A pose with a board corner at or behind ``znear`` falls
  back to pyrender. Measured (``benchmarks/bench_render.py``, 8 poses each, one thread): cornerSubPix
  corners minus the same detector on a CPU reference (``cv2.warpPerspective`` of the 4096-texel texture at
  8x, box-averaged) 0.002 (A5, AprilTag) to 0.005-0.007 px RMS (H4, H4 tilted up to 46 deg), which is the
  reference's own sampling error (0.002 px against a 16x reference), vs pyrender at s = 2: 0.012-0.048 px
  (s = 4: 0.004-0.012 px); edges of the H4 board within 2e-5 px of the projection (float32 rounding;
  ``tests/render/test_renderer.py``). Speed on the H4 scene: ~4 ms per pose, 0.13 x the floor
  (full-texture ``cv2.warpPerspective`` at 2x + area average), pyrender s = 2 ~1.8 x the floor.
- ``"warp"`` (opt-in, kept for comparison): a CPU homography warp of a mip-mapped board texture
  (:mod:`vision_calib.render.warp`), internally supersampled ``max(supersample, 4)`` x; bilinear sampling
  of a box-filtered mip level leaves a texel-phase-dependent edge error, coherent along straight edges:
  up to 0.05 px on the H4 board vs < 0.025 px for pyrender.
- ``"pyrender"`` (occluders, and the reference for checking): OpenGL through pyrender. Its internals are
  reached only through :mod:`vision_calib.render.gl_adapter`; pyrender is imported on first use, so a
  CPU-only process never loads OpenGL.

The rest of this docstring describes the pyrender path.

What :class:`TargetRenderer` renders is the *ideal* grey image of the target: pinhole projection with
the camera matrix K (no distortion, no noise, no blur), flat unlit shading (texture value = pixel
value: white 255, black 0), anti-aliased by supersampling.

Conventions (proved in ``tests/render/test_renderer.py``):
- ``T_cam_target`` is the pose of the target frame (see :mod:`vision_calib.targets.spec`) in the
  OpenCV camera frame (x right, y down, z forward); it is turned into the pyrender/OpenGL camera
  pose with :func:`vision_calib.frames.cam_gl_from_cv` only.
- Pixels follow OpenCV: pixel (u, v) = (column, row) has its centre at integer (u, v); a 3-D point
  p_cam projects to u = fx x/z + cx, v = fy y/z + cy exactly as ``cv2.projectPoints`` with zero
  distortion. pyrender's ``IntrinsicsCamera`` measures cx, cy from the top-left *edge* of the image
  (its projection matrix maps cx to NDC 1 - 2 cx / W, rows counted downward), so it gets
  cx + 0.5, cy + 0.5.
- Supersampling by s: the image is rendered at (s H, s W) with fx_s = s fx, fy_s = s fy and a
  high-res pixel u_s covering [(u_s) / s - 0.5, (u_s + 1) / s - 0.5] of the final image, i.e.
  cx_s = s (cx + 0.5) - 0.5; then each s x s block is averaged (``cv2.resize`` INTER_AREA, an exact
  box filter for an integer factor).
- The texture is drawn with exact per-texel area coverage (edges not quantised to texels), padded
  (edge replicated) to power-of-two sides, uploaded with mipmaps and sampled trilinearly
  (GL_LINEAR_MIPMAP_LINEAR / GL_LINEAR) with a LOD bias of -1 (each high-res sample uses half the
  footprint: the s x s box average does the rest) and 16x anisotropic filtering where the driver has it.
  The power-of-two padding matters: Mesa llvmpipe's anisotropic sampler is exact only for
  power-of-two textures (see :func:`_pad_for_mipmaps`); without it the H4 board (texture 4096 x 2821)
  rendered at s = 2 had its corners shifted by +0.022 px in v on average (a v scale error: up to
  0.09 px at the top edge of the board), which biased solvePnP by 0.12 deg / 0.45 mm (tz) RMS.
- Measured on Mesa 22.3 llvmpipe, 1024 x 768, cornerSubPix corner shift against a CPU reference
  (s = 8 homography warp of the same texture), mean (du, dv) / RMS / max [px], and single-thread speed
  (``LP_NUM_THREADS=1 python -m vision_calib.sim.render_bench``):
  A5 board, 0.3-0.6 m: s = 1: (+0.000, +0.003) / 0.030 / 0.061, ~40 frames/s; s = 2: (0.000, 0.001)
  / 0.012 / 0.030, ~10 frames/s; s = 4: (0.000, 0.000) / 0.004 / 0.009, ~2.6 frames/s.
  H4 board, 0.6-0.76 m, f = 1013 px: s = 1: (0.000, 0.000) / 0.034 / 0.085; s = 2: (0.000, 0.000)
  / 0.014 / 0.042; s = 4: (0.000, 0.000) / 0.008 / 0.027 (before the padding: s = 2: (0.000, +0.022)
  / 0.073 / 0.226, s = 4: (0.000, -0.006) / 0.016 / 0.044). cornerSubPix's own bias against
  ``cv2.projectPoints`` is ~0.05 px RMS on these boards, larger than the renderer's error for s >= 2.
- Only the printed face (the side of -z_target, where the camera is when R_cam_target ~= I) carries
  the pattern; the back face is a uniform grey (``back_grey``).
"""

from __future__ import annotations

import os

import cv2
import numpy as np

from ..camera import CameraIntrinsics
from ..errors import ConfigError, DataError
from ..frames import cam_gl_from_cv, check_finite, inv_T
from ..targets.spec import TargetSpec
from .coverage import PolygonRenderer
from .warp import MAX_WARP_TEXTURE_PX, MipWarp, planar_warp_ok

#: Default cap on the texture's larger side [texels] when ``texture_px_per_m`` is not given.
DEFAULT_MAX_TEXTURE_PX = 4096
BACKENDS = ("auto", "polygon", "warp", "pyrender")

def _quad(extent, z_front: bool, uv_max=(1.0, 1.0)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two triangles covering extent (x0, y0, x1, y1) [m] at z = 0; vertices (4, 3), faces (2, 3),
    uv (4, 2). uv_max = (W / W_padded, H / H_padded): the part of the (padded) texture holding the
    board (its top-left corner, see :func:`_pad_for_mipmaps`). Winding is counter-clockwise seen from
    -z (front, printed face) or from +z (back)."""
    x0, y0, x1, y1 = extent
    v = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
    # pyrender flips the texture rows on upload: texture row 0 (y = y0) is at v = 1.
    um, vm = uv_max
    uv = np.array([[0.0, 1.0], [um, 1.0], [um, 1.0 - vm], [0.0, 1.0 - vm]])
    # Seen from -z (looking along +z: x right, y down on the screen) the order 0, 1, 2 (TL, TR, BR) is
    # clockwise on the screen, so the front face uses 0, 2, 1 (OpenGL front = counter-clockwise).
    f = np.array([[0, 2, 1], [0, 3, 2]]) if z_front else np.array([[0, 1, 2], [0, 2, 3]])
    return v, f, uv


def _mip_padded_shape(shape) -> tuple[int, int]:
    """(H', W'): each side of shape (H, W) rounded up to a power of two."""
    return tuple(1 << max(0, int(n - 1).bit_length()) for n in shape)


def _pad_for_mipmaps(tex: np.ndarray) -> tuple[np.ndarray, tuple[float, float]]:
    """Pad texture (H, W) on the right and bottom (edge replicated) to power-of-two sides.
    Returns (padded (H', W'), (W / W', H / H')), the second for :func:`_quad`.

    Why: Mesa llvmpipe's anisotropic (EWA) sampler is only exact for power-of-two textures. It
    places the sample at s * width0 / 2^level (not the real level width floor(width0 / 2^level)) and
    fetches each texel u with a NEAREST lookup at u / level_width, which for other sizes rounds to
    the neighbouring texel for some u. Measured on a 4096 x 2821 texture (ChArUco 9 x 6, 25 mm,
    0.6-0.76 m, f = 1013 px, supersample 2): rendered corners shifted by +0.026 px in v on average,
    0.11 px RMS against a CPU reference; padded: 0.001 / 0.02 px (module docstring)."""
    H, W = tex.shape
    Hp, Wp = _mip_padded_shape((H, W))
    if (Hp, Wp) != (H, W):
        tex = cv2.copyMakeBorder(tex, 0, Hp - H, 0, Wp - W, cv2.BORDER_REPLICATE)
    return tex, (W / Wp, H / Hp)


class _GLScene:
    """The pyrender scene of one board (+ occluders) and its offscreen context (see gl_adapter)."""

    def __init__(self, target, K: CameraIntrinsics, s: int, background, occluders, texture_px_per_m, back_grey,
                 texture_lod_bias, anisotropy, znear, zfar):
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
        os.environ.setdefault("EGL_PLATFORM", "surfaceless")
        from ..errors import import_extra

        pyrender = import_extra("pyrender", "sim", "rendering images of the target (simulate, demo and studies in "
                                "image mode)")
        from .gl_adapter import GLOffscreen

        self.gl = GLOffscreen(s * K.width, s * K.height)
        max_tex = self.gl.max_texture_size()
        shape = target.texture_shape(texture_px_per_m)
        padded = _mip_padded_shape(shape)
        if max(padded) > max_tex:
            self.close()
            raise ConfigError(
                f"TargetRenderer: texture {shape[1]}x{shape[0]} px (padded to {padded[1]}x{padded[0]} for "
                f"mipmapping) exceeds GL_MAX_TEXTURE_SIZE {max_tex}; lower texture_px_per_m "
                f"({texture_px_per_m:.0f} px/m)")
        tex, uv_max = _pad_for_mipmaps(target.texture(texture_px_per_m))
        self.texture_padded_shape = tex.shape
        self.scene = pyrender.Scene(bg_color=np.array([background, background, background, 255.0]) / 255.0,
                                    ambient_light=np.ones(3))
        extent = target.texture_extent_m()
        v, f, uv = _quad(extent, z_front=True, uv_max=uv_max)
        front_mat = pyrender.MetallicRoughnessMaterial(
            baseColorFactor=np.ones(4), metallicFactor=0.0, roughnessFactor=1.0,
            baseColorTexture=pyrender.Texture(source=tex, source_channels="R"))
        front = pyrender.Primitive(positions=v, indices=f, texcoord_0=uv, material=front_mat,
                                   mode=pyrender.GLTF.TRIANGLES)
        vb, fb, _ = _quad(extent, z_front=False)
        g = back_grey / 255.0
        back_mat = pyrender.MetallicRoughnessMaterial(baseColorFactor=np.array([g, g, g, 1.0]), metallicFactor=0.0)
        back = pyrender.Primitive(positions=vb, indices=fb, material=back_mat, mode=pyrender.GLTF.TRIANGLES)
        self.scene.add(pyrender.Mesh([front, back]), pose=np.eye(4))
        cam = pyrender.IntrinsicsCamera(fx=s * K.fx, fy=s * K.fy, cx=s * (K.cx + 0.5), cy=s * (K.cy + 0.5),
                                        znear=znear, zfar=zfar)
        self.cam_node = self.scene.add(cam, pose=np.eye(4))
        self.occ_nodes = []
        for i, occ in enumerate(occluders):
            mesh, T_cam_mesh, grey = occ
            mat = pyrender.MetallicRoughnessMaterial(baseColorFactor=np.array([grey, grey, grey, 1.0]),
                                                     metallicFactor=0.0)
            node = self.scene.add(pyrender.Mesh.from_trimesh(mesh, material=mat, smooth=False), pose=np.eye(4))
            self.occ_nodes.append((node, T_cam_mesh))
        self.flags = pyrender.RenderFlags.FLAT
        self.gl.render_grey(self.scene, self.flags)  # warm-up: uploads the texture (lazily), then set its sampling
        self.anisotropy = self.gl.configure_texture(front_mat.baseColorTexture, texture_lod_bias,
                                                    16.0 if anisotropy is None else anisotropy)

    def render(self, T_cam_target, occluder_poses) -> np.ndarray:
        """Supersampled grey uint8 (s H, s W) at pose T_cam_target (checked by the caller)."""
        T_target_cam = inv_T(T_cam_target)
        self.scene.set_pose(self.cam_node, cam_gl_from_cv(T_target_cam))
        for i, (node, T_cam_mesh) in enumerate(self.occ_nodes):
            T = T_cam_mesh if occluder_poses is None else check_finite(f"occluder_poses[{i}]", occluder_poses[i])
            self.scene.set_pose(node, T_target_cam @ T)
        return self.gl.render_grey(self.scene, self.flags)

    def close(self) -> None:
        self.gl.close()


class TargetRenderer:
    """Render a textured target plane as seen by a pinhole camera (OpenCV intrinsics; no distortion unless
    ``distort``).

    target: TargetSpec. intrinsics: CameraIntrinsics (its ``dist`` is ignored unless ``distort``).
    supersample: s >= 1, render at s x resolution then box-average (pyrender; the warp backend uses
    max(s, 4); the polygon backend computes exact pixel areas and ignores it).
    background: grey level [0, 255] of empty pixels. occluders: optional list of
    ``(trimesh.Trimesh, T_cam_mesh (4, 4))`` or ``(mesh, T_cam_mesh, grey)``, flat grey objects (default
    grey 40) fixed in the camera frame unless ``occluder_poses`` is given to :meth:`render` (pyrender only).
    texture_px_per_m: texture resolution [texels/m] (default: larger board side = 4096 texels).
    texture_lod_bias: mipmap LOD bias of the GL sampler (default -1). anisotropy: max anisotropic filtering
    (default 16; 1 = off; ignored if the driver lacks it). back_grey: grey level of the board's back face.
    znear, zfar: clip distances [m]. distort: the polygon backend draws the intrinsics' lens distortion
    geometrically (exact pixel areas of the distorted image, ``PolygonRenderer(distort=True)``), so no
    resampling follows; :attr:`last_distorted` says whether the last image holds it (False for the other
    backends and for a pyrender fallback: the caller applies the distortion, ``sensor.apply_effects``). backend: "auto" (default: "polygon" without occluders, else "pyrender"),
    "polygon", "warp" or "pyrender" (module docstring); the chosen one is :attr:`backend`, the one that drew
    the last image :attr:`last_backend` (a planar backend hands poses with a board corner at or behind znear
    to pyrender). An OpenGL context is held only once pyrender is used; call :meth:`close` or use ``with``.
    """

    def __init__(self, target: TargetSpec, intrinsics: CameraIntrinsics, supersample: int = 2,
                 background: float = 128, occluders=None, texture_px_per_m: float | None = None,
                 back_grey: float = 200, texture_lod_bias: float = -1.0, anisotropy: float | None = None,
                 znear: float = 0.005, zfar: float = 100.0, backend: str = "auto", distort: bool = False):
        if int(supersample) != supersample or supersample < 1:
            raise ConfigError(f"TargetRenderer: supersample must be an integer >= 1, got {supersample}")
        if not (0 <= background <= 255):
            raise ConfigError(f"TargetRenderer: background must be a grey level in [0, 255], got {background}")
        if not (0 < znear < zfar):
            raise ConfigError(f"TargetRenderer: need 0 < znear < zfar [m], got {znear}, {zfar}")
        if backend not in BACKENDS:
            raise ConfigError(f"TargetRenderer: backend must be one of {BACKENDS}, got {backend!r}")
        occ = []
        for i, o in enumerate(occluders or []):
            if len(o) not in (2, 3):
                raise ConfigError(f"TargetRenderer: occluder {i} must be (mesh, T_cam_mesh) or (mesh, T_cam_mesh, grey)")
            occ.append((o[0], check_finite(f"occluder {i} T_cam_mesh", o[1]), (o[2] if len(o) == 3 else 40.0) / 255.0))
        if backend == "auto":
            backend = "pyrender" if occ else "polygon"
        if backend in ("polygon", "warp") and occ:
            raise ConfigError(f"TargetRenderer: backend {backend!r} renders a lone planar target; occluders need 'pyrender'")
        self.backend = backend
        self.target, self.intrinsics = target, intrinsics
        self.supersample = int(supersample)
        self.background = float(background)
        w_m, h_m = target.outline_m()
        self.texture_px_per_m = float(DEFAULT_MAX_TEXTURE_PX / max(w_m, h_m) if texture_px_per_m is None
                                      else texture_px_per_m)
        self.texture_shape = target.texture_shape(self.texture_px_per_m)
        self._gl_args = (target, intrinsics, self.supersample, self.background, occ, self.texture_px_per_m,
                         back_grey, texture_lod_bias, anisotropy, znear, zfar)
        self._znear = znear
        self._n_occ = len(occ)
        self._gl = self._cpu = None
        self.last_backend = None
        self.anisotropy = float("nan")  # GL sampler's anisotropy, once a GL context exists
        if backend == "polygon":
            self._cpu = PolygonRenderer(target, intrinsics, self.background, back_grey, distort=distort)
        self.last_distorted = False
        if backend in ("polygon", "warp"):
            if max(self.texture_shape) > MAX_WARP_TEXTURE_PX:  # the texture of a pyrender fallback
                raise ConfigError(
                    f"TargetRenderer: texture {self.texture_shape[1]}x{self.texture_shape[0]} px exceeds the CPU "
                    f"backends' {MAX_WARP_TEXTURE_PX} px (GL_MAX_TEXTURE_SIZE of common drivers); lower "
                    f"texture_px_per_m ({self.texture_px_per_m:.0f} px/m)")
        if backend == "warp":
            self._cpu = MipWarp(target, intrinsics, max(self.supersample, 4), self.background, back_grey,
                                 self.texture_px_per_m)
        if backend == "pyrender":
            self._open_gl()

    def _open_gl(self) -> _GLScene:
        if self._gl is None:
            self._gl = _GLScene(*self._gl_args)
            self.anisotropy = self._gl.anisotropy
            self.texture_padded_shape = self._gl.texture_padded_shape
        return self._gl

    # ------------------------------------------------------------------ rendering
    def render(self, T_cam_target, occluder_poses=None, dtype=np.float32) -> np.ndarray:
        """Ideal grey image (H, W) of the target at pose T_cam_target (4, 4) [m, OpenCV camera frame].

        occluder_poses: optional list of T_cam_mesh (4, 4), one per occluder, for this frame.
        dtype: np.float32 (values in [0, 255]) or np.uint8 (rounded).
        """
        T_cam_target = check_finite("T_cam_target", T_cam_target)
        if T_cam_target.shape != (4, 4):
            raise DataError(f"T_cam_target must be (4, 4), got {T_cam_target.shape}")
        if occluder_poses is not None and len(occluder_poses) != self._n_occ:
            raise DataError(f"occluder_poses: expected {self._n_occ} poses, got {len(occluder_poses)}")
        if self._cpu is not None and planar_warp_ok(self.target, T_cam_target, self._znear):
            img = self._cpu.render(T_cam_target)
            self.last_backend = self.backend
            self.last_distorted = bool(getattr(self._cpu, "distort", False))
        else:
            self.last_backend = "pyrender"
            self.last_distorted = False
            img = self._open_gl().render(T_cam_target, occluder_poses).astype(np.float32)
            if self.supersample > 1:  # exact s x s box average for an integer factor
                img = cv2.resize(img, self.intrinsics.size, interpolation=cv2.INTER_AREA)
        if np.dtype(dtype) == np.uint8:
            return np.clip(np.round(img), 0, 255).astype(np.uint8)
        return img.astype(dtype, copy=False)

    def render_batch(self, T_cam_targets, occluder_poses=None, dtype=np.float32) -> np.ndarray:
        """Images (N, H, W) for poses (N, 4, 4). occluder_poses: None or (N, n_occluders, 4, 4)."""
        T = np.asarray(T_cam_targets, dtype=float)
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise DataError(f"T_cam_targets must be (N, 4, 4), got {T.shape}")
        out = np.empty((T.shape[0], self.intrinsics.height, self.intrinsics.width), dtype=dtype)
        for i in range(T.shape[0]):
            occ = None if occluder_poses is None else occluder_poses[i]
            out[i] = self.render(T[i], occluder_poses=occ, dtype=dtype)
        return out

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Release the OpenGL context if one was opened (idempotent; other live renderers keep working)."""
        gl, self._gl = getattr(self, "_gl", None), None
        if gl is not None:
            gl.close()

    def __enter__(self) -> "TargetRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def look_at_target(target: TargetSpec, distance_m: float, rvec_tilt=(0.0, 0.0, 0.0), offset_m=(0.0, 0.0)) -> np.ndarray:
    """Convenience pose T_cam_target (4, 4): the board centre on the optical axis at distance_m [m]
    (shifted by offset_m = (dx, dy) [m] in the camera x-y plane), board rotated by the rotation
    vector rvec_tilt [rad] about its centre (zero = fronto-parallel, upright)."""
    from ..frames import T_from_rvec_tvec, make_T

    x0, y0, x1, y1 = target.texture_extent_m()
    T_target_centre = make_T(t=[(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    T_cam_centre = T_from_rvec_tvec(np.asarray(rvec_tilt, float), np.array([offset_m[0], offset_m[1], distance_m]))
    return T_cam_centre @ inv_T(T_target_centre)
