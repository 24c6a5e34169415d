"""Least-squares identification (LSE) with scipy ``least_squares``.

Cost: 0.5 * sum_k || W_k r_k(x) ||^2 with ``r = measured - model`` and ``W_k`` the inverse
Cholesky factor of ``obs_cov[k]`` (whitened residuals). Only free parameters move; the solver
works in *scaled* variables ``z = (x_free - x0_free) / scale_free`` (``params.scale``), so that
one unit of z is one typical deviation and scipy's tolerances are meaningful for lengths and
angles alike. The Jacobian is the problem's analytic one, whitened and scaled the same way
(``jac="2-point"``/``"3-point"`` uses scipy finite differences instead: the baseline).

Before solving, :func:`~vision_calib.identify.identifiability.analyze` runs at ``x0`` and, with
``fix_unidentifiable=True`` (default), the non-identifiable parameters are fixed at their ``x0``
value; a warning naming each of them (and what absorbs its deviation) goes in the result.

Covariance of the free parameters: ``(J_w^T J_w)^-1`` of the whitened Jacobian at the solution,
i.e. it trusts ``obs_cov``; with ``scale_cov_by_residual=True`` it is multiplied by the a-posteriori
variance factor ``2 cost / (N - n_free)``.
"""

from __future__ import annotations

import time
from typing import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares

from ..errors import ConfigError, DataError, ParameterError, VisionCalibError
from .identifiability import (BLOCK_POSES, IdentifiabilityReport, analyze, base_problem, check_problem,
                              gram_factor_svd, gram_of_blocks, pose_labels, row_compressed, scaled_prior_rows,
                              whitened_free_jacobian, whitened_gram, whitened_jacobian_blocks)
from .lm import LMResult, levenberg_marquardt
from .problem import NOISE_ESTIMATED, STATUS_CONVERGED, STATUS_NOT_FINITE, IdentificationProblem, IdentificationResult
from .threads import single_threaded_blas

#: |correlation| above which a pair of free parameters is reported
CORRELATION_WARN = 0.95
#: largest whitened free Jacobian (bytes, (n_obs m, n_free) doubles) :func:`solve_lse` keeps between its steps (the
#: first one from the analysis at x0, then the last one for chord steps): 128 MB is ~89,000 poses of 6 components
#: and 30 parameters; above it the normal equations are accumulated block by block at every step
KEEP_BYTES = 128 * 2 ** 20


