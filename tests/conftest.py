import os

# Offscreen rendering on CPU (EGL surfaceless Mesa); the render/ package also sets these defaults.
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("EGL_PLATFORM", "surfaceless")

# Single-threaded BLAS as in the CLI (small matrices; threads only add overhead on 2 cores).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# Real recorded data lives beside the repository (../shared/data; DESIGN.md), read in place.
# VISION_CALIB_SHARED_DATA overrides; tests that need it skip when it is absent.
from pathlib import Path as _Path

_REPO = _Path(__file__).resolve().parents[1]
for _cand in (os.environ.get("VISION_CALIB_SHARED_DATA"), _REPO.parent / "shared" / "data", "/work/shared/data"):
    if _cand and _Path(_cand).is_dir():
        os.environ["VISION_CALIB_SHARED_DATA"] = str(_cand)
        break
else:
    os.environ.setdefault("VISION_CALIB_SHARED_DATA", str(_REPO.parent / "shared" / "data"))
