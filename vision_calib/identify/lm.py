"""Levenberg-Marquardt on the normal equations, with chord steps: the solver of
:func:`~vision_calib.identify.lse.solve_lse` (method "lm", analytic Jacobian). MINPACK's ``lmder`` scaling and
termination tests; once J^T J and J^T r are formed, each iteration is (n, n) products and solves, so a problem too
large to hold J gives them block by block (``lse.normal_equations``). numpy and scipy.linalg only."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import LinAlgError
from scipy.linalg.lapack import dpotrf as _potrf, dpotrs as _potrs


@dataclass
class LMResult:
    """What :func:`levenberg_marquardt` returns (the fields of scipy's ``least_squares`` result that are read)."""

    x: np.ndarray
    cost: float
    status: int
    message: str
    nfev: int
    njev: int
    #: (n, n) normal matrix J^T J of the Jacobian the final Gauss-Newton step used (within CHORD_RADIUS of the
    #: solution: the covariance there); None when the normal equations were not given or there was no final step
    A: np.ndarray | None = None


#: levenberg_marquardt's termination messages by status (MINPACK's meaning of the three tolerances)
LM_MESSAGES = {0: "the maximum number of function evaluations is exceeded",
               1: "gtol: the gradient is orthogonal to the residual to within gtol",
               2: "ftol: the actual and predicted relative reductions of the cost are at most ftol",
               3: "xtol: the relative step is at most xtol",
               4: "ftol and xtol are both satisfied"}


#: levenberg_marquardt's message when the Gauss-Newton step at a new Jacobian predicts at most ftol (status 2)
LM_GN_FTOL = "ftol: the Gauss-Newton step predicts a relative reduction of the cost of at most ftol"

#: levenberg_marquardt's first damping (of the column-equilibrated normal matrix, unit diagonal): nearly Gauss-Newton
LM_LAMBDA0 = 1e-6

#: levenberg_marquardt takes chord steps (Gauss-Newton steps with the last Jacobian, no new one) while the point stays
#: within this distance (largest |dz|, scaled units: 1 = one ``params.scale``, 1 mm / 1 mrad by default, so 1e-4 is
#: 0.1 um / 0.1 urad) of the point where that Jacobian was computed; its final step (the minimum to rounding) and the
#: covariance use the last Jacobian only within this distance, else a new one. That Jacobian differs from the one at
#: the solution by ~1e-7 relative, and so do the answer and its covariance from Gauss-Newton's at the solution, in
#: units of the std (``benchmarks/bench_identify.py`` prints the difference from a full fit)
CHORD_RADIUS = 1e-4
#: a chord step is taken only when it is at most this fraction of the step before it (the iteration contracts)
CHORD_CONTRACTION = 0.25


def _cho_factor(A: np.ndarray):
    """scipy's ``cho_factor(A, check_finite=False)`` (upper factor, the other triangle not cleared) by LAPACK's potrf
    directly: the same numbers without the wrapper's argument handling (~30 us a call, ~17 calls per small fit).
    A (n, n) float. LinAlgError when A is not positive definite."""
    c, info = _potrf(A, lower=0, clean=0)
    if info > 0:
        raise LinAlgError(f"{info}-th leading minor of the array is not positive definite")
    if info < 0:
        raise ValueError(f"LAPACK potrf: illegal value in argument {-info}")
    return c


def _cho_solve(c: np.ndarray, b: np.ndarray) -> np.ndarray:
    """scipy's ``cho_solve((c, False), b, check_finite=False)`` by LAPACK's potrs: x (n,) with A x = b, c from
    :func:`_cho_factor`."""
    x, info = _potrs(c, b, lower=0)
    if info != 0:
        raise ValueError(f"LAPACK potrs: illegal value in argument {-info}")
    return x


def levenberg_marquardt(fun, jac, z0, max_nfev=None, xtol=1e-12, ftol=1e-12, gtol=1e-12, normal=None) -> LMResult:
    """Minimise 0.5 |fun(z)|^2 (fun: (n,) -> (M,), jac: (n,) -> (M, n)) from z0 (n,) by Levenberg-Marquardt on the
    normal equations: per iteration J^T J and J^T r (two BLAS products over the M rows) and an (n, n) Cholesky
    solve of (S J^T J S + lam I) y = -S J^T r, dz = S y, S = diag(J^T J)^-1/2 (running maximum, MINPACK's scaling,
    so the solve is that of the column-equilibrated problem), lam raised while a step does not lower the cost.
    After an accepted step, chord steps (undamped, with the same Jacobian: J^T r only) while each lowers the cost,
    is at most :data:`CHORD_CONTRACTION` of the one before and stays within :data:`CHORD_RADIUS` of the
    Jacobian's point; then a new Jacobian.
    Termination as MINPACK's ``lmder`` (scipy's method "lm"): gtol on the largest cosine between the residual and
    a column, ftol on the actual and predicted relative reduction (also, status 2, when the undamped step at a new
    Jacobian predicts at most ftol: a cost whose own rounding exceeds ftol then stops there instead of dithering
    until xtol), xtol on the scaled step, then one Gauss-Newton
    step (kept when it does not raise the cost: the minimum to rounding, so that inputs equal to rounding give
    answers equal to rounding through iterated fits) with the last Jacobian, or a new one when the point is
    farther than CHORD_RADIUS from it; max_nfev (default 100 (n + 1)) evaluations of fun. ``normal`` (z, r) ->
    (J^T J (n, n), J^T r (n,)), when given, replaces jac (a problem too large to hold J: :func:`normal_equations`;
    ``normal.chord(r)``, J^T r with its last Jacobian, or None: no chord steps, and the final step takes new
    normal equations), and the result carries the normal matrix of the final step (``A``). Returns an
    :class:`LMResult` (status 1-4 converged, 0 out of evaluations, -1 a non-finite Jacobian)."""
    z = np.asarray(z0, float).copy()
    n = z.size
    max_nfev = 100 * (n + 1) if max_nfev is None else int(max_nfev)
    r = np.asarray(fun(z), float)
    nfev, njev = 1, 0
    cost = 0.5 * float(r @ r)
    d2 = np.zeros(n)
    lam, status = None, 0

    def finish(z, r, cost, status, A, chord_g, zJ, message=None, factor=None):
        """The last Gauss-Newton step (module doc), then the result; factor: _cho_factor(A) when already taken."""
        nonlocal nfev, njev
        A_end = None
        if nfev < max_nfev:
            try:
                if chord_g is not None and np.max(np.abs(z - zJ), initial=0.0) <= CHORD_RADIUS:
                    gr = chord_g(r)
                else:  # a new Jacobian at z: its covariance, and the step with it
                    factor = None
                    if normal is None:
                        J = np.asarray(jac(z), float)
                        A, gr = J.T @ J, J.T @ r
                    else:
                        A, gr = normal(z, r)
                    njev += 1
                if np.all(np.isfinite(A)) and np.all(np.isfinite(gr)):
                    A_end = A
                    factor = _cho_factor(A) if factor is None else factor
                    dz = -_cho_solve(factor, gr)
                    r2 = np.asarray(fun(z + dz), float)
                    nfev += 1
                    c2 = 0.5 * float(r2 @ r2) if np.all(np.isfinite(r2)) else np.inf
                    # kept when it lowers the cost, or raises it by rounding alone (the reduction it predicts,
                    # -g.dz / 2, is below ftol: the cost cannot tell, the stationary point of the model is the answer)
                    if c2 <= cost or (np.isfinite(c2) and -0.5 * float(gr @ dz) <= ftol * cost
                                      and c2 - cost <= ftol * cost):
                        z, cost = z + dz, c2
            except (LinAlgError, ValueError):
                pass
        return LMResult(z, cost, status, message or LM_MESSAGES[status], nfev, njev,
                        A_end if normal is not None else None)

    while True:
        if normal is None:
            J = np.asarray(jac(z), float)
            A, g = J.T @ J, J.T @ r
            chord_g = (lambda rr, J=J: J.T @ rr)
        else:
            A, g = normal(z, r)
            chord_g = getattr(normal, "chord", None)
        njev += 1
        zJ = z.copy()
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(g))):
            return LMResult(z, cost, -1, "the Jacobian is not finite at the current point", nfev, njev)
        diag = np.diag(A).copy()
        d2 = np.maximum(d2, diag)
        dsafe = np.where(d2 > 0, d2, 1.0)
        rn = np.sqrt(2.0 * cost)
        if rn == 0 or np.max(np.abs(g) / (rn * np.sqrt(np.where(diag > 0, diag, np.inf)))) <= gtol:
            status = 1
            break
        try:  # the undamped (Gauss-Newton) step's predicted reduction at most ftol: no step can reach ftol
            factor = _cho_factor(A)  # (kept for the chord steps and the final step with A)
            if 0.5 * float(g @ _cho_solve(factor, g)) <= ftol * cost:
                return finish(z, r, cost, 2, A, chord_g, zJ, LM_GN_FTOL, factor)  # its final step: that GN step
        except (LinAlgError, ValueError):
            factor = None
        S = 1.0 / np.sqrt(dsafe)
        As, gs = A * np.outer(S, S), g * S
        if lam is None:
            lam = LM_LAMBDA0
        while True:
            try:
                y = -_cho_solve(_cho_factor(As + lam * np.eye(n)), gs)
            except LinAlgError:
                lam = max(lam * 10.0, 1e-12)
                continue
            dz = S * y
            pred = -(float(g @ dz) + 0.5 * float(dz @ A @ dz))  # predicted reduction of the cost (> 0)
            z_new = z + dz
            r_new = np.asarray(fun(z_new), float)
            nfev += 1
            cost_new = 0.5 * float(r_new @ r_new) if np.all(np.isfinite(r_new)) else np.inf
            actual = cost - cost_new
            rho = actual / pred if pred > 0 else -1.0
            step, size = float(np.linalg.norm(np.sqrt(dsafe) * dz)), float(np.linalg.norm(np.sqrt(dsafe) * z))
            f_ok = abs(actual) <= ftol * cost and pred <= ftol * cost and rho <= 2.0
            x_ok = step <= xtol * size
            if rho > 1e-4:  # accepted: less damping when the model predicted well
                z, r, cost = z_new, r_new, cost_new
                lam *= max(0.1, 1.0 - (2.0 * rho - 1.0) ** 3)
            else:
                lam *= 4.0
            if f_ok or x_ok:  # (a step rejected by rounding alone included: the final step is taken from z)
                status = 4 if f_ok and x_ok else (2 if f_ok else 3)
                return finish(z, r, cost, status, A, chord_g, zJ, factor=factor)
            if nfev >= max_nfev:
                return LMResult(z, cost, 0, LM_MESSAGES[0], nfev, njev)
            if rho > 1e-4:
                break
        if chord_g is None or np.max(np.abs(z - zJ)) - CHORD_CONTRACTION * step / np.sqrt(dsafe.min()) > CHORD_RADIUS:
            continue  # (no chord step can come back within CHORD_RADIUS of the Jacobian's point: none tried)
        if factor is None:  # (chord steps with this Jacobian, module doc: A not positive definite, none)
            continue
        prev = step
        while nfev < max_nfev:
            gc = chord_g(r)
            dz = -_cho_solve(factor, gc)
            step = float(np.linalg.norm(np.sqrt(dsafe) * dz))
            if not (step <= CHORD_CONTRACTION * prev and np.max(np.abs(z + dz - zJ)) <= CHORD_RADIUS):
                break
            r_new = np.asarray(fun(z + dz), float)
            nfev += 1
            cost_new = 0.5 * float(r_new @ r_new) if np.all(np.isfinite(r_new)) else np.inf
            pred = -(float(gc @ dz) + 0.5 * float(dz @ A @ dz))
            actual = cost - cost_new
            rho = actual / pred if pred > 0 else -1.0
            f_ok = abs(actual) <= ftol * cost and pred <= ftol * cost and rho <= 2.0
            x_ok = step <= xtol * float(np.linalg.norm(np.sqrt(dsafe) * z))
            accepted = cost_new <= cost
            if accepted:
                z, r, cost, prev = z + dz, r_new, cost_new, step
            if f_ok or x_ok:  # (a step rejected by rounding alone: the minimum, to rounding)
                status = 4 if f_ok and x_ok else (2 if f_ok else 3)
                return finish(z, r, cost, status, A, chord_g, zJ, factor=factor)
            if not accepted:
                break
        if nfev >= max_nfev:
            return LMResult(z, cost, 0, LM_MESSAGES[0], nfev, njev)
    return LMResult(z, cost, status, LM_MESSAGES[status], nfev, njev)


__all__ = ["LMResult", "levenberg_marquardt"]
