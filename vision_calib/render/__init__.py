"""render stage: the ideal image of a calibration target (CPU homography warp of a mip-mapped texture
for a lone planar board; pyrender + trimesh offscreen OpenGL otherwise and for checking).

pyrender/OpenGL are imported only when the pyrender backend is used; that import sets
``PYOPENGL_PLATFORM=egl`` and ``EGL_PLATFORM=surfaceless`` (setdefault) first (Mesa llvmpipe on CPU, the
GPU's EGL driver when there is one). Conventions: see :mod:`vision_calib.render.renderer`.
"""

from .renderer import TargetRenderer, look_at_target

__all__ = ["TargetRenderer", "look_at_target"]
