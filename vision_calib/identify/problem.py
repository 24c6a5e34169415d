"""Problem and result types shared by every identification method (LSE, EKF, H4 IGM).

An :class:`IdentificationProblem` is a pure description: the parameter set (names, nominal,
free mask, scales), a residual function and its analytic Jacobian over *observations*
(one observation = one robot pose), and the measurement covariance of each observation.

Residual convention: ``r = measured - model(x)`` with shape (n_obs, m) where m is the
number of components per pose (6 for full pose [dt (m), dtheta (rad)], 3 for position
only, 4 for H4 joint residuals (rad)). ``jacobian(x)`` is d r / d x with shape
(n_obs, m, n_params) over the FULL parameter vector; solvers select free columns.
Both functions take an optional ``idx`` (k,) int array of observations to evaluate.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
from numpy.typing import ArrayLike

from ..kinematics.params import ParameterSet

#: IdentificationResult.status: the solver met its convergence criterion
STATUS_CONVERGED = 1
#: IdentificationResult.status: stopped at the iteration / evaluation / pass limit before converging
STATUS_MAX_ITERATIONS = 0
#: IdentificationResult.status: non-finite parameters, residuals, cost, Jacobian or covariance at the end
STATUS_NOT_FINITE = -2

#: ``problem.meta["noise"]`` / ``IdentificationResult.noise`` when the caller gave no measurement noise: obs_cov
#: holds relative weights only, and the solvers scale the covariance by the a-posteriori variance factor
NOISE_ESTIMATED = "estimated from residuals, not given"

ResidualFn = Callable[..., np.ndarray]  # (x (n,), idx=None) -> (k, m)
JacobianFn = Callable[..., np.ndarray]  # (x (n,), idx=None) -> (k, m, n)
FactorsFn = Callable[..., tuple]  # (x (n,), idx=None) -> (D (k, m, c), Jc (k, c, n)): jacobian = D @ Jc


@dataclass(frozen=True)
class IdentificationProblem:
    """What to identify from which observations.

    params: parameter set (nominal = starting point, free mask = what is identified).
    residual: r(x, idx=None) -> (k, m), measured - model.
    jacobian: J(x, idx=None) -> (k, m, n_params), analytic d r / d x.
    obs_cov: (n_obs, m, m) covariance of each observation's measurement noise (SI units),
        used for weighting (whitening) and for the predicted parameter covariance.
    residual_kind: "pose" | "position" | "joint".
    labels: (n_obs,) pose identifiers for reports.
    prior_std: (n,) prior standard deviation of each parameter around nominal (EKF P0);
        None -> 100 x params.scale (effectively uninformative).
    component_names: names of the m residual components, for reports.
    meta: builder-specific data; ``meta["noise"] == NOISE_ESTIMATED`` marks an obs_cov of relative weights
        (no noise given): the solvers then scale the parameter covariance by chi2/dof.
    jacobian_factors: optional (x, idx=None) -> (D (k, m, c), Jc (k, c, n_params)) with ``jacobian(x, idx)`` =
        D @ Jc per observation (a per-pose left factor and the model's own Jacobian, which may be a view in
        parameter-major layout): the solvers whiten through (W D) @ Jc, one batched product, and select free
        columns from Jc (:func:`~vision_calib.identify.identifiability.whitened_jacobian_blocks`).
    prior_rows: names of parameters whose prior N(nominal, prior_std^2) enters the least-squares cost as
        one whitened row each, (nominal - x) / prior_std, while they are free (nuisance parameters,
        :mod:`~vision_calib.identify.nuisance`): the equations count N = n_obs * m + their number, so a
        nuisance parameter with its prior leaves the degrees of freedom unchanged. Needs ``prior_std``.
    """

    params: ParameterSet
    residual: ResidualFn
    jacobian: JacobianFn
    obs_cov: np.ndarray
    residual_kind: str
    labels: tuple = ()
    prior_std: np.ndarray | None = None
    component_names: tuple[str, ...] = ()
    meta: dict = field(default_factory=dict)
    prior_rows: tuple[str, ...] = ()
    jacobian_factors: FactorsFn | None = None

    @property
    def n_obs(self) -> int:
        return int(self.obs_cov.shape[0])

    @property
    def m(self) -> int:
        return int(self.obs_cov.shape[1])

    def with_params(self, params: ParameterSet) -> "IdentificationProblem":
        """Same observations, another parameter set (e.g. other free mask / starting point), sharing the whitening
        (computed here once for both: a problem solved again, e.g. from another start, whitens once)."""
        out = replace(self, params=params)
        try:
            object.__setattr__(out, "_whitening", self.whitening())
        except np.linalg.LinAlgError:  # a covariance that is not positive definite: check_problem names its poses
            pass
        return out

    def subset(self, idx: ArrayLike) -> "IdentificationProblem":
        """Problem restricted to observations ``idx`` (k,) int."""
        idx = np.asarray(idx, dtype=int)
        res, jac = self.residual, self.jacobian

        def residual(x, sub=None):
            return res(x, idx if sub is None else idx[np.asarray(sub, int)])

        def jacobian(x, sub=None):
            return jac(x, idx if sub is None else idx[np.asarray(sub, int)])

        factors = None
        if self.jacobian_factors is not None:
            fac = self.jacobian_factors

            def factors(x, sub=None):
                return fac(x, idx if sub is None else idx[np.asarray(sub, int)])

        labels = tuple(self.labels[i] for i in idx) if self.labels else ()
        return replace(self, residual=residual, jacobian=jacobian, obs_cov=self.obs_cov[idx], labels=labels,
                       jacobian_factors=factors)

    def _prior_index(self) -> tuple[np.ndarray, np.ndarray]:
        """(positions in the free vector (p,), positions in the full vector (p,)) of the free prior_rows."""
        if not self.prior_rows:
            return np.zeros(0, int), np.zeros(0, int)
        full = np.asarray(self.params.indices(list(self.prior_rows)), int)
        full = np.sort(full[self.params.free[full]])
        pos = np.searchsorted(self.params.free_index, full)
        return pos, full

    @property
    def n_prior(self) -> int:
        """Number of prior rows in the cost (free parameters of ``prior_rows``)."""
        return int(self._prior_index()[0].size)

    def prior_residual(self, x: ArrayLike) -> np.ndarray:
        """(p,) whitened prior rows (nominal - x) / prior_std of the free ``prior_rows`` at x (n,)."""
        _, full = self._prior_index()
        if not full.size:
            return np.zeros(0)
        sd = np.asarray(self.prior_std, float)[full]
        return (self.params.nominal[full] - np.asarray(x, float)[full]) / sd

    def prior_jacobian(self) -> np.ndarray:
        """(p, n_free) d prior_residual / d x_free (-1 / prior_std on each row's own column)."""
        pos, full = self._prior_index()
        out = np.zeros((pos.size, self.params.n_free))
        if pos.size:
            out[np.arange(pos.size), pos] = -1.0 / np.asarray(self.prior_std, float)[full]
        return out

    def whitening(self) -> np.ndarray:
        """(n_obs, m, m) matrices W with W @ cov @ W.T = I (inverse Cholesky factors); computed once per
        problem (read-only: the problem is immutable)."""
        W = self.__dict__.get("_whitening")
        if W is None:
            W = lower_triangular_inverse(np.linalg.cholesky(self.obs_cov))
            W.flags.writeable = False
            object.__setattr__(self, "_whitening", W)
        return W


def whitening_of(cov: np.ndarray) -> np.ndarray:
    """(..., m, m) inverse Cholesky factors W of the symmetrised covariances cov (..., m, m): W sym(cov) W^T = I (as
    :meth:`IdentificationProblem.whitening` for covariances not held by a problem); LinAlgError when one is not
    positive definite."""
    cov = np.asarray(cov, float)
    return lower_triangular_inverse(np.linalg.cholesky(0.5 * (cov + np.swapaxes(cov, -1, -2))))


def lower_triangular_inverse(L: np.ndarray) -> np.ndarray:
    """(..., m, m) inverses of lower-triangular L (..., m, m) by forward substitution on contiguous (...,) rows, one
    array operation per term (a batch of small factors: a few times faster than ``np.linalg.inv``'s LU); a zero on
    a diagonal gives inf/NaN."""
    L = np.asarray(L, float)
    m = L.shape[-1]
    Lt = np.ascontiguousarray(np.moveaxis(L, (-2, -1), (0, 1)))  # (m, m, ...)
    Wt = np.zeros_like(Lt)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_d = 1.0 / np.stack([Lt[i, i] for i in range(m)])
        for j in range(m):
            Wt[j, j] = inv_d[j]
            for i in range(j + 1, m):  # row i of L @ W = column j of the identity
                acc = Lt[i, j] * Wt[j, j]
                for k in range(j + 1, i):
                    acc += Lt[i, k] * Wt[k, j]
                np.multiply(acc, -inv_d[i], out=Wt[i, j])
    return np.ascontiguousarray(np.moveaxis(Wt, (0, 1), (-2, -1)))


@dataclass(frozen=True)
class IdentificationResult:
    """Outcome of one identification.

    names/nominal/identified: (n,) full parameter vectors (SI units); ``deviation`` =
    identified - nominal. free: (n,) bool, what was identified. std: (n,) predicted standard
    deviation (NaN for fixed parameters). covariance: (n_free, n_free) for free parameters
    in ``free`` order. residuals: (n_obs, m) final residuals (measured - model, SI).
    cost_initial/final: 0.5 * sum of squared whitened residuals.
    converged: the solver met its criterion AND everything at the solution is finite.
    status: STATUS_CONVERGED (1), STATUS_MAX_ITERATIONS (0) or STATUS_NOT_FINITE (-2) (scipy
    ``least_squares`` style); message: the reason in words (names the poses / parameters at fault).
    dof: N - n_free (scalar equations minus free parameters). chi2_dof: 2 cost_final / dof, the
    a-posteriori variance factor (about 1 when the model and obs_cov are right; NaN when dof <= 0).
    pose_chi2: (n_obs,) squared norm of each pose's whitened final residual (see
    :func:`~vision_calib.identify.adequacy.model_adequacy`).
    noise: "given" (obs_cov is the measurement covariance) or NOISE_ESTIMATED (no noise given: obs_cov
    held relative weights, std and covariance are scaled by chi2/dof, which is then the noise variance
    in those weights' units rather than a model-adequacy figure).
    """

    method: str
    names: tuple[str, ...]
    nominal: np.ndarray
    identified: np.ndarray
    free: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    cost_initial: float
    cost_final: float
    iterations: int
    converged: bool
    residuals: np.ndarray
    residual_kind: str
    labels: tuple = ()
    correlation_warnings: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    seconds: float = 0.0
    info: dict = field(default_factory=dict)
    status: int = STATUS_CONVERGED
    message: str = ""
    dof: int = 0
    chi2_dof: float = float("nan")
    pose_chi2: np.ndarray | None = field(default=None, repr=False)
    noise: str = "given"

    @property
    def deviation(self) -> np.ndarray:
        return self.identified - self.nominal

    def value(self, name: str) -> float:
        return float(self.identified[self.names.index(name)])

    def std_of(self, name: str) -> float:
        return float(self.std[self.names.index(name)])

    def to_dict(self) -> dict:
        """JSON-ready summary (SI units)."""
        return {
            "method": self.method,
            "converged": bool(self.converged),
            "iterations": int(self.iterations),
            "cost_initial": float(self.cost_initial),
            "cost_final": float(self.cost_final),
            "seconds": float(self.seconds),
            "residual_kind": self.residual_kind,
            "parameters": [
                {
                    "name": n,
                    "nominal": float(v0),
                    "identified": float(v),
                    "free": bool(f),
                    "std": None if not np.isfinite(s) else float(s),
                }
                for n, v0, v, f, s in zip(self.names, self.nominal, self.identified, self.free, self.std)
            ],
            "correlation_warnings": list(self.correlation_warnings),
            "warnings": list(self.warnings),
            "status": int(self.status),
            "message": self.message,
            "dof": int(self.dof),
            "chi2_dof": float(self.chi2_dof) if np.isfinite(self.chi2_dof) else None,
            "noise": self.noise,
        }
