"""The choice of the poses among the screened candidates and the figures of a design.

Every candidate's information is whitened by the pose covariance the image measurement will give it
(:func:`pose_covariances`: camera model, the target's projected corners, the corner noise, frames per pose). The
choice: D-optimal for the base parameters (``identify.pose_selection.select_poses``), then a Fedorov exchange on
the predicted mean squared position error over the validation poses, tr(W M^-1) (:func:`validation_blocks`,
:func:`refine_for_validation`). Figures: D criterion, D-efficiency against another design, each pose's leverage,
the first-order validation RMS quantiles over noise draws (:func:`validation_rms_quantiles`).

The exchange algorithm holds every candidate pair's information in memory ((K m)^2 numbers for K candidates of m
rows), so it runs on a pool: the :data:`POOL_TOP` candidates of largest leverage in the information of all screened
candidates (at most :data:`MAX_INFO` of them, drawn at random; leverage = trace(A_k M^-1 A_k^T): how much of the
parameter space a pose alone pins down; the extreme poses a D-optimal design needs are among them) and
:data:`POOL_RANDOM` others drawn at random. On the UR5e cell this pool gave validation errors 0.66x those of random
poses (synthetic, 10 seeds; D criterion alone, fixed pose noise), against 0.78x for a pool of 300 random
candidates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import IdentifiabilityError
from ..experiment.steps import analyze_setup, base_problem
from ..identify.pose_selection import design_criterion, information_blocks, select_poses

POOL_TOP = 200
POOL_RANDOM = 100
MAX_INFO = 4000
#: candidates analysed for the base parameters (identifiability at the nominal, SVD)
BASE_POSES = 300
#: exchange restarts of select_poses (from random designs; 0: greedy start only)
RESTARTS = 1
#: systematic corner error [px, per coordinate] of the detector, the same in every frame of a pose (the part of
#: ``measure.covariance``'s model that does not average over frames), chosen so that the planner's information
#: equals what the identification gets: the measurement's own per-pose covariance (which the fit weights by) over
#: its mean chi2/6 of the true errors, for rendered, detected and PnP-measured poses (``benchmarks/bench_plan_noise.py
#: --poses 60``, 2 frames, A5/H4 ChArUco boards, the scenes' noise and blur): 0.0203 px on the UR5e, 0.0196 px on the
#: RX-90, 0.0232 px on the H4 scene. The true errors' mean chi2/6 = 1 (0.0238 / 0.0252 / 0.0293 px) is not the
#: criterion: the systematic error varies from view to view and the fit weights each pose by its own estimate, so
#: its information is a harmonic mean over the poses, larger than that of one common error (at 0.025 px the planner
#: held 0.62-0.66x the information on the UR5e and RX-90 and predicted their validation RMS ~1.25x too high)
SYSTEMATIC_CORNER_PX = 0.021
#: growth of that error on oblique views [px]: s(theta)^2 = SYSTEMATIC_CORNER_PX^2 + (OBLIQUE_CORNER_PX tan theta)^2,
#: theta the angle between the board's normal and the line of sight to the pattern's centre (foreshortened
#: squares: the corner refiner's window takes in more of the neighbouring edges). The information-matched s per
#: 10-degree band of theta (``benchmarks/bench_plan_noise.py --by-angle``, 80 poses a scene): 0.020 px at 0-10 deg
#: (RX-90), 0.023 px at 30-40 deg and 0.035 px at 40-60 deg (the thesis eye-in-hand scene's steep views)
OBLIQUE_CORNER_PX = 0.02
#: noise draws of the first-order validation RMS distribution (:func:`validation_rms_quantiles`)
RMS_DRAWS = 4000
#: the validation criterion's exchange stops after this many swaps
MAX_SWAPS = 200


@dataclass(frozen=True)
class Information:
    """Information of candidate poses for the base parameters: A (K, m, L) the scaled whitened Jacobian blocks
    (``identify.pose_selection.information_blocks``), ``base`` (n_params,) bool, the base-parameter names, the
    residual kind, the analysis (IdentifiabilityReport) of the poses it was computed on."""

    A: np.ndarray
    base: np.ndarray
    names: tuple[str, ...]
    residual: str
    analysis: object
    cov: np.ndarray | None = None


def pose_covariances(scene, poses: np.ndarray, frames: int | None = None) -> np.ndarray:
    """(K, 6, 6) [m, rad] covariance of the target pose ``measure`` will give at commanded poses (K, .) with
    ``frames`` frames each (default the scene's ``measurement.frames``), at the nominal geometry: the image model's
    Cramér-Rao bound of the frame-averaged corners (``measure.covariance.image_bound_pose_cov``: the scene's camera,
    target, sensor noise and blur) plus the detector's systematic corner error s(theta) (:func:`systematic_corner_px`:
    :data:`SYSTEMATIC_CORNER_PX`, growing on oblique views), the same in every frame of a pose (the random +
    systematic model of ``measure.covariance``): + s^2 (J^T J)^-1, J the reprojection Jacobian of the target's
    corners (2K_c, 6)."""
    from ..measure.covariance import image_bound_pose_cov
    from ..measure.pnp import reprojection_jacobian
    from ..targets import load_target
    from .view import incidence_rad

    setup = scene.setup
    nf = int(frames or scene.measurement.frames)
    target = load_target(scene.target_path)
    _, p = target.corner_points()
    T = setup.T_cam_target(np.asarray(poses), setup.params.nominal)
    s2 = systematic_corner_px(incidence_rad(T, target)) ** 2
    out = np.empty((len(T), 6, 6))
    for k, Tk in enumerate(T):
        J = reprojection_jacobian(Tk, p, setup.camera)
        out[k] = image_bound_pose_cov(target, setup.camera, Tk, scene.effects, nf) + s2[k] * np.linalg.pinv(J.T @ J)
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def systematic_corner_px(incidence_rad: np.ndarray) -> np.ndarray:
    """(K,) the detector's systematic corner error s(theta) [px] (:data:`SYSTEMATIC_CORNER_PX`,
    :data:`OBLIQUE_CORNER_PX`) at the views' incidence angles theta (K,) [rad] (``view.incidence_rad``)."""
    return np.hypot(SYSTEMATIC_CORNER_PX, OBLIQUE_CORNER_PX * np.tan(np.clip(incidence_rad, 0.0, np.pi / 2 - 1e-6)))


