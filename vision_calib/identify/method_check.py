"""Two estimates of the same parameters from the same data, checked against each other (numpy/scipy only).

Two methods that minimise different residuals of the SAME measurements (e.g. the H4 joint residuals of the
inverse-model method and the pose residuals of the forward model) give two estimates x_a, x_b of one
parameter set. With a right model both are unbiased and their difference is noise only; with a wrong model
they absorb the error differently. The difference is strongly correlated noise (same data): its covariance
is NOT std_a^2 + std_b^2. To first order each estimate is a linear map of the raw measurement errors e
(per pose, covariance cov_e[k]) and of a shared error c ~ N(0, I) (nuisance directions, optional):

    x_i - x* = -A_i (B_i e + U_i c),   A_i = (J_i^T C_i^-1 J_i)^-1 J_i^T C_i^-1,   C_i = obs_cov_i + U_i U_i^T

with J_i the problem's Jacobian at its solution, B_i = d r_i / d e (block per pose) and U_i the residual
response to c. Hence cov(x_a - x_b) = D cov_e D^T + D_u D_u^T, D = A_a B_a - A_b B_b, D_u = A_a U_a - A_b U_b.
The difference is tested with a chi-square on the directions where it is not negligible against the
estimates' own spread (its variance at least MIN_RELATIVE_VARIANCE of the estimate's: generalised eigen-
directions of cov(x_a - x_b) against cov(x_a)); in the others (and in its null space) both estimators read the
data alike and second-order effects the linearisation leaves out would dominate.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .problem import IdentificationProblem

#: significance level of the chi-square test on the difference
LEVEL = 0.01
#: the chi-square uses the directions in which the difference's variance is at least this fraction of the
#: estimate's own (difference std >= ~3 % of the estimate's std): in the others the two estimators read the
#: data almost alike and second-order effects of the noise, left out of the linearisation, dominate (the IGM
#: method's errors-in-variables bias reaches ~2 % of a std (h4.h, 81-pose grid, 0.2 mm): measured with
#: antithetic noise pairs). 60 synthetic draws (tests/identify/test_method_check.py settings): mean chi2 11.95 on
#: 12 tested directions (0 cut: 22.8 on 19 in 30 draws; 1e-2 cut: 6.2 on 6)
MIN_RELATIVE_VARIANCE = 1e-3


def _linear_maps(problem: IdentificationProblem, x, B, U):
    """(M (n, N, K), Mu (n, d) or None) in the problem's scaled free coordinates: the estimator's response
    -dx/de to the raw errors (B (N, m, K)) and to the shared error (U (N, m, d) or None) at x (n_all,)."""
    p = problem.params
    fi, s = p.free_index, p.scale[p.free_index]
    W = problem.whitening()
    Jw = np.einsum("kij,kjn->kin", W, np.asarray(problem.jacobian(x), float)[..., fi] * s)
    Bw = np.einsum("kij,kjl->kil", W, B)
    JtB = np.einsum("kin,kil->nkl", Jw, Bw)  # (n, N, K)
    H = np.einsum("kin,kip->np", Jw, Jw)
    Mu = None
    if U is not None:  # C^-1 = W^T (I - Uw S^-1 Uw^T) W with S = I + Uw^T Uw (Woodbury)
        Uw = np.einsum("kij,kjd->kid", W, U)
        JtU = np.einsum("kin,kid->nd", Jw, Uw)
        Sinv = np.linalg.inv(np.eye(U.shape[2]) + np.einsum("kid,kie->de", Uw, Uw))
        H = H - JtU @ Sinv @ JtU.T
        JtB = JtB - np.einsum("nd,de,kie,kil->nkl", JtU, Sinv, Uw, Bw)
        Mu = np.linalg.solve(H, JtU - JtU @ Sinv @ np.einsum("kid,kie->de", Uw, Uw))
    M = np.linalg.solve(H, JtB.reshape(len(fi), -1)).reshape(JtB.shape)
    return M, Mu


def method_difference(problem_a: IdentificationProblem, x_a: ArrayLike, B_a: np.ndarray,
                      problem_b: IdentificationProblem, x_b: ArrayLike, B_b: np.ndarray, cov_e: np.ndarray,
                      U_a: np.ndarray | None = None, U_b: np.ndarray | None = None, level: float = LEVEL) -> dict:
    """Difference x_a - x_b of two estimates of the same free parameters from the same poses, with its
    first-order covariance (module doc) and a chi-square test.

    problem_a/b: the two problems (same parameter set and free mask, same poses in the same order);
    x_a/x_b: (n_all,) their solutions (SI); B_a (N, m_a, K), B_b (N, m_b, K): d residual / d raw errors;
    cov_e: (N, K, K) covariance of the raw errors; U_a (N, m_a, d), U_b (N, m_b, d): responses to a shared
    error of unit covariance (None: none). Returns {names, difference (n_free,) SI, std (n_free,), z,
    max_abs_z, worst, chi2, dof (directions tested), untested (n_free - dof), p_value, level, verdict
    "agree"|"disagree"}."""
    from scipy.stats import chi2 as chi2_dist

    if problem_a.params.names != problem_b.params.names or not np.array_equal(problem_a.params.free,
                                                                              problem_b.params.free):
        raise ValueError("method_difference: the two problems must have the same parameters and free mask")
    if problem_a.n_obs != problem_b.n_obs:
        raise ValueError(f"method_difference: {problem_a.n_obs} vs {problem_b.n_obs} poses")
    p = problem_a.params
    fi, s = p.free_index, p.scale[p.free_index]
    Ma, Mua = _linear_maps(problem_a, x_a, np.asarray(B_a, float), U_a)
    Mb, Mub = _linear_maps(problem_b, x_b, np.asarray(B_b, float), U_b)
    ce = np.asarray(cov_e, float)
    D = Ma - Mb
    cov = np.einsum("ikl,klm,jkm->ij", D, ce, D)
    cov_a = np.einsum("ikl,klm,jkm->ij", Ma, ce, Ma)
    if Mua is not None:
        Du = Mua - Mub
        cov, cov_a = cov + Du @ Du.T, cov_a + Mua @ Mua.T
    d_s = (np.asarray(x_a, float) - np.asarray(x_b, float))[fi] / s  # scaled units
    # directions v (v^T cov_a v = 1) of relative difference variance mu: var(v^T d) = mu var(v^T x_a)
    La = np.linalg.cholesky(cov_a)
    Li = np.linalg.inv(La)
    mu, Q = np.linalg.eigh(Li @ cov @ Li.T)
    keep = mu > MIN_RELATIVE_VARIANCE
    proj = Q[:, keep].T @ (Li @ d_s)
    chi2 = float(np.sum(proj**2 / mu[keep]))
    dof = int(keep.sum())
    cov = cov * np.outer(s, s)  # SI
    d = d_s * s
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(sd > 0, d / sd, np.where(d == 0, 0.0, np.inf))
    pval = float(chi2_dist.sf(chi2, dof)) if dof else 1.0
    names = [p.names[i] for i in fi]
    worst = int(np.argmax(np.abs(z))) if len(z) else 0
    return {"names": names, "difference": d.tolist(), "std": sd.tolist(), "z": z.tolist(),
            "max_abs_z": float(np.max(np.abs(z))) if len(z) else 0.0, "worst": names[worst] if names else None,
            "chi2": chi2, "dof": dof, "untested": int(len(fi) - dof), "p_value": pval, "level": float(level),
            "verdict": "agree" if pval >= level else "disagree"}


__all__ = ["method_difference", "LEVEL"]
