"""render stage: pyrender + trimesh offscreen rendering of calibration targets.

The only package that touches OpenGL; it sets ``PYOPENGL_PLATFORM=egl`` and
``EGL_PLATFORM=surfaceless`` (setdefault) before pyrender is imported (Mesa llvmpipe on CPU, the GPU's
EGL driver when there is one). Conventions: see :mod:`vision_calib.render.renderer`.
"""

import os

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("EGL_PLATFORM", "surfaceless")

from .renderer import TargetRenderer, look_at_target  # noqa: E402

__all__ = ["TargetRenderer", "look_at_target"]