def base_mask(scene, poses: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, object]:
    """(base parameter mask (n_params,) bool, IdentifiabilityReport) over up to BASE_POSES of the poses."""
    k = min(len(poses), BASE_POSES)
    sub = poses if k == len(poses) else poses[np.sort(rng.choice(len(poses), k, replace=False))]
    rep, _ = analyze_setup(scene.setup, sub, scene.identification.residual)
    return scene.setup.params.mask(rep.base_parameters), rep


def _problem(scene, poses: np.ndarray, base: np.ndarray, cov: np.ndarray | None = None, frames: int | None = None):
    setup = scene.setup
    residual = setup.residual_for(scene.identification.method, scene.identification.residual)
    cov = pose_covariances(scene, poses, frames) if cov is None else cov
    meas = setup.synthetic_measurements(poses, setup.params.nominal, np.random.default_rng(0), pose_cov=cov)
    problem, params = base_problem(setup, meas, residual, base)
    return problem, params, residual


def information(scene, poses: np.ndarray, base: np.ndarray, analysis=None, frames: int | None = None) -> Information:
    """Information blocks of commanded poses (K, .) for the ``base`` parameters, at the nominal geometry whitened
    by the image model's pose covariance (:func:`pose_covariances`, ``frames`` per pose); ``cov`` (K, 6, 6) kept."""
    cov = pose_covariances(scene, poses, frames)
    problem, params, residual = _problem(scene, poses, base, cov)
    return Information(information_blocks(problem), np.asarray(base, bool), tuple(params.free_names), residual, analysis,
                       cov)


