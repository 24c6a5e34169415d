"""Synthetic experiments without images: truth -> pose measurements ⊕ Gaussian noise ->
identifiability -> identification -> evaluation. Fast enough for Monte Carlo studies.

Seeds: the truth (robot deviations) comes from the scene's ``truth.seed``; poses, noise and
validation poses from the run seed through independent streams ``default_rng([seed, k])``.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import ConfigError, IdentifiabilityError
from ..identify import analyze, solve_ekf, solve_lse
from .scene import Scene, load_scene, scene_poses, true_parameters
from .setup import Measurements

STREAM_POSES, STREAM_NOISE, STREAM_VALIDATION, STREAM_TRUTH = 1, 2, 3, 4
#: base-parameter choice: keep earlier parameter names first (robot file order: left mount, joints,
#: right mount), so the same set is dropped whatever the pose set (pivoted QR depends on the poses)
BASE_SELECTION = "order"


def rngs(seed: int):
    """Independent generators (poses, noise, validation) of a run seed."""
    seed = int(seed)
    return (np.random.default_rng([seed, STREAM_POSES]), np.random.default_rng([seed, STREAM_NOISE]),
            np.random.default_rng([seed, STREAM_VALIDATION]))


def _scene(scene) -> Scene:
    return scene if isinstance(scene, Scene) else load_scene(scene)


def identifiability_report(scene: Scene, poses, residual: str | None = None, all_params: bool = False):
    """Identifiability of the scene's free parameters (every model parameter with ``all_params``)
    over ``poses`` at the nominal geometry with exact measurements: (IdentifiabilityReport, problem)."""
    setup = scene.setup
    x0 = setup.params.nominal
    meas = setup.synthetic_measurements(poses, x0, np.random.default_rng(0))
    problem = setup.problem(meas, residual or scene.identification["residual"])
    if all_params:  # bypass the builders' refusal of known-redundant pairs: the analysis must find them
        problem = problem.with_params(problem.params.only_free(problem.params.names))
    return analyze(problem, selection=BASE_SELECTION), problem


def report_to_json(rep) -> dict:
    return {
        "n_params": int(rep.n_params),
        "rank": int(rep.rank),
        "condition_number": float(rep.condition_number),
        "non_identifiable": list(rep.non_identifiable),
        "base_parameters": list(rep.base_parameters),
        "couplings": rep.couplings,
        "observability": {k: float(v) for k, v in rep.observability.items()},
        "singular_values": [float(s) for s in rep.singular_values],
        "scaling": rep.scaling,
        "n_equations": int(rep.n_equations),
    }


def identifiability_json(scene, residual=None, n_poses=None, seed=None, all_params=False) -> dict:
    """The CLI's ``identifiability`` output (one JSON object). all_params: analyse every model
    parameter, including those the model fixes by default (e.g. Hayati d, M_T_E.z)."""
    scene = _scene(scene)
    seed = 0 if seed is None else seed
    rp, _, _ = rngs(seed)
    poses = scene_poses(scene, rp, n_poses)
    rep, problem = identifiability_report(scene, poses, residual, all_params)
    out = {"scene": scene.name, "residual": problem.residual_kind, "n_poses": int(len(poses)), "seed": seed,
           "all_params": bool(all_params)}
    out.update(report_to_json(rep))
    return out


def base_problem_of(scene: Scene, meas, residual: str, base, context: str = ""):
    """(problem, params) identifying only the parameters of the ``base`` mask (n,) bool from
    measurements; IdentifiabilityError when the usable poses give fewer equations than that."""
    setup = scene.setup
    params = setup.params.only_free([n for n, b in zip(setup.params.names, base) if b])
    problem = setup.problem(meas, residual, params=params)
    if problem.n_obs * problem.m < params.n_free:
        raise IdentifiabilityError(
            f"{scene.name}: only {problem.n_obs} usable poses ({problem.n_obs * problem.m} equations) for "
            f"{params.n_free} identifiable parameters: need at least {int(np.ceil(params.n_free / problem.m))} poses"
            + (f" ({context})" if context else ""))
    return problem, params


def identify(problem, method: str, fix_unidentifiable: bool = True):
    """Run one identification method on a problem ("lse" and "igm" = least squares on the
    problem's residuals, "ekf" = extended Kalman filter)."""
    if method == "ekf":
        # 3 passes: one sequential pass on an ill-conditioned problem (H4) stays several std from
        # the LSE optimum (tests/identify/test_ekf.py); later passes relinearise at the estimate.
        res = solve_ekf(problem, passes=3, fix_unidentifiable=fix_unidentifiable)
        if not res.converged:  # slow (ill-conditioned) case: restart with more passes
            res = solve_ekf(problem, passes=8, fix_unidentifiable=fix_unidentifiable)
        return res
    return solve_lse(problem, fix_unidentifiable=fix_unidentifiable)


def scene_truth(scene: Scene) -> np.ndarray:
    """The scene's true parameters x_true (n,): a function of the scene (truth seed) only, whatever
    the run's poses. Random deviations go on the parameters identifiable from the scene's own
    identification poses (its default pose set)."""
    rng = np.random.default_rng([scene.truth["seed"], STREAM_TRUTH])
    rep, _ = identifiability_report(scene, scene_poses(scene, np.random.default_rng([scene.truth["seed"], 0])))
    return true_parameters(scene, rng, scene.setup.params.mask(rep.base_parameters))


def parameters_table(names, nominal, x_true, result) -> list[dict]:
    """Per-parameter rows: name, nominal, true (None on real data), identified, std, free."""
    out = []
    for i, n in enumerate(names):
        std = result.std[i]
        out.append({
            "name": n,
            "nominal": float(nominal[i]),
            "true": None if x_true is None else float(x_true[i]),
            "identified": float(result.identified[i]),
            "std": float(std) if np.isfinite(std) else None,
            "free": bool(result.free[i]),
        })
    return out


def run_synthetic(scene, method=None, residual=None, n_poses=None, sigma_t_m=None, sigma_r_rad=None, seed=0,
                  poses=None, validation=None, base=None, x_true=None):
    """One synthetic identification. Returns a dict with the result object, truth, poses and the
    accuracy before/after on validation poses (nominal vs identified parameters).

    poses / validation: commanded poses (default: drawn from the scene with the run seed).
    base: identifiable mask (n,) from a previous analysis (saves one SVD in Monte Carlo loops).
    """
    scene = _scene(scene)
    setup = scene.setup
    method = method or scene.identification["method"]
    if method == "igm" and setup.kind != "h4":
        raise ConfigError(f"{scene.path}: method 'igm' is the H4 inverse-model method; use lse or ekf for a serial arm")
    residual = residual or scene.identification["residual"]
    st = scene.measurement["sigma_t_m"] if sigma_t_m is None else sigma_t_m
    sr = scene.measurement["sigma_r_rad"] if sigma_r_rad is None else sigma_r_rad
    rp, rn, rv = rngs(seed)
    if poses is None:
        poses = scene_poses(scene, rp, n_poses)
    if validation is None:
        validation = scene_poses(scene, rv, which="validation")
    t0 = time.perf_counter()
    if base is None:
        rep, _ = identifiability_report(scene, poses, residual)
        base = setup.params.mask(rep.base_parameters)
    if x_true is None:
        x_true = scene_truth(scene)
    meas = setup.synthetic_measurements(poses, x_true, rn, st, sr, scene.measurement["sigma_q_rad"])
    problem, params = base_problem_of(scene, meas, residual, base)
    result = identify(problem, method)
    seconds = time.perf_counter() - t0
    meas_val = None
    if setup.kind == "h4":
        meas_val = setup.synthetic_measurements(validation, x_true, rv, st, sr, scene.measurement["sigma_q_rad"])
        before = setup.evaluate(setup.params.nominal, x_true, validation, meas_val)
        after = setup.evaluate(result.identified, x_true, validation, meas_val)
    else:
        before = setup.evaluate(setup.params.nominal, x_true, validation)
        after = setup.evaluate(result.identified, x_true, validation)
    return {"scene": scene, "result": result, "x_true": x_true, "poses": poses, "validation": validation,
            "measurements": meas, "problem": problem, "before": before, "after": after, "seconds": seconds,
            "method": method, "residual": residual, "base": base}


def identify_synthetic_json(scene, method=None, residual=None, n_poses=None, sigma_mm=None, sigma_deg=None,
                            seed=None) -> dict:
    """The CLI's ``identify-synthetic`` output."""
    scene = _scene(scene)
    seed = 0 if seed is None else seed
    out = run_synthetic(
        scene, method=method, residual=residual, n_poses=n_poses,
        sigma_t_m=None if sigma_mm is None else sigma_mm * 1e-3,
        sigma_r_rad=None if sigma_deg is None else np.radians(sigma_deg), seed=seed,
    )
    res = out["result"]
    ps = scene.setup.params
    return {
        "scene": scene.name,
        "method": out["method"],
        "residual": out["residual"],
        "seed": seed,
        "n_poses": int(len(out["poses"])),
        "sigma_mm": float((scene.measurement["sigma_t_m"] if sigma_mm is None else sigma_mm * 1e-3) * 1e3),
        "sigma_deg": float(np.degrees(scene.measurement["sigma_r_rad"]) if sigma_deg is None else sigma_deg),
        "parameters": parameters_table(ps.names, ps.nominal, out["x_true"], res),
        "accuracy": {"before": out["before"], "after": out["after"]},
        "converged": bool(res.converged),
        "iterations": int(res.iterations),
        "cost_initial": float(res.cost_initial),
        "cost_final": float(res.cost_final),
        "seconds": float(out["seconds"]),
        "warnings": list(res.warnings),
        "correlation_warnings": list(res.correlation_warnings),
    }


__all__ = ["identifiability_json", "identify_synthetic_json", "run_synthetic", "identify", "Measurements"]
