"""Identifiability analysis of an :class:`IdentificationProblem` (numpy/scipy only).

What is analysed
----------------
The *scaled, whitened* Jacobian of the free parameters at ``x``::

    A = blockdiag(W_k) @ J[:, :, free] @ diag(scale[free])        (N, n),  N = n_obs * m

with ``W_k`` the inverse Cholesky factor of ``obs_cov[k]`` (so the noise is N(0, I)) and
``scale`` the typical deviation of each parameter (``params.scale``, m or rad). A column of A is
"the effect of one typical deviation of that parameter, in units of measurement-noise
standard deviations". With ``normalize=True`` every column is further divided by its norm
(the analysis is then insensitive to the choice of scales; default False).

Rank and base set
-----------------
Singular values ``s`` of A (descending). Rank = number of ``s_i > tol * s_max`` where ``tol``
is relative (dimensionless); default ``tol = max(N, n) * eps * 1e3`` (eps = float64 machine
epsilon), i.e. 1e3 times the usual LAPACK/numpy rank tolerance, enough to ignore the rounding
of analytic kinematic Jacobians while keeping any genuinely (even weakly) observable parameter.
The base set is chosen greedily in parameter order (``selection="order"``, the default
everywhere in ``identify/``: a parameter is kept when its column is not in the span of the kept
ones, so earlier names are preferred and the dropped set depends only on which combinations the
poses cannot see, not on the poses' numbers: the same set over folds / subsets of one robot's
data) or by QR with column pivoting (``selection="pivot"``, LAPACK geqp3: the column with the
largest remaining norm first; its choice among tied columns changes with the poses). The dropped parameters
are ``non_identifiable``. For each dropped column ``a_j`` the least-squares fit
``a_j ~= A_base @ c`` (== ``R11^-1 R12`` of the pivoted QR) gives the linear combination of
base parameters it is confounded with, in scaled units: a deviation of one ``scale_j`` of the
dropped parameter looks exactly like deviations ``c_k * scale_k`` of the base ones.

Observability indices (over the singular values s_1 >= ... >= s_L of the base-set
columns of A, L = number of base parameters, M = number of robot poses)
------------------------------------------------------------------------------------------
* O1 = (s_1 s_2 ... s_L)^(1/L) / sqrt(M)      Borm & Menq, IJRR 10(1), 1991.
* O2 = s_L / s_1  (inverse condition number)   Driels & Pathre, IEEE TRA 6(2), 1990.
* O3 = s_L  (minimum singular value)           Nahvi, Hollerbach & Hayward, ICRA 1994.
* O4 = s_L^2 / s_1  (noise amplification)      Nahvi & Hollerbach, ICRA 1996.
* O5 = 1 / (1/s_1 + ... + 1/s_L)                Sun & Hollerbach, ICRA 2008 (who also review O1-O4).
Larger is better for all five. They depend on the scaling described in ``scaling``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from ..errors import DataError, IdentifiabilityError, ParameterError
from ..kinematics.params import ParameterSet
from .problem import IdentificationProblem
from .threads import single_threaded_blas

#: the weighting :func:`analyze` describes by default (``weighting`` names another, e.g. a planning analysis')
WEIGHTING_COV = "whitened by the poses' covariances"

#: |coefficient| below this fraction of the largest one is pruned from a reported coupling
COUPLING_PRUNE_REL = 1e-6


@dataclass(frozen=True)
class IdentifiabilityReport:
    """Result of :func:`analyze`. Arrays are in *scaled* units (see module docstring).

    names: (n,) free parameter names analysed, in ``params`` order. singular_values: (n,)
    of the scaled whitened Jacobian A. condition_number: s_max / s_min over the base set; condition_of:
    what it is computed on, in words (which Jacobian, how many parameters and poses, weighting, column scaling).
    non_identifiable / base_parameters: names (partition of ``names``). couplings: one dict
    per dropped parameter: {"parameter", "combination" {base name: coeff (scaled)},
    "combination_si" {base name: coeff in SI ratio}, "fit_residual" (relative norm of the
    part of the column not explained)}. null_space: (n, n - rank) orthonormal, scaled units.
    observability: {"O1".."O5"}. scaling: text. tol: relative rank tolerance used.
    """

    names: tuple[str, ...]
    n_params: int
    rank: int
    singular_values: np.ndarray
    condition_number: float
    non_identifiable: tuple[str, ...]
    base_parameters: tuple[str, ...]
    couplings: list
    null_space: np.ndarray
    observability: dict
    scaling: str
    n_equations: int = 0
    n_obs: int = 0
    tol: float = 0.0
    scale: np.ndarray = field(default=None, repr=False)
    column_norms: np.ndarray = field(default=None, repr=False)
    #: free parameters with a prior row in the analysed problem (``IdentificationProblem.prior_rows``): their
    #: identifiability comes partly from that prior (e.g. the H4 mount tilts' rotation-axis estimate)
    prior_parameters: tuple = ()
    #: what ``condition_number`` is computed on, in words (printed beside it: reports, CLI summaries)
    condition_of: str = ""

    @property
    def identifiable(self) -> bool:
        return self.rank == self.n_params

    def coupling_of(self, name: str) -> dict:
        """Coupling dict of the dropped parameter ``name`` (ParameterError if it is not dropped)."""
        for c in self.couplings:
            if c["parameter"] == name:
                return c
        raise ParameterError(f"{name!r} is not a dropped (non-identifiable) parameter; dropped: {list(self.non_identifiable)}")

    def to_dict(self) -> dict:
        """JSON-ready summary."""
        return {
            "names": list(self.names),
            "n_params": self.n_params,
            "n_equations": self.n_equations,
            "n_obs": self.n_obs,
            "rank": self.rank,
            "tol_rel": self.tol,
            "singular_values": [float(s) for s in self.singular_values],
            "condition_number": float(self.condition_number),
            "condition_number_of": self.condition_of,
            "non_identifiable": list(self.non_identifiable),
            "base_parameters": list(self.base_parameters),
            "prior_parameters": list(self.prior_parameters),
            "couplings": [
                {
                    "parameter": c["parameter"],
                    "combination": {k: float(v) for k, v in c["combination"].items()},
                    "combination_si": {k: float(v) for k, v in c["combination_si"].items()},
                    "fit_residual": float(c["fit_residual"]),
                    "no_effect": bool(c.get("no_effect", False)),
                }
                for c in self.couplings
            ],
            "observability": {k: float(v) for k, v in self.observability.items()},
            "scaling": self.scaling,
        }

    def summary(self) -> str:
        """A few human-readable lines."""
        lines = [
            f"{self.n_params} free parameters, {self.n_equations} equations ({self.n_obs} poses), rank {self.rank}, "
            f"condition number {self.condition_number:.3g}"
        ]
        for c in self.couplings:
            comb = " + ".join(f"{v:+.4g}*{k}" for k, v in c["combination"].items()) or "0 (no effect)"
            lines.append(f"  not identifiable: {c['parameter']} ~ {comb}")
        return "\n".join(lines)


# ----------------------------------------------------------------------------- helpers
def pose_labels(problem: IdentificationProblem, idx: ArrayLike) -> list[str]:
    """Labels of observations ``idx`` (k,) ("#k" when the problem has none)."""
    return [str(problem.labels[i]) if problem.labels else f"#{int(i)}" for i in idx]


def check_problem(problem: IdentificationProblem, x: ArrayLike | None = None,
                  jacobian: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """Validate data at ``x`` (n,) (default nominal); return (residual (n_obs, m), jacobian (n_obs, m, n), or None
    with ``jacobian=False``: then the Jacobian is checked block by block where it is used, :func:`whitened_gram`).

    Raises DataError naming the poses (labels) whose residual, Jacobian or covariance is not
    finite / not positive definite, or when shapes disagree.
    """
    n = len(problem.params)
    x = problem.params.nominal if x is None else np.asarray(x, float).reshape(-1)
    if x.shape != (n,):
        raise ParameterError(f"parameter vector has shape {x.shape}, expected ({n},) for {n} parameters")
    if not np.all(np.isfinite(x)):
        bad = [problem.params.names[i] for i in np.flatnonzero(~np.isfinite(x))]
        raise ParameterError(f"parameter vector is not finite for {bad}")
    cov = np.asarray(problem.obs_cov, float)
    if cov.ndim != 3 or cov.shape[1] != cov.shape[2] or cov.shape[0] < 1:
        raise DataError(f"obs_cov has shape {cov.shape}, expected (n_obs, m, m) with n_obs >= 1")
    n_obs, m = cov.shape[:2]
    if problem.labels and len(problem.labels) != n_obs:
        raise DataError(f"{len(problem.labels)} labels for {n_obs} observations")
    bad = np.flatnonzero(~np.all(np.isfinite(cov), axis=(1, 2)))
    if bad.size:
        raise DataError(f"measurement covariance is not finite for poses {pose_labels(problem, bad)}")
    try:  # the whitening's Cholesky factors exist exactly when every covariance is positive definite
        W = problem.whitening()
        pd = bool(np.all(np.isfinite(W)))
    except np.linalg.LinAlgError:
        pd = False
    if not pd:  # name the poses, one by one
        bad = np.array([k for k in range(n_obs) if not _whitenable(cov[k])], int)
        raise DataError(f"measurement covariance is not positive definite for poses {pose_labels(problem, bad)}")
    r = np.asarray(problem.residual(x), float)
    if r.shape != (n_obs, m):
        raise DataError(f"residual has shape {r.shape}, expected ({n_obs}, {m}) from obs_cov")
    bad = np.flatnonzero(~np.all(np.isfinite(r), axis=1))
    if bad.size:
        raise DataError(
            f"residual (measured - model) is not finite (NaN/inf measurement?) for poses {pose_labels(problem, bad)}"
        )
    if not jacobian:
        return r, None
    J = np.asarray(problem.jacobian(x), float)
    _check_jacobian_block(problem, J, 0, n_obs)
    return r, J


def _whitenable(c: np.ndarray) -> bool:
    """Whether the covariance c (m, m) has a finite inverse Cholesky factor (positive definite to rounding)."""
    try:
        return bool(np.linalg.eigvalsh(0.5 * (c + c.T))[0] > 0 and np.all(np.isfinite(np.linalg.inv(np.linalg.cholesky(c)))))
    except np.linalg.LinAlgError:
        return False


def _check_jacobian_block(problem: IdentificationProblem, J: np.ndarray, a: int, b: int) -> None:
    """DataError for a Jacobian block J of poses a..b-1 of the wrong shape or not finite (naming the poses)."""
    shape = (b - a, problem.m, len(problem.params))
    if J.shape != shape:
        raise DataError(f"jacobian has shape {J.shape}, expected {shape}")
    bad = np.flatnonzero(~np.all(np.isfinite(J), axis=(1, 2)))
    if bad.size:
        raise DataError(f"jacobian is not finite for poses {pose_labels(problem, a + bad)}")


def whitened_blocks(problem: IdentificationProblem, jacobian_block, scale: np.ndarray, W: np.ndarray | None = None,
                    block: int | None = None, check: bool = True):
    """Yield (a, b, Aw ((b - a) m, n_free)): the whitened free Jacobian of poses a..b-1, columns times ``scale``
    (n_free,), for consecutive blocks of ``block`` poses (default :data:`BLOCK_POSES`); ``jacobian_block(a, b)``
    gives their Jacobian ((b - a), m, n), with ``check`` checked here (DataError naming its non-finite poses;
    a solver that reads a non-finite product as its own verdict passes False)."""
    block = int(block or BLOCK_POSES)
    W = problem.whitening() if W is None else W
    fi = problem.params.free_index
    for a in range(0, problem.n_obs, block):
        b = min(a + block, problem.n_obs)
        J = np.asarray(jacobian_block(a, b), float)
        if check:
            _check_jacobian_block(problem, J, a, b)
        yield a, b, np.matmul(W[a:b], J[:, :, fi]).reshape(-1, fi.size) * scale


def whitened_jacobian_blocks(problem: IdentificationProblem, x: ArrayLike, scale: np.ndarray,
                             W: np.ndarray | None = None, block: int | None = None, check: bool = True):
    """:func:`whitened_blocks` of the Jacobian at x (n,): from ``problem.jacobian_factors`` when the problem has them
    (per block one batched product (W D) @ Jc[:, :, free], no (k, m, n) Jacobian formed), else from
    ``problem.jacobian(x, idx)`` (the whole Jacobian for one block, which the problem may hold from its last call).
    Yields (a, b, Aw ((b - a) m, n_free)), columns times ``scale``; ``check`` as whitened_blocks (DataError naming the
    poses whose Jacobian is not finite)."""
    x = np.asarray(x, float)
    fac = problem.jacobian_factors
    if fac is None:
        one = problem.n_obs <= int(block or BLOCK_POSES)
        jac = (lambda a, b: problem.jacobian(x)) if one else (lambda a, b: problem.jacobian(x, np.arange(a, b)))
        yield from whitened_blocks(problem, jac, scale, W, block, check)
        return
    block = int(block or BLOCK_POSES)
    W = problem.whitening() if W is None else W
    fi = problem.params.free_index
    n, m = len(problem.params), problem.m
    for a in range(0, problem.n_obs, block):
        b = min(a + block, problem.n_obs)
        D, Jc = fac(x, None if (a, b) == (0, problem.n_obs) else np.arange(a, b))
        if D.shape[:2] != (b - a, m) or Jc.shape != (b - a, D.shape[2], n):
            raise DataError(f"jacobian factors have shapes {D.shape} and {Jc.shape}, expected ({b - a}, {m}, c) and "
                            f"({b - a}, c, {n})")
        X = np.ascontiguousarray(Jc.transpose(2, 1, 0)[fi].transpose(2, 1, 0))  # (k, c, n_free): a row gather
        Aw = np.matmul(np.matmul(W[a:b], D), X)
        if check:
            bad = np.flatnonzero(~np.all(np.isfinite(Aw), axis=(1, 2)))
            if bad.size:
                raise DataError(f"jacobian is not finite for poses {pose_labels(problem, a + bad)}")
        Aw *= scale
        yield a, b, Aw.reshape(-1, fi.size)


def scaled_prior_rows(problem: IdentificationProblem, scale: np.ndarray) -> np.ndarray | None:
    """(p, n_free) the problem's prior rows (``prior_jacobian``) with columns times ``scale``; None without any."""
    return problem.prior_jacobian() * scale[None, :] if problem.prior_rows else None