def with_axis_tilts(scene, poses: np.ndarray, base: np.ndarray, cov: np.ndarray, validation: np.ndarray):
    """What the identification estimates beyond the base parameters, for a setup with the preparation step
    ``experiment.prepare`` (capability ``rig.base.TiltsFromAxis``, the H4, tilt_mode not "off"): its four tilt
    parameters, identified with the rotation-axis estimate as their prior. Returns (A (K, m + 3, L + 4): the blocks
    of the commanded poses (K, .) on the base parameters and the tilts, whitened by the pose covariances cov
    (K, 6, 6), each with the 3 rows the pose adds to the axis fit (``identify.camera_axis.axis_information_rows``:
    the prior's information is the sum over the design's poses), W (L + 4, L + 4): the validation weight of the
    validation poses (V, .) on them), or None for other setups (nothing estimated beyond the base parameters)."""
    from dataclasses import replace

    from ..identify.camera_axis import axis_information_rows
    from ..rig.base import TiltsFromAxis

    setup = scene.setup
    if not isinstance(setup, TiltsFromAxis) or setup.tilt_mode == "off":
        return None
    tilted = setup.with_tilts(np.zeros(4), np.ones(4))
    names = list(tilted.params.names)
    base_t = np.array([n in setup.tilt_names or bool(base[setup.params.names.index(n)]) for n in names])
    sc = replace(scene, setup=tilted)
    problem, params, _ = _problem(sc, poses, base_t, cov)
    A = information_blocks(problem)
    cols = [list(params.free_names).index(n) for n in setup.tilt_names]
    scale = params.scale[params.free_index][cols]
    R_BC0, R_ME0 = setup.tilt_reference()
    T = setup.T_cam_target(np.asarray(poses), setup.params.nominal)
    axis = np.zeros((len(A), 3, A.shape[2]))
    axis[:, :, cols] = axis_information_rows(T, cov[:, 3:, 3:], R_BC0, R_ME0) * scale
    return np.concatenate([A, axis], axis=1), validation_weight(validation_blocks(sc, validation, base_t))


def identifiability(scene, poses: np.ndarray, base: np.ndarray, frames: int | None = None):
    """IdentifiabilityReport (``identify.analyze``) of commanded poses for the ``base`` parameters, whitened by the
    image model's pose covariance (the parameters outside the base set are not identifiable from the candidate
    region at all)."""
    from ..identify import analyze

    return analyze(_problem(scene, poses, base, frames=frames)[0], selection="order")


def info_matrix(A: np.ndarray, idx=None) -> np.ndarray:
    Ai = A if idx is None else A[np.asarray(idx, int)]
    return np.einsum("kmi,kmj->ij", Ai, Ai)


def leverages(A: np.ndarray, M: np.ndarray) -> np.ndarray:
    """(K,) trace(A_k M^-1 A_k^T) of blocks A (K, m, L) against the information M (L, L) (pseudo-inverse)."""
    Mi = np.linalg.pinv(M)
    return np.einsum("kmi,ij,kmj->k", A, Mi, A)


def pool_indices(A: np.ndarray, rng: np.random.Generator, top: int = POOL_TOP, extra: int = POOL_RANDOM) -> np.ndarray:
    """Indices of the exchange pool among K candidates (module docstring), sorted."""
    K = A.shape[0]
    if K <= top + extra:
        return np.arange(K)
    order = np.argsort(-leverages(A, info_matrix(A)), kind="stable")
    rest = rng.choice(order[top:], extra, replace=False)
    return np.sort(np.concatenate([order[:top], rest]))


def d_criterion(A: np.ndarray, idx) -> dict:
    """{logdet (D criterion, scaled units), O1 (Borm-Menq), s_min (E)} of the design idx over blocks A."""
    return {"logdet": design_criterion(A, idx, "D"), "O1": design_criterion(A, idx, "O1"),
            "s_min": design_criterion(A, idx, "E")}


def d_efficiency(logdet_a: float, logdet_b: float, L: int) -> float:
    """D-efficiency of design a against design b: exp((logdet_a - logdet_b) / L) (1: as good, 0.5: b needs half
    the poses for the same parameter-confidence volume)."""
    if not (np.isfinite(logdet_a) and np.isfinite(logdet_b)):
        return 0.0 if not np.isfinite(logdet_a) else float("inf")
    return float(np.exp((logdet_a - logdet_b) / L))