# ----------------------------------------------------------------------------- shared with ekf.py
def prepare(
    problem: IdentificationProblem,
    x0: ArrayLike | None = None,
    free: Iterable[str] | None = None,
    fix: Iterable[str] = (),
    fix_unidentifiable: bool = True,
    selection: str = "order",
    keep: dict | None = None,
    keep_jacobian: bool = True,
) -> tuple[IdentificationProblem, np.ndarray, IdentifiabilityReport, tuple[str, ...]]:
    """Common set-up of the solvers.

    Returns (problem with the final free set, x0 (n,), report, warnings). ``free``: names that
    are exactly the free ones (None = keep the problem's mask); ``fix``: names fixed in addition.
    selection: how the base set is chosen ("order": earlier names kept, the same whatever the
    poses; "pivot": column-pivoted QR), see :func:`~vision_calib.identify.identifiability.analyze`.
    Unknown names raise ParameterError; bad data (non-finite residual, Jacobian, covariance or
    cost at x0) DataError naming the poses; too few equations IdentifiabilityError.
    keep: a dict that receives ``"r0"``, the residual (n_obs, m) at x0 checked here, and ``"blocks"``, the
    whitened free Jacobian at x0 of the final free set in blocks [(a, b, Aw ((b - a) m, n_free), columns times
    ``params.scale``)], when it fits in :data:`KEEP_BYTES` (the solver's first normal equations; the analysis reads
    their Gram matrix, the same sums it would form; not with ``keep_jacobian=False``), and ``"gram"``, that Gram
    matrix (prior rows included), when the free set is the one of the blocks.
    """
    params = problem.params
    if free is not None:
        params = params.only_free(list(free))
    fix = list(fix)
    if fix:
        params = params.fix(fix)
    if params.n_free == 0:
        raise ParameterError("no free parameter left to identify (every parameter is fixed)")
    problem = problem.with_params(params)
    x0 = params.nominal.copy() if x0 is None else np.asarray(x0, float).reshape(-1).copy()
    big = problem.n_obs > BLOCK_POSES  # no (n_obs, m, n) Jacobian held: its Gram matrix, block by block
    fits = keep is not None and keep_jacobian and kept_jacobian_fits(problem)
    r0, J0 = check_problem(problem, x0, jacobian=not big and not fits)  # (analyze computes J if it needs it)
    check_start_cost(problem, r0)
    blocks = None
    if fits:  # the whitened blocks at x0, for the solver's first step
        s = params.scale[params.free_index]
        blocks = list(whitened_jacobian_blocks(problem, x0, s))
        G0 = gram_of_blocks(blocks, scaled_prior_rows(problem, s), s.size) \
            if problem.n_obs * problem.m + problem.n_prior > s.size else None  # as analyze's own (few rows: A itself)
    else:
        G0 = whitened_gram(problem, x0) if big else None
    report = analyze(problem, x0, jacobian=J0, selection=selection, gram=G0)
    warnings: tuple[str, ...] = ()
    if report.non_identifiable:
        if fix_unidentifiable:
            kept = problem.params.free_names
            problem, report, warnings = base_problem(problem, report)
            sel = [kept.index(nm) for nm in problem.params.free_names]
            if G0 is not None:  # the base set's columns of the same Gram matrix
                G0 = G0[np.ix_(sel, sel)]
            if blocks is not None:
                blocks = [(a, b, Aw[:, sel]) for a, b, Aw in blocks]
            report = analyze(problem, x0, jacobian=J0, selection=selection, gram=G0)
        else:
            warnings = (
                "parameters not identifiable from these poses were left free (fix_unidentifiable=False): "
                + ", ".join(report.non_identifiable)
                + "; their covariance is a pseudo-inverse and their values are arbitrary along the null space",
            )
    if keep is not None:
        keep["r0"] = r0
        if blocks is not None:
            keep["blocks"] = blocks
            if G0 is not None and not (report.non_identifiable and fix_unidentifiable):
                keep["gram"] = G0  # the blocks' own J^T J (after a column selection the solver forms it anew)
    return problem, x0, report, warnings


def kept_jacobian_fits(problem: IdentificationProblem) -> bool:
    """Whether the whitened free Jacobian of ``problem`` ((n_obs m, n_free) doubles) fits in :data:`KEEP_BYTES`."""
    return problem.n_obs * problem.m * problem.params.n_free * 8 <= KEEP_BYTES


def check_start_cost(problem: IdentificationProblem, r0: np.ndarray) -> None:
    """DataError naming the poses whose whitened squared residual at the start overflows (e.g. a joint
    reading of 1e300: finite residual, infinite cost); r0 (n_obs, m) already checked finite."""
    with np.errstate(over="ignore", invalid="ignore"):
        chi2 = pose_chi2(problem, r0)
    bad = np.flatnonzero(~np.isfinite(chi2))
    if bad.size:
        raise DataError(
            f"whitened residual at the starting point overflows (cost = inf) for poses {pose_labels(problem, bad)}: "
            "a measurement or joint value is absurdly large"
        )


def pose_chi2(problem: IdentificationProblem, r: np.ndarray, W: np.ndarray | None = None) -> np.ndarray:
    """(n_obs,) squared norm of each pose's whitened residual ``|W_k r_k|^2`` (dimensionless)."""
    W = problem.whitening() if W is None else W
    return np.sum(np.einsum("kij,kj->ki", W, np.asarray(r, float)) ** 2, axis=1)


