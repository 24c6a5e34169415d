"""Is the fitted model adequate, and which poses are outliers? (numpy/scipy only)

:func:`model_adequacy` reads an :class:`IdentificationResult`: the whitened final cost gives
``chi2 = 2 cost_final`` (sum of squared whitened residuals), which for a right model and right
``obs_cov`` follows a chi-square law with ``dof = N - n_free`` degrees of freedom (N scalar
equations, n_free identified parameters; linearised). ``chi2 / dof`` (the a-posteriori variance
factor) should then lie in the central ``1 - level`` interval of ``chi2(dof) / dof``; above it the
model misses something or ``obs_cov`` is optimistic, below it ``obs_cov`` is pessimistic.

:func:`fit_rejecting_outliers` is the robust-outlier procedure for the pipelines:

1. LSE with a robust loss (scipy ``soft_l1`` by default, or ``cauchy``) on the whitened residuals,
   ``f_scale = 1`` (noise std units);
2. robust scale of the whitened residual components ``s = 1.4826 * median |W r|`` (1 when obs_cov is
   right; ``scale=<float>`` imposes one, ``scale=1.0`` trusts obs_cov), robust refit with ``f_scale = s``;
3. a pose is rejected when ``|W_k r_k|^2 / s^2 > chi2.ppf(1 - level / n_obs, m)``: a chi-square test
   with m degrees of freedom per pose at the family-wise false-alarm level ``level`` (Bonferroni over
   the n_obs poses: on clean data, the probability that ANY pose is rejected is at most ``level``,
   a little less since fitted residuals are smaller than the noise);
4. plain LSE (linear loss) from the caller's ``x0`` on the kept poses.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigError, DataError
from .lse import pose_chi2, solve_lse
from .problem import IdentificationProblem, IdentificationResult

def _chi2():
    """``scipy.stats.chi2``, imported on first use: scipy.stats is about half of the CLI's start-up imports."""
    from scipy.stats import chi2

    return chi2


#: default significance level of the adequacy test and family-wise false-alarm level of the outlier test
DEFAULT_LEVEL = 0.01
#: robust losses accepted by :func:`fit_rejecting_outliers`
ROBUST_LOSSES = ("soft_l1", "cauchy", "huber", "arctan")
#: relative tolerances (x, f, g) of the robust fits of :func:`fit_rejecting_outliers`, which only rank the poses
ROBUST_TOL = 1e-8


#: range [lo, hi] of the factor k by which the true covariance of an image-measured pose may differ from the
#: chain's predicted one (``measure.covariance``): the covariance model's own accuracy, measured on clean
#: image-mode H4 runs (81 poses x 10 frames, 15 seeds each, ``benchmarks/bench_zscores.py``): chi2/dof
#: 0.57-1.16 with a new true robot per seed (typical views: the per-pose systematic corner variance is
#: estimated conservatively), 1.18-1.27 with the scene's own truth on its 81-pose grid (at theta = 0 the tags
#: are aligned with the pixel grid: a pixel-phase-locked detector error, correlated between corners, that
#: the independent-corner model does not carry); pose-level z RMS per component 0.73-1.22 over the bench
#: scenes (bench_measure). Synthetic or user-given covariances: (1, 1).
IMAGE_COV_SCALE = (0.55, 1.3)