def whitened_gram(problem: IdentificationProblem, x: ArrayLike, jacobian: np.ndarray | None = None) -> np.ndarray:
    """(n_free, n_free) Gram matrix (Jw S)^T (Jw S) of the whitened free Jacobian at x (n,) with the columns
    times their scales (S = diag(params.scale[free])), prior rows included, summed over :func:`whitened_blocks`
    of ``problem.jacobian(x, idx)`` (or of ``jacobian`` (n_obs, m, n) when given): no (N, n_free) matrix held.
    :func:`analyze` takes it (``gram=``)."""
    scale = problem.params.scale[problem.params.free_index]
    blocks = whitened_blocks(problem, lambda a, b: jacobian[a:b], scale) if jacobian is not None else \
        whitened_jacobian_blocks(problem, x, scale)
    return gram_of_blocks(blocks, scaled_prior_rows(problem, scale), scale.size)


def gram_of_blocks(blocks, P: np.ndarray | None, n: int) -> np.ndarray:
    """(n, n) sum of Aw^T Aw over blocks [(a, b, Aw ((b - a) m, n))] (any iterable, e.g. :func:`whitened_blocks`)
    plus P^T P (prior rows (p, n), or None): the Gram matrix of the stacked rows, none of them held together."""
    G = np.zeros((n, n))
    for _, _, Aw in blocks:
        G += Aw.T @ Aw
    return G if P is None else G + P.T @ P


