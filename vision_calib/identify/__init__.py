"""identify stage: problem/result types, identifiability analysis, LSE and EKF solvers.

Public API::

    IdentificationProblem, IdentificationResult            (problem.py)
    analyze(problem, x=None, tol=None) -> IdentifiabilityReport
    base_problem(problem, report=None) -> (problem, report, warnings)
    solve_lse(problem, x0=None, ...) / solve_lse_fd(...) -> IdentificationResult
    solve_ekf(problem, x0=None, passes=None (until converged), ...) -> IdentificationResult
    model_adequacy(result) -> dict;  fit_rejecting_outliers(problem, ...) -> (result, rejected)
    small_blas(): single-threaded BLAS context used by every solver (threads.py)
"""

from .adequacy import fit_rejecting_outliers, model_adequacy
from .ekf import solve_ekf
from .identifiability import (
    IdentifiabilityReport,
    analyze,
    base_problem,
    check_problem,
    equivalent_base_values,
    observability_indices,
)
from .lse import solve_lse, solve_lse_fd
from .problem import (
    STATUS_CONVERGED,
    STATUS_MAX_ITERATIONS,
    STATUS_NOT_FINITE,
    IdentificationProblem,
    IdentificationResult,
)
from .threads import small_blas

__all__ = [
    "IdentificationProblem",
    "IdentificationResult",
    "IdentifiabilityReport",
    "analyze",
    "base_problem",
    "check_problem",
    "equivalent_base_values",
    "observability_indices",
    "solve_lse",
    "solve_lse_fd",
    "solve_ekf",
    "model_adequacy",
    "fit_rejecting_outliers",
    "small_blas",
    "STATUS_CONVERGED",
    "STATUS_MAX_ITERATIONS",
    "STATUS_NOT_FINITE",
]