def select(scene, info: Information, poses: np.ndarray, n: int, rng: np.random.Generator,
           candidates: np.ndarray | None = None) -> np.ndarray:
    """Indices (n,) into the commanded poses (K, .) of the information ``info`` (or among ``candidates``, a subset
    of them) of a D-optimal design of n poses: leverage pool, then ``select_poses`` (greedy + Fedorov exchange) on
    the pool's problem. IdentifiabilityError when n poses cannot identify the base parameters (naming the minimum)
    or when fewer candidates than n are left."""
    sub = np.arange(info.A.shape[0]) if candidates is None else np.asarray(candidates, int)
    A = info.A[sub]
    m, L = A.shape[1], A.shape[2]
    if n * m < L:
        raise IdentifiabilityError(f"{n} poses give {n * m} equations for the {L} base parameters: plan at least "
                                   f"{-(-L // m)} poses")
    if n > len(sub):
        raise IdentifiabilityError(f"{n} poses asked, only {len(sub)} candidates are measurable and collision-free: "
                                   "widen the candidate region or ask for fewer poses")
    pool = pool_indices(A, rng)
    cov = None if info.cov is None else info.cov[sub[pool]]
    problem, _, _ = _problem(scene, np.asarray(poses)[sub[pool]], info.base, cov)
    idx = select_poses(problem, n, restarts=RESTARTS)
    return sub[pool[idx]]


def validation_blocks(scene, validation: np.ndarray, base: np.ndarray, step: float = 1e-3) -> np.ndarray:
    """(V, 3, L) derivative of the position error [m] at the validation poses (V, .) (``Setup.evaluate``: what
    ``simulate`` reports as the validation position error) with respect to the ``base`` parameters, in units of
    their ``scale`` (the columns of :class:`Information`); central differences of ``step`` scale units."""
    setup = scene.setup
    x0 = np.asarray(setup.params.nominal, float)
    cols = np.flatnonzero(np.asarray(base, bool) & np.asarray(setup.params.free, bool))
    G = np.zeros((len(validation), 3, len(cols)))
    for k, c in enumerate(cols):
        xp, xm = x0.copy(), x0.copy()
        xp[c] += step * setup.params.scale[c]
        xm[c] -= step * setup.params.scale[c]
        ep = setup.evaluate(xp, x0, validation).errors[:, :3]
        em = setup.evaluate(xm, x0, validation).errors[:, :3]
        G[:, :, k] = (ep - em) / (2 * step)
    return G


def validation_weight(G: np.ndarray) -> np.ndarray:
    """(L, L) W = sum_v G_v^T G_v / V of validation blocks G (V, 3, L): the mean squared validation position error
    of a design of information M is tr(W M^-1) [m^2] (first order, unit-whitened pose noise)."""
    return np.einsum("vai,vaj->ij", G, G) / G.shape[0]


def _inv(M: np.ndarray) -> np.ndarray:
    return np.linalg.pinv(M, hermitian=True)


def validation_mse(A: np.ndarray, idx, W: np.ndarray) -> float:
    """tr(W M^-1) [m^2] of the design idx over blocks A (K, m, L): the predicted mean squared validation position
    error (inf when the design does not identify the base parameters)."""
    M = info_matrix(A, idx)
    if np.linalg.matrix_rank(M) < M.shape[0]:
        return float("inf")
    return float(np.trace(W @ _inv(M)))


def validation_rms_quantiles(A: np.ndarray, idx, W: np.ndarray, rng: np.random.Generator,
                             draws: int = RMS_DRAWS) -> dict:
    """{median_mm, p95_mm}: quantiles over noise draws of the validation position RMS of the design idx, first
    order: RMS^2 = d^T W d with the parameter error d ~ N(0, M^-1) (what one ``simulate`` run gives is one draw; the
    RMS of a few effective directions spreads widely, its median is below sqrt(tr(W M^-1))). None when the design
    does not identify the base parameters."""
    M = info_matrix(A, idx)
    if np.linalg.matrix_rank(M) < M.shape[0]:
        return {"median_mm": None, "p95_mm": None}
    w, U = np.linalg.eigh(W)
    S = U * np.sqrt(np.clip(w, 0, None))  # W = S S^T
    lam = np.clip(np.linalg.eigvalsh(S.T @ _inv(M) @ S), 0, None)  # RMS^2 = sum lam_i chi2_1
    r = np.sqrt(rng.chisquare(1, size=(draws, lam.size)) @ lam) * 1e3
    return {"median_mm": float(np.median(r)), "p95_mm": float(np.percentile(r, 95))}


