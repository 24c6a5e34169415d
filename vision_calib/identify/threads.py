"""Single-threaded BLAS around the identify stage's small dense algebra, without the caller's help.

Our matrices are small (a few hundred rows x tens of columns). A multi-threaded BLAS (OpenBLAS
starts one thread per core by default) only adds synchronisation to an SVD/QR of that size, and
on a loaded machine its spinning threads thrash: a 7-axis MDH fit (114 poses, 40 parameters,
5 folds) took 11.8 s with the default threading instead of 0.23 s single-threaded (issue 11).
The CLI sets ``OMP_NUM_THREADS=1`` before numpy loads, but a library user does not, so every
public entry point of ``identify/`` (``solve_lse``, ``solve_ekf``, ``analyze``, ``select_poses``)
runs inside :func:`small_blas`, which limits the BLAS thread pools to one thread with
``threadpoolctl`` for the duration of the call when the problem is small, and restores them after.

"Small": the whitened Jacobian has at most :data:`SMALL_MAX_ENTRIES` entries (rows x columns);
larger problems keep the caller's threading (there threads pay off). The limit is process-wide
while it is active (that is how BLAS thread pools work): other Python threads of the process that
call BLAS at the same moment run single-threaded too. Nested calls (``solve_lse`` -> ``analyze``)
enter the limit once. Without ``threadpoolctl`` installed this is a no-op.
"""

from __future__ import annotations

import contextlib
import functools
import threading
from typing import Callable, Iterator

from .problem import IdentificationProblem

#: largest whitened-Jacobian size (rows x free parameters) treated as "small": 2e6 entries = 16 MB
SMALL_MAX_ENTRIES = 2_000_000

_lock = threading.Lock()
_depth = 0
_controller = None
_limiter = None


def _get_controller():
    """The threadpoolctl controller, built once (scanning the loaded libraries costs ~0.2 ms); None
    when threadpoolctl is missing."""
    global _controller
    if _controller is None:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:  # pragma: no cover - threadpoolctl is a declared dependency
            _controller = False
        else:
            _controller = ThreadpoolController()
    return _controller or None


@contextlib.contextmanager
def small_blas(n_entries: int | None = None) -> Iterator[None]:
    """Context: BLAS limited to one thread when ``n_entries`` (rows x columns of the largest matrix,
    None = unknown/small) is at most :data:`SMALL_MAX_ENTRIES`; re-entrant; restores on exit."""
    global _depth, _limiter
    if n_entries is not None and n_entries > SMALL_MAX_ENTRIES:
        yield
        return
    with _lock:
        if _depth == 0:
            ctrl = _get_controller()
            _limiter = None if ctrl is None else ctrl.limit(limits=1, user_api="blas")
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0 and _limiter is not None:
                _limiter.restore_original_limits()
                _limiter = None


def problem_size(problem: IdentificationProblem) -> int:
    """Rows x free columns of ``problem``'s whitened Jacobian (the size :func:`small_blas` looks at)."""
    try:
        return int(problem.n_obs * problem.m * max(1, problem.params.n_free))
    except Exception:  # noqa: BLE001 - size unknown: treat as small; the solver validates the problem itself
        return 0


def single_threaded_blas(fn: Callable) -> Callable:
    """Decorator for ``fn(problem, ...)``: run it inside :func:`small_blas` sized by ``problem``."""

    @functools.wraps(fn)
    def wrapper(problem, *args, **kwargs):
        with small_blas(problem_size(problem)):
            return fn(problem, *args, **kwargs)

    return wrapper


def blas_threads() -> int | None:
    """Current number of BLAS threads (max over the loaded BLAS libraries), None when unknown."""
    ctrl = _get_controller()
    if ctrl is None:
        return None
    info = [lib.num_threads for lib in ctrl.select(user_api="blas").lib_controllers]
    return max(info) if info else None
