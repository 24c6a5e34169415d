"""The accuracy a pose set predicts: identify-synthetic Monte Carlo under the image measurement
(``experiment.synthetic.run_synthetic``: the scene's truth, synthetic pose measurements drawn from each pose's
image-model covariance for the frames the user records (``design.pose_covariances``), the scene's identification,
then the position error on the validation poses: the scene's random validation poses, new each draw, or the
user's ``--validate-on`` poses), and its first-order figure (``design.validation_mse``: sqrt(tr(W M^-1))).

For each pose count, the planned (D-optimal) poses and random measurable collision-free poses (drawn from the
same screened candidates, new ones each draw) are identified with the same draws (same noise and validation poses:
a paired comparison). Figures per set: the median and the 95th percentile of the validation position errors
[mm] pooled over the draws, and the median over the draws of their RMS (what ``simulate`` reports as the
validation position RMS).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..errors import VisionCalibError
from ..experiment.synthetic import run_synthetic

#: Monte Carlo draws per pose set (default)
DRAWS = 10
#: seeds of the draws: SEED_OFFSET + k (independent of the simulate seeds 0, 1, ... a user compares against)
SEED_OFFSET = 1000


def _stats(errs: list[np.ndarray], rms: list[float], failed: int, error: str | None = None) -> dict:
    e = np.concatenate(errs) if errs else np.zeros(0)
    return {"median_mm": float(np.median(e)) if e.size else None,
            "p95_mm": float(np.percentile(e, 95)) if e.size else None,
            "rms_median_mm": float(np.median(rms)) if rms else None,
            "rms_per_draw_mm": [float(v) for v in rms], "draws": len(rms), "failed_draws": failed,
            "first_error": error}


def monte_carlo(scene, poses_of_draw: Callable[[int], np.ndarray], base: np.ndarray, draws: int = DRAWS,
                frames: int | None = None, validation: np.ndarray | None = None) -> dict:
    """Validation position error figures (module docstring) of the pose sets ``poses_of_draw(k)`` (k = 0..draws-1),
    identified with the scene's base mask ``base`` (n_params,) bool, their noise from the image model at ``frames``
    frames per pose; ``validation`` (V, .): fixed validation poses (default the scene's, new each draw). A draw
    whose identification fails (an error of the package: too few usable equations...) is counted in
    ``failed_draws``."""
    from .design import pose_covariances

    errs, rms, failed, first = [], [], 0, None
    for k in range(draws):
        P = poses_of_draw(k)
        try:
            run = run_synthetic(scene, poses=P, seed=SEED_OFFSET + k, base=base, validation=validation,
                                pose_cov=pose_covariances(scene, P, frames))
        except VisionCalibError as exc:
            failed += 1
            first = first or str(exc)
            continue
        e = run.after.position_errors_mm
        errs.append(e)
        rms.append(float(np.sqrt(np.mean(e**2))))
    return _stats(errs, rms, failed, first)


def predicted_accuracy(scene, plan_of_count: Callable[[int], np.ndarray], pool: np.ndarray, counts, base: np.ndarray,
                       draws: int = DRAWS, seed: int = 0, given: np.ndarray | None = None, frames: int | None = None,
                       validation: np.ndarray | None = None) -> dict:
    """{counts: [...], rows: [{count, plan: figures, random: figures, ratio_rms}], given: figures | None}: the
    accuracy of the planned poses ``plan_of_count(n)`` and of n random poses of ``pool`` (K, .) for each count,
    and of the ``given`` pose set (a user's list) when given (its count among the rows); ``frames`` per pose,
    ``validation`` poses as :func:`monte_carlo`."""
    rows = []
    frames = int(frames or scene.measurement.frames)
    for n in counts:
        P = plan_of_count(n)
        rng = np.random.default_rng([seed, n])
        picks = [np.sort(rng.choice(len(pool), n, replace=False)) for _ in range(draws)]
        plan = monte_carlo(scene, lambda k: P, base, draws, frames, validation)
        rand = monte_carlo(scene, lambda k: pool[picks[k]], base, draws, frames, validation)
        ratio = (plan["rms_median_mm"] / rand["rms_median_mm"]
                 if plan["rms_median_mm"] is not None and rand["rms_median_mm"] else None)
        rows.append({"count": int(n), "plan": plan, "random": rand, "ratio_rms": ratio})
    from .design import SYSTEMATIC_CORNER_PX

    out = {"method": scene.identification.method, "draws": int(draws),
           "noise": {"model": "image: Cramér-Rao bound of the corners (camera, target, sensor noise and blur) + "
                              f"systematic corner error {SYSTEMATIC_CORNER_PX:g} px, per pose",
                     "frames": frames, "sigma_q_deg": float(np.degrees(scene.measurement.sigma_q_rad))},
           "validation": (f"the scene's {scene.validation.count or 30} validation poses ({scene.validation.kind}, new "
                          "each draw) over the workspace" if validation is None else
                          f"the {len(validation)} given validation poses"),
           "seeds": f"run_synthetic seed {SEED_OFFSET} + k, k = 0..{draws - 1} (the same for every pose set)",
           "counts": [int(n) for n in counts], "rows": rows, "given": None}
    if given is not None:
        out["given"] = monte_carlo(scene, lambda k: given, base, draws, frames, validation)
    return out


__all__ = ["predicted_accuracy", "monte_carlo", "DRAWS"]