def gram_factor(G: np.ndarray) -> np.ndarray | None:
    """R (n, n) with R^T R = G when its Cholesky factor is finite and conditioned below ``GRAM_COND_MAX`` (the
    same factor :func:`row_compressed` takes), else None (the Jacobian itself is needed)."""
    out = gram_factor_svd(G)
    return None if out is None else out[0]


def gram_factor_svd(G: np.ndarray) -> tuple[np.ndarray, tuple] | None:
    """(R, (U, s, Vt)): :func:`gram_factor` and the SVD of R it judged the condition by (s descending), for a
    caller that needs that SVD too; None where gram_factor gives None."""
    try:
        R = np.linalg.cholesky(G).T
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(R)):
        return None
    U, s, Vt = np.linalg.svd(R, full_matrices=False)
    return (R, (U, s, Vt)) if s.size and s[-1] > 0 and s[0] / s[-1] < GRAM_COND_MAX else None


def whitened_free_jacobian(problem: IdentificationProblem, J: np.ndarray, W: np.ndarray | None = None) -> np.ndarray:
    """(N, n_free) whitened Jacobian of the free parameters (physical units) from J (n_obs, m, n): the
    n_obs * m pose rows, then the problem's prior rows (``problem.prior_rows``; N = n_obs * m + n_prior)."""
    W = problem.whitening() if W is None else W
    Jf = J[:, :, problem.params.free_index]
    A = np.matmul(W, Jf).reshape(-1, Jf.shape[-1])  # stacked (m, m) @ (m, n_free) products (einsum: ~5x slower)
    return np.vstack([A, problem.prior_jacobian()]) if problem.prior_rows else A