def final_check(problem: IdentificationProblem, x: np.ndarray, cov: np.ndarray, W: np.ndarray,
                J: np.ndarray | None = None, r: np.ndarray | None = None) -> tuple[np.ndarray | None, str]:
    """Residuals (n_obs, m) at the solution x (n,) (None if they cannot be evaluated; ``r`` when the solver already
    has them there) and "" when x, the residuals, the cost, J (n_obs, m, n) (if given) and cov are all finite; else
    the cause, naming the parameters or poses (pose labels)."""
    params = problem.params
    if not np.all(np.isfinite(x)):
        return None, f"parameters are not finite at the solution: {[params.names[i] for i in np.flatnonzero(~np.isfinite(x))]}"
    if r is None:
        try:
            r = np.asarray(problem.residual(x), float)
        except VisionCalibError as exc:
            return None, f"the residual cannot be evaluated at the solution: {exc}"
    bad = np.flatnonzero(~np.all(np.isfinite(r), axis=1))
    if bad.size:
        return r, f"residual is not finite at the solution for poses {pose_labels(problem, bad)}"
    with np.errstate(over="ignore", invalid="ignore"):
        bad = np.flatnonzero(~np.isfinite(pose_chi2(problem, r, W)))
    if bad.size:
        return r, f"cost is infinite at the solution (whitened residual overflows) for poses {pose_labels(problem, bad)}"
    if J is not None:
        bad = np.flatnonzero(~np.all(np.isfinite(J), axis=(1, 2)))
        if bad.size:
            return r, f"Jacobian is not finite at the solution for poses {pose_labels(problem, bad)}"
    if not np.all(np.isfinite(cov)):
        return r, "covariance is not finite at the solution"
    return r, ""


def covariance_from_jacobian(Jw_free: np.ndarray, scale_free: np.ndarray) -> tuple[np.ndarray, bool]:
    """(n_free, n_free) covariance (JwᵀJw)^-1 computed in scaled variables; returns (cov, full_rank)."""
    return _covariance_of_rows(row_compressed(Jw_free * scale_free[None, :]), max(Jw_free.shape), scale_free)


def covariance_from_normal(A_z: np.ndarray, scale_free: np.ndarray, rows: int) -> np.ndarray | None:
    """(n_free, n_free) covariance from the normal matrix A_z = (Jw S)^T (Jw S) (n_free, n_free) of the whitened
    Jacobian in scaled variables (S = diag(scale_free)) over ``rows`` equations: the same numbers as
    :func:`covariance_from_jacobian` takes from its Cholesky factor (``row_compressed``); None when that factor
    is not finite or too ill-conditioned (``identifiability.gram_factor``: then the Jacobian itself is needed)."""
    fac = gram_factor_svd(A_z)
    if fac is None:
        return None
    cov, full = _covariance_of_rows(fac[0], rows, scale_free, svd=fac[1])
    return cov if full else None


def _covariance_of_rows(A: np.ndarray, rows: int, scale_free: np.ndarray, svd=None) -> tuple[np.ndarray, bool]:
    U, s, Vt = np.linalg.svd(A, full_matrices=False) if svd is None else svd
    tol = rows * np.finfo(float).eps * 1e3 * (s[0] if s.size else 0.0)
    full = bool(s.size and s[-1] > tol)
    inv_s2 = np.where(s > tol, 1.0 / np.where(s > tol, s, 1.0) ** 2, 0.0)
    cov_z = (Vt.T * inv_s2) @ Vt
    return cov_z * np.outer(scale_free, scale_free), full


def correlation_warnings(names: Sequence[str], cov: np.ndarray, threshold: float = CORRELATION_WARN) -> tuple[str, ...]:
    """Strings ``"corr(a, b) = +0.973"`` for every pair with |corr| > threshold."""
    d = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(d, d)
    with np.errstate(invalid="ignore"):
        hit = np.triu(np.isfinite(corr) & (np.abs(corr) > threshold), k=1)
    return tuple(f"corr({names[i]}, {names[j]}) = {corr[i, j]:+.3f}" for i, j in zip(*np.nonzero(hit)))


def whitened_cost(problem: IdentificationProblem, x: ArrayLike, W: np.ndarray | None = None,
                  r: np.ndarray | None = None) -> float:
    """0.5 * sum of squared whitened residuals at x (n,), prior rows included (``r``: the residual (n_obs, m) at x
    when already computed)."""
    W = problem.whitening() if W is None else W
    rw = np.einsum("kij,kj->ki", W, problem.residual(x) if r is None else r)
    return 0.5 * float(np.sum(rw**2) + np.sum(problem.prior_residual(x) ** 2))


