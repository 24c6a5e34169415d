"""Optimal pose selection (experimental design) for an :class:`IdentificationProblem` (numpy only).

Which ``n`` of the problem's K candidate observations (robot poses) to measure so that the
identification is best conditioned. Everything is computed on the *scaled, whitened* Jacobian of
the free parameters (as in :mod:`.identifiability`)::

    A_k = W_k @ J_k[:, free] @ diag(scale[free])        (m, L) per candidate pose k
    M(S) = sum_{k in S} A_k^T A_k                        (L, L) information matrix of a design S

Criteria (larger is better)
---------------------------
* ``"D"``: log det M(S) (D-optimality). At a fixed number of poses M this ranks designs exactly
  like the Borm & Menq index O1 = det(M)^(1/2L) / sqrt(M), and it does not depend on the column
  scales (they add a constant), so it is the default.
* ``"O1"``: the same selection as ``"D"``; :func:`design_criterion` reports the O1 value.
* ``"E"``: s_min = sqrt(lambda_min(M(S))) (E-optimality, Nahvi-Hollerbach O3). Depends on the scales.

Algorithm
---------
1. Seeding ("well-spread" in parameter space): while M(S) is rank deficient, add the pose with the
   largest information in the directions not yet observed, ``||A_k N||_F^2`` with N an orthonormal
   basis of the null space of M(S) (a block version of QR with column pivoting); the first pose is
   the one with the largest ``||A_k||_F``. This takes about ceil(L / m) poses.
2. Greedy forward selection up to ``n`` poses: add the pose with the largest criterion gain. For D the
   gain of every candidate at once comes from the matrix determinant lemma,
   ``det(M + A_k^T A_k) = det(M) det(I_m + A_k M^-1 A_k^T)`` (batched m x m slogdet); for E a batched
   eigvalsh of the K updated matrices.
3. Exchange pass (Fedorov 1972; DETMAX, Mitchell 1974, is a variant): repeatedly make the single swap
   (selected i <-> unselected j) with the best criterion, while it improves the criterion by more than
   a relative 1e-10; each accepted swap strictly increases the criterion, so the pass ends. For D
   every pair is scored at once with the rank-2m determinant lemma
   ``det(M - A_i^T A_i + A_j^T A_j) / det(M) = det(I_2m + [[G_jj, G_ji], [-G_ij, -G_ii]])``, with
   ``G = A M^-1 A^T`` over all candidates; for E a batched eigvalsh per selected pose. The pass ends
   in a local optimum, so it is repeated from ``restarts`` random designs (a fixed generator: the
   result is deterministic) and the best design is kept.

Complexity (K candidates, n selected, m rows per pose, L free parameters): Jacobian once; seeding and
greedy O(n K m L^2) for D (O(n K L^3) for E); one exchange iteration O(K^2 m^2 L + n K m^3) for D
(O(n K L^3) for E); the number of exchange iterations is small in practice (tens), capped at
``max_exchanges`` (default 50 n) per pass, 1 + ``restarts`` passes. For the H4 81-pose grid (L = 19,
m = 4) a D selection takes ~0.1 s, an E selection of 15 poses ~0.7 s (one core).

The selection needs the Jacobian only (evaluated at ``x``, default nominal): with a problem built from
exact measurements at the nominal geometry it does not look at any truth or noise.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..errors import DataError, IdentifiabilityError, ParameterError
from .identifiability import check_problem
from .problem import IdentificationProblem
from .threads import single_threaded_blas

CRITERIA = ("D", "O1", "E")
#: relative eigenvalue threshold below which M(S) is treated as rank deficient (seeding phase)
RANK_TOL = 1e-10
#: minimum relative improvement for an exchange to be accepted
EXCHANGE_TOL = 1e-10


def _check_criterion(criterion: str) -> str:
    c = str(criterion).upper()
    if c not in CRITERIA:
        raise ParameterError(f"unknown pose-selection criterion {criterion!r} (expected one of {', '.join(CRITERIA)})")
    return c


def information_blocks(problem: IdentificationProblem, x: ArrayLike | None = None) -> np.ndarray:
    """Scaled whitened Jacobian of the free parameters per observation, (n_obs, m, n_free), at ``x``
    (default nominal); rows are in units of noise std, columns in units of ``params.scale``."""
    p = problem.params
    if p.n_free == 0:
        raise ParameterError("no free parameter: nothing to select poses for")
    J = check_problem(problem, x)[1]
    W = problem.whitening()
    A = np.einsum("kij,kjn->kin", W, J[:, :, p.free_index])
    return A * p.scale[p.free_index][None, None, :]


def _info(A: np.ndarray, idx) -> np.ndarray:
    Ai = A[np.asarray(idx, int)]
    return np.einsum("kmi,kmj->ij", Ai, Ai)


def _logdet(M: np.ndarray) -> float:
    sign, ld = np.linalg.slogdet(M)
    return float(ld) if sign > 0 else -np.inf


def _lam_min(M: np.ndarray) -> float:
    return float(np.linalg.eigvalsh(M)[0])


def design_criterion(problem_or_blocks: IdentificationProblem | np.ndarray, idx: ArrayLike, criterion: str = "D",
                     x: ArrayLike | None = None) -> float:
    """Criterion of the design ``idx`` (k,) int: "D" -> log det M (-inf if singular), "O1" -> Borm-Menq
    O1 = det(M)^(1/2L) / sqrt(k), "E" -> s_min = sqrt(lambda_min(M)) (0 if singular). Scaled units.
    ``problem_or_blocks``: an IdentificationProblem or the (n_obs, m, L) array of :func:`information_blocks`."""
    c = _check_criterion(criterion)
    A = problem_or_blocks if isinstance(problem_or_blocks, np.ndarray) else information_blocks(problem_or_blocks, x)
    idx = np.asarray(idx, int)
    M = _info(A, idx)
    if c == "E":
        return float(np.sqrt(max(_lam_min(M), 0.0)))
    ld = _logdet(M)
    if c == "D":
        return ld
    return 0.0 if not np.isfinite(ld) else float(np.exp(ld / (2 * M.shape[0])) / np.sqrt(idx.size))


def _rank_deficient(M: np.ndarray, ref: float) -> tuple[bool, np.ndarray]:
    """(is M rank deficient, orthonormal null-space basis (L, r)) with threshold RANK_TOL * ref."""
    w, V = np.linalg.eigh(M)
    null = w <= RANK_TOL * ref
    return bool(np.any(null)), V[:, null]


def _greedy_gains(A: np.ndarray, M: np.ndarray, cand: np.ndarray, c: str) -> np.ndarray:
    """Criterion after adding each candidate (D: log det ratio; E: lambda_min), (len(cand),)."""
    Ac = A[cand]
    if c == "E":
        return np.linalg.eigvalsh(M[None] + np.einsum("kmi,kmj->kij", Ac, Ac))[:, 0]
    Minv = np.linalg.inv(M)
    B = np.einsum("kmi,ij,klj->kml", Ac, Minv, Ac)
    sign, ld = np.linalg.slogdet(np.eye(A.shape[1])[None] + B)
    return np.where(sign > 0, ld, -np.inf)


def _best_swap(A: np.ndarray, M: np.ndarray, sel: np.ndarray, out: np.ndarray, c: str, reg: float):
    """Best single exchange: (i position in sel, j position in out, new criterion value or gain).
    D: returns the log det ratio of the best swap; E: the new lambda_min of the best swap."""
    m = A.shape[1]
    Mr = M + reg * np.eye(M.shape[0])
    if c == "E":
        F = np.einsum("kmi,kmj->kij", A, A)
        best = (-1, -1, -np.inf)
        Fo = F[out]
        for a, i in enumerate(sel):
            lam = np.linalg.eigvalsh(Mr[None] - F[i][None] + Fo)[:, 0]
            b = int(np.argmax(lam))
            if lam[b] > best[2]:
                best = (a, b, float(lam[b]))
        return best
    Minv = np.linalg.inv(Mr)
    K = A.shape[0]
    Af = A.reshape(K * m, -1)
    G = (Af @ Minv @ Af.T).reshape(K, m, K, m)
    Gii = G[sel][:, :, sel].diagonal(axis1=0, axis2=2).transpose(2, 0, 1)  # (ns, m, m)
    Gjj = G[out][:, :, out].diagonal(axis1=0, axis2=2).transpose(2, 0, 1)  # (no, m, m)
    Gji = G[out][:, :, sel]  # (no, m, ns, m)
    ns, no = sel.size, out.size
    D = np.empty((ns, no, 2 * m, 2 * m))
    D[:, :, :m, :m] = Gjj[None]
    D[:, :, :m, m:] = Gji.transpose(2, 0, 1, 3)
    D[:, :, m:, :m] = -Gji.transpose(2, 0, 3, 1)  # -G_ij = -G_ji^T
    D[:, :, m:, m:] = -Gii[:, None]
    D += np.eye(2 * m)
    sign, ld = np.linalg.slogdet(D)
    ld = np.where(sign > 0, ld, -np.inf)
    a, b = np.unravel_index(int(np.argmax(ld)), ld.shape)
    return int(a), int(b), float(ld[a, b])


def _exchange(A, sel, c, ref, max_exchanges) -> np.ndarray:
    """Fedorov exchange from design ``sel`` (n,) until no swap improves the criterion; returns the design."""
    K, L = A.shape[0], A.shape[2]
    sel_a = np.array(sel, int)
    n = sel_a.size
    for _ in range(max_exchanges):
        out = np.flatnonzero(~np.isin(np.arange(K), sel_a))
        M = _info(A, sel_a)
        deficient, _ = _rank_deficient(M, ref * n)
        reg = 1e-8 * ref if deficient else 0.0
        a, b, val = _best_swap(A, M, sel_a, out, c, reg)
        if c == "E":
            cur = _lam_min(M + reg * np.eye(L))
            improve = val > cur + EXCHANGE_TOL * max(abs(cur), ref)
        else:
            improve = val > EXCHANGE_TOL
        if not improve or a < 0:
            break
        sel_a[a] = out[b]
    return sel_a


def _value(A, sel, c) -> float:
    M = _info(A, sel)
    return _lam_min(M) if c == "E" else _logdet(M)


@single_threaded_blas
def select_poses(problem: IdentificationProblem, n: int, criterion: str = "D", x: ArrayLike | None = None,
                 start: ArrayLike | None = None, exchange: bool = True, max_exchanges: int | None = None,
                 restarts: int = 4) -> np.ndarray:
    """Choose ``n`` of the problem's observations maximising an observability criterion (module doc).

    n: number of poses to select (1 <= n <= n_obs). criterion: "D" (log det, = O1 ranking), "O1" or
    "E" (smallest singular value, O3). x: (n_params,) linearisation point (default nominal).
    start: (k,) int initial poses (k <= n; kept by the greedy phase, open to exchange); k == n runs
    the exchange pass only. exchange: run the exchange pass (False: seeding + greedy only).
    restarts: further exchange passes from random designs (fixed generator: deterministic); the best
    of the greedy start and the restarts is returned (an exchange pass ends in a local optimum: no
    single swap improves it). No restarts when ``start`` is given.
    Returns idx (n,) int, sorted, unique, in [0, n_obs).
    Raises IdentifiabilityError when n * m < n_free or when the free parameters are not all
    identifiable from the whole pool (naming them; fix them first, e.g. identify.base_problem),
    ParameterError on a bad n / criterion / start, DataError on non-finite data.
    Longer than 80 lines: argument checks and the greedy + exchange loop share the information blocks.
    """
    c = _check_criterion(criterion)
    K, m = problem.n_obs, problem.m
    L = problem.params.n_free
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise ParameterError(f"number of poses to select must be a positive integer, got {n!r}")
    n = int(n)
    if n > K:
        raise ParameterError(f"{n} poses asked, the problem has {K} candidate poses")
    if n * m < L:
        raise IdentifiabilityError(
            f"{n} poses give {n * m} equations ({m} per pose) for {L} free parameters "
            f"({', '.join(problem.params.free_names)}): select at least {-(-L // m)} poses")
    A = information_blocks(problem, x)
    M_pool = _info(A, np.arange(K))
    ref = float(np.trace(M_pool)) / L / K  # mean eigenvalue of one pose's information
    deficient, _ = _rank_deficient(M_pool, ref * K)
    if deficient:
        from .identifiability import analyze

        rep = analyze(problem, x, jacobian=check_problem(problem, x)[1])
        raise IdentifiabilityError(
            f"parameters {list(rep.non_identifiable) or '(near-singular set)'} are not identifiable even from all "
            f"{K} candidate poses: fix them before selecting poses (identify.base_problem)")

    sel: list[int] = []
    if start is not None:
        st = np.asarray(start).reshape(-1)
        if st.size and (not np.issubdtype(st.dtype, np.integer) or st.min() < 0 or st.max() >= K):
            raise ParameterError(f"start must hold pose indices in [0, {K}), got {start!r}")
        if len(set(st.tolist())) != st.size or st.size > n:
            raise ParameterError(f"start must hold at most n={n} distinct pose indices, got {st.size} ({start!r})")
        sel = [int(i) for i in st]
    mask = np.zeros(K, bool)
    mask[sel] = True

    # 1-2: seeding while rank deficient, then greedy on the criterion
    while len(sel) < n:
        cand = np.flatnonzero(~mask)
        M = _info(A, sel) if sel else np.zeros((L, L))
        deficient, N = _rank_deficient(M, ref * max(len(sel), 1))
        if deficient:
            score = np.einsum("kmi,ir->kmr", A[cand], N)
            score = np.sum(score**2, axis=(1, 2))
        else:
            score = _greedy_gains(A, M, cand, c)
        k = int(cand[int(np.argmax(score))])
        sel.append(k)
        mask[k] = True

    # 3: exchange pass
    if exchange and n < K:
        max_exchanges = 50 * n if max_exchanges is None else int(max_exchanges)
        best = _exchange(A, sel, c, ref, max_exchanges)
        best_v = _value(A, best, c)
        rng = np.random.default_rng(0)
        for _ in range(0 if start is not None else int(restarts)):
            cand = _exchange(A, rng.choice(K, n, replace=False), c, ref, max_exchanges)
            v = _value(A, cand, c)
            if v > best_v + EXCHANGE_TOL * max(abs(best_v), 1.0):
                best, best_v = cand, v
        sel = best.tolist()
    idx = np.sort(np.array(sel, int))
    if np.unique(idx).size != n:  # pragma: no cover - guarded by construction
        raise DataError("pose selection produced duplicate poses")
    return idx


__all__ = ["CRITERIA", "select_poses", "design_criterion", "information_blocks"]