#: :func:`row_compressed` takes R from the Cholesky factor of A^T A (one BLAS product) when R's condition number is
#: below this: the squared conditioning then costs at most ~eps * 1e8 ~ 2e-8 relative on the smallest singular
#: value; above it, from a Householder QR of A
GRAM_COND_MAX = 1e4


def row_compressed(A: np.ndarray) -> np.ndarray:
    """R (n, n) with R^T R = A^T A (A: (N, n), N > n), else A: the same column norms, singular values and right
    singular vectors, column spans and least-squares fits as A (A = Q R, Q orthonormal), at n x n size."""
    if A.shape[0] <= A.shape[1]:
        return A
    R = gram_factor(A.T @ A)
    return R if R is not None else scipy.linalg.qr(A, mode="r", check_finite=False)[0][:A.shape[1]]


#: poses per block of the whitened Jacobian (:func:`whitened_blocks`: the Gram matrix here, the normal equations of
#: ``lse.normal_equations``): a block's model Jacobian is ~8 MB at 4096 x 6 x 40 doubles (no (N, m, n) Jacobian is
#: formed beyond it; ``lse.KEEP_BYTES`` bounds the whitened blocks kept). When chosen (RX-90, 30 parameters, one
#: thread, machine shared): 50,000 poses solved in 0.98 / 0.91 / 0.87 / 0.89 s with blocks of 1,024 / 2,048 / 4,096
#: / 8,192 (1.81 s at 8,192 before the Jacobian factors: the transposed copy of a block left the cache), 5,000 in
#: 0.095 / 0.098 / 0.087 / 0.101 s
BLOCK_POSES = 4096