def model_adequacy(result: IdentificationResult, level: float = DEFAULT_LEVEL, n_worst: int = 5,
                   cov_scale: tuple[float, float] = (1.0, 1.0)) -> dict:
    """Chi-square adequacy verdict of ``result`` (JSON-ready dict).

    A two-sided test at ``level``: under a right model, chi2 = 2 cost_final follows k chi2(dof), with k the
    factor by which the true measurement covariance differs from obs_cov, known to lie in ``cov_scale``
    [k_lo, k_hi] ((1, 1): obs_cov is the covariance; image-measured poses: :data:`IMAGE_COV_SCALE`). The
    p-value is the largest over that range of 2 min(P[chi2(dof) >= chi2 / k], P[chi2(dof) <= chi2 / k])
    (capped at 1), and the band ``expected_chi2_dof`` = [k_lo q(level/2), k_hi q(1 - level/2)] / dof is
    exactly where p >= level: "consistent" inside, "too large" above (model error, outliers, or an
    optimistic covariance), "too small" below (residuals smaller than obs_cov predicts).

    Keys: chi2, dof, chi2_dof, expected_chi2_dof [low, high], p_value (two-sided), cov_scale [k_lo, k_hi],
    level, verdict ("consistent", "too large", "too small" or "not available"), explanation (a sentence),
    worst_poses: up to ``n_worst`` {label, chi2, p_value} with the largest whitened squared residual norm
    (p_value: upper tail of chi2(m), m = residual components per pose), largest first.
    """
    if not 0 < level < 1:
        raise ConfigError(f"model_adequacy: level={level}, expected 0 < level < 1")
    k_lo, k_hi = (float(v) for v in cov_scale)
    if not (0 < k_lo <= k_hi and np.isfinite(k_hi)):
        raise ConfigError(f"model_adequacy: cov_scale={cov_scale!r}, expected 0 < k_lo <= k_hi < inf")
    dof = int(result.dof)
    chi2 = 2.0 * float(result.cost_final)
    out = {"chi2": chi2 if np.isfinite(chi2) else None, "dof": dof, "level": float(level),
           "chi2_dof": float(result.chi2_dof) if np.isfinite(result.chi2_dof) else None,
           "expected_chi2_dof": None, "p_value": None, "cov_scale": [k_lo, k_hi], "worst_poses": []}
    m = int(result.residuals.shape[1]) if np.ndim(result.residuals) == 2 else 0
    if result.pose_chi2 is not None and m:
        pc = np.asarray(result.pose_chi2, float)
        order = np.argsort(-np.where(np.isfinite(pc), pc, np.inf))[: max(0, int(n_worst))]
        out["worst_poses"] = [
            {"label": str(result.labels[k]) if result.labels else f"#{int(k)}",
             "chi2": float(pc[k]) if np.isfinite(pc[k]) else None,
             "p_value": float(_chi2().sf(pc[k], m)) if np.isfinite(pc[k]) else 0.0}
            for k in order
        ]
    if result.pose_chi2 is not None and m and dof > 0:
        out["pose_tail"] = pose_tail(np.asarray(result.pose_chi2, float), m, result.labels, k_hi, level)
    if dof <= 0 or not np.isfinite(chi2):
        why = "no redundancy (dof <= 0)" if dof <= 0 else "the cost is not finite"
        out.update(verdict="not available", explanation=f"no chi-square test: {why}")
        return out
    lo, hi = k_lo * _chi2().ppf(level / 2, dof) / dof, k_hi * _chi2().isf(level / 2, dof) / dof
    out["expected_chi2_dof"] = [float(lo), float(hi)]
    p_hi, p_lo = float(_chi2().sf(chi2 / k_hi, dof)), float(_chi2().cdf(chi2 / k_lo, dof))
    # between k_lo and k_hi some k puts chi2 at the median: p = 1; else the nearest end of the range
    med = _chi2().median(dof)
    p = 1.0 if chi2 / k_hi <= med <= chi2 / k_lo else min(1.0, 2.0 * min(p_hi, p_lo))
    out["p_value"] = p
    v = chi2 / dof
    how = (f"two-sided test at level {level:g}, p = {p:.2g}" + (
        "" if k_lo == k_hi == 1.0 else f", the measurement covariance trusted within a factor {k_lo:g}-{k_hi:g}"))
    if v > hi:
        out.update(verdict="too large", explanation=(
            f"chi2/dof = {v:.3g} above the expected {lo:.3g}-{hi:.3g} ({how}): the residuals are larger than the "
            "measurement covariance predicts: a model error (missing parameter, wrong structure), outlier poses, "
            "or an optimistic measurement covariance"))
    elif v < lo:
        out.update(verdict="too small", explanation=(
            f"chi2/dof = {v:.3g} below the expected {lo:.3g}-{hi:.3g} ({how}): the residuals are smaller than the "
            "measurement covariance predicts; the reported std come from that covariance and are not reduced "
            "(they may be pessimistic)"))
    else:
        out.update(verdict="consistent", explanation=(
            f"chi2/dof = {v:.3g} within the expected {lo:.3g}-{hi:.3g} ({how}): the residuals agree with the "
            "measurement covariance"))
    return out


