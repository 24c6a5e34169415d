"""Steps shared by the pipelines (synthetic, simulate, process) and the studies: random streams,
identifiability at the nominal, the true robot of a scene, the base-parameter problem, one
identification (method by name), and the plausibility checks of an identified result.

Seeds: the truth (robot deviations) comes from the scene's ``truth.seed``; poses, noise and
validation poses from the run seed through independent streams ``default_rng([seed, k])``.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from dataclasses import dataclass, replace
from typing import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..errors import ConfigError, IdentifiabilityError
from ..identify import analyze, solve_ekf, solve_lse
from ..identify.identifiability import IdentifiabilityReport
from ..identify.nuisance import split_nuisance, with_nuisance
from ..identify.problem import IdentificationProblem, IdentificationResult
from ..kinematics.params import ParameterSet
from ..report.text import method_check_line
from ..rig import Measurements, Scene, Setup, scene_poses, true_parameters
from .prepare import prepare_setup

STREAM_POSES, STREAM_NOISE, STREAM_VALIDATION, STREAM_TRUTH = 1, 2, 3, 4
#: base-parameter choice: keep earlier parameter names first (robot file order: left mount, joints,
#: right mount), so the same set is dropped whatever the pose set (pivoted QR depends on the poses)
BASE_SELECTION = "order"
#: outlier test on measured data: family-wise false-alarm level, and the factor by which a pose's residual
#: norm must also exceed the median pose's. Image measurements carry systematic errors (detector bias) that
#: make the residuals heavier-tailed than Gaussian: good poses of the 81-pose demo failed the bare chi-square
#: test (27.6 > 23.1 at 1 %, 41.7 > 32.9 at 1e-4: 3.5x the median norm); the gross errors the test is for
#: (swapped images, a wrong joint reading) are tens to hundreds of times the typical residual.
OUTLIER_LEVEL = 1e-4
OUTLIER_MIN_RATIO = 5.0


def rngs(seed: int) -> tuple[np.random.Generator, np.random.Generator, np.random.Generator]:
    """Independent generators (poses, noise, validation) of a run seed."""
    seed = int(seed)
    return (np.random.default_rng([seed, STREAM_POSES]), np.random.default_rng([seed, STREAM_NOISE]),
            np.random.default_rng([seed, STREAM_VALIDATION]))


#: the rows' weighting of :func:`analyze_setup` (exact measurements, no noise model), in words
PLANNING_WEIGHTING = "unweighted (no noise model: 1 mm and 1 mrad of residual weigh alike)"


def analyze_setup(setup: Setup, poses: ArrayLike, residual: str | None = None,
                  all_params: bool = False) -> tuple[IdentifiabilityReport, IdentificationProblem]:
    """Identifiability of the setup's free parameters (every model parameter with ``all_params``)
    over commanded ``poses`` at the nominal geometry with exact measurements:
    (IdentifiabilityReport, problem). Its condition number weighs every pose's components alike
    (PLANNING_WEIGHTING); measured data are analysed whitened by their covariances (:func:`identify_measurements`)."""
    meas = setup.synthetic_measurements(poses, setup.params.nominal, np.random.default_rng(0))
    problem = setup.problem(meas, residual)
    if all_params:  # bypass the builders' refusal of known-redundant pairs: the analysis must find them
        problem = problem.with_params(problem.params.only_free(problem.params.names))
    return analyze(problem, selection=BASE_SELECTION, weighting=PLANNING_WEIGHTING), problem


#: the generic poses' (rank, non-identifiable names) of :func:`generic_rank`, by setup (its fields but the camera,
#: which neither the generic poses nor exact measurements read) and residual; the setups are kept with their entry
_GENERIC_RANK: list[tuple[tuple, tuple, tuple[int, tuple[str, ...]]]] = []
_GENERIC_RANK_KEPT = 8


def generic_rank(setup: Setup, residual: str | None, n_generic: int = 200) -> tuple[int, tuple[str, ...]]:
    """(rank, non-identifiable names) of the setup's free parameters over ``n_generic`` generic poses
    (``Setup.generic_poses``, seed 12345; :func:`analyze_setup`): a function of the setup's model, so computed once
    per setup and residual (the held-out folds and the cause test's second hypothesis, whose setup differs by its
    camera only, reuse it)."""
    fields = tuple((f.name, getattr(setup, f.name)) for f in dataclasses.fields(setup) if f.name != "camera")
    key = (type(setup), tuple((n, id(v)) for n, v in fields), residual, int(n_generic))
    for k, _, value in _GENERIC_RANK:
        if k == key:
            return value
    ref, _ = analyze_setup(setup, setup.generic_poses(np.random.default_rng(12345), n_generic), residual)
    value = (int(ref.rank), tuple(ref.non_identifiable))
    _GENERIC_RANK.append((key, fields, value))  # the field objects kept alive: their ids are not reused
    del _GENERIC_RANK[:-_GENERIC_RANK_KEPT]
    return value


def structural_rank_check(setup: Setup, rep: IdentifiabilityReport, residual: str | None, where: str,
                          accept: bool = False,
                          n_generic: int = 200) -> list[str]:
    """IdentifiabilityError naming the parameters the user's pose set loses compared with generic poses
    (``rep``: IdentifiabilityReport of the user's poses; :func:`generic_rank`), unless ``accept``; returns those
    names."""
    ref_rank, ref_non = generic_rank(setup, residual, n_generic)
    lost = [n for n in rep.non_identifiable if n not in ref_non]
    if rep.rank < ref_rank and lost and not accept:
        raise IdentifiabilityError(
            f"{where}: the {rep.n_obs} poses identify {rep.rank} of the {ref_rank} parameters that varied poses "
            f"identify; not identifiable from these poses: {', '.join(lost)}. Use more (and more varied) poses, "
            "or accept fixing them at nominal (--fix-unidentifiable)")
    return lost


def truth_poses(scene: Scene) -> np.ndarray:
    """The pose set the scene's truth is drawn on (its default identification poses, truth seed)."""
    return scene_poses(scene, np.random.default_rng([scene.truth.seed, 0]))


def scene_truth(scene: Scene, analysis: IdentifiabilityReport | None = None) -> np.ndarray:
    """The scene's true parameters x_true (n,): a function of the scene (truth seed) only, whatever
    the run's poses. Random deviations go on the parameters identifiable from :func:`truth_poses`
    (``analysis``: that pose set's IdentifiabilityReport when the caller already has it)."""
    rng = np.random.default_rng([scene.truth.seed, STREAM_TRUTH])
    if analysis is None:
        analysis, _ = analyze_setup(scene.setup, truth_poses(scene), scene.identification.residual)
    return true_parameters(scene, rng, scene.setup.params.mask(analysis.base_parameters))


def unmodelled_truth(scene: Scene) -> tuple[Setup | None, np.ndarray | None]:
    """(truth setup, x_true (n_truth,)) when the scene's truth has errors the model does not share
    (``truth.unmodelled``), else (None, None). The truth's free parameters get random deviations with the
    scene's sigmas, then the scene's explicit deviations on the names both models share."""
    if not scene.truth.unmodelled:
        return None, None
    rng = np.random.default_rng([scene.truth.seed, STREAM_TRUTH, 1])
    tsetup = scene.setup.truth_model(scene.truth.unmodelled, rng, where=f"{scene.path}: truth")
    ps = tsetup.params
    sig = np.where(np.array(ps.kinds) == "length", scene.truth.sigma_length_m, scene.truth.sigma_angle_rad)
    x = ps.nominal + ps.free * rng.normal(size=len(ps)) * sig
    for k, v in scene.truth.deviations.items():
        if k in ps.names:
            x[ps.index(k)] = ps.nominal[ps.index(k)] + v
    return tsetup, x


def shared_truth(setup: Setup, truth: Setup, x_true: ArrayLike) -> np.ndarray:
    """(n,) true values of the identified setup's parameters that the truth model shares (NaN elsewhere)."""
    tv = truth.params.values(x_true)
    return np.array([tv.get(n, np.nan) for n in setup.params.names])


def run_analysis_and_truth(scene: Scene, poses: ArrayLike,
                           residual: str | None) -> tuple[IdentifiabilityReport, np.ndarray]:
    """(IdentifiabilityReport of ``poses``, x_true): one analysis when the run's poses are the truth's."""
    rep, _ = analyze_setup(scene.setup, poses, residual)
    tp = truth_poses(scene)
    same = residual == scene.identification.residual and np.shape(tp) == np.shape(poses) and np.array_equal(tp, poses)
    return rep, scene_truth(scene, rep if same else None)


def base_problem(setup: Setup, meas: Measurements, residual: str | None, base: ArrayLike,
                 context: str = "") -> tuple[IdentificationProblem, ParameterSet]:
    """(problem, params) identifying only the parameters of the ``base`` mask (n,) bool from
    measurements; IdentifiabilityError when the usable poses give fewer equations than that."""
    params = setup.params.only_free([n for n, b in zip(setup.params.names, base) if b])
    problem = setup.problem(meas, residual, params=params)
    n_prior = problem.n_prior  # a prior is one equation each (the H4 tilts' axis prior)
    if problem.n_obs * problem.m + n_prior < params.n_free:
        raise IdentifiabilityError(
            f"{setup.name}: only {problem.n_obs} usable poses ({problem.n_obs * problem.m} equations"
            + (f" + {n_prior} prior rows" if n_prior else "") + f") for {params.n_free} identifiable parameters: "
            f"need at least {int(np.ceil((params.n_free - n_prior) / problem.m))} poses"
            + (f" ({context})" if context else ""))
    return problem, params


def solve(problem: IdentificationProblem, method: str, fix_unidentifiable: bool = True,
          x0: ArrayLike | None = None) -> IdentificationResult:
    """One identification method on a problem ("ekf" = extended Kalman filter, passes until converged; any
    other = least squares on the problem's residuals: which residual a method means is
    ``Setup.residual_for``); the result carries the method's name."""
    if method == "ekf":
        return solve_ekf(problem, x0=x0, fix_unidentifiable=fix_unidentifiable)
    return replace(solve_lse(problem, x0=x0, fix_unidentifiable=fix_unidentifiable), method=method)


def check_method(setup: Setup, method: str, where: str) -> str:
    """ConfigError naming ``where`` when the setup's kind has no such method."""
    if method not in setup.methods:
        raise ConfigError(f"{where}: method {method!r} does not apply to a {setup.kind} robot "
                          f"(use {' or '.join(setup.methods)})")
    return method


@dataclass(frozen=True)
class Identified:
    """Identification from measured data: the result (std and covariance scaled by the a-posteriori
    variance factor when it exceeds 1), its problem (kept poses) and parameter set, the identifiability
    report (None when the caller gave the base mask), the poses rejected as outliers [(label, reason)],
    the chi-square adequacy of the fit (``identify.model_adequacy``, before scaling) and the factor."""

    result: IdentificationResult
    problem: IdentificationProblem
    params: ParameterSet
    analysis: IdentifiabilityReport | None
    rejected: tuple
    adequacy: dict
    variance_factor: float
    setup: Setup | None = None  #: the setup identified (after :func:`.prepare.prepare_setup`): evaluate and export with it
    prepared: dict = None  #: what :func:`.prepare.prepare_setup` determined from the data (e.g. the H4 camera axis)
    #: shared measurement error fitted as nuisance coefficients (``identify.nuisance``): {n_directions,
    #: coefficients (d,) and their std (posterior, in prior std units), std_inflation {name: std / std without
    #: it}}; None without
    nuisance: dict = None
    #: lack-of-fit tests of the final fit (``identify.lack_of_fit`` via :func:`lack_of_fit_of`): do the residuals
    #: depend on a joint (harmonics) or on the target's image position / depth? None when not computed
    lack_of_fit: dict = None
    #: the setup's other method on the same kept poses and base set, compared (:func:`method_check`); None without
    method_check: dict = None


def analyse_measurements(setup: Setup, meas: Measurements, residual: str | None, where: str = "",
                         context: str = "") -> IdentifiabilityReport:
    """Identifiability of the setup's problem on measured data ``meas`` (rows whitened by the measurement
    covariances, base parameters chosen by BASE_SELECTION); IdentifiabilityError naming ``where`` (default:
    the setup's name) and ``context`` when there is no pose or the analysis fails."""
    where, ctx = where or setup.name, f" ({context})" if context else ""
    if len(meas.T_cam_target) == 0:
        raise IdentifiabilityError(f"{where}: no usable poses{ctx}")
    try:
        return analyze(setup.problem(meas, residual), selection=BASE_SELECTION)
    except IdentifiabilityError as exc:
        raise IdentifiabilityError(f"{where}: {exc}{ctx}") from None


def prepare_measured(setup: Setup, meas: Measurements, residual: str | None, where: str = "",
                     context: str = "") -> tuple[Setup, dict, IdentifiabilityReport | None]:
    """The preparation step before an identification (:func:`.prepare.prepare_setup`: H4 camera axis and tilts)
    and what it does to the identifiability: (prepared setup, the report's ``prepared`` record, the
    :func:`analyse_measurements` of the prepared setup when the preparation changed the free parameters, else
    None: an analysis of the same poses made before still holds). Used by measured data
    (:func:`identify_measurements`) and synthetic runs (``synthetic.run_synthetic``)."""
    before = setup.params.free_names
    setup, prepared = prepare_setup(setup, meas)
    if setup.params.free_names == before:
        return setup, prepared, None
    return setup, prepared, analyse_measurements(setup, meas, residual, where, context)


def identify_measurements(setup: Setup, meas: Measurements, method: str, residual: str | None,
                          analysis: IdentifiabilityReport | None = None, context: str = "", robust: bool = True,
                          where: str = "", fix_unidentifiable: bool = False, rejected: Sequence[tuple[str, str]] = (),
                          nuisance: Callable | None = None, cross_check: bool = True,
                          diagnostics: bool = True, start: Mapping[str, float] | None = None) -> Identified:
    """Identification of the setup's identifiable free parameters from measured data ``meas`` (``rejected``:
    [(label, reason)] of poses the caller removed before; ``analysis``: the
    IdentifiabilityReport of these poses when the caller has it; a pose set that loses parameters generic
    poses identify is refused unless ``fix_unidentifiable``). With ``robust`` (and at least twice as many
    equations as parameters), poses failing a chi-square test after a robust fit are rejected
    (``identify.fit_rejecting_outliers``, family-wise false-alarm level OUTLIER_LEVEL) and the fit is
    redone without them; the std are then scaled by the
    a-posteriori variance factor chi2/dof when it exceeds 1 (the residuals show errors the measurement
    covariance misses). ``nuisance``: a shared measurement error (e.g. intrinsics calibrated from the same
    images), a callable (setup, meas, problem, x) -> U (n_obs, m, d) (or None) giving the response of every
    pose's residual to one std along each of its d independent directions; U is evaluated once at a first
    plain fit and the error enters every step (outlier test, fit, adequacy, variance factor, covariance) as d
    nuisance coefficients (``identify.nuisance``: the GLS fit with C = obs_cov + U U^T). With ``cross_check``
    and a method the setup's ``cross_methods`` pairs with another, that one runs too (:func:`method_check`).
    ``diagnostics``: the lack-of-fit tests of the final fit (:func:`lack_of_fit_of`, a warning when significant);
    False for a fit whose warnings nobody reads (a held-out fold: only its parameters are used), then
    ``Identified.lack_of_fit`` is None. ``start``: {parameter name: value} near the answer (e.g. the fit of a superset
    of these poses, for a held-out fold): the least squares of a method other than "ekf" start there for the free
    parameters it names (the others at their nominal values); the same minimum, fewer steps."""
    from ..identify import fit_rejecting_outliers, model_adequacy

    where = where or setup.name
    setup, prepared, reanalysis = prepare_measured(setup, meas, residual, where, context)
    rep = reanalysis if reanalysis is not None else analysis
    if rep is not None and not set(rep.base_parameters) <= set(setup.params.names):
        # an analysis made for another preparation (e.g. a held-out fold whose poses do not determine the H4
        # camera axis the whole data did): it does not apply to this setup, analyse these poses afresh
        rep = None
    if rep is None:
        rep = analyse_measurements(setup, meas, residual, where, context)
    structural_rank_check(setup, rep, residual, where, accept=fix_unidentifiable)
    base = setup.params.mask(rep.base_parameters)
    problem, params = base_problem(setup, meas, residual, base, context)
    rejected = list(rejected)  # poses the caller already rejected (e.g. motion consistency): kept in the record
    fitted = problem
    U = None if nuisance is None else nuisance(setup, meas, problem, solve_lse(problem).identified)
    if U is not None:
        fitted = with_nuisance(problem, U, NUISANCE_PREFIX)
    # the outlier test needs redundancy: with fewer equations than twice the parameters, a bad pose is
    # absorbed by the fit (high leverage) and good poses fail the test (measured: 1-2 of 6 H4 poses)
    if robust and problem.n_obs * problem.m >= 2 * params.n_free:
        fit, out = fit_rejecting_outliers(fitted, level=OUTLIER_LEVEL, min_ratio=OUTLIER_MIN_RATIO)
        if out:
            keep = [k for k, lab in enumerate(problem.labels) if lab not in {r[0] for r in out}]
            problem, fitted = problem.subset(keep), fitted.subset(keep)
            U = None if U is None else U[keep]
            rejected += out
        result = replace(fit, method=method) if method != "ekf" else solve(fitted, method)
    else:
        x0 = None
        if start and method != "ekf":  # (an EKF's start is its prior mean: not moved)
            x0 = fitted.params.nominal.copy()
            for i in fitted.params.free_index:
                x0[i] = float(start.get(fitted.params.names[i], x0[i]))
        result = solve(fitted, method, x0=x0)
    adequacy = model_adequacy(result, cov_scale=meas.cov_scale)  # of the augmented fit when there is a nuisance: the GLS chi-square
    nz = None
    if U is not None:
        result, nz = split_nuisance(result, len(params))
        nz = {"n_directions": int(U.shape[2]), "coefficients": nz["values"], "coefficients_std": nz["std"],
              "std_inflation": _std_inflation(problem, result)}
    factor = float(result.chi2_dof) if robust and np.isfinite(result.chi2_dof) else 1.0
    check = None
    if cross_check and setup.cross_methods.get(method):
        check = method_check(setup, meas, method, problem, result, U, nuisance, max(factor, 1.0))
    if factor > 1:
        result = replace(result, std=result.std * np.sqrt(factor), covariance=result.covariance * factor)
    extra = tuple(plausibility_warnings(params, result)) + ((prepared["warning"],) if prepared.get("warning") else ())
    if adequacy.get("verdict") == "too large":
        extra += (misfit_warning(adequacy),)
    lof = lack_of_fit_of(setup, meas, problem, result) if diagnostics else None
    if lof is not None and lof.get("significant"):
        extra += (lof["message"],)
    if rejected:
        extra += (f"{len(rejected)} outlier poses rejected: " + "; ".join(f"{lab}: {why}" for lab, why in rejected[:5]),)
    if check is not None and check["verdict"] == "disagree":
        extra += (method_check_line(check),)
    if extra:
        result = replace(result, warnings=tuple(result.warnings) + extra)
    return Identified(result, problem, params, rep, tuple(rejected), adequacy, max(factor, 1.0), setup, prepared,
                      nz, lof, check)


#: step [rad] of the central difference giving each pose's residual response to a joint error
JOINT_STEP_RAD = 1e-6


def lack_of_fit_of(setup: Setup, meas: Measurements, problem: IdentificationProblem, result: IdentificationResult,
                   level: float | None = None) -> dict:
    """``identify.lack_of_fit`` of ``result`` (fit of ``problem``, whose labels pick the poses of ``meas``): the
    joint groups use the measured joints with each pose's residual response to a true joint error (central
    difference of ``setup.problem`` in the reported joints), the image groups the target origin's normalised
    image coordinates and depth from the measured T_cam_target (left out when a pose's target is not in front of
    the "camera": poses measured by a tracker). {"significant": False, "error": why} when the
    tests cannot be computed (a diagnostic: it never stops the pipeline)."""
    from ..errors import VisionCalibError
    from ..identify.lack_of_fit import DEFAULT_LEVEL, lack_of_fit

    try:
        sub = meas.select(problem.labels)
        x = np.asarray(result.identified, float)
        q = np.asarray(sub.joints, float)
        G = np.zeros((problem.n_obs, problem.m, q.shape[1]))
        for j in range(q.shape[1]):
            dq = np.zeros_like(q)
            dq[:, j] = JOINT_STEP_RAD
            rp, rm = (setup.problem(replace(sub, joints=q + s * dq), problem.residual_kind, params=problem.params)
                      .residual(x) for s in (1.0, -1.0))
            G[:, :, j] = -(rp - rm) / (2 * JOINT_STEP_RAD)  # residual = measured - model(reported joints)
        T = np.asarray(sub.T_cam_target, float)
        seen = bool(np.all(T[:, 2, 3] > 0))  # a camera in front of the target; a tracker's frame need not be
        return lack_of_fit(problem, result, joints=q, joint_response=G,
                           image_xy=T[:, :2, 3] / T[:, 2:3, 3] if seen else None, depth=T[:, 2, 3] if seen else None,
                           level=DEFAULT_LEVEL if level is None else level)
    except (VisionCalibError, KeyError, np.linalg.LinAlgError) as exc:
        return {"significant": False, "error": f"lack-of-fit tests not computed: {exc}"}


def method_check(setup: Setup, meas: Measurements, method: str, problem: IdentificationProblem,
                 result: IdentificationResult, U: np.ndarray | None = None, nuisance: Callable | None = None,
                 noise_scale: float = 1.0) -> dict:
    """The setup's other method (``setup.cross_methods[method]``) on the poses ``problem`` kept, with its
    parameter set (base set, prepared setup), started from ``result``'s solution (and with the same shared
    error, when ``nuisance`` gave U (n_obs, m, d) for ``problem``), compared with ``result``
    (``identify.method_check.method_difference``: the difference's covariance from the two linearised
    estimators on the same measurement errors, not std_a^2 + std_b^2; the measurement errors' covariance
    times ``noise_scale``, the variance factor that scales the reported std). JSON-ready dict: methods,
    residual kinds, n_poses, per-parameter difference (``method`` - other, SI) / std / z / naive_std
    (sqrt(std_a^2 + std_b^2), for comparison only), chi2, dof, p_value, verdict, the other fit's convergence and
    chi2/dof, seconds."""
    import time

    from ..identify.method_check import method_difference

    t0 = time.perf_counter()
    other = setup.cross_methods[method]
    kept = meas.select(problem.labels)
    params = problem.params
    r_a, r_b = problem.residual_kind, setup.residual_for(other)
    prob_b = setup.problem(kept, r_b, params=params)
    fitted_b, U_b, x0 = prob_b, None, result.identified
    if U is not None:
        U_b = nuisance(setup, kept, prob_b, result.identified)
        if U_b is not None:
            fitted_b = with_nuisance(prob_b, U_b, NUISANCE_PREFIX)
            x0 = np.concatenate([x0, np.zeros(U_b.shape[2])])
    fit_b = solve(fitted_b, other, x0=x0)
    if U_b is not None:
        fit_b, _ = split_nuisance(fit_b, len(params))
    B_a, cov_e = setup.noise_response(kept, r_a, params, result.identified)
    B_b, _ = setup.noise_response(kept, r_b, params, fit_b.identified)
    both = U is not None and U_b is not None  # the shared error in both fits, else in neither
    d = method_difference(problem, result.identified, B_a, prob_b, fit_b.identified, B_b, cov_e * noise_scale,
                          U if both else None, U_b if both else None)
    fi = params.free_index
    naive = np.sqrt(noise_scale) * np.hypot(result.std[fi], fit_b.std[fi])  # what std_a^2 + std_b^2 would say
    return {"methods": [method, other], "residual_kinds": [r_a, r_b], "n_poses": int(problem.n_obs),
            "parameters": [{"name": n, "difference": v, "std": s, "z": z, "naive_std": float(nv)}
                           for n, v, s, z, nv in zip(d["names"], d["difference"], d["std"], d["z"], naive)],
            **{k: d[k] for k in ("max_abs_z", "worst", "chi2", "dof", "untested", "p_value", "level", "verdict")},
            "other": {"converged": bool(fit_b.converged), "chi2_dof": float(fit_b.chi2_dof),
                      "iterations": int(fit_b.iterations)},
            "shared_error": bool(both), "noise_scale": float(noise_scale), "seconds": time.perf_counter() - t0,
            "how": "difference of the two estimates; its covariance from the two linearised estimators applied to "
                   "the same measurement errors (A_a B_a - A_b B_b) cov(e) (.)^T, not std_a^2 + std_b^2, cov(e) "
                   "scaled by noise_scale (the variance factor of the reported std); chi-square on the directions "
                   "where the difference's variance is at least identify.method_check.MIN_RELATIVE_VARIANCE of the "
                   "estimate's (dof; 'untested': the others, where second-order effects dominate)"}


def misfit_warning(adequacy: dict, what: str = "the model", noise: str = "the measurement noise") -> str:
    """The warning of a "too large" ``identify.model_adequacy`` dict: chi2/dof against its expected band, the std
    scaled by sqrt(chi2/dof), the poses with the largest residuals."""
    worst = ", ".join(str(w["label"]) for w in adequacy["worst_poses"][:3])
    lo, hi = adequacy["expected_chi2_dof"]
    return (f"{what} does not explain the data at {noise}: chi2/dof = {adequacy['chi2_dof']:.3g} (expected "
            f"{lo:.2g}-{hi:.2g}); std scaled by sqrt(chi2/dof); largest residuals at poses {worst}")


def inconsistency_failure(ident: "Identified") -> dict | None:
    """The report's ``failure`` of a fit whose parameters are inconsistent with the data, whatever its held-out
    prediction of the measured poses says (a fit can predict T_cam_target better while the robot it writes is
    worse than the nominal one: the mounts absorb what the model misses): BOTH tests of the model reject it, the
    residuals above their chi-square band (adequacy verdict "too large") AND the setup's two methods disagreeing
    on the same poses (``method_check`` verdict "disagree": the estimate depends on the residual's form, which it
    does not when the model holds); each alone is a warning (a noise model that is off, a weak second method).
    None when either holds, or was not computed. The message says what to change: more poses / frames, the
    parameter the methods disagree on most, the poses with the largest residuals, and the preparation step's
    warning when it had one."""
    chk, adq = ident.method_check, ident.adequacy or {}
    c2 = adq.get("chi2_dof")
    if chk is None or chk.get("verdict") != "disagree" or adq.get("verdict") != "too large" or c2 is None \
            or not np.isfinite(c2):
        return None
    lo, hi = adq.get("expected_chi2_dof", (None, None))
    worst = ", ".join(str(w["label"]) for w in adq.get("worst_poses", [])[:3])
    prep = (ident.prepared or {}).get("warning")
    return {"kind": "model inconsistency",
            "message": (
                f"no calibrated model written: the fitted parameters are inconsistent with the data: chi2/dof "
                f"{c2:.3g} (expected {lo:.2g}-{hi:.2g}) and the {chk['methods'][0]} and {chk['methods'][1]} "
                f"estimates disagree (chi2 "
                f"{chk['chi2']:.3g} on {chk['dof']} dof, p {chk['p_value']:.2g}; largest |z| {chk['max_abs_z']:.3g} "
                f"on {chk['worst']}): a model that predicts the measured poses while its robot parameters absorb an "
                f"error it does not represent can be worse than the nominal robot. What to change: more poses "
                f"({ident.problem.n_obs} used) spread over the workspace and more frames per pose (less rotation "
                f"noise), check the mounts and the parameter {chk['worst']}; largest residuals at poses {worst}"
                + (f"; preparation step: {prep}" if prep else ""))}


#: name prefix of the nuisance coefficients of a shared measurement error (``identify_measurements(nuisance=)``)
NUISANCE_PREFIX = "shared_error"


def _std_inflation(problem, result) -> dict:
    """{free name: std of ``result`` / std of the same fit without the shared error} (both before any
    variance-factor scaling; the latter from ``problem``'s own Jacobian at the solution)."""
    from ..identify.lse import covariance_from_jacobian

    fi = np.flatnonzero(result.free)
    J = np.asarray(problem.jacobian(result.identified), float)[:, :, fi]
    Jw = np.einsum("kij,kjn->kin", problem.whitening(), J).reshape(-1, fi.size)
    cov0, _ = covariance_from_jacobian(Jw, problem.params.scale[fi])
    std0 = np.sqrt(np.diag(cov0))
    return {result.names[i]: float(result.std[i] / s0) for i, s0 in zip(fi, std0) if s0 > 0}


#: a large move is unexplained when the data do not determine it (|move| < MOVE_SIGMAS x its std) or the fit
#: leaves residuals far above the noise (chi2/dof > UNEXPLAINED_CHI2_DOF: residual std twice the predicted)
MOVE_SIGMAS = 3.0
UNEXPLAINED_CHI2_DOF = 4.0


def plausibility_warnings(params: ParameterSet, result: IdentificationResult, rel: float = 0.2,
                          length_floor_m: float = 0.05, angle_limit_rad: float = 0.2) -> list[str]:
    """Warnings for identified deviations too large to be calibration corrections that the data do not
    explain: a length moved by more than ``rel`` of max(|nominal|, length_floor_m), an angle by more than
    angle_limit_rad, AND either the move is not determined by the data (|move| < MOVE_SIGMAS x its std:
    a weakly identifiable direction absorbed it) or the fit leaves residuals far above the noise
    (``result.chi2_dof`` > UNEXPLAINED_CHI2_DOF). A large, well-determined move of a fit at the noise
    level (a roughly known mount) is a correction, not warned. Typical causes of a warning: wrong units in
    a file, a wrong target size, a wrong robot model, a parameter the poses do not excite."""
    out = []
    chi2 = float(result.chi2_dof)
    bad_fit = np.isfinite(chi2) and chi2 > UNEXPLAINED_CHI2_DOF
    for i in np.flatnonzero(result.free):
        dev = result.identified[i] - params.nominal[i]
        std = float(result.std[i])
        name = params.names[i]
        weak = not (np.isfinite(std) and abs(dev) >= MOVE_SIGMAS * std)
        if not (weak or bad_fit):
            continue
        why = (f"std {std * (1e3 if params.kinds[i] == 'length' else np.degrees(1)):.3g} "
               f"{'mm' if params.kinds[i] == 'length' else 'deg'}: the data do not determine it" if weak
               else f"the fit leaves residuals above the noise (chi2/dof = {chi2:.3g})")
        if params.kinds[i] == "length":
            lim = rel * max(abs(params.nominal[i]), length_floor_m)
            if abs(dev) > lim:
                out.append(f"{name} moved by {dev * 1e3:+.1f} mm from its nominal {params.nominal[i] * 1e3:.1f} mm "
                           f"({why}): too large for a calibration correction (units, target size, robot model?)")
        elif abs(dev) > angle_limit_rad:
            out.append(f"{name} moved by {np.degrees(dev):+.2f} deg ({why}): too large for a calibration "
                       "correction (units, robot model?)")
    return out


def rejection_summary(pms: Sequence) -> str:
    """'k of n poses rejected: reason (count); ...' for a list of PoseMeasurement."""
    bad = [pm.reason for pm in pms if not pm.valid]
    if not bad:
        return f"0 of {len(pms)} poses rejected"
    top = "; ".join(f"{r} ({c})" for r, c in Counter(bad).most_common(3))
    return f"{len(bad)} of {len(pms)} poses rejected: {top}"
