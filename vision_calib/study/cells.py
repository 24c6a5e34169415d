"""One cell of a study: its poses and one run (cell x repetition) in synthetic or images mode -> one table row
(the cell's scene, variant / model / trial applied: :func:`.spec.cell_scene`)."""

from __future__ import annotations

import functools
import threading
from dataclasses import replace

import numpy as np

from ..errors import VisionCalibError
from ..rig.base import ACCURACY_FIELDS
from .spec import ACCURACY_KEYS, StudySpec, run_seed, scene_with, scene_with_trial


@functools.lru_cache(maxsize=4)
def _load_scene_cached(path: str, spec_hash: str):
    from ..rig import load_scene

    return load_scene(path)


@functools.lru_cache(maxsize=32)
def scene_for(scene_path: str, variant, model, spec_hash: str = "", trial=None):
    """Scene of a cell in a worker (cached per process and spec hash, which covers the scene's
    files; values were validated by load_study)."""
    return scene_with_trial(scene_with(_load_scene_cached(scene_path, spec_hash), variant, model), trial)


def _sigmas(scene, s: dict) -> tuple[float, float]:
    """The cell's synthetic pose noise [m, rad] (sweep value, else the scene's)."""
    st = scene.measurement.sigma_t_m if s.get("sigma_mm") is None else s["sigma_mm"] * 1e-3
    sr = scene.measurement.sigma_r_rad if s.get("sigma_deg") is None else float(np.radians(s["sigma_deg"]))
    return float(st), float(sr)


@functools.lru_cache(maxsize=32)
def _selected_poses(scene_path: str, variant, model, spec_hash: str, trial, residual: str, n, criterion: str,
                    sigma_t_m: float, sigma_r_rad: float, pool_seed: int) -> np.ndarray:
    """Poses (n, .) chosen by ``criterion`` from the scene's pose pool (cached per process): the
    pool is ``scene_poses(scene, rngs(pool_seed)[0])`` (all of a grid / configuration set), the
    problem is built at the nominal geometry from exact measurements weighted by the given pose
    sigmas and restricted to the parameters identifiable from the whole pool."""
    from ..identify import analyze
    from ..identify.pose_selection import select_poses
    from ..rig import pose_cov_from_sigmas, scene_poses
    from ..experiment.steps import BASE_SELECTION, rngs

    setup = scene_for(scene_path, variant, model, spec_hash, trial).setup
    pool = scene_poses(scene_for(scene_path, variant, model, spec_hash, trial), rngs(pool_seed)[0])
    meas = setup.synthetic_measurements(pool, setup.params.nominal, np.random.default_rng(0))
    meas = replace(meas, cov=pose_cov_from_sigmas(len(pool), sigma_t_m, sigma_r_rad))
    problem = setup.problem(meas, residual)
    rep = analyze(problem, selection=BASE_SELECTION)
    problem = problem.with_params(problem.params.only_free(rep.base_parameters))
    idx = select_poses(problem, len(pool) if n is None else int(n), criterion)
    out = np.asarray(pool)[idx]
    out.setflags(write=False)
    return out


def cell_poses(spec: StudySpec, scene, s: dict, seed: int, residual: str) -> np.ndarray:
    """Identification poses of a run: a random subset (pose stream of the run seed) or, with
    ``pose_selection`` D/E, the cell's deterministic optimal subset of the scene's pose pool."""
    from ..experiment.steps import rngs
    from ..rig import scene_poses

    crit = s.get("pose_selection", "random")
    if crit == "random":
        return scene_poses(scene, rngs(seed)[0], s.get("n_poses"))
    return np.array(_selected_poses(str(spec.scene_path), s.get("variant"), s.get("model"), spec.hash,
                                    s.get("trial"), residual, s.get("n_poses"), crit, *_sigmas(scene, s),
                                    run_seed(spec.seed, 0)))


# ----------------------------------------------------------------------------- one run
def run_cell(spec: StudySpec, cell: dict, repetition: int) -> dict:
    """One run (cell x repetition): a pure function of its arguments. Returns the row dict
    (see the package docstring); a VisionCalibError of the run becomes a row with ``error`` set."""
    s = {**spec.settings, **cell}
    seed = run_seed(spec.seed, repetition)
    row = {"study": spec.name, **cell, "repetition": int(repetition), "seed": seed, "error": ""}
    scene = scene_for(str(spec.scene_path), s.get("variant"), s.get("model"), spec.hash, s.get("trial"))
    try:
        out = (_run_images if spec.mode == "images" else _run_synthetic)(spec, scene, s, seed)
    except (VisionCalibError, np.linalg.LinAlgError) as exc:
        row.update({"error": f"{type(exc).__name__}: {exc}", "converged": False})
        return row
    row.update({"converged": bool(out["converged"]), "iterations": int(out["iterations"]),
                "seconds": float(out["seconds"]), "n_free": int(out["n_free"])})
    for when in ("before", "after"):
        d = out[when]
        if "accuracy" in spec.outputs:
            row.update({f"{when}_{k}": float(d[k]) for k in ACCURACY_KEYS})
        if "criteria" in spec.outputs:  # the kind's own figures (H4: V1..V3)
            row.update({f"{when}_{k}": float(v) for k, v in d.items() if k not in ACCURACY_FIELDS})
    if "condition" in spec.outputs:
        row["cond"] = float(out["cond"])
    if "parameters" in spec.outputs:
        for p in out["parameters"]:
            if spec.parameters is not None and p["name"] not in spec.parameters:
                continue
            free = p["free"] and p["true"] is not None
            row[f"err:{p['name']}"] = float(p["identified"] - p["true"]) if free else float("nan")
            row[f"std:{p['name']}"] = float(p["std"]) if free and p["std"] is not None else float("nan")
    return row


