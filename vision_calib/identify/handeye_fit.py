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
   and rotation columns of D, ``P = W - W J (J^T W J)^-1 J^T W``, ``W = C^-1``, penalised by the
   boundary-avoiding prior ``log s_t + log s_r`` (Chung et al. 2013: where the data resolve the robot's error the
   prior is negligible; where they do not, the estimate stays about one standard error above 0 instead of
   collapsing onto it), searched over the whole box :data:`THETA_BOUNDS` (log grid + bounded refinement: a global
   maximum, no runaway of a local Fisher-scoring fixed point); their covariance ``2 (tr(P V_i P V_j))^-1``;
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
from .handeye_problem import (flange_error_map, handeye_initial_guess, handeye_problem, model_many, reweighted,
                              robot_blocks, robot_pose_cov, robot_weighted_cov, transforms_from_x, x_from_transforms)
from .lse import solve_lse
from .problem import IdentificationProblem, IdentificationResult, whitening_of
from .reml import reml_max, reml_variance_cov

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
    candidates: the closed forms it started from (``fit_handeye``'s argument); noise: the measured poses' noise
    when estimated ({source "estimated", frame, translation_mm (3,), rotation_deg (3,) std per axis, their
    std_*}), else None (``pose_cov`` given)."""

    result: IdentificationResult
    A: np.ndarray
    B: np.ndarray
    problem: IdentificationProblem
    robot: dict
    closed_forms: dict
    iterations: int
    candidates: dict
    noise: dict | None = None

    @property
    def robot_variances(self) -> np.ndarray:
        """(2,) the variances (s_t^2 [m^2], s_r^2 [rad^2]) per axis of the robot's pose error (given or estimated)."""
        return np.square([1e-3 * self.robot["translation_mm"], np.radians(self.robot["rotation_deg"])])


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


def candidate_costs(problem: IdentificationProblem, X: ArrayLike, robot_cov: ArrayLike | None = None,
                    mask: ArrayLike | None = None, W: ArrayLike | None = None) -> np.ndarray:
    """(K,) :func:`weighted_cost` at each row of X (K, 12) of a hand-eye problem, all rows in one batched evaluation
    (``handeye_problem.model_many``): with the problem's own weights, or the whitening ``W`` (K or 1, N, 6, 6), or,
    given ``robot_cov`` (6, 6), with the weights at each row itself (camera + robot pose error there,
    :func:`.handeye_problem.reweighted`). mask (K or 1, N) bool: each row's cost over those poses only."""
    X = np.asarray(X, float).reshape(-1, 12)
    r, _, D = model_many(problem, X, flange_map=robot_cov is not None, jacobian=False)
    if robot_cov is not None:
        W = whitening_of(robot_weighted_cov(np.asarray(problem.meta["camera_cov"], float)[None], D, robot_cov))
    W = problem.whitening()[None] if W is None else np.asarray(W, float)
    rw = (W @ r[..., None])[..., 0]
    if mask is not None:
        rw = rw * np.asarray(mask, bool)[..., None]
    return 0.5 * np.einsum("kni,kni->k", rw, rw)


def _robot_cov(theta) -> np.ndarray:
    return robot_pose_cov(np.sqrt(max(theta[0], 0.0)), np.sqrt(max(theta[1], 0.0)))


#: bounds of the robot's estimated std per axis in the REML search: translation [m], rotation [rad] (the lower
#: ones stand for 0: far below any camera's resolution; the upper ones far above any robot's error)
THETA_BOUNDS = ((1e-7, 0.5), (1e-8, 0.5))


def _reml_terms(problem: IdentificationProblem, x):
    """(J (N, m, p) free columns, r (N, m), camera cov (N, m, m), V_t, V_r (N, m, m)) at x: what the REML
    likelihood of the robot's variances needs (module docstring)."""
    free = problem.params.free
    J = np.asarray(problem.jacobian(x), float)[:, :, free]
    r = np.asarray(problem.residual(x), float)
    return (J, r, np.asarray(problem.meta["camera_cov"], float), *_robot_blocks(problem, x))


def _reml_step(problem: IdentificationProblem, result: IdentificationResult, start=None, covariance: bool = True):
    """(theta (2,), cov (2, 2) or None when not ``covariance``): the robot's variances maximising the penalised
    REML likelihood (``reml.reml_negll``) of the model linearised at the result's x (camera covariance known),
    searched over the whole box :data:`THETA_BOUNDS` (``reml.reml_max``: a log grid, then a projected Newton
    refinement from its best point): the maximum is global on the box, so the estimate neither runs away nor, with
    the boundary-avoiding prior, collapses to 0; its covariance is the inverse Fisher information
    2 (tr(P V_i P V_j))^-1 at the maximum. ``start``: variances (2,) near the maximum (e.g. the fit of a superset
    of the poses): a local refinement from there, no grid. ``result``: an IdentificationResult or the x (12,)."""
    x = getattr(result, "identified", result)
    J, r, cam, Vt, Vr = _reml_terms(problem, x)
    theta = reml_max(J, r, cam, np.stack([Vt, Vr]), THETA_BOUNDS, start)
    return theta, reml_variance_cov(J, cam, np.stack([Vt, Vr]), theta) if covariance else None


#: Gauss-Newton refits (:func:`gauss_newton_refit`) stop when no free parameter moves by more than this fraction of
#: its std
GN_TOL_STD = 1e-9


def gauss_newton_refit(problem: IdentificationProblem, x: ArrayLike, max_iter: int = 8,
                       with_cov: bool = False):
    """x (n,) at the minimum of ``problem``'s weighted cost by undamped Gauss-Newton steps from a nearby x (e.g. a
    fit of a superset of its poses, or of the same poses under nearby weights), on its free parameters; with_cov:
    (x, covariance (n_free, n_free) of the free parameters, (J^T W J)^-1 at the last step, as
    :func:`.lse.solve_lse` gives it). None when a step is singular, raises the cost, or the steps do not settle
    (no free parameter moving by more than :data:`GN_TOL_STD` of its std) within ``max_iter``: the caller then
    runs :func:`.lse.solve_lse`."""
    free = np.asarray(problem.params.free, bool)
    W = problem.whitening()
    x = np.array(x, float)
    cost = np.inf
    for _ in range(max_iter):
        rw = np.einsum("kij,kj->ki", W, np.asarray(problem.residual(x), float)).ravel()
        c = float(rw @ rw)
        if not np.isfinite(c) or c > cost * (1 + 1e-12) + 1e-300:
            return None
        cost = c
        Jw = (W @ np.asarray(problem.jacobian(x), float)[:, :, free]).reshape(len(rw), -1)
        try:
            Li = np.linalg.inv(np.linalg.cholesky(Jw.T @ Jw))
        except np.linalg.LinAlgError:
            return None
        dx = -(Li.T @ (Li @ (Jw.T @ rw)))
        x[free] += dx
        std = np.sqrt(np.sum(Li**2, axis=0))  # sqrt(diag(A^-1)), A = J^T W J = L L^T
        if np.all(np.abs(dx) <= GN_TOL_STD * std):
            return (x, Li.T @ Li) if with_cov else x
    return None


@dataclass(frozen=True)
class Refit:
    """A fit by :func:`gauss_newton_refit`: identified (n,), covariance (n_free, n_free) of the free parameters,
    free (n,) bool, std (n,) (0 where fixed): the fields of an IdentificationResult the deletion test reads."""

    identified: np.ndarray
    covariance: np.ndarray
    free: np.ndarray
    std: np.ndarray


def _robot_blocks(problem: IdentificationProblem, x) -> tuple[np.ndarray, np.ndarray]:
    """(V_t, V_r) (N, 6, 6): the residual covariance per unit variance of the flange's translation and rotation
    error per axis at x (``D_t D_t^T``, ``D_r D_r^T`` of :func:`.handeye_problem.flange_error_map`)."""
    return robot_blocks(flange_error_map(problem, x))


def _irls(base: IdentificationProblem, x0, theta, estimate: bool, max_iter: int = 50, theta_start=None):
    """(result, problem with the final weights, theta, theta cov or None, iterations) from x0; theta_start: the
    REML search's start (None: a global search over the box at the first step). The first fit and the last are
    :func:`.lse.solve_lse`; the minimum under each step's new weights is found by :func:`gauss_newton_refit` from
    the last one (an LSE where it does not settle)."""
    x = np.asarray(x0, float)
    tcov = None
    pb = reweighted(base, x, _robot_cov(theta))
    res = solve_lse(pb, x)
    x, free = res.identified, np.asarray(res.free, bool)
    it = 1
    for it in range(1, max_iter + 1):
        t_old = theta.copy()
        if estimate:
            theta, tcov = _reml_step(pb, x, theta_start if it == 1 else theta)
        pb = reweighted(base, x, _robot_cov(theta))
        gn = gauss_newton_refit(pb, x, with_cov=True) if free.all() else None
        if gn is None:
            res = solve_lse(pb, x)
            new, std, free = res.identified, res.std, np.asarray(res.free, bool)
        else:
            res = None
            new, std = gn[0], np.sqrt(np.diag(gn[1]))
        dx = np.abs(new - x)[free] / np.where(std[free] > 0, std[free], np.inf)
        tstd = np.sqrt(np.clip(np.diag(tcov), 0, None)) if tcov is not None else np.full(2, np.inf)
        dt = np.abs(theta - t_old) / np.where(tstd > 0, tstd, np.inf)
        x = new
        if np.all(dx < X_TOL_STD) and np.all(dt < THETA_TOL_STD):
            break
    return (solve_lse(pb, x) if res is None else res), pb, theta, tcov, it


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


def fit_handeye(T_base_flange: ArrayLike, T_cam_target: ArrayLike, mount: str, pose_cov: ArrayLike | None,
                labels: Sequence[str] | None = None, robot_std: tuple[float, float] | None = None,
                estimate_robot: bool = True, candidates: dict | None = None, theta_start=None,
                noise_frame: str | None = None, compare: bool = True) -> HandeyeFit:
    """Hand-eye fit with the robot's pose error (module docstring).

    T_base_flange (N, 4, 4) reported flange poses [m]; T_cam_target (N, 4, 4) measured; pose_cov (N, 6, 6)
    their covariance [m, rad] (``PoseMeasurement.cov``); labels (N,). robot_std: (translation m, rotation
    rad) std per axis of the flange pose error, given (e.g. recording.yaml ``robot_pose_std``); None ->
    estimated from the data when ``estimate_robot`` (REML, camera covariance known), else 0 (exact flange
    poses). candidates: {name: (A, B) (4, 4) each, or an error message (str)}, the closed forms of these poses
    to start from and compare with (e.g. ``measure.handeye.closed_forms``); None -> :func:`default_candidates`.
    theta_start: (s_t^2 [m^2], s_r^2 [rad^2]) near the estimate (e.g. of a superset of these poses): the REML
    search refines locally from there instead of searching the whole box.
    noise_frame: None (the measured poses' covariance is ``pose_cov``), or "target" | "camera": their noise is
    not known and its std per axis (3 translations, 3 rotations) in that frame is estimated with the robot's
    (:func:`fit_estimated_noise`; ``pose_cov`` is not used).
    compare: False when the caller reads only which closed form the fit started from (the held-out folds):
    ``closed_forms`` is then {"start": name}, the comparison block not computed.
    DataError when no candidate is a solution (degenerate motions)."""
    F = np.asarray(T_base_flange, float)
    M = np.asarray(T_cam_target, float)
    cands = default_candidates(F, M, mount) if candidates is None else dict(candidates)
    ok = {m: v for m, v in cands.items() if not isinstance(v, str)}
    if not ok:
        raise DataError("no closed-form hand-eye solution (" + "; ".join(f"{m}: {v}" for m, v in cands.items())
                        + ")")
    if noise_frame is not None:
        return fit_estimated_noise(F, M, mount, labels, robot_std, estimate_robot, cands, noise_frame)
    if pose_cov is None:
        raise DataError("fit_handeye: give pose_cov (the measured poses' covariance), or noise_frame to estimate it")
    estimate = robot_std is None and estimate_robot
    theta = np.zeros(2) if robot_std is None else np.array([float(robot_std[0]) ** 2, float(robot_std[1]) ** 2])
    first = next(iter(ok.values()))
    base = handeye_problem(F, M, mount, first[0], first[1], pose_cov, labels=labels, robot_cov=_robot_cov(theta))

    names = list(ok)
    AB = np.array([ok[m] for m in names])  # (k, 2, 4, 4)
    Xc = x_from_transforms(base, AB[:, 0], AB[:, 1])  # (pb below shares base's parametrization)
    start = names[int(np.argmin(candidate_costs(base, Xc, _robot_cov(theta))))]  # weights at each candidate
    res, pb, th, tcov, its = _irls(base, Xc[names.index(start)], theta, estimate, theta_start=theta_start)
    # never worse than a closed form under the final weights: restart from one that is lower
    costs = dict(zip(names, candidate_costs(pb, Xc)))
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
    cf = closed_form_comparison(pb, res.identified, cands, start) if compare else {"start": start}
    return HandeyeFit(res, A, B, pb, robot, cf, its,
                      cands)


def deletion_fit(T_base_flange: ArrayLike, T_cam_target: ArrayLike, mount: str, pose_cov: ArrayLike,
                 labels: Sequence[str], A: np.ndarray, B: np.ndarray, theta: ArrayLike, estimate: bool):
    """The fit of a subset of the poses near a fit of all of them (A, B (4, 4), robot variances ``theta`` =
    (s_t^2 [m^2], s_r^2 [rad^2])): the variances re-estimated on the subset (REML refined locally from
    ``theta``) when ``estimate``, then the least squares with those weights from (A, B) (Gauss-Newton from there:
    the minimum is near). Returns (problem with the final weights, result: a :class:`Refit`, or the
    IdentificationResult of :func:`.lse.solve_lse` where Gauss-Newton does not settle or a parameter is fixed,
    theta (2,)); for the deletion test (``experiment.handeye_step``)."""
    theta = np.asarray(theta, float)
    pb = handeye_problem(T_base_flange, T_cam_target, mount, A, B, pose_cov, labels=labels,
                         robot_cov=_robot_cov(theta))  # weights at (A, B)
    x = x_from_transforms(pb, A, B)
    if estimate:  # the subset's minimum under these weights: Gauss-Newton from the fit of all (LSE if it fails)
        xs = gauss_newton_refit(pb, x)
        xs = solve_lse(pb, x).identified if xs is None else xs
        theta, _ = _reml_step(pb, xs, start=theta, covariance=False)
        pb = reweighted(pb, xs, _robot_cov(theta))
        x = xs
    free = np.asarray(pb.params.free, bool)
    gn = gauss_newton_refit(pb, x, with_cov=True) if free.all() else None
    if gn is None:
        return pb, solve_lse(pb, x), theta
    return pb, Refit(gn[0], gn[1], free, np.sqrt(np.diag(gn[1]))), theta


# ----------------------------------------------------------------------- measured poses of unknown noise
#: frames in which the measured poses' per-axis noise is estimated: the target's axes (a single tag: tilt about its
#: in-plane x, y and depth along its z are the noisy ones) or the camera's
NOISE_FRAMES = ("target", "camera")
#: an estimated per-axis variance is kept at least this fraction of the largest of its kind (the weights stay finite)
NOISE_FLOOR_REL = 1e-6
#: ... and at least this [m^2 for translations, rad^2 for rotations]
NOISE_FLOOR_ABS = 1e-14
#: bounds of the measured poses' estimated std per axis in the REML search: translation x, y, z [m], rotation x, y,
#: z [rad] (as :data:`THETA_BOUNDS`)
NOISE_BOUNDS = 3 * (THETA_BOUNDS[0],) + 3 * (THETA_BOUNDS[1],)
ROBOT_TRANSLATION_NOT_SEPARABLE = (
    "not separable from the measured poses' translation noise: an isotropic flange translation error is an "
    "isotropic error of the measured translation, whatever its frame; it is part of their estimated std")


def measured_noise_blocks(T_cam_target: ArrayLike, frame: str) -> np.ndarray:
    """(6, N, 6, 6): the covariance of each measured pose's error (``frames.pose_error`` convention, camera frame)
    for a unit variance of one axis of its error in ``frame`` ("target": the axes of R_cam_target; "camera"):
    ``b b^T`` with b the axis' column of blockdiag(R, R). Axes: x, y, z translation, then rotation."""
    T = np.asarray(T_cam_target, float)
    if frame not in NOISE_FRAMES:
        raise DataError(f"noise frame must be one of {', '.join(NOISE_FRAMES)}, got {frame!r}")
    R = T[:, :3, :3] if frame == "target" else np.broadcast_to(np.eye(3), (T.shape[0], 3, 3))
    Bk = np.zeros((T.shape[0], 6, 6))
    Bk[:, :3, :3] = R
    Bk[:, 3:, 3:] = R
    return np.einsum("nai,nbi->inab", Bk, Bk)


def _floored(theta_cam: np.ndarray) -> np.ndarray:
    """Per-axis variances (6,) with the floors (:data:`NOISE_FLOOR_REL`, :data:`NOISE_FLOOR_ABS`) per kind."""
    out = np.array(theta_cam, float)
    for sl in (slice(0, 3), slice(3, 6)):
        out[sl] = np.maximum(out[sl], max(NOISE_FLOOR_REL * float(np.max(out[sl])), NOISE_FLOOR_ABS))
    return out


def _noise_weights(base: IdentificationProblem, x, Vc: np.ndarray, theta_cam, robot_cov) -> IdentificationProblem:
    """The problem with obs_cov = sum_i theta_cam_i Vc_i + D robot_cov D^T at x."""
    import dataclasses

    cam = np.einsum("i,inab->nab", np.asarray(theta_cam, float), Vc)
    pb = dataclasses.replace(base, obs_cov=cam, meta={**base.meta, "camera_cov": cam})
    return reweighted(pb, x, robot_cov)


def _noise_irls(base, x0, Vc, theta_cam, s_robot, est_robot: bool, max_iter: int = 50):
    """(result, problem with the final weights, theta_cam (6,), robot variances (2,), theta cov or None,
    iterations): IRLS with REML of the 6 per-axis variances (and the robot's rotation variance when est_robot;
    its translation is then 0: :data:`ROBOT_TRANSLATION_NOT_SEPARABLE`), the robot's given variances s_robot (2,)
    otherwise known."""
    x = np.asarray(x0, float)
    th_c, th_r = _floored(theta_cam), np.array(s_robot, float)
    pb = _noise_weights(base, x, Vc, th_c, _robot_cov(th_r))
    res = solve_lse(pb, x)
    tcov, it = None, 1
    for it in range(1, max_iter + 1):
        old = np.r_[th_c, th_r[1]]
        Vt, Vr = _robot_blocks(pb, res.identified)
        free = np.asarray(res.free, bool)
        J = np.asarray(pb.jacobian(res.identified), float)[:, :, free]
        r = np.asarray(pb.residual(res.identified), float)
        if est_robot:
            blocks, known = np.stack([*Vc, Vr]), np.zeros_like(Vr)
            th = reml_max(J, r, known, blocks, NOISE_BOUNDS + (THETA_BOUNDS[1],), np.r_[th_c, th_r[1]],
                           grid_axes=[6] if it == 1 else None)
            th_c, th_r = _floored(th[:6]), np.array([0.0, th[6]])
        else:
            blocks, known = np.stack(list(Vc)), th_r[0] * Vt + th_r[1] * Vr
            th = reml_max(J, r, known, blocks, NOISE_BOUNDS, th_c)
            th_c = _floored(th)
        tcov = reml_variance_cov(J, known, blocks, th)
        pb = _noise_weights(base, res.identified, Vc, th_c, _robot_cov(th_r))
        new = solve_lse(pb, res.identified)
        free = np.asarray(new.free, bool)
        dx = np.abs(new.identified - res.identified)[free] / np.where(new.std[free] > 0, new.std[free], np.inf)
        tstd = np.sqrt(np.clip(np.diag(tcov), 0, None))
        now = np.r_[th_c, th_r[1]][:len(tstd)]
        dt = np.abs(now - old[:len(tstd)]) / np.where(tstd > 0, tstd, np.inf)
        res = new
        if np.all(dx < X_TOL_STD) and np.all(dt < THETA_TOL_STD):
            break
    return res, pb, th_c, th_r, tcov, it


def _std_of_std(var: np.ndarray, var_cov_diag: np.ndarray) -> np.ndarray:
    """Delta method: std(s) = std(s^2) / (2 s) (sqrt(std(s^2)) where s ~ 0)."""
    sd = np.sqrt(np.clip(var_cov_diag, 0, None))
    s = np.sqrt(np.clip(var, 0, None))
    return np.where(s > 0, sd / (2 * np.maximum(s, 1e-300)), np.sqrt(sd))


def fit_estimated_noise(T_base_flange: np.ndarray, T_cam_target: np.ndarray, mount: str, labels, robot_std,
                        estimate_robot: bool, candidates: dict, frame: str) -> HandeyeFit:
    """:func:`fit_handeye` when the measured poses' noise is not known (pose pairs from a tracker or a tag
    detector: a single AR tag's pose is far noisier in depth and in tilt about its in-plane axes than in-plane).

    Their error is modelled per axis of ``frame`` (:func:`measured_noise_blocks`): 6 variances (translation x, y,
    z [m^2], rotation x, y, z [rad^2]) estimated by REML with the robot's rotation variance (the robot's
    translation variance is confounded with them: :data:`ROBOT_TRANSLATION_NOT_SEPARABLE`), or with the robot's
    given std known. Start: each axis' mean squared residual at the closed forms (the smallest over them), the
    candidate of least cost under those weights; then as :func:`fit_handeye` (IRLS, never worse than a closed form
    under the final weights)."""
    F, M = T_base_flange, T_cam_target
    ok = {m: v for m, v in candidates.items() if not isinstance(v, str)}
    Vc = measured_noise_blocks(M, frame)
    R = M[:, :3, :3] if frame == "target" else np.broadcast_to(np.eye(3), (M.shape[0], 3, 3))
    first = next(iter(ok.values()))
    probe = handeye_problem(F, M, mount, first[0], first[1], None, sigma_t_m=1e-3, sigma_rot_rad=1e-3, labels=labels)

    def axis_ms(v):  # mean squared residual per axis of the frame at a candidate
        r = np.asarray(probe.residual(x_from_transforms(probe, *v)), float)
        e = np.concatenate([np.einsum("nji,nj->ni", R, r[:, :3]), np.einsum("nji,nj->ni", R, r[:, 3:])], axis=1)
        return np.mean(e**2, axis=0)

    theta0 = _floored(np.min([axis_ms(v) for v in ok.values()], axis=0))
    s_robot = np.zeros(2) if robot_std is None else np.array([float(robot_std[0]) ** 2, float(robot_std[1]) ** 2])
    est_robot = robot_std is None and estimate_robot
    base = handeye_problem(F, M, mount, first[0], first[1], np.einsum("i,inab->nab", theta0, Vc), labels=labels)

    def cost_at(v):
        xc = x_from_transforms(base, *v)
        return weighted_cost(_noise_weights(base, xc, Vc, theta0, _robot_cov(s_robot)), xc)

    start = min(ok, key=lambda m: cost_at(ok[m]))
    out = _noise_irls(base, x_from_transforms(base, *ok[start]), Vc, theta0, s_robot, est_robot)
    pb = out[1]
    costs = {m: weighted_cost(pb, x_from_transforms(pb, *v)) for m, v in ok.items()}
    best = min(costs, key=costs.get)
    if costs[best] < out[0].cost_final * (1 - 1e-9):
        o2 = _noise_irls(base, x_from_transforms(base, *ok[best]), Vc, theta0, s_robot, est_robot)
        if o2[0].cost_final < out[0].cost_final:
            out, start = o2, best
    res, pb, th_c, th_r, tcov, its = out
    A, B = transforms_from_x(pb, res.identified)
    dg = np.diag(tcov) if tcov is not None else np.full(7, np.nan)
    sc = _std_of_std(th_c, dg[:6])
    noise = {"source": "estimated", "frame": frame,
             "method": "penalised REML (boundary-avoiding prior) of the variance per axis of the measured poses' error"
                       + (", with the robot's rotation variance" if est_robot else ", the robot's std given"),
             "translation_mm": (1e3 * np.sqrt(th_c[:3])).tolist(),
             "rotation_deg": np.degrees(np.sqrt(th_c[3:])).tolist(),
             "std_translation_mm": (1e3 * sc[:3]).tolist(), "std_rotation_deg": np.degrees(sc[3:]).tolist()}
    if est_robot:
        sr = _std_of_std(th_r[1:], dg[6:7])
        robot = {"source": "estimated", "translation_mm": None, "rotation_deg": float(np.degrees(np.sqrt(th_r[1]))),
                 "std_translation_mm": None, "std_rotation_deg": float(np.degrees(sr[0])),
                 "translation": ROBOT_TRANSLATION_NOT_SEPARABLE,
                 "method": "penalised REML (boundary-avoiding prior) with the measured poses' per-axis variances"}
    else:
        robot = {"source": "given" if robot_std is not None else "none",
                 "translation_mm": 1e3 * float(np.sqrt(s_robot[0])),
                 "rotation_deg": float(np.degrees(np.sqrt(s_robot[1]))),
                 "std_translation_mm": None, "std_rotation_deg": None}
    return HandeyeFit(res, A, B, pb, robot, closed_form_comparison(pb, res.identified, candidates, start), its,
                      candidates, noise)


__all__ = ["HandeyeFit", "deletion_fit", "DEFAULT_CANDIDATE", "NOISE_FRAMES", "default_candidates", "closed_form_comparison",
           "gauss_newton_refit", "Refit", "candidate_costs", "fit_handeye", "fit_estimated_noise", "measured_noise_blocks", "weighted_cost"]
