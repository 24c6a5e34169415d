"""Extended Kalman filter identification (the thesis' chapter 4 filter, done properly).

State: the free parameters, handled internally in scaled units ``z = (x_free - x0_free) / scale``.
Parameters are constant, so the prediction step is ``z_k|k-1 = z_k-1``, ``P_k|k-1 = P_k-1 + Q``
with ``Q = q_process * I`` in scaled units (i.e. ``q_process * diag(scale^2)`` in SI; default 0).

Measurement model of pose k: ``y_k = h_k(x) + v_k``, ``v_k ~ N(0, R_k)``, ``R_k = obs_cov[k]``.
With ``r_k(x) = y_k - h_k(x)`` (the problem's residual) and ``J_k = dr_k/dx = -dh_k/dx``, the
measurement is whitened by ``W_k`` (inverse Cholesky factor of R_k), so the filter sees R = I;
this is exactly the update with R_k.

Update (ONE per robot pose, in the order of the observations). ``iterations_per_update=1`` is
the plain EKF of the thesis (eqs. 4.2-4.9), linearised at the prediction::

    H = W_k J_k(z_k|k-1) diag(scale)         (m, n_free)  (= -dh/dz, whitened)
    S = H P Hᵀ + I;   K = -P Hᵀ S^-1         (gain for y - h; the sign comes from H = -dh/dz)
    z_k|k = z_k|k-1 + K W_k r_k(z_k|k-1)

``iterations_per_update > 1`` (default 5) is the iterated EKF (Gauss-Newton on the posterior of
that pose, Bell & Cathey 1993) with a backtracking line search on the pose's posterior cost
``0.5 |W_k r_k(z)|² + 0.5 (z - z_k|k-1)ᵀ P^-1 (z - z_k|k-1)`` (Skoglund, Hendeby & Axehill 2015),
which keeps the early poses -- where P is still the broad prior -- from oscillating::

    z_gn = z_k|k-1 + K(z_i) (W_k r_k(z_i) + H(z_i) (z_k|k-1 - z_i)),  z_{i+1} = z_i + a (z_gn - z_i)

stopping when the step is below STEP_TOL * max(1, |z|) or no descent is left. Covariance:
``P_k|k = (I - K H_h) P (I - K H_h)ᵀ + K Kᵀ`` (Joseph form, H_h = -H, R = I after whitening; K, H
at the final iterate).

P0 = diag(prior_std²) of the free parameters (``problem.prior_std``, default 100 x scale: an
essentially uninformative prior around x0). The problem's prior rows (``problem.prior_rows``: parameters whose
prior N(nominal, prior_std²) is part of the least-squares cost, e.g. the H4's measured mount tilts) start from the
uninformative 100 x scale instead and enter every pass as linear pseudo-observations, applied before the poses,
so that the passes reach the same optimum as ``solve_lse`` (which has them as rows of its cost).

Passes. Pass 1 is the sequential filter above. Its weak point: with a broad prior the first
poses fix the estimate only along the few directions they see, the estimate can wander far
(tens of scales on the ill-conditioned H4 models) and those poses' information stays linearised
there; on H4 variant D with 81 poses one pass differs from LSE by ~1-3 posterior std, while on
the well-conditioned toy arm it agrees to < 0.01 std. Passes 2.. fix this: each restarts
``P = P0`` with the prior mean at the previous pass's estimate ``z_p`` and linearises EVERY pose
at ``z_p`` (one linear update per pose). Such a pass is exactly one Gauss-Newton step on the
least-squares cost damped by ``P0^-1`` (a Levenberg-Marquardt step), so passes converge to the
LSE solution itself (no prior bias at the fixed point; the data are never counted twice). The
reported covariance is the final P of the last pass ((JᵀJ + P0^-1)^-1, i.e. the LSE covariance up
to the (std / prior std)² damping).

Convergence (what ``converged`` means). After every pass, at the pass's estimate ``z`` the
undamped Gauss-Newton step to the least-squares optimum ``delta = -pinv(H) W r`` (all poses,
whitened, scaled) is computed; ``distance = max_i |delta_i| / std_i`` (std = posterior std of the
pass) is, to first order, how far the estimate still is from the LSE solution in posterior std
(exact for a linear model). ``converged`` is ``distance < tol`` (default 1e-3) and everything
finite. ``passes=None`` (default) runs passes until converged, at most ``max_passes`` (default
20), and says so in ``message`` and ``warnings`` when it stops early (status 0); an integer
``passes`` runs exactly that many and judges the result the same way (so one pass on an
ill-conditioned problem honestly reports converged=False). ``info["distance_std"]`` holds the
distance after each pass; ``info["first_pass_updates_converged"]`` whether every iterated update
of pass 1 converged.
"""

from __future__ import annotations

