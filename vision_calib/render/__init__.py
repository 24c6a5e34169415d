"""render stage: the ideal image of a calibration target (exact pixel-area coverage of the board's projected
rectangles on the CPU for a lone planar board, the default; an opt-in CPU warp of a mip-mapped texture;
pyrender + trimesh offscreen OpenGL with occluders, and as the reference for checking).

pyrender/OpenGL are imported only when the pyrender backend is used; that import sets
``PYOPENGL_PLATFORM=egl`` and ``EGL_PLATFORM=surfaceless`` (setdefault) first (Mesa llvmpipe on CPU, the
GPU's EGL driver when there is one). Conventions: see :mod:`vision_calib.render.renderer`.
"""

from .renderer import TargetRenderer, look_at_target

__all__ = ["TargetRenderer", "look_at_target"]