def compressed_whitened_jacobian(problem: IdentificationProblem, J: np.ndarray) -> np.ndarray:
    """:func:`row_compressed` of the whitened free Jacobian with columns times their scales (``params.scale``) from
    J (n_obs, m, n): the factor of its Gram matrix (:func:`whitened_gram`, no (N, n_free) copy held) when well
    conditioned, else the Householder QR of the whole matrix, as row_compressed."""
    scale = problem.params.scale[problem.params.free_index]
    if J.shape[0] * J.shape[1] + problem.n_prior <= scale.size:
        return whitened_free_jacobian(problem, J) * scale[None, :]
    R = gram_factor(whitened_gram(problem, None, J))
    return R if R is not None else row_compressed(whitened_free_jacobian(problem, J) * scale[None, :])


def observability_indices(s: np.ndarray, n_poses: int) -> dict[str, float]:
    """O1..O5 from singular values s (L,) (descending or not) and the number of poses M (see module doc)."""
    s = np.sort(np.asarray(s, float))[::-1]
    if s.size == 0 or s[-1] <= 0:
        return {"O1": 0.0, "O2": 0.0, "O3": 0.0, "O4": 0.0, "O5": 0.0}
    return {
        "O1": float(np.exp(np.mean(np.log(s))) / np.sqrt(n_poses)),
        "O2": float(s[-1] / s[0]),
        "O3": float(s[-1]),
        "O4": float(s[-1] ** 2 / s[0]),
        "O5": float(1.0 / np.sum(1.0 / s)),
    }


