"""Hand-eye identification from measured data (flange poses known): the same steps as the robot-chain path
(:func:`.steps.identify_measurements`) on :func:`vision_calib.identify.handeye_fit.fit_handeye`:

1. the fit with the robot's pose error in the weights (given std, or estimated), started from the best of
   OpenCV's closed forms (``measure.handeye.closed_forms``, passed to ``fit_handeye`` as its candidates);
2. with redundancy (at least twice as many equations as parameters), the outlier test of
   ``identify.fit_rejecting_outliers`` (robust fit, chi-square test per pose at the family-wise level
   ``steps.OUTLIER_LEVEL``, also ``steps.OUTLIER_MIN_RATIO`` x the median pose), and the fit redone on the
   kept poses (closed forms, robot variance and weights recomputed without the rejected ones);
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
from .steps import NUISANCE_PREFIX, OUTLIER_LEVEL, OUTLIER_MIN_RATIO, misfit_warning


@dataclass(frozen=True)
class HandeyeIdentified:
    """Hand-eye identification: result (std scaled by the variance factor when > 1), A, B (4, 4), problem
    (kept poses, final weights), rejected [(label, reason)], adequacy (``model_adequacy`` before scaling),
    variance_factor, fit (``HandeyeFit`` of the kept poses: robot std, closed-form comparison), nuisance
    (the shared error's block or None); no lack-of-fit test or method check (None). The report's
    ``io.report.IdentifiedFit``."""

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


def identify_handeye(T_base_flange: ArrayLike, T_cam_target: ArrayLike, mount: str, pose_cov: ArrayLike | None,
                     labels: Sequence[str], robot_std: tuple[float, float] | None = None, robust: bool = True,
                     nuisance: Callable | None = None, where: str = "",
                     noise_frame: str | None = None) -> HandeyeIdentified:
    """Steps of the module docstring. T_base_flange, T_cam_target (N, 4, 4) [m]; pose_cov (N, 6, 6) [m, rad]
    (None with noise_frame); labels (N,); robot_std: (translation m, rotation rad) per axis of the flange pose
    error, or None (estimated); nuisance: callable (problem, x) -> U (n_obs, 6, d) or None, the response of every
    pose's residual to one std of each direction of a shared error (``experiment.camera_step.residual_response``);
    noise_frame: "target" | "camera" when the measured poses' noise is not known: its std per axis of that frame
    is estimated (``identify.handeye_fit.fit_estimated_noise``)."""
    F, M = (np.asarray(a, float) for a in (T_base_flange, T_cam_target))
    C = None if pose_cov is None else np.asarray(pose_cov, float)
    labels = list(labels)
    fit = fit_handeye(F, M, mount, C, labels, robot_std, candidates=closed_forms(F, M, mount), noise_frame=noise_frame)
    rejected = []
    pb = fit.problem
    if robust and pb.n_obs * pb.m >= 2 * int(np.sum(fit.result.free)):
        _, out = fit_rejecting_outliers(pb, fit.result.identified, level=OUTLIER_LEVEL, min_ratio=OUTLIER_MIN_RATIO)
        if out:
            bad = {lab for lab, _ in out}
            keep = [k for k, lab in enumerate(labels) if str(lab) not in bad]
            if len(keep) < 3:
                raise IdentifiabilityError(f"{where}: only {len(keep)} poses left after rejecting outliers")
            rejected = list(out)
            fit = fit_handeye(F[keep], M[keep], mount, None if C is None else C[keep], [labels[k] for k in keep],
                              robot_std, candidates=closed_forms(F[keep], M[keep], mount), noise_frame=noise_frame)
    result, pb, nz = fit.result, fit.problem, None
    if nuisance is not None:
        result, nz = _with_shared_error(fit, nuisance)
    adequacy = model_adequacy(result)
    factor = float(result.chi2_dof) if robust and np.isfinite(result.chi2_dof) else 1.0
    if factor > 1:
        result = replace(result, std=result.std * np.sqrt(factor), covariance=result.covariance * factor)
    extra = ()
    if adequacy.get("verdict") == "too large":
        extra += (misfit_warning(adequacy, "the hand-eye model", "the measurement noise (camera + robot pose error, "
                                 f"robot std {fit.robot['source']}"
                                 + (", measured poses' std estimated per axis" if fit.noise else "") + ")"),)
    if rejected:
        extra += (f"{len(rejected)} outlier poses rejected: " + "; ".join(f"{lab}: {why}" for lab, why in rejected[:5]),)
    if extra:
        result = replace(result, warnings=tuple(result.warnings) + extra)
    A, B = transforms_from_x(pb, result.identified)
    return HandeyeIdentified(result, A, B, pb, tuple(rejected), adequacy, max(factor, 1.0), fit, nz)


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
    final solution, under the final weights)."""
    fit = ident.fit
    cf = fit.closed_forms
    if ident.nuisance is not None:  # the solution moved with the shared error: compare with the final one
        cf = closed_form_comparison(ident.problem, ident.result.identified, fit.candidates, cf["start"])
    out = {"robot_pose_std": fit.robot, "closed_form_comparison": cf}
    if fit.noise is not None:
        out["measured_noise"] = fit.noise
    return out


__all__ = ["HandeyeIdentified", "identify_handeye", "handeye_blocks"]