def finish_result(method, original, problem, x0, x, cov, cost0, iterations, converged, warnings, t0, info, W=None,
                  status=None, message="", J=None, r=None):
    """Build the IdentificationResult (shared by LSE and EKF); r: the residual (n_obs, m) at x when the solver has it.

    status/message: the solver's verdict (status default: 1 when converged else 0). Whatever the solver
    says, non-finite parameters, residuals, cost, Jacobian J (n_obs, m, n) (if given) or covariance at
    the solution give converged=False, status -2 and a message naming the cause (and the poses).
    """
    params = problem.params
    fi = params.free_index
    W = problem.whitening() if W is None else W
    status = (STATUS_CONVERGED if converged else 0) if status is None else int(status)
    r, bad = final_check(problem, np.asarray(x, float), cov, W, J, r)
    warnings = list(warnings)
    if bad:
        converged, status, message = False, STATUS_NOT_FINITE, bad
        warnings.append(f"result not usable: {bad}")
    if r is None:
        r = np.full((problem.n_obs, problem.m), np.nan)
    std = np.full(len(params), np.nan)
    std[fi] = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(over="ignore", invalid="ignore"):
        chi2_k = pose_chi2(problem, r, W)
        cost = 0.5 * float(np.sum(chi2_k) + np.sum(problem.prior_residual(x) ** 2))
    dof = problem.n_obs * problem.m + problem.n_prior - fi.size
    noise = "given"
    if problem.meta.get("noise") == NOISE_ESTIMATED:  # relative weights only: the scale comes from the residuals
        noise = NOISE_ESTIMATED
        factor = 2.0 * cost / dof if dof > 0 and np.isfinite(cost) else float("nan")
        if not info.get("scale_cov_by_residual"):
            cov = cov * factor
            std = std * np.sqrt(factor)
        warnings.append(f"noise: {NOISE_ESTIMATED} (std scaled by sqrt(chi2/dof) = {np.sqrt(factor):.3g}"
                        + ("; no degrees of freedom left: std unknown" if not np.isfinite(factor) else "") + ")")
    return IdentificationResult(
        method=method,
        names=params.names,
        nominal=original.params.nominal.copy(),
        identified=np.asarray(x, float).copy(),
        free=params.free.copy(),
        std=std,
        covariance=cov,
        cost_initial=float(cost0),
        cost_final=cost,
        iterations=int(iterations),
        converged=bool(converged),
        residuals=r,
        residual_kind=problem.residual_kind,
        labels=tuple(problem.labels),
        correlation_warnings=correlation_warnings(params.free_names, cov),
        warnings=tuple(warnings),
        seconds=time.perf_counter() - t0,
        info=dict(info, x0=np.asarray(x0, float).copy()),
        status=status,
        message=str(message),
        dof=int(dof),
        chi2_dof=2.0 * cost / dof if dof > 0 and np.isfinite(cost) else float("nan"),
        pose_chi2=chi2_k,
        noise=noise,
    )