def _select_base(A: np.ndarray, rank: int, tol_abs: float, selection: str, s_weakest: float = 0.0) -> np.ndarray:
    """Indices of kept columns (sorted). ``s_weakest``: the smallest singular value counted in the rank; with
    ``selection="order"`` a column is kept when its part outside the kept columns' span exceeds
    :data:`BASE_KEEP_REL` of it (a nearly dependent column -- a right angle written 1.5707963 in a URDF -- would
    make a basis of the right size whose conditioning is not the rank's: a parameter of std ~1e7 x the others');
    columns left short of ``rank`` are then filled at the rank tolerance."""
    n = A.shape[1]
    if selection == "pivot":
        _, _, piv = scipy.linalg.qr(A, mode="economic", pivoting=True)
        return np.sort(piv[:rank])
    if selection == "order":
        if rank == n:  # every column: each one's part outside the others' span is >= the smallest singular value
            return np.arange(n)
        kept: list[int] = []
        Q = np.zeros((A.shape[0], 0))
        for tol in dict.fromkeys((max(tol_abs, BASE_KEEP_REL * s_weakest), tol_abs)):
            for j in range(n):
                if j in kept or len(kept) >= rank:
                    continue
                a = A[:, j]
                resid = a - Q @ (Q.T @ a)
                resid = resid - Q @ (Q.T @ resid)  # re-orthogonalise
                nr = np.linalg.norm(resid)
                if nr > tol:
                    kept.append(j)
                    Q = np.column_stack([Q, resid / nr])
        return np.array(sorted(kept), dtype=int)
    raise ParameterError(f"unknown base selection {selection!r} (expected 'pivot' or 'order')")


#: ``selection="order"``: a column joins the base when its part outside the kept columns' span exceeds this
#: fraction of the smallest singular value counted in the rank (scaled, whitened units)
BASE_KEEP_REL = 1e-3


# ----------------------------------------------------------------------------- main API
def condition_description(params: ParameterSet, base_idx: ArrayLike, problem: IdentificationProblem, at_nominal: bool,
                          normalize: bool = False, weighting: str | None = None) -> str:
    """What :func:`analyze`'s condition number is computed on, in words: the base columns (their count), the
    point of linearisation, the poses and equations, the weighting and the column scales (per parameter kind)."""
    kinds = np.asarray(params.kinds, dtype=object)[params.free_index][base_idx]
    scale = params.scale[params.free_index][base_idx]
    unit = {"length": (1e3, "mm"), "angle": (1e3, "mrad"), "coefficient": (1.0, "")}
    scales = []
    for k in dict.fromkeys(kinds):
        f, u = unit.get(k, (1.0, ""))
        vals = sorted({float(v) for v in scale[kinds == k]})
        txt = "/".join(f"{v * f:g}" for v in vals)
        scales.append(f"{txt} {u} per {k}".replace("  ", " ") if u else f"{txt} per {k}")
    prior = f" + {problem.n_prior} prior rows" if problem.n_prior else ""
    return (f"Jacobian of the {len(base_idx)} identifiable parameters at "
            f"{'the nominal model' if at_nominal else 'the given parameters'}, {problem.n_obs} poses "
            f"({problem.n_obs * problem.m} equations{prior}), {weighting or WEIGHTING_COV}, columns scaled by "
            + ", ".join(scales) + ("; then normalised" if normalize else ""))