import time
from typing import Iterable

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigError, DataError, UnreachablePoseError
from .identifiability import pose_labels
from .lse import finish_result, prepare, whitened_cost
from .problem import STATUS_CONVERGED, STATUS_MAX_ITERATIONS, IdentificationProblem, IdentificationResult
from .threads import single_threaded_blas

STEP_TOL = 1e-9  # iterated update stops when ||z_{i+1} - z_i|| < STEP_TOL * max(1, ||z||) (scaled units)
#: default convergence tolerance: distance to the least-squares optimum, in posterior std
DEFAULT_TOL = 1e-3
#: default largest number of passes when ``passes=None``
DEFAULT_MAX_PASSES = 20


class _Model:
    """The problem seen in scaled free variables z (x_free = x0_free + scale * z), whitened."""

    def __init__(self, problem: IdentificationProblem, x0: np.ndarray, W: np.ndarray):
        self.problem, self.W, self.x0 = problem, W, x0
        self.fi = problem.params.free_index
        self.s = problem.params.scale[self.fi]
        self.x0_free = x0[self.fi]

    def x_of(self, z) -> np.ndarray:
        x = self.x0.copy()
        x[self.fi] = self.x0_free + self.s * z
        return x

    def label(self, k) -> str:
        return pose_labels(self.problem, [k])[0]

    def pose_terms(self, k, z, need_jac=True):
        """Whitened residual (m,) and scaled whitened Jacobian H (m, n) of pose k at z."""
        x = self.x_of(z)
        r = self.W[k] @ np.asarray(self.problem.residual(x, np.array([k])), float)[0]
        if not np.all(np.isfinite(r)):
            raise DataError(f"EKF: residual of pose {self.label(k)} is not finite at the current estimate")
        if not need_jac:
            return r, None
        J = np.asarray(self.problem.jacobian(x, np.array([k])), float)[0]
        return r, (self.W[k] @ J[:, self.fi]) * self.s[None, :]

    def prior_terms(self, z):
        """The problem's prior rows (``problem.prior_rows``, linear pseudo-observations N(nominal, prior_std^2)) at
        z: whitened residual (p,) and scaled H (p, n); (None, None) when there are none."""
        if not self.problem.n_prior:
            return None, None
        return (self.problem.prior_residual(self.x_of(z)),
                self.problem.prior_jacobian() * self.s[None, :])

    def batch_terms(self, z):
        """All poses at z: whitened residuals (n_obs, m), H (n_obs, m, n), full Jacobian (n_obs, m, n_params);
        None when the model cannot be evaluated there or a value is not finite (the result says which)."""
        x = self.x_of(z)
        try:
            r = np.asarray(self.problem.residual(x), float)
            J = np.asarray(self.problem.jacobian(x), float)
        except (UnreachablePoseError, DataError):
            return None
        with np.errstate(over="ignore", invalid="ignore"):
            rw = np.einsum("kij,kj->ki", self.W, r)
            H = np.einsum("kij,kjn->kin", self.W, J[:, :, self.fi]) * self.s[None, None, :]
        if not (np.all(np.isfinite(rw)) and np.all(np.isfinite(H))):
            return None
        return rw, H, J


def _gain(P, H):
    PHt = P @ H.T
    S = H @ PHt + np.eye(H.shape[0])
    return -np.linalg.solve(S, PHt.T).T  # K = -P Hᵀ S^-1 (gain for y - h, H = -dh/dz)


def _joseph(P, K, H):
    IKH = np.eye(P.shape[0]) + K @ H  # I - K H_h with H_h = -H
    P = IKH @ P @ IKH.T + K @ K.T  # Joseph form (R = I after whitening)
    return 0.5 * (P + P.T)


def _iterated_update(model: _Model, k, z_prior, P, n_iter):
    """Iterated update of pose k with backtracking on c(z) = 0.5 |W r(z)|^2 + 0.5 (z - z_prior)ᵀ P^-1 (z - z_prior).
    Returns (z, K, H at the final iterate, number of linear updates, converged)."""
    cP = np.linalg.cholesky(P)

    def post_cost(zz, rr):
        d = np.linalg.solve(cP, zz - z_prior)
        return 0.5 * float(rr @ rr + d @ d)

    zi = z_prior.copy()
    r, H = model.pose_terms(k, zi)
    ci = post_cost(zi, r)
    conv, n_up = False, 0
    for _it in range(n_iter):
        K = _gain(P, H)
        step = z_prior + K @ (r + H @ (z_prior - zi)) - zi
        n_up += 1
        alpha, accepted = 1.0, False
        for _ls in range(12):
            z_try = zi + alpha * step
            try:
                r_try, _ = model.pose_terms(k, z_try, need_jac=False)
                c_try = post_cost(z_try, r_try)
            except (UnreachablePoseError, DataError):  # trial point outside the model's domain
                c_try = np.inf
            if c_try <= ci:
                accepted = True
                break
            alpha *= 0.5
        small = np.linalg.norm(alpha * step) < STEP_TOL * max(1.0, np.linalg.norm(zi))
        if not accepted or small:
            conv = True  # no descent left: at the minimum to rounding
            if accepted:
                zi = z_try
            break
        zi, r, ci = z_try, r_try, c_try
        _, H = model.pose_terms(k, zi)
    return zi, _gain(P, H), H, n_up, conv