#: per-pose p-value below which a pose counts in the tail test (:func:`pose_tail`)
POSE_TAIL_P = 0.01


def pose_tail(pose_chi2: np.ndarray, m: int, labels=(), k_hi: float = 1.0, level: float = DEFAULT_LEVEL) -> dict:
    """The per-pose p-values tested as a whole: the count of poses whose whitened squared residual norm has an
    upper-tail p < :data:`POSE_TAIL_P` under chi2(m) (at the most lenient covariance factor ``k_hi``) against
    Binomial(n, POSE_TAIL_P), and the clusters of such poses (runs in pose order with gaps of at most 2 poses).
    {threshold, n_poses, n_below, expected, p_value (P[count >= n_below]), significant (p_value < level),
    clusters: [[first label, last label, count]], message}."""
    from scipy.stats import binom

    pc = np.asarray(pose_chi2, float)
    ok = np.isfinite(pc)
    n = int(ok.sum())
    p = np.where(ok, _chi2().sf(np.where(ok, pc, 0.0) / k_hi, m), 0.0)
    below = np.flatnonzero(ok & (p < POSE_TAIL_P))
    pv = float(binom.sf(len(below) - 1, n, POSE_TAIL_P)) if n else 1.0
    lab = [str(x) for x in labels] if len(labels) == len(pc) else [f"#{i}" for i in range(len(pc))]
    clusters, run = [], []
    for i in below:
        if run and i - run[-1] > 3:
            clusters.append(run)
            run = []
        run.append(int(i))
    if run:
        clusters.append(run)
    clusters = [[lab[r[0]], lab[r[-1]], len(r)] for r in clusters if len(r) >= 2]
    sig = bool(pv < level)
    where = ("; clustered in " + ", ".join(f"{a}-{b} ({c} poses)" for a, b, c in clusters)) if clusters else ""
    msg = (f"{len(below)} of {n} poses have a residual with p < {POSE_TAIL_P:g} ({n * POSE_TAIL_P:.2g} expected at "
           f"the measurement noise; binomial p {pv:.2g}){where}: those poses fit worse than their noise allows (an "
           "error in their images or joint readings, or a model term that matters only there)") if sig else ""
    return {"threshold": POSE_TAIL_P, "n_poses": n, "n_below": int(len(below)), "expected": n * POSE_TAIL_P,
            "p_value": pv, "significant": sig, "clusters": clusters, "message": msg}


def _robust_scale(problem: IdentificationProblem, res: IdentificationResult) -> float:
    """1.4826 * median |whitened residual component| (= 1 for N(0, 1) components), corrected for the
    parameters fitted: fitted residuals are smaller than the noise by about sqrt((N - n) / N) for N
    equations and n free parameters (with 60 equations for 30 parameters, uncorrected, 4 good poses
    of 10 failed the test)."""
    rw = np.einsum("kij,kj->ki", problem.whitening(), res.residuals)
    # a nuisance parameter with its prior row (problem.prior_rows) takes no degree of freedom from the poses
    n_eq, n_free = rw.size, int(np.sum(res.free)) - problem.n_prior
    s = 1.4826 * float(np.median(np.abs(rw))) * np.sqrt(n_eq / max(n_eq - n_free, 1))
    if not (np.isfinite(s) and s > 0):
        raise DataError(f"robust scale of the whitened residuals is {s}: cannot test poses for outliers")
    return s