def _run_synthetic(spec: StudySpec, scene, s: dict, seed: int) -> dict:
    """Synthetic run (experiment.synthetic.run_synthetic) -> the fields run_cell records. With
    ``truth_variant``, the measurements come from that variant's robot (deviations on all its free
    parameters) while the cell's model is identified (model error); parameter errors are recorded for
    the names both models share."""
    from ..experiment.steps import STREAM_TRUTH, analyze_setup, shared_truth
    from ..experiment.synthetic import run_synthetic
    from ..report.build import parameters_table
    from ..rig import true_parameters

    residual = s.get("residual") or scene.identification.residual
    poses = cell_poses(spec, scene, s, seed, residual)
    rep, _ = analyze_setup(scene.setup, poses, residual)
    base = scene.setup.params.mask(rep.base_parameters)
    truth, x_true = None, None
    if spec.truth_variant is not None:
        tscene = scene_for(str(spec.scene_path), spec.truth_variant, None, spec.hash)
        truth = tscene.setup
        tseed = seed if spec.truth == "per_run" else tscene.truth.seed
        x_true = true_parameters(tscene, np.random.default_rng([tseed, STREAM_TRUTH]))
    elif spec.truth == "per_run":
        x_true = true_parameters(scene, np.random.default_rng([seed, STREAM_TRUTH]), base)
    st, sr = _sigmas(scene, s)
    # prepare as measured data do (H4: mount tilts of the scene's truth measured from the rotation axis; without
    # it the kinematic parameters absorb them, z-scores ~10)
    out = run_synthetic(scene, method=s.get("method"), residual=residual, poses=poses, seed=seed, base=base,
                        x_true=x_true, truth=truth, sigma_t_m=st, sigma_r_rad=sr, prepare=True)
    res, ps = out.result, out.setup.params
    # true values of the names both models share (NaN elsewhere -> no error recorded)
    x_shared = shared_truth(out.setup, out.truth or scene.setup, out.x_true)
    return {"converged": res.converged, "iterations": res.iterations, "seconds": out.seconds,
            "n_free": int(res.free.sum()), "before": out.before.to_dict(), "after": out.after.to_dict(),
            "cond": rep.condition_number, "parameters": parameters_table(ps.names, ps.nominal, x_shared, res)}


_LOCAL = threading.local()  # per thread: {chain key: InlineImagePool}


def image_pool(scene):
    """The image chain of an images-mode run, in the thread that runs it (``image_chain.InlineImagePool``): a
    study's parallelism is its workers (local processes, Dask workers), one run each, so a run never starts a
    pool of its own (a daemonic Dask worker may not have children; nested pools oversubscribe the cores and were
    left holding their children). One per thread and camera/target/supersampling, built at the thread's first
    images-mode run and reused by its next runs (target geometry, renderer, sensor tables built once)."""
    from ..experiment.image_chain import InlineImagePool
    from ..experiment.simulate import image_chain_of

    chain = image_chain_of(scene)
    pools = getattr(_LOCAL, "pools", None)
    if pools is None:
        pools = _LOCAL.pools = {}
    key = (chain.target_path, chain.camera, chain.supersample)
    if key not in pools:
        pools[key] = InlineImagePool(chain)
    return pools[key]


def _run_images(spec: StudySpec, scene, s: dict, seed: int) -> dict:
    """End-to-end run (render + measure + identify, experiment.simulate.run_simulation without its synthetic
    reference, which the row does not record), the image chain in this thread (:func:`image_pool`)."""
    from ..experiment.simulate import run_simulation

    if s.get("residual"):
        scene = replace(scene, identification=replace(scene.identification, residual=s["residual"]))
    overrides = {k: s[k] for k in ("noise_grey", "blur_px") if s.get(k) is not None}
    rep = run_simulation(scene, out_dir=None, seed=seed, n_poses=s.get("n_poses"), frames=s.get("frames"),
                         method=s.get("method"), workers=1, progress=False, overrides=overrides,
                         pool=image_pool(scene), reference=False, accuracy_map=False)
    ident = rep["identification"]
    return {"converged": ident["converged"], "iterations": ident["iterations"],
            "seconds": rep.get("timings_s", {}).get("identify", float("nan")),
            "n_free": sum(1 for p in rep["parameters"] if p["free"]),
            "before": rep["accuracy"]["before"], "after": rep["accuracy"]["after"],
            "cond": rep["identifiability"]["condition_number"], "parameters": rep["parameters"]}