# ----------------------------------------------------------------------------- LSE
@single_threaded_blas
def solve_lse(
    problem: IdentificationProblem,
    x0: ArrayLike | None = None,
    method: str = "auto",
    loss: str = "linear",
    f_scale: float = 1.0,
    fix_unidentifiable: bool = True,
    max_nfev: int | None = None,
    xtol: float = 1e-12,
    ftol: float = 1e-12,
    gtol: float = 1e-12,
    jac: str = "analytic",
    scale_cov_by_residual: bool = False,
    free: Iterable[str] | None = None,
    fix: Iterable[str] = (),
    selection: str = "order",
) -> IdentificationResult:
    """Weighted non-linear least squares on the free parameters of ``problem``.

    x0: (n,) full starting vector (SI), default ``params.nominal``; fixed parameters keep their x0 value.
    method: "lm" | "trf" | "dogbox" | "auto" (lm for the linear loss, trf otherwise).
    loss, f_scale: scipy robust loss on the whitened residuals (f_scale in noise-std units).
    jac: "analytic" (problem.jacobian) or "2-point"/"3-point" (finite-difference baseline).
    free / fix: parameter names (exactly free / additionally fixed).
    selection: base-set choice when parameters are not identifiable: "order" (default; the earlier
    names are kept, the same set whatever the poses) or "pivot" (column-pivoted QR).
    Bad input raises a clear error before solving (scipy style): non-finite residual/Jacobian/
    covariance or an overflowing cost at x0 -> DataError naming the poses.
    Returns an IdentificationResult with method "lse": converged/status/message (non-finite values at
    the solution -> converged False, status -2, message naming the cause and poses), chi2_dof;
    ``info`` holds nfev, njev, scipy status/message, the identifiability report
    (``info["identifiability"]``), jac mode, loss. Small problems run with single-threaded BLAS
    (:mod:`~vision_calib.identify.threads`).
    Longer than 80 lines: validation, the scipy call with its closures, and the result assembly share the problem's scaled state.
    """
    t0 = time.perf_counter()
    method = _lse_method(method, loss, jac)
    original = problem
    kept: dict = {}
    problem, x0, report, warnings = prepare(problem, x0, free, fix, fix_unidentifiable, selection, keep=kept,
                                            keep_jacobian=method == "lm" and jac == "analytic")
    params = problem.params
    fi = params.free_index
    s = params.scale[fi]
    W = problem.whitening()
    x0_free = x0[fi]
    last = {"z": np.zeros(fi.size), "r": np.array(kept["r0"])}  # the residual (n_obs, m) at the last z (a copy)

    def x_of(z):
        x = x0.copy()
        x[fi] = x0_free + s * z
        return x

    def fun(z):
        x = x_of(z)
        if not np.array_equal(z, last["z"]):
            last["z"], last["r"] = np.array(z, float), None
            last["r"] = np.array(problem.residual(x), float)  # a copy: kept past the problem's next call
        rw = np.einsum("kij,kj->ki", W, last["r"]).ravel()
        return np.concatenate([rw, problem.prior_residual(x)]) if problem.prior_rows else rw

    def jac_fn(z):
        return whitened_free_jacobian(problem, problem.jacobian(x_of(z)), W) * s[None, :]

    cost0 = whitened_cost(problem, x0, W, kept["r0"])
    cov = J = None
    if method == "lm" and jac == "analytic":  # the normal equations in BLAS, accumulated over blocks of poses
        sol = levenberg_marquardt(fun, None, np.zeros(fi.size), max_nfev, xtol, ftol, gtol,
                                  normal=normal_equations(problem, W, x_of, s, start=kept.get("blocks"),
                                                          start_gram=kept.get("gram")))
        if sol.A is not None:
            cov = covariance_from_normal(sol.A, s, problem.n_obs * problem.m + problem.n_prior)
    else:
        sol = least_squares(fun, np.zeros(fi.size), jac=jac_fn if jac == "analytic" else jac, method=method,
                            loss=loss, f_scale=f_scale, max_nfev=max_nfev, xtol=xtol, ftol=ftol, gtol=gtol)
    x = x_of(sol.x)
    if cov is None:  # no normal matrix at the solution, or an ill-conditioned one: the whole Jacobian (SVD)
        J = _jacobian_or_nan(problem, x)
    cov, warnings = _lse_covariance(problem, J, W, s, sol.cost if scale_cov_by_residual else None, warnings,
                                    cov=cov)
    converged = bool(sol.status > 0)
    info = {
        "nfev": int(sol.nfev),
        "njev": None if sol.njev is None else int(sol.njev),
        "status": int(sol.status),
        "message": str(sol.message),
        "scipy_method": method,
        "loss": loss,
        "jac": jac,
        "identifiability": report,
        "scale_cov_by_residual": bool(scale_cov_by_residual),
    }
    iterations = sol.njev if sol.njev is not None else sol.nfev
    status = 1 if sol.status > 0 else (0 if sol.status == 0 else -1)
    message = (f"Levenberg-Marquardt (normal equations): {sol.message}" if isinstance(sol, LMResult)
               else f"scipy least_squares ({method}): {sol.message}")
    r = last["r"] if np.array_equal(sol.x, last["z"]) else None
    return finish_result("lse", original, problem, x0, x, cov, cost0, iterations, converged, warnings, t0, info, W,
                         status=status, message=message, J=J, r=r)


