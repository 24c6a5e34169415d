import os

# Offscreen rendering on CPU (EGL surfaceless Mesa); the render/ package also sets these defaults.
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("EGL_PLATFORM", "surfaceless")
