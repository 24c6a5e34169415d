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
   ``theta = (s_t^2, s_r^2)`` are estimated at each step with the camera covariance known: REML of the
   model linearised at x (Fisher scoring, the fixed point of ``sum_j tr(P V_i P V_j) theta_j =
   r^T W V_i W r - tr(P V_i P V_cam)``, ``V_t = D_t D_t^T``, ``V_r = D_r D_r^T`` the blocks of the
   translation and rotation columns of D, ``W = C^-1``, ``P = W - W J (J^T W J)^-1 J^T W``; a negative value
   is set to 0); their covariance ``2 (tr(P V_i P V_j))^-1``;
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


def _reml_step(problem: IdentificationProblem, result: IdentificationResult):
    """(theta (2,), cov (2, 2)): one REML Fisher-scoring step for the robot's variances (module docstring) at
    the result's x, with the problem's current weights; a component the data do not see (tr ~ 0) stays 0."""
    x = result.identified
    D = flange_error_map(problem, x)  # (N, 6, 6)
    n_obs, m = problem.n_obs, problem.m
    free = np.asarray(result.free, bool)
    J = np.asarray(problem.jacobian(x), float)[:, :, free].reshape(n_obs * m, -1)
    r = np.asarray(problem.residual(x), float).reshape(-1)
    W = np.zeros((n_obs * m, n_obs * m))
    Vs = [np.zeros_like(W) for _ in range(3)]
    blocks = (problem.meta["camera_cov"], D[:, :, :3] @ np.swapaxes(D[:, :, :3], 1, 2),
              D[:, :, 3:] @ np.swapaxes(D[:, :, 3:], 1, 2))
    Winv = np.linalg.inv(problem.obs_cov)
    for k in range(n_obs):
        sl = slice(k * m, (k + 1) * m)
        W[sl, sl] = Winv[k]
        for V, b in zip(Vs, blocks):
            V[sl, sl] = b[k]
    WJ = W @ J
    P = W - WJ @ np.linalg.pinv(J.T @ WJ) @ WJ.T
    PV = [P @ V for V in Vs]
    T = np.array([[np.sum(PV[i] * PV[j].T) for j in range(3)] for i in range(3)])
    Wr = W @ r
    q = np.array([Wr @ V @ Wr for V in Vs])
    Ti, rhs = T[1:, 1:], q[1:] - T[1:, 0]
    theta = np.zeros(2)
    seen = np.diag(Ti) > 1e-12 * max(np.max(np.abs(Ti)), 1e-300)
    for _ in range(3):  # solve, then drop a component that comes out negative (boundary of theta >= 0)
        if not seen.any():
            break
        idx = np.flatnonzero(seen)
        sol = np.linalg.solve(Ti[np.ix_(idx, idx)], rhs[idx])
        theta[:] = 0.0
        theta[idx] = sol
        if np.all(sol >= 0):
            break
        seen[idx[sol < 0]] = False
    theta = np.maximum(theta, 0.0)
    cov = 2.0 * np.linalg.pinv(Ti)
    return theta, cov


def _irls(base: IdentificationProblem, x0, theta, estimate: bool, max_iter: int = 50):
    """(result, problem with the final weights, theta, theta cov or None, iterations) from x0."""
    x = np.asarray(x0, float)
    tcov = None
    pb = reweighted(base, x, _robot_cov(theta))
    res = solve_lse(pb, x)
    it = 1
    for it in range(1, max_iter + 1):
        t_old = theta.copy()
        if estimate:
            theta, tcov = _reml_step(pb, res)
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
                estimate_robot: bool = True, candidates: dict | None = None) -> HandeyeFit:
    """Hand-eye fit with the robot's pose error (module docstring).

    T_base_flange (N, 4, 4) reported flange poses [m]; T_cam_target (N, 4, 4) measured; pose_cov (N, 6, 6)
    their covariance [m, rad] (``PoseMeasurement.cov``); labels (N,). robot_std: (translation m, rotation
    rad) std per axis of the flange pose error, given (e.g. recording.yaml ``robot_pose_std``); None ->
    estimated from the data when ``estimate_robot`` (REML, camera covariance known), else 0 (exact flange
    poses). candidates: {name: (A, B) (4, 4) each, or an error message (str)}, the closed forms of these poses
    to start from and compare with (e.g. ``measure.handeye.closed_forms``); None -> :func:`default_candidates`.
    DataError when no candidate is a solution (degenerate motions)."""
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
    res, pb, th, tcov, its = _irls(base, x_from_transforms(base, *ok[start]), theta, estimate)
    # never worse than a closed form under the final weights: restart from one that is lower
    costs = {m: weighted_cost(pb, x_from_transforms(pb, *v)) for m, v in ok.items()}
    best = min(costs, key=costs.get)
    if costs[best] < res.cost_final * (1 - 1e-9):
        r2 = _irls(base, x_from_transforms(base, *ok[best]), theta, estimate)
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
                     method="REML (Fisher scoring) with the camera covariance known")
    return HandeyeFit(res, A, B, pb, robot, closed_form_comparison(pb, res.identified, cands, start), its,
                      cands)


__all__ = ["HandeyeFit", "DEFAULT_CANDIDATE", "default_candidates", "closed_form_comparison", "fit_handeye",
           "weighted_cost"]