def normal_equations(problem: IdentificationProblem, W: np.ndarray, x_of, s: np.ndarray, block: int | None = None,
                     start: list | None = None, start_gram: np.ndarray | None = None):
    """(z, r) -> (A (n_free, n_free), g (n_free,)): J^T J and J^T r of the whitened, scaled residual
    ``fun`` of :func:`solve_lse` at z (r: its (n_obs m + n_prior,) value at z), accumulated over the
    :func:`~vision_calib.identify.identifiability.whitened_jacobian_blocks` of ``block`` poses (default
    ``BLOCK_POSES``), the prior rows last. W (n_obs, m, m) whitening, x_of: z -> x (n,), s (n_free,) scales. start:
    the blocks at z = 0 when already computed (``prepare(keep=...)``), used by the first call there, with
    ``start_gram`` their J^T J when also computed (the same sums). When the
    whitened Jacobian fits in :data:`KEEP_BYTES` the last call's blocks are kept and ``normal.chord(r)`` is J^T r
    with them (a chord step: no new Jacobian); else ``normal.chord`` is None."""
    n_obs, m = problem.n_obs, problem.m
    block = int(block or BLOCK_POSES)
    P = scaled_prior_rows(problem, s)
    keep = kept_jacobian_fits(problem)
    last = {"start": start, "gram": start_gram}

    def normal(z, r):
        blocks, gram = last.pop("start", None), last.pop("gram", None)
        if blocks is None or np.any(z):  # LM: status -1 when not finite
            blocks, gram = whitened_jacobian_blocks(problem, x_of(z), s, W, block, check=False), None
        A = np.zeros((s.size, s.size)) if gram is None else np.array(gram)
        g = np.zeros(s.size)
        kept = []
        for a, b, Jw in blocks:
            if gram is None:
                A += Jw.T @ Jw
            g += Jw.T @ r[a * m:b * m]
            if keep:
                kept.append((a, b, Jw))
        if P is not None:
            if gram is None:
                A += P.T @ P
            g += P.T @ r[n_obs * m:]
        last["blocks"] = kept
        return A, g

    def chord(r):
        g = np.zeros(s.size)
        for a, b, Jw in last["blocks"]:
            g += Jw.T @ r[a * m:b * m]
        return g + P.T @ r[n_obs * m:] if P is not None else g

    normal.chord = chord if keep else None
    return normal


def _lse_covariance(problem, J, W, s, cost, warnings, cov=None):
    """(cov (n_free, n_free) SI, warnings list) from J (n_obs, m, n) at the solution (or ``cov`` already
    taken from the normal matrix there, :func:`covariance_from_normal`); NaN when J is not finite; multiplied
    by 2 cost / dof when ``cost`` is given (a-posteriori variance factor)."""
    warnings = list(warnings)
    if cov is None:
        Jw = whitened_free_jacobian(problem, J, W)
        if not np.all(np.isfinite(Jw)):
            return np.full((s.size, s.size), np.nan), warnings
        cov, full_rank = covariance_from_jacobian(Jw, s)
        if not full_rank:
            warnings.append("Jacobian at the solution is rank deficient: covariance is a pseudo-inverse")
    dof = problem.n_obs * problem.m + problem.n_prior - s.size
    if cost is not None and dof > 0:
        cov = cov * (2.0 * float(cost) / dof)
    return cov, warnings


def _lse_method(method: str, loss: str, jac: str) -> str:
    """Checked scipy method ("auto" -> lm for the linear loss, trf otherwise)."""
    if jac not in ("analytic", "2-point", "3-point"):
        raise ConfigError(f"solve_lse: jac={jac!r}; expected 'analytic', '2-point' or '3-point'")
    if method == "auto":
        method = "lm" if loss == "linear" else "trf"
    if method not in ("lm", "trf", "dogbox"):
        raise ConfigError(f"solve_lse: method={method!r}; expected 'lm', 'trf', 'dogbox' or 'auto'")
    if method == "lm" and loss != "linear":
        raise ConfigError(f"solve_lse: method 'lm' supports only loss='linear' (got {loss!r}); use method='trf'")
    return method


def _jacobian_or_nan(problem: IdentificationProblem, x) -> np.ndarray:
    """Jacobian (n_obs, m, n) at x, all NaN when x is not finite or the model cannot be evaluated there."""
    shape = (problem.n_obs, problem.m, len(problem.params))
    if not np.all(np.isfinite(x)):
        return np.full(shape, np.nan)
    try:
        return np.asarray(problem.jacobian(x), float)
    except VisionCalibError:
        return np.full(shape, np.nan)


def solve_lse_fd(problem: IdentificationProblem, x0: ArrayLike | None = None, jac: str = "2-point",
                 **kwargs) -> IdentificationResult:
    """Same as :func:`solve_lse` with a finite-difference Jacobian (the benchmark's baseline)."""
    return solve_lse(problem, x0, jac=jac, **kwargs)
