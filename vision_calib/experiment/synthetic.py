"""Synthetic experiments without images: truth -> pose measurements ⊕ Gaussian noise ->
identifiability -> identification -> evaluation. Fast enough for Monte Carlo studies.

Seeds: see :mod:`.steps` (truth from the scene's ``truth.seed``, the rest from the run seed).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ..identify import model_adequacy
from ..identify.problem import IdentificationProblem, IdentificationResult
from ..report.build import misfit_message, parameters_table, verdict
from ..rig import Evaluation, Measurements, Scene, Setup, load_scene, scene_poses
from .steps import (analyze_setup, base_problem, check_method, lack_of_fit_of, prepare_measured, rngs, scene_truth,
                    shared_truth, solve, unmodelled_truth)


def _scene(scene: Scene | str | Path) -> Scene:
    return scene if isinstance(scene, Scene) else load_scene(scene)


@dataclass(frozen=True)
class SyntheticRun:
    """One synthetic identification: the result, truth x_true (n,), poses, validation poses, the
    measurements and problem, accuracy before (nominal) / after (identified) on the validation poses."""

    scene: Scene
    result: IdentificationResult
    x_true: np.ndarray
    poses: np.ndarray
    validation: np.ndarray
    measurements: Measurements
    problem: IdentificationProblem
    before: Evaluation
    after: Evaluation
    seconds: float
    method: str
    residual: str
    base: np.ndarray
    truth: Setup | None = None  #: the truth setup when it is not the identified model (x_true is then its vector)
    setup: Setup | None = None  #: the setup identified (after :func:`.prepare.prepare_setup` when asked; params match result)
    prepared: dict | None = None  #: what :func:`.prepare.prepare_setup` determined from the data (report's ``prepared`` block)


def identifiability_json(scene: Scene | str | Path, residual: str | None = None, n_poses: int | None = None,
                         seed: int | None = None, all_params: bool = False) -> dict:
    """The CLI's ``identifiability`` output (one JSON object). all_params: analyse every model
    parameter, including those the model fixes by default (e.g. Hayati d, M_T_E.z)."""
    scene = _scene(scene)
    seed = 0 if seed is None else seed
    poses = scene_poses(scene, rngs(seed)[0], n_poses)
    rep, problem = analyze_setup(scene.setup, poses, residual or scene.identification.residual, all_params)
    return {"scene": scene.name, "residual": problem.residual_kind, "n_poses": int(len(poses)), "seed": seed,
            "all_params": bool(all_params), **rep.to_dict()}


def run_synthetic(scene: Scene | str | Path, method: str | None = None, residual: str | None = None,
                  n_poses: int | None = None, sigma_t_m: float | None = None, sigma_r_rad: float | None = None,
                  seed: int = 0, poses: ArrayLike | None = None, validation: ArrayLike | None = None,
                  base: ArrayLike | None = None, x_true: ArrayLike | None = None, truth: Setup | None = None,
                  prepare: bool = True, pose_cov: ArrayLike | None = None, validation_cov: ArrayLike | None = None,
                  validation_measured: ArrayLike | None = None, sigma_q_rad: float | None = None,
                  noise_rngs: tuple[np.random.Generator, np.random.Generator] | None = None) -> SyntheticRun:
    """One synthetic identification (see :class:`SyntheticRun`).

    poses / validation: commanded poses (default: drawn from the scene with the run seed).
    base: identifiable mask (n,) from a previous analysis (saves one SVD in Monte Carlo loops).
    truth: the setup that produces the measurements (default the scene's; another model, e.g. an H4
    model-31 robot identified as model 12, to study model error), with parameters x_true.
    prepare (default): run :func:`.steps.prepare_measured` on the measurements first, as measured data do (H4: camera
    axis and tilt parameters; the base mask is then re-analysed when prepare frees parameters; the result then has
    the prepared setup's parameters, H4: 4 tilt parameters appended). Without it an H4 truth with mount
    tilts ends ~10 mm off after calibration (the kinematic parameters absorb the camera tilt, README);
    False only to study exactly that.
    pose_cov: (N, 6, 6) covariance of each identification pose's noise (``frames.pose_error`` convention, e.g.
    the covariances image measurements gave: a like-for-like reference of an image run), instead of
    sigma_t_m / sigma_r_rad; validation_cov: the same for the validation measurements (V1/V2), of the
    validation poses ``validation_measured`` (M,) indices (default: all; none: no validation measurements,
    the criteria that need them are left out). sigma_q_rad: joint-reading noise
    (default the scene's). noise_rngs: (identification noise, validation noise) generators (default the run
    seed's streams, :func:`.steps.rngs`).
    """
    scene = _scene(scene)
    setup = scene.setup
    method = check_method(setup, method or scene.identification.method, f"{scene.path}: method")
    residual = setup.residual_for(method, residual or scene.identification.residual)
    m = scene.measurement
    st = m.sigma_t_m if sigma_t_m is None else sigma_t_m
    sr = m.sigma_r_rad if sigma_r_rad is None else sigma_r_rad
    sq = m.sigma_q_rad if sigma_q_rad is None else sigma_q_rad
    rp, rn, rv = rngs(seed)
    if poses is None:
        poses = scene_poses(scene, rp, n_poses)
    if validation is None:
        validation = scene_poses(scene, rv, which="validation")
    t0 = time.perf_counter()
    if base is None:
        rep, _ = analyze_setup(setup, poses, residual)
        base = setup.params.mask(rep.base_parameters)
    if x_true is None and truth is None:
        truth, x_true = unmodelled_truth(scene)
    if x_true is None:
        x_true = scene_truth(scene)
    truth_setup = truth or setup
    if noise_rngs is not None:
        rn, rv = noise_rngs
    meas = truth_setup.synthetic_measurements(poses, x_true, rn, st, sr, sq, pose_cov=pose_cov)
    prepared = {}
    if prepare:
        setup, prepared, reanalysis = prepare_measured(setup, meas, residual, scene.name)
        if reanalysis is not None:  # the preparation freed parameters: the base mask of the prepared setup
            base = setup.params.mask(reanalysis.base_parameters)
    problem, _ = base_problem(setup, meas, residual, base)
    result = solve(problem, method)
    seconds = time.perf_counter() - t0
    vi = np.arange(len(validation)) if validation_measured is None else np.asarray(validation_measured, int)
    meas_val = None if vi.size == 0 else truth_setup.synthetic_measurements(
        np.asarray(validation)[vi], x_true, rv, st, sr, sq, labels=[f"v{i:03d}" for i in vi], pose_cov=validation_cov)
    before = setup.evaluate(setup.params.nominal, x_true, validation, meas_val, truth=truth_setup)
    after = setup.evaluate(result.identified, x_true, validation, meas_val, truth=truth_setup)
    return SyntheticRun(scene, result, x_true, poses, validation, meas, problem, before, after, seconds, method,
                        residual, base, truth, setup, prepared)


def identify_synthetic_json(scene: Scene | str | Path, method: str | None = None, residual: str | None = None,
                            n_poses: int | None = None, sigma_mm: float | None = None, sigma_deg: float | None = None,
                            seed: int | None = None) -> dict:
    """The CLI's ``identify-synthetic`` output."""
    scene = _scene(scene)
    seed = 0 if seed is None else seed
    st = scene.measurement.sigma_t_m if sigma_mm is None else sigma_mm * 1e-3
    sr = scene.measurement.sigma_r_rad if sigma_deg is None else float(np.radians(sigma_deg))
    out = run_synthetic(scene, method=method, residual=residual, n_poses=n_poses, sigma_t_m=st, sigma_r_rad=sr,
                        seed=seed, prepare=True)  # as measured data (simulate, process) do
    res = out.result
    ps = out.setup.params  # after prepare_setup (H4: the tilt parameters)
    adequacy = model_adequacy(res)
    warnings = list(res.warnings) + ([out.prepared["warning"]] if out.prepared.get("warning") else [])
    if adequacy["verdict"] == "too large":
        warnings.append("the model does not explain the data at the measurement noise: " + misfit_message(adequacy))
    lof = lack_of_fit_of(out.setup, out.measurements, out.problem, res)
    if lof.get("significant"):
        warnings.append(lof["message"])
    return {
        "scene": scene.name,
        "method": out.method,
        "residual": out.residual,
        "seed": seed,
        "n_poses": int(len(out.poses)),
        "sigma_mm": float(st * 1e3),
        "sigma_deg": float(np.degrees(sr)),
        "verdict": verdict(res, warnings=warnings[len(res.warnings):], adequacy=adequacy, lack_of_fit=lof),
        "parameters": parameters_table(ps.names, ps.nominal, shared_truth(out.setup, out.truth or scene.setup,
                                                                          out.x_true), res, ps.kinds),
        "accuracy": {"before": out.before.to_dict(), "after": out.after.to_dict()},
        "converged": bool(res.converged),
        "iterations": int(res.iterations),
        "cost_initial": float(res.cost_initial),
        "cost_final": float(res.cost_final),
        "seconds": float(out.seconds),
        "adequacy": adequacy,
        "lack_of_fit": lof,
        "prepared": out.prepared or None,
        "warnings": warnings,
        "correlation_warnings": list(res.correlation_warnings),
    }


__all__ = ["identifiability_json", "identify_synthetic_json", "run_synthetic", "SyntheticRun"]
