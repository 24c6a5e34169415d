"""Hand-eye fit with the robot's pose error in the model, started from the best closed form.

The flange poses a robot reports carry its own pose error (:mod:`.handeye_problem`, "Robot pose error"):
each pose's residual covariance is ``C_k = camera_cov_k + D_k robot_cov D_k^T`` with ``D_k`` the residual's
response to the flange pose error at the current estimate, ``robot_cov = diag(s_t^2 I3, s_r^2 I3)``.
:func:`fit_handeye`:

1. the candidate starts: closed forms given by the caller (the pipeline passes OpenCV's 7,
   :func:`vision_calib.measure.handeye.closed_forms`), else the numpy closed form of
   :func:`.handeye_problem.handeye_initial_guess` (:data:`DEFAULT_CANDIDATE`);
2. the start: the candidate of least weighted cost (weights at that closed form);
3. iteratively reweighted least squares: LSE with the weights at x, weights recomputed at the new x, until x
   moves by less than 1e-3 of its std. When the robot's std are not given, the two variances
   ``theta = (s_t^2, s_r^2)`` are estimated at each step with the camera covariance known: the maximum of the
   REML likelihood of the model linearised at x, ``-0.5 (log|C| + log|J^T C^-1 J| + r^T P r)``,
   ``C = camera + s_t^2 V_t + s_r^2 V_r``, ``V_t = D_t D_t^T``, ``V_r = D_r D_r^T`` the blocks of the translation
   and rotation columns of D, ``P = W - W J (J^T W J)^-1 J^T W``, ``W = C^-1``, searched over the whole box
   :data:`THETA_BOUNDS` (log grid + bounded refinement: a global maximum, so no collapse to 0 and no runaway
   of a local Fisher-scoring fixed point); their covariance ``2 (tr(P V_i P V_j))^-1``;
4. never worse than a candidate: every candidate's cost under the final weights; when one is below
   ours (another local minimum), the iteration restarts from it and the lower cost is kept.

The result's covariance is the GLS one with the final weights (no variance factor here: the pipeline,
``experiment.handeye_step``, applies the adequacy test, the outlier test and the variance factor).
numpy/scipy only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike

from .. import frames
from ..errors import DataError
from .handeye_problem import (handeye_initial_guess, handeye_problem, reweighted, robot_pose_cov, transforms_from_x,
                              flange_error_map, x_from_transforms)
from .lse import solve_lse
from .problem import IdentificationProblem, IdentificationResult

#: name of the candidate start when the caller gives none (:func:`.handeye_problem.handeye_initial_guess`)
DEFAULT_CANDIDATE = "shah_numpy"
#: IRLS stops when no parameter moves by more than this fraction of its std
X_TOL_STD = 1e-3
#: ... and no estimated variance by more than this fraction of its std
THETA_TOL_STD = 1e-3


@dataclass(frozen=True)
class HandeyeFit:
    """Outcome of :func:`fit_handeye`. result: LSE result on ``problem`` (final weights); A, B (4, 4);
    robot: {source "given" | "estimated" | "none", translation_mm, rotation_deg (std per axis of the flange
    pose error), std_translation_mm, std_rotation_deg (of the estimate; None when given)}; closed_forms:
    the report's ``closed_form_comparison`` block (:func:`closed_form_comparison`); iterations: IRLS steps;
    candidates: the closed forms it started from (``fit_handeye``'s argument)."""

    result: IdentificationResult
    A: np.ndarray
    B: np.ndarray
    problem: IdentificationProblem
    robot: dict
    closed_forms: dict
    iterations: int
    candidates: dict


def default_candidates(T_base_flange: ArrayLike, T_cam_target: ArrayLike, mount: str) -> dict:
    """{:data:`DEFAULT_CANDIDATE`: (A, B) (4, 4) each, or the error message (str)}: the numpy closed form."""
    try:
        return {DEFAULT_CANDIDATE: handeye_initial_guess(T_base_flange, T_cam_target, mount)}
    except DataError as exc:
        return {DEFAULT_CANDIDATE: str(exc)}


def weighted_cost(problem: IdentificationProblem, x: ArrayLike) -> float:
    """0.5 sum_k |W_k r_k(x)|^2 with the problem's obs_cov (the LSE cost)."""
    rw = np.einsum("kij,kj->ki", problem.whitening(), np.asarray(problem.residual(np.asarray(x, float)), float))
    return 0.5 * float(np.sum(rw**2))


def _robot_cov(theta) -> np.ndarray:
    return robot_pose_cov(np.sqrt(max(theta[0], 0.0)), np.sqrt(max(theta[1], 0.0)))


#: bounds of the robot's estimated std per axis in the REML search: translation [m], rotation [rad] (the lower
#: ones stand for 0: far below any camera's resolution; the upper ones far above any robot's error)
THETA_BOUNDS = ((1e-7, 0.5), (1e-8, 0.5))


def _reml_terms(problem: IdentificationProblem, x):
    """(J (N, m, p) free columns, r (N, m), camera cov (N, m, m), V_t, V_r (N, m, m)) at x: what the REML
    likelihood of the robot's variances needs (module docstring)."""
    D = flange_error_map(problem, x)  # (N, 6, 6)
    free = problem.params.free
    J = np.asarray(problem.jacobian(x), float)[:, :, free]
    r = np.asarray(problem.residual(x), float)
    Vt = D[:, :, :3] @ np.swapaxes(D[:, :, :3], 1, 2)
    Vr = D[:, :, 3:] @ np.swapaxes(D[:, :, 3:], 1, 2)
    return J, r, np.asarray(problem.meta["camera_cov"], float), Vt, Vr


def _reml_negll(theta, J, r, cam, Vt, Vr) -> float:
    """-REML log-likelihood (up to a constant) of theta = (s_t^2, s_r^2) for the model linearised at x:
    0.5 (log|C| + log|J^T C^-1 J| + r^T P r), C = blockdiag(cam_k + s_t^2 Vt_k + s_r^2 Vr_k)."""
    C = cam + theta[0] * Vt + theta[1] * Vr
    try:
        L = np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        return np.inf
    Li = np.linalg.inv(L)
    Jw = Li @ J  # whitened (N, m, p)
    rw = np.einsum("kij,kj->ki", Li, r)
    A = np.einsum("kip,kiq->pq", Jw, Jw)
    g = np.einsum("kip,ki->p", Jw, rw)
    sign, logdetA = np.linalg.slogdet(A)
    if sign <= 0:
        return np.inf
    rPr = float(np.sum(rw**2) - g @ np.linalg.solve(A, g))
    return 0.5 * (2.0 * np.sum(np.log(np.diagonal(L, axis1=1, axis2=2))) + logdetA + rPr)


def _reml_step(problem: IdentificationProblem, result: IdentificationResult, start=None):
    """(theta (2,), cov (2, 2)): the robot's variances maximising the REML likelihood of the model linearised at
    the result's x (camera covariance known), searched over the whole box :data:`THETA_BOUNDS` (a log grid, then
    a bounded quasi-Newton refinement from its best point): the maximum is global on the box, so the estimate
    neither collapses to 0 nor runs away where the likelihood does not; its covariance is the inverse Fisher
    information 2 (tr(P V_i P V_j))^-1 at the maximum. A component at its lower bound is reported as 0. ``start``:
    variances (2,) near the maximum (e.g. the fit of a superset of the poses): a local refinement from there, no
    grid."""
    from scipy.optimize import minimize

    terms = _reml_terms(problem, result.identified)
    lo = np.log([b[0] ** 2 for b in THETA_BOUNDS])
    hi = np.log([b[1] ** 2 for b in THETA_BOUNDS])
    if start is not None:
        u0 = np.clip(np.log(np.maximum(np.asarray(start, float), 1e-300)), lo, hi)
        f0 = _reml_negll(np.exp(u0), *terms)
    else:
        grid = [np.linspace(lo[i], hi[i], 17) for i in range(2)]
        vals = np.array([[_reml_negll(np.exp([u, v]), *terms) for v in grid[1]] for u in grid[0]])
        i, j = np.unravel_index(np.argmin(vals), vals.shape)
        u0, f0 = np.array([grid[0][i], grid[1][j]]), vals[i, j]
    opt = minimize(lambda u: _reml_negll(np.exp(u), *terms), u0, method="L-BFGS-B", bounds=list(zip(lo, hi)))
    u = opt.x if np.isfinite(opt.fun) and opt.fun <= f0 else u0
    theta = np.exp(u)
    theta[u <= lo + 1e-6] = 0.0  # at the lower bound: no robot error visible along that component
    return theta, _theta_cov(problem, terms, theta)


def _theta_cov(problem, terms, theta) -> np.ndarray:
    """2 (tr(P V_i P V_j))^-1 over the robot's two variances at theta (pseudo-inverse: an unseen one is inf-free 0)."""
    J, r, cam, Vt, Vr = terms
    n_obs, m = r.shape
    C = cam + theta[0] * Vt + theta[1] * Vr
    Winv = np.linalg.inv(C)
    W = np.zeros((n_obs * m, n_obs * m))
    Vs = [np.zeros_like(W), np.zeros_like(W)]
    for k in range(n_obs):
        sl = slice(k * m, (k + 1) * m)
        W[sl, sl] = Winv[k]
        Vs[0][sl, sl], Vs[1][sl, sl] = Vt[k], Vr[k]
    Jf = J.reshape(n_obs * m, -1)
    WJ = W @ Jf
    P = W - WJ @ np.linalg.pinv(Jf.T @ WJ) @ WJ.T
    PV = [P @ V for V in Vs]
    T = np.array([[np.sum(PV[i] * PV[j].T) for j in range(2)] for i in range(2)])
    return 2.0 * np.linalg.pinv(T)


def _irls(base: IdentificationProblem, x0, theta, estimate: bool, max_iter: int = 50, theta_start=None):
    """(result, problem with the final weights, theta, theta cov or None, iterations) from x0; theta_start: the
    REML search's start (None: a global search over the box at the first step)."""
    x = np.asarray(x0, float)
    tcov = None
    pb = reweighted(base, x, _robot_cov(theta))
    res = solve_lse(pb, x)
    it = 1
    for it in range(1, max_iter + 1):
        t_old = theta.copy()
        if estimate:
            theta, tcov = _reml_step(pb, res, theta_start if it == 1 else theta)
        pb = reweighted(base, res.identified, _robot_cov(theta))
        new = solve_lse(pb, res.identified)
        free = np.asarray(new.free, bool)
        dx = np.abs(new.identified - res.identified)[free] / np.where(new.std[free] > 0, new.std[free], np.inf)
        tstd = np.sqrt(np.clip(np.diag(tcov), 0, None)) if tcov is not None else np.full(2, np.inf)
        dt = np.abs(theta - t_old) / np.where(tstd > 0, tstd, np.inf)
        res = new
        if np.all(dx < X_TOL_STD) and np.all(dt < THETA_TOL_STD):
            break
    return res, pb, theta, tcov, it


def closed_form_comparison(problem: IdentificationProblem, x: ArrayLike, candidates: dict, start: str | None) -> dict:
    """The report block: for each closed form its weighted cost under ``problem``'s weights (the final
    ones), that cost minus ours, and its distance to our solution (translation mm, rotation deg of A and B,
    ``frames.pose_error`` from ours to it); ``start``: the method the iteration started from."""
    A, B = transforms_from_x(problem, x)
    nA, nB = problem.meta["A_name"], problem.meta["B_name"]
    ours = weighted_cost(problem, x)
    methods = {}
    for m, v in candidates.items():
        if isinstance(v, str):
            methods[m] = {"error": v}
            continue
        xc = x_from_transforms(problem, *v)
        eA, eB = frames.pose_error(A, v[0]), frames.pose_error(B, v[1])
        c = weighted_cost(problem, xc)
        methods[m] = {"cost": c, "cost_minus_ours": c - ours,
                      "distance": {nA: {"translation_mm": 1e3 * float(np.linalg.norm(eA[:3])),
                                        "rotation_deg": float(np.degrees(np.linalg.norm(eA[3:])))},
                                   nB: {"translation_mm": 1e3 * float(np.linalg.norm(eB[:3])),
                                        "rotation_deg": float(np.degrees(np.linalg.norm(eB[3:])))}}}
    return {"cost": "0.5 sum of squared whitened residuals, weights of the final fit (camera + robot pose error)",
            "ours": ours, "start": start, "methods": methods}


def fit_handeye(T_base_flange: ArrayLike, T_cam_target: ArrayLike, mount: str, pose_cov: ArrayLike,
                labels: Sequence[str] | None = None, robot_std: tuple[float, float] | None = None,
                estimate_robot: bool = True, candidates: dict | None = None, theta_start=None) -> HandeyeFit:
    """Hand-eye fit with the robot's pose error (module docstring).

    T_base_flange (N, 4, 4) reported flange poses [m]; T_cam_target (N, 4, 4) measured; pose_cov (N, 6, 6)
    their covariance [m, rad] (``PoseMeasurement.cov``); labels (N,). robot_std: (translation m, rotation
    rad) std per axis of the flange pose error, given (e.g. recording.yaml ``robot_pose_std``); None ->
    estimated from the data when ``estimate_robot`` (REML, camera covariance known), else 0 (exact flange
    poses). candidates: {name: (A, B) (4, 4) each, or an error message (str)}, the closed forms of these poses
    to start from and compare with (e.g. ``measure.handeye.closed_forms``); None -> :func:`default_candidates`.
    theta_start: (s_t^2 [m^2], s_r^2 [rad^2]) near the estimate (e.g. of a superset of these poses): the REML
    search refines locally from there instead of searching the whole box. DataError when no candidate is a
    solution (degenerate motions)."""
    F = np.asarray(T_base_flange, float)
    M = np.asarray(T_cam_target, float)
    cands = default_candidates(F, M, mount) if candidates is None else dict(candidates)
    ok = {m: v for m, v in cands.items() if not isinstance(v, str)}
    if not ok:
        raise DataError("no closed-form hand-eye solution (" + "; ".join(f"{m}: {v}" for m, v in cands.items())
                        + ")")
    estimate = robot_std is None and estimate_robot
    theta = np.zeros(2) if robot_std is None else np.array([float(robot_std[0]) ** 2, float(robot_std[1]) ** 2])
    first = next(iter(ok.values()))
    base = handeye_problem(F, M, mount, first[0], first[1], pose_cov, labels=labels, robot_cov=_robot_cov(theta))

    def cost_at(v):  # weights at the candidate itself
        xc = x_from_transforms(base, *v)
        return weighted_cost(reweighted(base, xc, _robot_cov(theta)), xc)

    start = min(ok, key=lambda m: cost_at(ok[m]))
    res, pb, th, tcov, its = _irls(base, x_from_transforms(base, *ok[start]), theta, estimate, theta_start=theta_start)
    # never worse than a closed form under the final weights: restart from one that is lower
    costs = {m: weighted_cost(pb, x_from_transforms(pb, *v)) for m, v in ok.items()}
    best = min(costs, key=costs.get)
    if costs[best] < res.cost_final * (1 - 1e-9):
        r2 = _irls(base, x_from_transforms(base, *ok[best]), theta, estimate, theta_start=theta_start)
        if r2[0].cost_final < res.cost_final:
            res, pb, th, tcov, its = r2
            start = best
    A, B = transforms_from_x(pb, res.identified)
    robot = {"source": "estimated" if estimate else ("given" if robot_std is not None else "none"),
             "translation_mm": 1e3 * float(np.sqrt(th[0])), "rotation_deg": float(np.degrees(np.sqrt(th[1]))),
             "std_translation_mm": None, "std_rotation_deg": None}
    if estimate and tcov is not None:  # delta method: std(s) = std(s^2) / (2 s), large when s ~ 0
        sd = np.sqrt(np.clip(np.diag(tcov), 0, None))
        s = np.sqrt(th)
        ss = np.where(s > 0, sd / (2 * np.maximum(s, 1e-300)), np.sqrt(sd))
        robot.update(std_translation_mm=1e3 * float(ss[0]), std_rotation_deg=float(np.degrees(ss[1])),
                     method="REML (maximum over a box) with the camera covariance known")
    return HandeyeFit(res, A, B, pb, robot, closed_form_comparison(pb, res.identified, cands, start), its,
                      cands)


def deletion_fit(T_base_flange: ArrayLike, T_cam_target: ArrayLike, mount: str, pose_cov: ArrayLike,
                 labels: Sequence[str], A: np.ndarray, B: np.ndarray, theta: ArrayLike, estimate: bool):
    """The fit of a subset of the poses near a fit of all of them (A, B (4, 4), robot variances ``theta`` =
    (s_t^2 [m^2], s_r^2 [rad^2])): the variances re-estimated on the subset (REML refined locally from
    ``theta``) when ``estimate``, then the least squares with those weights from (A, B). Returns (problem with
    the final weights, result, theta (2,)); for the deletion test (``experiment.handeye_step``)."""
    theta = np.asarray(theta, float)
    base = handeye_problem(T_base_flange, T_cam_target, mount, A, B, pose_cov, labels=labels,
                           robot_cov=_robot_cov(theta))
    x = x_from_transforms(base, A, B)
    pb = reweighted(base, x, _robot_cov(theta))
    res = solve_lse(pb, x)
    if estimate:
        theta, _ = _reml_step(pb, res, start=theta)
        pb = reweighted(base, res.identified, _robot_cov(theta))
        res = solve_lse(pb, res.identified)
    return pb, res, theta


__all__ = ["HandeyeFit", "deletion_fit", "DEFAULT_CANDIDATE", "default_candidates", "closed_form_comparison", "fit_handeye",
           "weighted_cost"]