def fit_rejecting_outliers(
    problem: IdentificationProblem,
    x0: ArrayLike | None = None,
    level: float = DEFAULT_LEVEL,
    loss: str = "soft_l1",
    scale: float | str = "auto",
    max_reject_fraction: float = 0.3,
    min_ratio: float = 0.0,
    **lse_kwargs,
) -> tuple[IdentificationResult, list[tuple[str, str]]]:
    """Robust fit, chi-square rejection of outlier poses, plain LSE without them (module docstring).

    x0: (n,) starting vector (SI), default nominal. level: family-wise false-alarm level of the pose
    test. loss: scipy robust loss. scale: "auto" (robust scale of the whitened residuals) or a float
    (noise-std units; 1.0 trusts obs_cov). max_reject_fraction: more rejected poses than this
    fraction raise DataError (the model or obs_cov is wrong, not a few outliers). min_ratio: when > 0, a pose
    must also exceed min_ratio times the median pose's whitened residual norm (gross errors only: residuals
    with a systematic, non-Gaussian part have heavier tails than the chi-square law). lse_kwargs go to
    every :func:`~vision_calib.identify.lse.solve_lse` call (free, fix, selection, ...).
    Returns (result of the plain LSE on the kept poses, rejected [(label, reason)]); the result's
    ``info["outliers"]`` records the test and its warnings name the rejected poses.
    """
    if loss not in ROBUST_LOSSES:
        raise ConfigError(f"fit_rejecting_outliers: loss={loss!r}; expected one of {', '.join(ROBUST_LOSSES)}")
    if not 0 < level < 1:
        raise ConfigError(f"fit_rejecting_outliers: level={level}, expected 0 < level < 1")
    for key in ("loss", "f_scale", "method"):
        if key in lse_kwargs:
            raise ConfigError(f"fit_rejecting_outliers: {key!r} is chosen by the procedure, do not pass it")
    # the robust fits only rank the poses (their residuals against a threshold): tolerances of ROBUST_TOL, not
    # the final fit's (scipy's trf crawls from 1e-8 to 1e-12 relative for nothing a threshold can see)
    rkw = {**lse_kwargs, **{k: max(float(lse_kwargs.get(k, ROBUST_TOL)), ROBUST_TOL) for k in ("xtol", "ftol", "gtol")}}
    plain = solve_lse(problem, x0, **lse_kwargs)  # the answer when no pose is rejected; the robust fits start there
    start = plain.identified if np.all(np.isfinite(plain.identified)) else x0
    robust = solve_lse(problem, start, loss=loss, f_scale=1.0, **rkw)
    if scale == "auto":
        s = _robust_scale(problem, robust)
        robust = solve_lse(problem, robust.identified, loss=loss, f_scale=s, **rkw)
    else:
        s = float(scale)
        if not (np.isfinite(s) and s > 0):
            raise ConfigError(f"fit_rejecting_outliers: scale={scale!r}; expected 'auto' or a float > 0")
    n_obs, m = problem.n_obs, problem.m
    d = pose_chi2(problem, robust.residuals) / s**2
    thr = float(_chi2().isf(level / n_obs, m))
    if min_ratio > 0:  # gross errors only: also min_ratio x the median pose's residual norm
        thr = max(thr, min_ratio**2 * float(np.nanmedian(d)))
    bad = np.flatnonzero(~(d <= thr))  # NaN fails too
    labels = [str(problem.labels[k]) if problem.labels else f"#{int(k)}" for k in range(n_obs)]
    rejected = [(labels[k], f"whitened residual norm^2 {d[k]:.4g} > {thr:.4g} (chi-square, {m} dof, family-wise "
                 f"false-alarm level {level:g} over {n_obs} poses, robust scale {s:.3g}, loss {loss})") for k in bad]
    if bad.size > max_reject_fraction * n_obs:
        raise DataError(f"{bad.size} of {n_obs} poses fail the outlier test (more than {max_reject_fraction:.0%}): "
                        f"the model or the measurement covariance is wrong, not a few outliers; first: {labels[bad[0]]}")
    keep = np.setdiff1d(np.arange(n_obs), bad)
    final = solve_lse(problem.subset(keep), x0, **lse_kwargs) if bad.size else plain
    info = dict(final.info, outliers={"level": float(level), "loss": loss, "scale": s, "threshold": thr,
                                      "pose_chi2_robust": d, "rejected": [lab for lab, _ in rejected]})
    warnings = final.warnings + tuple(f"pose {lab} rejected as an outlier: {why}" for lab, why in rejected)
    return dataclasses.replace(final, info=info, warnings=warnings), rejected
