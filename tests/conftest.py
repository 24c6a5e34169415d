import os

# Offscreen rendering on CPU (EGL surfaceless Mesa); the render/ package also sets these defaults.
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("EGL_PLATFORM", "surfaceless")

# Single-threaded BLAS as in the CLI (small matrices; threads only add overhead on 2 cores).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