def _first_pass(model: _Model, P0, Q, obs_order, n_iter):
    """Sequential (iterated) EKF over the poses from z = 0. Returns (z, P, updates, every update converged)."""
    z, P = np.zeros(P0.shape[0]), P0.copy()
    updates, all_conv = 0, True
    rp, Hp = model.prior_terms(z)
    if rp is not None:  # the prior rows: one linear update (exact), before the poses
        K = _gain(P, Hp)
        z = z + K @ rp
        P = _joseph(P, K, Hp)
    for k in obs_order:
        P = P + Q
        if n_iter == 1:  # plain EKF (thesis eqs. 4.2-4.9), linearised at the prediction
            r, H = model.pose_terms(k, z)
            K = _gain(P, H)
            zi = z + K @ r
            updates += 1
        else:
            zi, K, H, n_up, conv = _iterated_update(model, k, z, P, n_iter)
            updates += n_up
            all_conv &= conv
        if not np.all(np.isfinite(zi)):
            raise DataError(f"EKF update diverged (non-finite state) at pose {model.label(k)}")
        P = _joseph(P, K, H)
        z = zi
    return z, P, updates, all_conv


def _relinearised_pass(z_lin, rw, H, P0, Q, obs_order, prior=(None, None)):
    """One pass with every pose linearised at z_lin (rw (n_obs, m), H (n_obs, m, n) there), prior mean z_lin;
    ``prior``: the problem's prior rows (rp (p,), Hp (p, n)) at z_lin, applied first (they are linear)."""
    z, P = z_lin.copy(), P0.copy()
    rp, Hp = prior
    if rp is not None:
        K = _gain(P, Hp)
        z = z + K @ rp
        P = _joseph(P, K, Hp)
    for k in obs_order:
        P = P + Q
        K = _gain(P, H[k])
        z = z + K @ (rw[k] + H[k] @ (z - z_lin))
        P = _joseph(P, K, H[k])
    return z, P


def _distance(rw, H, P, prior=(None, None)) -> float:
    """max_i |delta_i| / std_i with delta the undamped Gauss-Newton step to the LSE optimum (scaled units; the
    problem's prior rows ``prior`` = (rp, Hp) are part of that cost, as in solve_lse)."""
    n = H.shape[-1]
    A, b = H.reshape(-1, n), rw.ravel()
    if prior[0] is not None:
        A, b = np.vstack([A, prior[1]]), np.concatenate([b, prior[0]])
    delta = -np.linalg.lstsq(A, b, rcond=None)[0]
    std = np.sqrt(np.clip(np.diag(P), 1e-300, None))
    d = float(np.max(np.abs(delta) / std)) if n else 0.0
    return d if np.isfinite(d) else float("inf")


def _check_options(passes, max_passes, tol, iterations_per_update, q_process):
    if passes is not None and int(passes) < 1:
        raise ConfigError(f"solve_ekf: passes={passes}, expected >= 1 (or None: until converged)")
    if int(max_passes) < 1:
        raise ConfigError(f"solve_ekf: max_passes={max_passes}, expected >= 1")
    if not (np.isfinite(tol) and tol > 0):
        raise ConfigError(f"solve_ekf: tol={tol}, expected a finite value > 0 (posterior std)")
    if int(iterations_per_update) < 1:
        raise ConfigError(f"solve_ekf: iterations_per_update={iterations_per_update}, expected >= 1")
    if not (np.isfinite(q_process) and q_process >= 0):
        raise ConfigError(f"solve_ekf: q_process={q_process}, expected a finite value >= 0")


def _prior_cov(problem: IdentificationProblem, s) -> np.ndarray:
    params = problem.params
    if problem.prior_std is None:
        prior = 100.0 * params.scale
    else:
        prior = np.asarray(problem.prior_std, float).reshape(-1)
        if prior.shape != (len(params),):
            raise DataError(f"prior_std has shape {prior.shape}, expected ({len(params)},)")
    prior_z = prior[params.free_index] / s
    if problem.n_prior:  # their prior enters as the prior rows (pseudo-observations), not as P0
        rows = np.flatnonzero(np.any(problem.prior_jacobian() != 0, axis=0))
        prior_z[rows] = 100.0
    ok = np.isfinite(prior_z) & (prior_z > 0)
    if not np.all(ok):
        bad = [params.free_names[i] for i in np.flatnonzero(~ok)]
        raise DataError(f"prior_std must be finite and > 0 for free parameters; bad: {bad}")
    return np.diag(prior_z**2)


