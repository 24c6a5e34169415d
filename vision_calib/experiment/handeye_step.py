"""Hand-eye identification from measured data (flange poses known): the same steps as the robot-chain path
(:func:`.steps.identify_measurements`) on :func:`vision_calib.identify.handeye_fit.fit_handeye`:

0. the motion check (``checks.handeye_motions``): fewer than 3 distinct flange poses, or motions that do not
   rotate about two non-parallel axes, are a DataError naming the degenerate motion, never a model;
1. the fit with the robot's pose error in the weights (given std, or estimated), started from the best of
   OpenCV's closed forms (``measure.handeye.closed_forms``, passed to ``fit_handeye`` as its candidates);
2. with redundancy (at least twice as many equations as parameters), the deletion outlier test
   (:func:`deletion_test`: each pose against the fit without it, the robot's pose-error variances estimated
   without it, so an outlier cannot mask itself by inflating them; chi-square per pose at the family-wise level
   ``steps.OUTLIER_LEVEL``, also ``steps.OUTLIER_MIN_RATIO`` x the median pose), the worst failing pose
   rejected and the test redone until none fails; the leave-one-out fits of the kept poses give the jackknife
   std, and a reported std below it by more than :data:`JACKKNIFE_TOLERANCE` is raised to it;
3. an optional shared measurement error (intrinsics calibrated from the same images) as nuisance
   coefficients (``identify.nuisance.with_nuisance``) on the final weights;
4. the chi-square adequacy test (``identify.model_adequacy``) and the a-posteriori variance factor: the std
   and covariance scaled by chi2/dof when it exceeds 1, a warning naming the worst poses when "too large".
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..errors import IdentifiabilityError
from ..identify import fit_rejecting_outliers, model_adequacy
from ..identify.handeye_fit import HandeyeFit, closed_form_comparison, fit_handeye
from ..identify.handeye_problem import transforms_from_x
from ..identify.problem import IdentificationProblem, IdentificationResult
from ..measure.handeye import closed_forms
from .checks import handeye_motions
from .steps import NUISANCE_PREFIX, OUTLIER_LEVEL, OUTLIER_MIN_RATIO, misfit_warning


@dataclass(frozen=True)
class HandeyeIdentified:
    """Hand-eye identification: result (std scaled by the variance factor when > 1), A, B (4, 4), problem
    (kept poses, final weights), rejected [(label, reason)], adequacy (``model_adequacy`` before scaling),
    variance_factor, fit (``HandeyeFit`` of the kept poses: robot std, closed-form comparison), nuisance
    (the shared error's block or None); no lack-of-fit test or method check (None). The report's
    ``report.build.IdentifiedFit``."""

    result: IdentificationResult
    A: np.ndarray
    B: np.ndarray
    problem: IdentificationProblem
    rejected: tuple
    adequacy: dict
    variance_factor: float
    fit: HandeyeFit
    nuisance: dict | None = None
    prepared: dict | None = None
    lack_of_fit: dict | None = None
    method_check: dict | None = None
    #: the deletion outlier test and the leave-one-out scatter of the kept poses (:func:`deletion_test`)
    deletion: dict | None = None
    #: the motion check before the fit (``checks.handeye_motions``: distinct poses, rotation axes' spread, rank)
    motion: dict | None = None


def identify_handeye(T_base_flange: ArrayLike, T_cam_target: ArrayLike, mount: str, pose_cov: ArrayLike | None,
                     labels: Sequence[str], robot_std: tuple[float, float] | None = None, robust: bool = True,
                     nuisance: Callable | None = None, where: str = "",
                     cov_scale: tuple[float, float] = (1.0, 1.0), noise_frame: str | None = None,
                     theta_start=None, compare: bool = True) -> HandeyeIdentified:
    """Steps of the module docstring. T_base_flange, T_cam_target (N, 4, 4) [m]; pose_cov (N, 6, 6) [m, rad]
    (None with noise_frame); labels (N,); robot_std: (translation m, rotation rad) per axis of the flange pose
    error, or None (estimated); nuisance: callable (problem, x) -> U (n_obs, 6, d) or None, the response of every
    pose's residual to one std of each direction of a shared error (``experiment.camera_step.residual_response``);
    cov_scale: the range of the factor by which the true camera covariance may differ from ``pose_cov``
    (``identify.adequacy.IMAGE_COV_SCALE`` for poses measured from images), read by the adequacy test;
    noise_frame: "target" | "camera" when the measured poses' noise is not known: its std per axis of that frame
    is estimated (``identify.handeye_fit.fit_estimated_noise``; outliers then by the robust chi-square test of
    ``identify.fit_rejecting_outliers``, the deletion test needing the noise known). theta_start: the robot's
    variances of a fit of a superset of these poses (``fit_handeye``: REML refined from there, no global search).
    compare: False: ``fit.closed_forms`` says only which closed form the fit started from (``fit_handeye``)."""
    F, M = (np.asarray(a, float) for a in (T_base_flange, T_cam_target))
    C = None if pose_cov is None else np.asarray(pose_cov, float)
    labels = list(labels)
    motion = handeye_motions(F, mount, labels, where or "the hand-eye pose set")
    fit = fit_handeye(F, M, mount, C, labels, robot_std, candidates=closed_forms(F, M, mount), noise_frame=noise_frame,
                      theta_start=theta_start, compare=compare)
    rejected, deletion = [], None
    if robust and noise_frame is None and fit.problem.n_obs * fit.problem.m >= 2 * int(np.sum(fit.result.free)):
        keep = list(range(len(labels)))
        while True:
            deletion = deletion_test(F[keep], M[keep], mount, C[keep], [labels[k] for k in keep], robot_std, fit)
            worst = int(np.argmax(deletion["d"]))
            if not deletion["d"][worst] > deletion["threshold"]:
                break
            lab = str(labels[keep[worst]])
            rejected.append((lab, f"deletion residual norm^2 {deletion['d'][worst]:.4g} > {deletion['threshold']:.4g} "
                                  f"(each pose against the fit without it, the robot pose error re-estimated without "
                                  f"it; chi-square, 6 dof, family-wise false-alarm level {OUTLIER_LEVEL:g} over "
                                  f"{len(keep)} poses)"))
            del keep[worst]
            if len(keep) < 3 or len(rejected) > MAX_REJECT_FRACTION * len(labels):
                raise IdentifiabilityError(f"{where}: {len(rejected)} of {len(labels)} poses fail the deletion "
                                           "outlier test: the model or the measurement is wrong, not a few outliers")
            fit = fit_handeye(F[keep], M[keep], mount, C[keep], [labels[k] for k in keep], robot_std,
                              candidates=closed_forms(F[keep], M[keep], mount))
    elif robust and fit.problem.n_obs * fit.problem.m >= 2 * int(np.sum(fit.result.free)):
        _, out = fit_rejecting_outliers(fit.problem, fit.result.identified, level=OUTLIER_LEVEL,
                                        min_ratio=OUTLIER_MIN_RATIO)
        if out:
            bad = {lab for lab, _ in out}
            keep = [k for k, lab in enumerate(labels) if str(lab) not in bad]
            if len(keep) < 3:
                raise IdentifiabilityError(f"{where}: only {len(keep)} poses left after rejecting outliers")
            rejected = list(out)
            fit = fit_handeye(F[keep], M[keep], mount, None if C is None else C[keep], [labels[k] for k in keep],
                              robot_std, candidates=closed_forms(F[keep], M[keep], mount), noise_frame=noise_frame)
    stability = []
    if deletion is not None and rejected:
        bad = {lab for lab, _ in rejected}
        stability = decision_stability(F, M, mount, C, labels, keep, [k for k, lab in enumerate(labels)
                                                                       if str(lab) in bad], deletion, robot_std, fit)
    result, pb, nz = fit.result, fit.problem, None
    if nuisance is not None:
        result, nz = _with_shared_error(fit, nuisance)
    adequacy = model_adequacy(result, cov_scale=cov_scale)
    factor = float(result.chi2_dof) if robust and np.isfinite(result.chi2_dof) else 1.0
    if factor > 1:
        result = replace(result, std=result.std * np.sqrt(factor), covariance=result.covariance * factor)
    extra = ()
    if deletion is not None:  # the leave-one-out scatter of the kept poses' fits against the reported std
        result, jk_line = _with_jackknife(result, deletion)
        extra += (jk_line,) if jk_line else ()
    if adequacy.get("verdict") == "too large":
        extra += (misfit_warning(adequacy, "the hand-eye model", "the measurement noise (camera + robot pose error, "
                                 f"robot std {fit.robot['source']}"
                                 + (", measured poses' std estimated per axis" if fit.noise else "") + ")"),)
    if rejected:
        extra += (f"{len(rejected)} outlier poses rejected: " + "; ".join(f"{lab}: {why}" for lab, why in rejected[:5]),)
    for st in stability:
        if st["kept_when_left_out"]:
            extra += (f"the rejection of pose {st['pose_id']} is unstable: it would be kept in {len(st['kept_when_left_out'])}"
                      f" of {st['of']} leave-one-out runs (leaving out {', '.join(st['kept_when_left_out'][:5])}); the "
                      "std include those runs' fits (jackknife)",)
    if extra:
        result = replace(result, warnings=tuple(result.warnings) + extra)
    A, B = transforms_from_x(pb, result.identified)
    return HandeyeIdentified(result, A, B, pb, tuple(rejected), adequacy, max(factor, 1.0), fit, nz,
                             deletion=None if deletion is None else _deletion_block(deletion, result, stability),
                             motion=motion)


#: more poses failing the deletion test than this fraction: the model or the measurement is wrong
MAX_REJECT_FRACTION = 0.3
#: the leave-one-out scatter may exceed the reported std by this factor before the std are inflated to it
JACKKNIFE_TOLERANCE = 1.3


def _theta(fit: HandeyeFit) -> tuple[float, float]:
    """(translation m, rotation rad) std per axis of the robot's pose error of a fit (given or estimated)."""
    return fit.robot["translation_mm"] * 1e-3, float(np.radians(fit.robot["rotation_deg"]))


def deletion_test(F, M, mount: str, C, labels: Sequence[str], robot_std, fit: HandeyeFit) -> dict:
    """Each pose k tested against the fit WITHOUT it (``identify.handeye_fit.deletion_fit``: the robot's pose-error
    variances re-estimated without it, refined from ``fit``'s, and the least squares with those weights; all N fits
    at once by ``identify.handeye_loo.leave_one_out``): the deletion (externally studentized) statistic
    ``d_k = r_k^T S_k^-1 r_k``, r_k the
    residual of pose k under the fit without it, ``S_k = C_k + J_k Sigma_(-k) J_k^T`` (C_k: camera + robot pose
    error at that fit; Sigma_(-k) its parameter covariance), against chi2(6) at the family-wise level
    ``OUTLIER_LEVEL`` over the N poses (and ``OUTLIER_MIN_RATIO`` x the median). An outlier cannot inflate the
    variances it is tested with. Above :data:`LOO_EXACT_MAX` poses, every pose is screened in closed form and only
    those near or above the threshold are refitted (O(N) instead of O(N^2)). Returns {d (N,), threshold, x_loo
    (N, 12): each fit's parameters}."""
    from scipy.stats import chi2

    from ..identify.handeye_fit import deletion_fit
    from ..identify.handeye_loo import deletion_statistics, leave_one_out, linearized_deletion
    from ..identify.handeye_problem import x_from_transforms

    n = len(labels)
    d, xs = np.full(n, np.inf), np.zeros((n, 12))
    theta = np.square(_theta(fit))
    est = robot_std is None and fit.robot["source"] == "estimated"
    fits = []  # per k: (x, parameter covariance of the free ones, free mask, robot variances) of the fit without k
    allp = all_poses_problem(F, M, mount, C, fit.A, fit.B)
    x = x_from_transforms(allp, fit.A, fit.B)
    thr = float(chi2.isf(OUTLIER_LEVEL / n, 6))
    if n <= LOO_EXACT_MAX:  # all the subsets' fits at once (identify.handeye_loo: deletion_fit's steps, batched)
        X, cov, th_k, settled = leave_one_out(allp, x, theta, est)
        d_all = deletion_statistics(allp, X, cov, th_k)  # pose k at the fit without it
    else:  # every pose screened in closed form, the exact fit without it where the decision could turn on it
        X, cov, d_all = linearized_deletion(allp, x, theta)
        th_k, settled = np.tile(theta, (n, 1)), np.isfinite(d_all)
        fin = d_all[np.isfinite(d_all)]
        limit = max(thr, OUTLIER_MIN_RATIO**2 * float(np.median(fin))) if fin.size else thr
        screen = np.flatnonzero(~(d_all <= LOO_SCREEN * limit))  # (inf / NaN: refitted too)
        if screen.size:
            Xe, ce, te, se = leave_one_out(allp, x, theta, est, which=screen)
            X[screen], cov[screen], th_k[screen], settled[screen] = Xe[screen], ce[screen], te[screen], se[screen]
            d_all[screen] = deletion_statistics(allp, X, cov, th_k)[screen]
    for k in range(n):
        if settled[k]:
            fk = (X[k], cov[k], np.ones(12, bool), th_k[k])
            d[k] = d_all[k]
        else:
            rest = [j for j in range(n) if j != k]
            _, rk, th = deletion_fit(F[rest], M[rest], mount, C[rest], [labels[j] for j in rest], fit.A, fit.B,
                                     theta, est)
            fk = (rk.identified, rk.covariance, np.asarray(rk.free, bool), th)
            d[k] = pose_statistic(F, M, mount, C, k, fit.A, fit.B, fk, allp)
        xs[k] = fk[0]
        fits.append(fk)
    thr = max(thr, OUTLIER_MIN_RATIO**2 * float(np.median(d[np.isfinite(d)]))) if np.isfinite(d).any() else thr
    return {"d": d, "threshold": thr, "x_loo": xs, "labels": [str(lab) for lab in labels], "fits": fits}


#: the deletion test fits every subset exactly (``identify.handeye_loo.leave_one_out``, O(N^2)) up to this many poses;
#: above it each pose is screened by the closed-form fit without it (``linearized_deletion``: the model linearised,
#: the weights and robot variances of all the poses, O(N)) and refitted exactly only where its screened statistic
#: exceeds :data:`LOO_SCREEN` x the threshold. A pose cannot hide below that by inflating the variances: one pose
#: of statistic d moves them by about d / (6 N) of themselves, so the screened value is at least min(d / 2, 3 N)
LOO_EXACT_MAX = 300
#: fraction of the deletion threshold above which a screened pose is refitted exactly (:data:`LOO_EXACT_MAX`)
LOO_SCREEN = 0.25


def pose_statistic(F, M, mount: str, C, idx: int, A, B, fit_k, base=None) -> float:
    """The deletion statistic of pose ``idx`` of (F, M (N, 4, 4), C (N, 6, 6); N >= 3) under a fit that does not
    contain it (``fit_k`` = (x, covariance, free, robot variances) of :func:`deletion_test`'s ``fits``). base: the
    problem of all N poses at (A, B) without robot pose error (:func:`all_poses_problem`; built when None)."""
    from ..identify.handeye_problem import reweighted, robot_pose_cov

    x, cov, free, th = fit_k
    allp = all_poses_problem(F, M, mount, C, A, B) if base is None else base
    one = reweighted(allp, x, robot_pose_cov(*np.sqrt(th))).subset([idx])
    r = np.asarray(one.residual(x), float)[0]
    J = np.asarray(one.jacobian(x), float)[0][:, free]
    try:
        return float(r @ np.linalg.solve(one.obs_cov[0] + J @ cov @ J.T, r))
    except np.linalg.LinAlgError:
        return float("inf")


def all_poses_problem(F, M, mount: str, C, A, B):
    """The hand-eye problem of all the poses (F, M (N, 4, 4), C (N, 6, 6)) at (A, B), camera covariance only: the
    one :func:`pose_statistic` reweights with each fit's robot variances."""
    from ..identify.handeye_problem import handeye_problem

    return handeye_problem(F, M, mount, A, B, C, labels=[str(k) for k in range(len(F))])


def decision_stability(F, M, mount: str, C, labels, keep: list, rejected_idx: list, deletion: dict, robot_std,
                       fit: HandeyeFit) -> list[dict]:
    """Does each rejection hold in every leave-one-out run? For each rejected pose r and each kept pose k: r's
    deletion statistic under the fit without k (and without r) against the threshold. Where it passes (the run
    without k would keep r), that run's fit is redone with r (``deletion["x_loo"][k]`` replaced), so that the
    jackknife std carry the instability. Returns [{pose_id, same_decision (count), of, kept_when_left_out
    [labels]}] per rejected pose."""
    from ..identify.handeye_fit import deletion_fit

    out = []
    theta = np.square(_theta(fit))
    est = robot_std is None and fit.robot["source"] == "estimated"
    allp = all_poses_problem(F, M, mount, C, fit.A, fit.B)
    for r in rejected_idx:
        flips = []
        for i, k in enumerate(keep):
            if pose_statistic(F, M, mount, C, r, fit.A, fit.B, deletion["fits"][i], allp) <= deletion["threshold"]:
                flips.append(str(labels[k]))
                sub = [j for j in keep if j != k] + [r]
                _, rk, _ = deletion_fit(F[sub], M[sub], mount, C[sub], [labels[j] for j in sub], fit.A, fit.B,
                                        theta, est)
                deletion["x_loo"][i] = rk.identified
        out.append({"pose_id": str(labels[r]), "same_decision": len(keep) - len(flips), "of": len(keep),
                    "kept_when_left_out": flips})
    return out


def _with_jackknife(result: IdentificationResult, deletion: dict):
    """(result, warning or ""): the jackknife std of the leave-one-out fits of the kept poses; where it exceeds the
    reported std by more than :data:`JACKKNIFE_TOLERANCE`, the std (and covariance) are raised to it: the
    estimate depends on single poses more than the noise model says."""
    xs = deletion["x_loo"]
    n = len(xs)
    jk = np.sqrt((n - 1) / n * np.sum((xs - xs.mean(axis=0)) ** 2, axis=0))
    free = np.asarray(result.free, bool)
    ratio = np.where(free & (result.std > 0), jk / np.where(result.std > 0, result.std, 1.0), 1.0)
    deletion["jackknife_std"], deletion["ratio"] = jk, ratio
    big = free & (ratio > JACKKNIFE_TOLERANCE)
    if not big.any():
        return result, ""
    f = np.where(big, ratio, 1.0)
    std = result.std * f
    cov = result.covariance * np.outer(f[free], f[free])
    names = [nm for nm, b in zip(result.names, big) if b]
    line = (f"the leave-one-out scatter of the estimate is up to {ratio.max():.2f} x its reported std "
            f"({', '.join(names[:6])}): single poses move it more than the noise model says; those std are raised to "
            "the jackknife std")
    return replace(result, std=std, covariance=cov), line


def _deletion_block(deletion: dict, result: IdentificationResult, stability=()) -> dict:
    """The report's ``deletion`` block: per pose its deletion statistic, the threshold, the jackknife / reported
    std ratio per identified parameter, the stability of each rejection (:func:`decision_stability`)."""
    free = np.asarray(result.free, bool)
    return {"how": "each pose against the fit without it (robot pose error re-estimated without it)",
            "threshold": float(deletion["threshold"]), "rejections": list(stability),
            "poses": [{"pose_id": lab, "d": float(v) if np.isfinite(v) else None}
                      for lab, v in zip(deletion["labels"], deletion["d"])],
            "jackknife_ratio": {n: float(r) for n, r, f in zip(result.names, deletion.get("ratio", []), free) if f}}


def _with_shared_error(fit, nuisance):
    """(result over the 12 mount parameters with the shared error's coefficients fitted and marginalised,
    block {n_directions, coefficients, coefficients_std, std_inflation}) or (fit.result, None) when the
    response is None. The adequacy and variance factor then read the GLS fit (``identify.nuisance``)."""
    from ..identify import solve_lse
    from ..identify.nuisance import split_nuisance, with_nuisance

    pb, x = fit.problem, fit.result.identified
    U = nuisance(pb, x)
    if U is None:
        return fit.result, None
    full = solve_lse(with_nuisance(pb, U, NUISANCE_PREFIX), np.concatenate([x, np.zeros(U.shape[2])]))
    res, nz = split_nuisance(full, len(pb.params))
    free = np.asarray(res.free, bool)
    ratio = res.std / fit.result.std
    block = {"n_directions": int(U.shape[2]), "coefficients": nz["values"], "coefficients_std": nz["std"],
             "std_inflation": {n: float(v) for n, v, f in zip(res.names, ratio, free) if f and np.isfinite(v)}}
    return res, block


def handeye_blocks(ident: HandeyeIdentified) -> dict:
    """The report's hand-eye additions: ``robot_pose_std`` (given or estimated, mm / deg per axis, with the
    estimate's std), ``measured_noise`` (when the measured poses' std per axis was estimated) and
    ``closed_form_comparison`` (each OpenCV method's weighted cost and distance to the
    final solution, under the final weights), ``motion`` (the motion check before the fit)."""
    fit = ident.fit
    cf = fit.closed_forms
    if ident.nuisance is not None:  # the solution moved with the shared error: compare with the final one
        cf = closed_form_comparison(ident.problem, ident.result.identified, fit.candidates, cf["start"])
    out = {"robot_pose_std": fit.robot, "closed_form_comparison": cf, "deletion_test": ident.deletion,
           "motion": ident.motion}
    if fit.noise is not None:
        out["measured_noise"] = fit.noise
    return out


__all__ = ["HandeyeIdentified", "identify_handeye", "handeye_blocks"]
