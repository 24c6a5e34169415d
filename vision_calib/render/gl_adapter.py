"""The ONE place that touches pyrender internals (private attributes), so that a pyrender upgrade breaks
here and nowhere else. Why each one is needed:

- ``OffscreenRenderer._platform.make_current()``: GL calls of our own (texture sampling, pixel store,
  framebuffer) need the renderer's context current; pyrender has no public accessor.
- ``Texture._texid``: pyrender uploads textures lazily and exposes no sampler settings; the LOD bias,
  clamp-to-edge wrapping and anisotropic filtering (see renderer.py: corner accuracy) are set on its GL id.
- ``Renderer._configure_main_framebuffer`` / ``_main_fb_ms`` / ``_read_main_framebuffer``: pyrender's
  offscreen pass draws into a 4x multisampled RGBA + depth framebuffer, then resolves colour AND depth
  and reads both back (float depth conversion included) on every frame; that read-back was most of the
  render time. We only need one colour channel at full resolution, already anti-aliased by supersampling,
  so the forward pass is pointed at a plain single-sample R8 + depth framebuffer of ours and the read-back
  is one ``glReadPixels(GL_RED)``.
- EGL teardown (``_egl_display`` / ``_egl_context``): pyrender's ``delete()`` calls eglTerminate on the
  process-wide EGL display, which kills every other live context; with several renderers open, only this
  context is destroyed and the display is terminated by the last one closed.
"""

from __future__ import annotations

import numpy as np
import pyrender
from OpenGL import GL

_GL_TEXTURE_MAX_ANISOTROPY = 0x84FE  # GL 4.6 / EXT_texture_filter_anisotropic
_GL_MAX_TEXTURE_MAX_ANISOTROPY = 0x84FF

_LIVE: set[int] = set()  # ids of open GLOffscreen objects (see close)


class GLOffscreen:
    """One pyrender offscreen context of (width, height) px that renders a scene to a grey uint8 image."""

    def __init__(self, width: int, height: int):
        self.width, self.height = int(width), int(height)
        self._r = pyrender.OffscreenRenderer(self.width, self.height)
        _LIVE.add(id(self))
        self._fb = self._rb = None
        self.make_current()
        self._install_plain_framebuffer()

    def make_current(self) -> None:
        self._r._platform.make_current()

    @staticmethod
    def max_texture_size() -> int:
        """GL_MAX_TEXTURE_SIZE of the current context."""
        return int(GL.glGetIntegerv(GL.GL_MAX_TEXTURE_SIZE))

    def _install_plain_framebuffer(self) -> None:
        w, h = self.width, self.height
        cb, db = GL.glGenRenderbuffers(2)
        GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, cb)
        GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, GL.GL_R8, w, h)
        GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, db)
        GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, GL.GL_DEPTH_COMPONENT24, w, h)
        fb = GL.glGenFramebuffers(1)
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, fb)
        GL.glFramebufferRenderbuffer(GL.GL_DRAW_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0, GL.GL_RENDERBUFFER, cb)
        GL.glFramebufferRenderbuffer(GL.GL_DRAW_FRAMEBUFFER, GL.GL_DEPTH_ATTACHMENT, GL.GL_RENDERBUFFER, db)
        status = GL.glCheckFramebufferStatus(GL.GL_DRAW_FRAMEBUFFER)
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, 0)
        if status != GL.GL_FRAMEBUFFER_COMPLETE:
            raise RuntimeError(f"OpenGL: single-sample R8 framebuffer incomplete (status {status:#x})")
        self._fb, self._rb = fb, (cb, db)
        rr = self._r._renderer
        rr._configure_main_framebuffer = lambda: None  # instance attributes shadow pyrender's methods
        rr._main_fb_ms = fb  # the forward pass binds this one for drawing
        rr._read_main_framebuffer = lambda scene, flags: self._read()

    def _read(self) -> np.ndarray:
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._fb)
        GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
        buf = GL.glReadPixels(0, 0, self.width, self.height, GL.GL_RED, GL.GL_UNSIGNED_BYTE)
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, 0)
        img = np.frombuffer(buf, dtype=np.uint8).reshape(self.height, self.width)
        return img[::-1]  # GL rows are bottom-up

    def render_grey(self, scene, flags) -> np.ndarray:
        """Render ``scene`` (pyrender.Scene) -> grey uint8 (height, width), red channel only, rows top-down."""
        self.make_current()
        GL.glPixelStorei(GL.GL_UNPACK_ALIGNMENT, 1)  # single-channel texture rows of any width
        out = self._r.render(scene, flags=flags)
        return np.ascontiguousarray(out[0] if isinstance(out, tuple) else out)

    def configure_texture(self, texture, lod_bias: float, anisotropy: float) -> float:
        """Set LOD bias, clamp-to-edge and anisotropic filtering on an uploaded pyrender.Texture; returns
        the anisotropy used (1 when the driver lacks the extension)."""
        self.make_current()
        GL.glBindTexture(GL.GL_TEXTURE_2D, texture._texid)
        GL.glTexParameterf(GL.GL_TEXTURE_2D, GL.GL_TEXTURE_LOD_BIAS, float(lod_bias))
        for wrap in (GL.GL_TEXTURE_WRAP_S, GL.GL_TEXTURE_WRAP_T):  # no wrap-around at the board's edges
            GL.glTexParameteri(GL.GL_TEXTURE_2D, wrap, GL.GL_CLAMP_TO_EDGE)
        used = 1.0
        if anisotropy > 1:
            try:
                max_aniso = float(GL.glGetFloatv(_GL_MAX_TEXTURE_MAX_ANISOTROPY))
                used = min(float(anisotropy), max_aniso)
                GL.glTexParameterf(GL.GL_TEXTURE_2D, _GL_TEXTURE_MAX_ANISOTROPY, used)
            except GL.GLError:  # extension missing: plain trilinear
                used = 1.0
        GL.glBindTexture(GL.GL_TEXTURE_2D, 0)
        return used

    def close(self) -> None:
        """Release the context (idempotent); the EGL display is terminated only by the last one closed."""
        r = getattr(self, "_r", None)
        if r is None:
            return
        self._r = None
        _LIVE.discard(id(self))
        plat = r._platform
        plat.make_current()
        if self._fb is not None:
            GL.glDeleteFramebuffers(1, [self._fb])
            GL.glDeleteRenderbuffers(2, list(self._rb))
            self._fb = None
        r._renderer.delete()
        if type(plat).__name__ == "EGLPlatform" and _LIVE:
            from OpenGL.EGL import eglDestroyContext

            eglDestroyContext(plat._egl_display, plat._egl_context)
            plat._egl_context = None
            plat._egl_display = None
        else:
            plat.delete_context()
        r._renderer = None
        r._platform = None