@single_threaded_blas
def analyze(
    problem: IdentificationProblem,
    x: ArrayLike | None = None,
    tol: float | None = None,
    normalize: bool = False,
    selection: str = "order",
    jacobian: np.ndarray | None = None,
    weighting: str | None = None,
    gram: np.ndarray | None = None,
) -> IdentifiabilityReport:
    """Identifiability of the free parameters of ``problem`` at ``x`` (n,) (default nominal).

    tol: relative rank tolerance (fraction of s_max); default max(N, n) * eps * 1e3.
    normalize: divide each scaled column by its norm before the analysis.
    selection: "order" (default: prefer earlier parameters, stable over pose subsets) or "pivot"
        (QR with column pivoting).
    jacobian: (n_obs, m, n) Jacobian at x already validated by :func:`check_problem` (skips a recompute).
    gram: (n_free, n_free) :func:`whitened_gram` at x instead (a large problem: no Jacobian held); used when
    :func:`gram_factor` accepts it, else the Jacobian is computed.
    weighting: how the rows are weighted, in words, for ``condition_of`` (default WEIGHTING_COV).
    Raises IdentifiabilityError when there are fewer scalar equations than free parameters,
    ParameterError when nothing is free, DataError on non-finite data (naming the poses).
    Longer than 80 lines: one sequence (checks, scaled whitened Jacobian, SVD, base selection, couplings, indices) over shared arrays; split, it would pass ten arrays between helpers.
    """
    params = problem.params
    names = params.free_names
    n = len(names)
    if n == 0:
        raise ParameterError("no free parameter to analyse (every parameter is fixed)")
    N = problem.n_obs * problem.m + problem.n_prior
    if N < n:
        raise IdentifiabilityError(
            f"{N} scalar equations ({problem.n_obs} poses x {problem.m} components) for {n} free parameters: "
            f"need at least {n} equations (more poses or fewer free parameters)"
        )
    scale = params.scale[params.free_index]
    fac = None if gram is None else gram_factor_svd(gram)
    if fac is None:
        J = check_problem(problem, x)[1] if jacobian is None else jacobian
        A = compressed_whitened_jacobian(problem, J)  # below: only column norms, spans, fits, singular values
    else:
        A = fac[0]
    col_norms = np.linalg.norm(A, axis=0)
    if normalize:
        A = A / np.where(col_norms > 0, col_norms, 1.0)[None, :]
    U, s, Vt = fac[1] if fac is not None and not normalize else np.linalg.svd(A, full_matrices=False)
    s_max = float(s[0]) if s.size else 0.0
    tol_rel = max(N, n) * np.finfo(float).eps * 1e3 if tol is None else float(tol)
    tol_abs = tol_rel * s_max
    rank = int(np.sum(s > tol_abs)) if s_max > 0 else 0
    null_space = Vt[rank:].T.copy()

    base_idx = _select_base(A, rank, tol_abs, selection, float(s[rank - 1])) if rank > 0 else np.zeros(0, int)
    drop_idx = np.flatnonzero(~np.isin(np.arange(n), base_idx)) if base_idx.size < n else np.zeros(0, int)
    A_base = A[:, base_idx]
    couplings = []
    if drop_idx.size:
        if base_idx.size:
            C, *_ = np.linalg.lstsq(A_base, A[:, drop_idx], rcond=None)
        else:
            C = np.zeros((0, drop_idx.size))
        for col, j in enumerate(drop_idx):
            c = C[:, col]
            a = A[:, j]
            na = np.linalg.norm(a)
            fit_res = float(np.linalg.norm(a - A_base @ c) / na) if na > 0 else 0.0
            cmax = np.max(np.abs(c)) if c.size else 0.0
            keep = np.abs(c) > COUPLING_PRUNE_REL * cmax if cmax > 0 else np.zeros(c.size, bool)
            if na <= tol_abs:  # the parameter has no effect at all: no combination to report
                keep[:] = False
            # SI ratio: a unit (m or rad) deviation of the dropped parameter ~ combination_si[k] units of k.
            # (With normalize=True the scaled columns also include 1/col_norm; undo both.)
            eff_j = scale[j] / (col_norms[j] if normalize and col_norms[j] > 0 else 1.0)
            comb = {names[base_idx[i]]: float(c[i]) for i in np.flatnonzero(keep)}
            comb_si = {}
            for i in np.flatnonzero(keep):
                k = base_idx[i]
                eff_k = scale[k] / (col_norms[k] if normalize and col_norms[k] > 0 else 1.0)
                comb_si[names[k]] = float(c[i] * eff_k / eff_j)
            couplings.append(
                {"parameter": names[j], "combination": comb, "combination_si": comb_si,
                 "fit_residual": 0.0 if na <= tol_abs else fit_res, "no_effect": bool(na <= tol_abs)}
            )

    s_base = s if base_idx.size == n else \
        (np.linalg.svd(A_base, compute_uv=False) if base_idx.size else np.zeros(0))  # (every column: A's own)
    cond = float(s_base[0] / s_base[-1]) if s_base.size and s_base[-1] > 0 else float("inf")
    scaling = (
        "whitened by the inverse Cholesky factor of obs_cov (noise std units), each column multiplied by "
        "params.scale (effect of one typical deviation)"
        + ("; then each column divided by its norm" if normalize else "; no column normalisation")
    )
    return IdentifiabilityReport(
        condition_of=condition_description(
            params, base_idx, problem, x is None or np.array_equal(np.asarray(x, float).reshape(-1), params.nominal),
            normalize, weighting),
        prior_parameters=tuple(n for n in names if n in problem.prior_rows),
        names=tuple(names),
        n_params=n,
        rank=rank,
        singular_values=s,
        condition_number=cond,
        non_identifiable=tuple(names[j] for j in drop_idx),
        base_parameters=tuple(names[j] for j in base_idx),
        couplings=couplings,
        null_space=null_space,
        observability=observability_indices(s_base, problem.n_obs),
        scaling=scaling,
        n_equations=N,
        n_obs=problem.n_obs,
        tol=tol_rel,
        scale=scale.copy(),
        column_norms=col_norms,
    )