@single_threaded_blas
def solve_ekf(
    problem: IdentificationProblem,
    x0: ArrayLike | None = None,
    passes: int | None = None,
    iterations_per_update: int = 5,
    q_process: float = 0.0,
    fix_unidentifiable: bool = True,
    free: Iterable[str] | None = None,
    fix: Iterable[str] = (),
    order: ArrayLike | None = None,
    max_passes: int = DEFAULT_MAX_PASSES,
    tol: float = DEFAULT_TOL,
    selection: str = "order",
) -> IdentificationResult:
    """Identify the free parameters with an (iterated) EKF, one measurement update per pose.

    x0: (n,) full starting vector (SI), default ``params.nominal`` (= prior mean of the first pass).
    passes: None (default) = passes until converged, at most ``max_passes``; an int = exactly that many.
    tol: convergence tolerance, distance to the LSE optimum in posterior std (see module docstring).
    iterations_per_update: >= 1 (1 = plain EKF). q_process: process noise variance per pose, in
    scaled units (fraction of scale², >= 0). order: optional (n_obs,) permutation of the observations.
    selection: base-set choice ("order" default, or "pivot"), as in :func:`~vision_calib.identify.lse.solve_lse`.
    Returns an IdentificationResult with method "ekf", covariance = final P (SI, free parameters),
    converged/status/message as defined in the module docstring. ``info``: passes (run), updates,
    distance_std (per pass), pass_estimates ((passes, n) full vectors), identifiability report, ...
    """
    t0 = time.perf_counter()
    _check_options(passes, max_passes, tol, iterations_per_update, q_process)
    original = problem
    problem, x0, report, warnings = prepare(problem, x0, free, fix, fix_unidentifiable, selection)
    model = _Model(problem, x0, problem.whitening())
    n = model.fi.size
    P0 = _prior_cov(problem, model.s)
    Q = q_process * np.eye(n)
    obs_order = np.arange(problem.n_obs) if order is None else np.asarray(order, int).reshape(-1)
    if obs_order.size == 0 or obs_order.min() < 0 or obs_order.max() >= problem.n_obs:
        raise ConfigError(f"solve_ekf: order must hold observation indices in [0, {problem.n_obs}), got {order!r}")
    cost0 = whitened_cost(problem, x0, model.W)
    z, P, updates, first_conv = _first_pass(model, P0, Q, obs_order, int(iterations_per_update))
    pass_estimates, distances, J = [model.x_of(z)], [], None
    limit = int(max_passes) if passes is None else int(passes)
    while True:
        terms = model.batch_terms(z)
        if terms is None:  # not finite / not evaluable at the estimate: finish_result names the cause
            distances.append(float("inf"))
            break
        rw, H, J = terms
        prior = model.prior_terms(z)
        distances.append(_distance(rw, H, P, prior))
        if (passes is None and distances[-1] < tol) or len(pass_estimates) >= limit:
            break
        z, P = _relinearised_pass(z, rw, H, P0, Q, obs_order, prior)
        updates += obs_order.size
        pass_estimates.append(model.x_of(z))
    converged, message = _verdict(distances[-1], tol, len(pass_estimates), passes, max_passes)
    if not converged:
        warnings = tuple(warnings) + (f"EKF {message}",)
    info = {
        "passes": len(pass_estimates),
        "max_passes": int(max_passes),
        "tol": float(tol),
        "distance_std": [float(d) for d in distances],
        "first_pass_updates_converged": bool(first_conv),
        "iterations_per_update": int(iterations_per_update),
        "updates": updates,
        "q_process": float(q_process),
        "pass_estimates": np.array(pass_estimates),
        "identifiability": report,
    }
    status = STATUS_CONVERGED if converged else STATUS_MAX_ITERATIONS
    return finish_result("ekf", original, problem, x0, model.x_of(z), P * np.outer(model.s, model.s), cost0, updates,
                         converged, warnings, t0, info, model.W, status=status, message=message, J=J)


def _verdict(distance, tol, n_passes, passes, max_passes) -> tuple[bool, str]:
    where = f"{distance:.3g} posterior std from the least-squares optimum (tol {tol:g})"
    if distance < tol:
        return True, f"converged after {n_passes} pass(es): the estimate is {where}"
    if not np.isfinite(distance):
        return False, f"stopped after {n_passes} pass(es): the model is not finite at the estimate"
    if passes is None:
        return False, (f"stopped at max_passes={max_passes} without converging: the estimate is still {where}; "
                       "raise max_passes or use solve_lse")
    return False, (f"ran the requested {n_passes} pass(es) without converging: the estimate is {where} "
                   "(passes=None iterates until converged)")
