"""Correlated measurement errors as nuisance parameters (numpy only).

When every measured pose also carries a shared error with a known covariance (e.g. the camera intrinsics
calibrated from the same images: their error moves all poses together, pose by pose differently), the
total covariance of the stacked residuals is ``C = blockdiag(obs_cov) + U U^T`` with ``U`` (N, d) the
response of every residual component to one standard deviation along each of d independent directions of
that error. The weighted fit with C is exactly the ordinary fit of the augmented problem

    r_k(x) - U_k c   (pose rows, whitened by obs_cov[k]),     (0 - c) / 1   (d prior rows),

over (x, c), c (d,) the error's coefficients with prior N(0, I): minimising over c gives
``e^T (I + Uw Uw^T)^-1 e`` (Woodbury, Uw the whitened U), the GLS chi-square; the d prior rows and d
parameters leave the degrees of freedom unchanged, and the marginal covariance of x carries the shared
error. The problem's per-pose structure stays, so the outlier test and the adequacy test read it as usual
(the pose residuals are then measured - model with the fitted shared error U_k c removed).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import ArrayLike

from ..errors import DataError
from ..kinematics.params import ParameterSet
from .problem import IdentificationProblem, IdentificationResult


def nuisance_names(prefix: str, d: int) -> tuple[str, ...]:
    """Names of d nuisance coefficients: ``prefix.c0`` .. ``prefix.c{d-1}``."""
    return tuple(f"{prefix}.c{i}" for i in range(d))


def with_nuisance(problem: IdentificationProblem, U: ArrayLike, prefix: str = "nuisance") -> IdentificationProblem:
    """``problem`` augmented with d nuisance coefficients c ~ N(0, 1) (module docstring).

    U: (n_obs, m, d) response of each pose's residual (measured - model, SI) to one std of each direction.
    The coefficients are appended to the parameter set (kind "coefficient", nominal 0, scale 1, free) with
    prior_std 1 and a prior row each (``problem.prior_rows``); the other parameters keep the problem's
    prior_std (default 100 x scale, the EKF's uninformative start). residual(x) = r(x[:n]) - U c, jacobian
    [J, -U]. DataError when U's shape does not match the problem or it is not finite."""
    U = np.asarray(U, float)
    if U.ndim != 3 or U.shape[:2] != (problem.n_obs, problem.m):
        raise DataError(f"nuisance response U has shape {U.shape}, expected ({problem.n_obs}, {problem.m}, d)")
    if not np.all(np.isfinite(U)):
        bad = np.flatnonzero(~np.all(np.isfinite(U), axis=(1, 2)))
        raise DataError(f"nuisance response U is not finite for poses {[problem.labels[k] if problem.labels else k for k in bad]}")
    d = U.shape[2]
    n = len(problem.params)
    names = nuisance_names(prefix, d)
    extra = ParameterSet.from_lists(names, np.zeros(d), ("coefficient",) * d, np.ones(d, bool), np.ones(d))
    params = problem.params.concat(extra)
    prior = 100.0 * problem.params.scale if problem.prior_std is None else np.asarray(problem.prior_std, float)
    res, jac = problem.residual, problem.jacobian

    def sel(idx):
        return U if idx is None else U[np.asarray(idx, int)]

    def residual(x, idx=None):
        x = np.asarray(x, float)
        return np.asarray(res(x[:n], idx), float) - sel(idx) @ x[n:]

    def jacobian(x, idx=None):
        x = np.asarray(x, float)
        J = np.asarray(jac(x[:n], idx), float)
        return np.concatenate([J, -sel(idx)], axis=2)

    meta = dict(problem.meta, nuisance={"n": n, "d": d, "prefix": prefix})
    return dataclasses.replace(problem, params=params, residual=residual, jacobian=jacobian, jacobian_factors=None,
                               prior_std=np.concatenate([prior, np.ones(d)]),
                               prior_rows=tuple(problem.prior_rows) + names, meta=meta)


def split_nuisance(result: IdentificationResult, n: int) -> tuple[IdentificationResult, dict]:
    """(result over the first n parameters, {names, values (d,), std (d,)} of the nuisance coefficients) of a
    fit of :func:`with_nuisance`'s problem (nuisance coefficients last and free). The covariance and std of
    the n parameters are their marginal ones (the shared error included); cost, dof, chi2_dof, residuals
    and pose_chi2 stay those of the augmented fit (the GLS ones)."""
    free = np.asarray(result.free, bool)
    nf = int(np.sum(free[:n]))
    names = result.names[n:]
    std_c = np.asarray(result.std, float)[n:]
    out = dataclasses.replace(
        result, names=tuple(result.names[:n]), nominal=np.asarray(result.nominal)[:n].copy(),
        identified=np.asarray(result.identified)[:n].copy(), free=free[:n].copy(),
        std=np.asarray(result.std)[:n].copy(), covariance=np.asarray(result.covariance)[:nf, :nf].copy(),
        correlation_warnings=tuple(w for w in result.correlation_warnings if not any(c in w for c in names)),
        info={k: (np.asarray(v)[:n].copy() if k == "x0" else v) for k, v in result.info.items()})
    return out, {"names": list(names), "values": [float(v) for v in np.asarray(result.identified)[n:]],
                 "std": [float(v) for v in std_c]}


__all__ = ["with_nuisance", "split_nuisance", "nuisance_names"]