def base_problem(problem: IdentificationProblem, report: IdentifiabilityReport | None = None,
                 x: ArrayLike | None = None,
                 selection: str = "order") -> tuple[IdentificationProblem, IdentifiabilityReport, tuple[str, ...]]:
    """Fix the non-identifiable parameters at their current value (``params.nominal``).

    Returns (problem with those parameters fixed, report, warnings) where warnings is a tuple of
    strings naming every fixed parameter and what it is confounded with. ``report`` defaults to
    ``analyze(problem, x, selection=selection)``.
    """
    report = analyze(problem, x, selection=selection) if report is None else report
    if not report.non_identifiable:
        return problem, report, ()
    warnings = []
    for c in report.couplings:
        comb = " + ".join(f"{v:+.4g}*{k}" for k, v in c["combination_si"].items()) or "nothing (no effect on the residuals)"
        warnings.append(
            f"parameter {c['parameter']} is not identifiable from these poses: fixed at its current value; "
            f"its deviation is absorbed as {comb} (SI ratio)"
        )
    return problem.with_params(problem.params.fix(report.non_identifiable)), report, tuple(warnings)


def equivalent_base_values(problem: IdentificationProblem, report: IdentifiabilityReport, x_true: ArrayLike,
                           x_fixed: ArrayLike | None = None) -> np.ndarray:
    """Full vector (n,) that a solver fixing ``report.non_identifiable`` at ``x_fixed`` should find when the
    data come from ``x_true`` (simulation): each base parameter gets the deviation of the dropped ones it is
    confounded with, to first order (exact when the coupling is linear, e.g. two offsets about one axis).
    """
    x_true = np.asarray(x_true, float)
    x_fixed = problem.params.nominal if x_fixed is None else np.asarray(x_fixed, float)
    out = x_true.copy()
    p = problem.params
    for c in report.couplings:
        j = p.index(c["parameter"])
        out[j] = x_fixed[j]
        dj = x_true[j] - x_fixed[j]
        for k, ratio in c["combination_si"].items():
            out[p.index(k)] += ratio * dj
    return out