def add_gains(A: np.ndarray, Mi: np.ndarray, W: np.ndarray) -> np.ndarray:
    """Decrease of tr(W M^-1) when each block A_k (K, m, L) is added to the information of inverse Mi (L, L), or
    of each of several inverses Mi (P, L, L): (K,) or (P, K) (Woodbury: tr((I + B A_k^T)^-1 B W B^T), B = A_k Mi)."""
    one = Mi.ndim == 2
    Mi = Mi[None] if one else Mi
    B = np.matmul(A[None], Mi[:, None])  # (P, K, m, L)
    S = np.eye(A.shape[1]) + np.matmul(B, np.swapaxes(A, 1, 2)[None])
    BW = np.matmul(np.matmul(B, W), np.swapaxes(B, 2, 3))
    g = np.trace(np.linalg.solve(S, BW), axis1=2, axis2=3)
    return g[0] if one else g


def _removal_inverses(A: np.ndarray, sel: list) -> np.ndarray:
    """(n, L, L) inverses of the information without each pose of the design sel (a tiny ridge where one is
    singular)."""
    As = A[np.asarray(sel, int)]
    M = np.einsum("kmi,kmj->ij", As, As)
    Mk = M[None] - np.einsum("kmi,kmj->kij", As, As)
    ridge = 1e-9 * np.trace(M) / M.shape[0] * np.eye(M.shape[0])
    out = np.empty_like(Mk)
    for k, Mr in enumerate(Mk):
        try:
            out[k] = np.linalg.inv(Mr) if np.linalg.matrix_rank(Mr) == Mr.shape[0] else np.linalg.inv(Mr + ridge)
        except np.linalg.LinAlgError:
            out[k] = np.linalg.pinv(Mr + ridge, hermitian=True)
    return out


#: design positions per batch of the exchange's gains (memory: batch x candidates x m x L doubles)
SWAP_BATCH = 8


def refine_for_validation(A: np.ndarray, idx, W: np.ndarray, candidates=None, max_swaps: int = MAX_SWAPS) -> np.ndarray:
    """Fedorov exchange of the design idx (n,) over blocks A (K, m, L) (or among ``candidates``) on the validation
    criterion tr(W M^-1) (:func:`validation_mse`): the best swap (one pose out, one in) while it lowers the
    criterion; the start must identify the base parameters (a D-optimal design). Returns the design (n,)."""
    sel = [int(i) for i in idx]
    cand = np.arange(A.shape[0]) if candidates is None else np.asarray(candidates, int)
    cur = validation_mse(A, sel, W)
    for _ in range(max_swaps if np.isfinite(cur) else 0):
        out = np.setdiff1d(cand, sel)
        if not out.size:
            break
        Mi = _removal_inverses(A, sel)
        base_val = np.einsum("ij,kji->k", W, Mi)  # tr(W Mi_k)
        val = np.concatenate([base_val[s:s + SWAP_BATCH, None] - add_gains(A[out], Mi[s:s + SWAP_BATCH], W)
                              for s in range(0, len(sel), SWAP_BATCH)])
        pos, j = np.unravel_index(int(np.argmin(val)), val.shape)
        if not val[pos, j] < cur * (1 - 1e-9):
            break
        sel[pos] = int(out[j])
        cur = validation_mse(A, sel, W)
    return np.array(sel, int)


__all__ = ["Information", "information", "base_mask", "identifiability", "select", "d_criterion", "d_efficiency", "leverages",
           "pool_indices", "info_matrix", "pose_covariances", "validation_blocks", "validation_weight", "validation_mse",
           "refine_for_validation", "with_axis_tilts", "validation_rms_quantiles", "add_gains", "SYSTEMATIC_CORNER_PX",
           "OBLIQUE_CORNER_PX", "systematic_corner_px"]
