"""identify stage: problem/result types, identifiability analysis, LSE and EKF solvers.

Public API::

    IdentificationProblem, IdentificationResult            (problem.py)
    analyze(problem, x=None, tol=None) -> IdentifiabilityReport
    base_problem(problem, report=None) -> (problem, report, warnings)
    solve_lse(problem, x0=None, ...) / solve_lse_fd(...) -> IdentificationResult
    solve_ekf(problem, x0=None, passes=1, ...) -> IdentificationResult
"""

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
from .problem import IdentificationProblem, IdentificationResult

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
]
