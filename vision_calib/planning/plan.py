"""``vision-calib plan CELL --poses N --out DIR``: the joint values to command for a calibration, (``plan
CELL --check poses.csv``, the same figures for a user's own list: :mod:`.check`).

Steps of a plan (figures and seeds in ``plan.json``):

1. candidates (:func:`candidate_poses`): the scene's pose sampling region (default; serial: q_center +- q_spread
   within the joint limits; H4: the workspace box), a user's list (a ``poses.csv``), the region's poses whose end
   point (flange / nacelle) lies in a workspace box, or joint sets within +-delta of a start joint set;
2. screening (:func:`screen`): reachable (joint limits; H4: the inverse model closes), the target measurable
   (:mod:`.view`), collision-free with the clearance (:mod:`.collision`; arms only);
3. selection of N poses (:mod:`.design`): D-optimal for the base parameters under the image measurement (each
   candidate's pose covariance from the camera model, the target's corners and the corner noise, for the frames
   the user records), then a Fedorov exchange on the predicted mean squared position error over the validation
   poses (the scene's validation sampler, :data:`CRITERION_POSES` of them, or ``--validate-on``);
4. the tour (:mod:`.tour`): short in joint-space travel time, its moves checked for collisions; a move that
   collides in every order sends the selection back without one of its ends (:data:`MOVE_REPLANS` times);
5. clearance, view figures and leverage per pose, identifiability, and the predicted accuracy of the plan against
   random measurable poses (:mod:`.predict`);
6. outputs (:mod:`.report`): ``poses.csv``, ``recording.yaml`` and ``images/<pose_id>/`` (a recording to fill),
   ``plan.json``, ``report.html``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from dataclasses import replace as dc_replace
from pathlib import Path

import numpy as np

from ..errors import ConfigError, DataError, VisionCalibError
from ..rig import Scene, load_scene
from ..rig.base import ArmFrames
from . import design as D
from .predict import DRAWS, predicted_accuracy
from .tour import plan_tour
from .view import FIGURES, MIN_SQUARE_PX, ViewLimits, measurable, view_figures

FORMAT = "vision_calib.plan/1"
#: candidates drawn by default (screening 20 000 takes a few seconds on one core; benchmarks/bench_plan.py)
DEFAULT_CANDIDATES = 20000
#: candidates per screening block (memory: link frames of a block ~ block x (n + 2) x 128 bytes)
SCREEN_BLOCK = 20000
H4_NOTE = "no collision model for the H4: checked visibility and reachability (inverse model) only"


def no_collision_note(setup) -> str:
    """The plan's note for a robot kind without a collision model (the H4: :data:`H4_NOTE`)."""
    return (f"no collision model for the {setup.kind.upper()}: checked visibility and reachability "
            f"({setup.reach_check}) only")
#: random designs whose D criterion the plan's is compared with (D-efficiency)
EFFICIENCY_DRAWS = 20
#: selections again without one end of a move that collides in every order of the tour (then it is named)
MOVE_REPLANS = 3
#: validation poses drawn from the scene's validation sampler for the design criterion
CRITERION_POSES = 200
#: the most poses --target-accuracy plans
MAX_TARGET_POSES = 200
#: random candidates, beside the D pool, among which the validation criterion's exchange swaps poses
EXCHANGE_RANDOM = 600


@dataclass(frozen=True)
class CandidateSource:
    """Where the candidates come from: kind "region" (the scene's pose sampling region), "list" (``path``: a
    poses.csv, its angles read with ``angle_factor`` to rad), "box" (the region's poses whose end point lies in
    [box_lo_m, box_hi_m] (3,) each, robot base frame) or "around" (joint sets ``start_rad`` (n,) +- ``delta_rad``)."""

    kind: str = "region"
    path: Path | None = None
    angle_factor: float | None = None
    box_lo_m: tuple | None = None
    box_hi_m: tuple | None = None
    start_rad: tuple | None = None
    delta_rad: float | None = None

    def describe(self) -> str:
        if self.kind == "list":
            return f"the poses of {self.path}"
        if self.kind == "box":
            return (f"the scene's pose region, end point in the box [{', '.join(f'{v:.4g}' for v in self.box_lo_m)}] .. "
                    f"[{', '.join(f'{v:.4g}' for v in self.box_hi_m)}] m (robot base frame)")
        if self.kind == "around":
            return (f"joint sets within +-{np.degrees(self.delta_rad):.4g} deg of "
                    f"[{', '.join(f'{np.degrees(v):.4g}' for v in self.start_rad)}] deg")
        return "the scene's pose sampling region"


def as_scene(scene) -> Scene:
    scene = scene if isinstance(scene, Scene) else load_scene(scene)
    if scene.setup.camera is None or scene.target_path is None:
        raise ConfigError(f"{scene.path}: planning needs a camera and a target in the scene (the view checks)")
    return scene


def _commanded(setup, q: np.ndarray, block: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """(commanded poses of the joint sets q (K, n) that the nominal model maps, their indices): blocks, and joint set
    by joint set in a block whose mapping fails (H4: the forward model's Newton iteration)."""
    out, ok = [], []
    for s in range(0, len(q), block):
        qb = q[s:s + block]
        try:
            out.append(setup.commanded_from_joints(qb))
            ok.extend(range(s, s + len(qb)))
        except VisionCalibError:
            for i, qi in enumerate(qb):
                try:
                    out.append(setup.commanded_from_joints(qi[None]))
                    ok.append(s + i)
                except VisionCalibError:
                    pass
    if not out:
        return np.zeros((0, 0)), np.zeros(0, int)
    return np.concatenate(out), np.array(ok, int)


def read_pose_list(scene: Scene, path, angle_factor: float | None = None) -> tuple[list[str], np.ndarray, np.ndarray, str]:
    """(pose ids, joint sets (N, n) rad, commanded poses (N, .), where the angle unit came from) of a user's
    poses.csv (``rig.pose_file``: its unit from ``angle_factor``, else the recording.yaml beside it, else the
    scene's). DataError naming the file and pose when the nominal model cannot map a joint set to a pose."""
    from ..config import Section
    from ..rig.pose_file import pose_file_units, read_joint_file

    path = Path(path)
    if angle_factor is None:
        Lf, Af = Section(scene.raw, scene.path).units(default_length="m", default_angle="deg")
        _, af, where = pose_file_units(path, Lf, Af)
    else:
        af, where = angle_factor, "the command line"
    ids, q = read_joint_file(path, scene.setup.n_joints, af)
    # joint limits are a finding of the check (screen), not an input error
    poses, ok = _commanded(scene.setup, q)
    if len(ok) < len(q):
        bad = sorted(set(range(len(q))) - set(ok.tolist()))
        raise DataError(f"{path}: pose {ids[bad[0]]!r}: the nominal model cannot map these joint values to a pose "
                        f"({len(bad)} such poses)")
    return ids, q, poses, where


def candidate_poses(scene: Scene, source: CandidateSource, n: int, rng: np.random.Generator) -> np.ndarray:
    """(K, .) candidate commanded poses (module docstring, step 1)."""
    setup = scene.setup
    if source.kind == "list":
        return read_pose_list(scene, source.path, source.angle_factor)[2]
    if source.kind == "around":
        start = np.asarray(source.start_rad, float)
        if start.shape != (setup.n_joints,):
            raise ConfigError(f"--around: {start.size} joint values, the robot has {setup.n_joints}")
        q = start + rng.uniform(-1, 1, size=(n, setup.n_joints)) * source.delta_rad
        return _commanded(setup, q)[0]
    poses = setup.sample_poses(rng, n, check_view=False)
    if source.kind == "box":
        p = setup.end_point(poses)
        lo, hi = np.asarray(source.box_lo_m, float), np.asarray(source.box_hi_m, float)
        poses = poses[np.all((p >= lo) & (p <= hi), axis=1)]
        if not len(poses):
            raise ConfigError(f"--box: none of {n} candidates of the scene's pose region has its end point in the box "
                              f"{lo.tolist()} .. {hi.tolist()} m (robot base frame)")
    return poses


def screen(scene: Scene, poses: np.ndarray, checker=None, limits: ViewLimits | None = None) -> dict:
    """Screen candidate poses (K, .): {kept (k,) indices, figures {name: (K,) float, NaN where not computed},
    clearance_ok (K,) bool, counts {candidates, unreachable, not_measurable {reason: count}, colliding, kept},
    collision_why {index: (body, other, m)}, seconds, fcl_queries}. Vectorised in blocks; collisions are checked on
    the measurable poses only."""
    from ..targets import load_target

    t0 = time.perf_counter()
    setup = scene.setup
    limits = limits or ViewLimits.of_scene(scene)
    target = load_target(scene.target_path)
    K = len(poses)
    figs = {k: np.full(K, np.nan) for k in FIGURES}
    reach = np.zeros(K, bool)
    meas_ok = np.zeros(K, bool)
    col_ok = np.zeros(K, bool)
    reasons = {}
    why = {}
    n_fcl0 = checker.n_fcl if checker is not None else 0
    for s in range(0, K, SCREEN_BLOCK):
        P = poses[s:s + SCREEN_BLOCK]
        r = setup.reachable(P)
        reach[s:s + len(P)] = r
        ir = np.flatnonzero(r)
        if not ir.size:
            continue
        f = view_figures(setup.T_cam_target(P[ir], setup.params.nominal), setup.camera, target)
        for k in FIGURES:
            figs[k][s + ir] = f[k]
        ok, fails = measurable(f, limits)
        for k, v in fails.items():
            reasons[k] = reasons.get(k, 0) + int(np.sum(v))
        im = ir[ok]
        meas_ok[s + im] = True
        if checker is None:
            col_ok[s + im] = True
            continue
        if im.size:
            c_ok, c_why = checker.screen(setup.link_frames(P[im]))
            col_ok[s + im] = c_ok
            for j in np.flatnonzero(~c_ok):
                why[int(s + im[j])] = c_why[j]
    kept = np.flatnonzero(reach & meas_ok & col_ok)
    counts = {"candidates": int(K), "unreachable": int(K - reach.sum()),
              "not_measurable": int(reach.sum() - meas_ok.sum()), "not_measurable_by_reason": reasons,
              "colliding": int(meas_ok.sum() - (meas_ok & col_ok).sum()) if checker is not None else None,
              "kept": int(kept.size)}
    seconds = time.perf_counter() - t0
    return {"kept": kept, "figures": figs, "reachable": reach, "measurable": meas_ok,
            "collision_free": col_ok if checker is not None else None, "counts": counts, "collision_why": why,
            "seconds": seconds, "rate_per_s": K / seconds if seconds > 0 else None,
            "fcl_queries": (checker.n_fcl - n_fcl0) if checker is not None else 0}


def collision_setup(scene: Scene):
    """(collision model, checker) of the scene's arm, (None, None) for a kind without one (H4)."""
    if not isinstance(scene.setup, ArmFrames):
        return None, None
    from .bodies import build_model, own_poses
    from .collision import CollisionChecker

    model = build_model(scene, scene.setup)
    checker = CollisionChecker(model, scene.planning.clearance_m)
    own = own_poses(scene, scene.setup, np.random.default_rng(5))
    checker.fixed = checker.mark_fixed(scene.setup.link_frames(own)) if own is not None else None
    return model, checker


def pose_rows(scene, ids, poses, joints, figs, clear, lev) -> list[dict]:
    setup = scene.setup
    rows = []
    for i, pid in enumerate(ids):
        r = {"id": pid, "joints_rad": [float(v) for v in joints[i]], "joints_deg": [float(np.degrees(v)) for v in joints[i]],
             "view": {k: (None if not np.isfinite(figs[k][i]) else float(figs[k][i])) for k in FIGURES},
             "leverage": None if lev is None else float(lev[i])}
        if poses.shape != joints.shape or not np.allclose(poses[i], joints[i]):
            r["commanded"] = [float(v) for v in poses[i]]
        if clear is not None:
            r.update(clear[i])
        rows.append(r)
    return rows


def _tour_block(tour: dict, ids, joints_ordered) -> dict:
    moves = []
    ids = list(ids)
    for k in range(len(ids) - 1):
        a, b = k, k + 1
        m = {"from": ids[a], "to": ids[b], "time_s": tour["times_s"][k],
             "largest_joint_change_deg": float(np.degrees(np.max(np.abs(joints_ordered[b] - joints_ordered[a]))))}
        m["collides"] = None if not tour["moves_checked"] else False
        moves.append(m)
    return {"total_s": tour["total_s"], "length_deg": float(np.degrees(tour["length_rad"])), "moves": moves,
            "moves_checked": tour["moves_checked"], "move_samples": tour["move_samples"], "reorder_rounds": tour["rounds"]}


def _counts(n: int, n_min: int, n_max: int, counts=None) -> list[int]:
    if counts is None:
        counts = [max(n_min, n // 2), n, 2 * n]
    return sorted({int(c) for c in counts if n_min <= c <= n_max} | {n})


def _efficiency(A: np.ndarray, idx, rng: np.random.Generator, n: int) -> dict:
    """D criterion of the design idx and its D-efficiency against EFFICIENCY_DRAWS random designs of n poses."""
    crit = D.d_criterion(A, idx)
    L = A.shape[2]
    rand = [D.d_criterion(A, rng.choice(A.shape[0], n, replace=False))["logdet"] for _ in range(EFFICIENCY_DRAWS)]
    eff = [D.d_efficiency(crit["logdet"], r, L) for r in rand]
    return {**crit, "n_base_parameters": int(L),
            "d_efficiency_vs_random": {"median": float(np.median(eff)), "min": float(np.min(eff)),
                                       "max": float(np.max(eff)), "draws": EFFICIENCY_DRAWS,
                                       "meaning": "exp((logdet M_plan - logdet M_random) / L): > 1, the plan's "
                                                  "parameter-confidence volume is smaller"}}


def plan_settings(scene: Scene, source: CandidateSource, n_candidates: int, seed: int) -> dict:
    return {**scene.planning.to_dict(), "min_square_px": MIN_SQUARE_PX, "candidates": int(n_candidates),
            "candidate_source": source.describe(), "seed": int(seed),
            "noise": {"model": "image: each pose's covariance from the camera model, the target's projected corners, "
                               "the sensor's noise and blur (Cramér-Rao bound of the frame-averaged corners) and the "
                               "detector's systematic corner error",
                      "systematic_corner_px": D.SYSTEMATIC_CORNER_PX}}


def validation_poses(scene: Scene, validate_on=None, seed: int = 0) -> tuple[np.ndarray, str]:
    """(validation poses (V, .) of the design criterion, what they are): ``validate_on`` (a poses.csv path, or
    commanded poses (V, .)) or :data:`CRITERION_POSES` poses of the scene's validation sampler."""
    from ..rig.scene import scene_poses

    if validate_on is None:
        V = scene_poses(scene, np.random.default_rng([int(seed), 31]), CRITERION_POSES
                        if scene.validation.kind == "random" else None, which="validation")
        return V, f"{len(V)} poses of the scene's validation sampler ({scene.validation.kind})"
    if isinstance(validate_on, (str, Path)):
        ids, _, V, _ = read_pose_list(scene, validate_on)
        return V, f"the {len(ids)} poses of {validate_on}"
    V = np.asarray(validate_on, float)
    return V, f"{len(V)} given poses"


def _select(scene, info, poses, n, rng, W, candidates=None) -> np.ndarray:
    """D-optimal start (``design.select``), then the exchange on the validation criterion W among the D pool and
    :data:`EXCHANGE_RANDOM` random candidates (indices into ``poses``)."""
    start = D.select(scene, info, poses, n, rng, candidates=candidates)
    sub = np.arange(info.A.shape[0]) if candidates is None else np.asarray(candidates, int)
    pool = sub[D.pool_indices(info.A[sub], rng)]
    extra = sub if len(sub) <= EXCHANGE_RANDOM else rng.choice(sub, EXCHANGE_RANDOM, replace=False)
    return D.refine_for_validation(info.A, start, W, np.union1d(np.union1d(pool, extra), start))


def smallest_count(quantiles, target_mm: float, lo: int, hi: int) -> int:
    """The smallest pose count in [lo, hi] whose ``quantiles(count)["p95_mm"]`` reaches ``target_mm``: growing by half
    until one does, then bisection. DataError naming the best reached when none up to hi does."""
    def ok(c):
        q = quantiles(c)["p95_mm"]
        return q is not None and q <= target_mm

    c, fail = lo, lo - 1
    while not ok(c):
        fail = c
        if c >= hi:
            best = min((quantiles(k)["p95_mm"] for k in (lo, hi) if quantiles(k)["p95_mm"] is not None), default=None)
            raise DataError(f"--target-accuracy {target_mm:g} mm: not reached with up to {hi} poses (95th percentile "
                            f"of the predicted validation position RMS at {hi} poses: "
                            f"{'n/a' if best is None else f'{best:.3g} mm'}): record more frames per pose, or ask less")
        c = min(hi, max(c + 1, int(1.5 * c)))
    a, b = fail + 1, c
    while a < b:
        m = (a + b) // 2
        if ok(m):
            b = m
        else:
            a = m + 1
    return b


def plan_cell(scene, n_poses: int, out_dir=None, seed: int = 0, n_candidates: int = DEFAULT_CANDIDATES,
              source: CandidateSource | None = None, draws: int = DRAWS, counts=None, plots: bool = True,
              frames: int | None = None, validate_on=None, target_accuracy_m: float | None = None) -> dict:
    """Plan ``n_poses`` poses for the scene (module docstring); writes the outputs into ``out_dir`` when given and
    returns plan.json's content. Seeded: the same seed gives the same plan. draws: Monte Carlo draws of the
    predicted accuracy (0: none); counts: its pose counts (default N / 2, N, 2 N); frames: frames the user records
    per pose (default the scene's); validate_on: the validation poses (:func:`validation_poses`); target_accuracy_m:
    plan the smallest count whose predicted validation position RMS (95th percentile over noise draws, first order)
    reaches it (:func:`smallest_count`; n_poses ignored)."""
    t0 = time.perf_counter()
    scene = as_scene(scene)
    setup = scene.setup
    source = source or CandidateSource()
    rng = np.random.default_rng([int(seed), 27])
    if isinstance(n_poses, bool) or int(n_poses) < 1:
        raise ConfigError(f"--poses: expected a positive number of poses, got {n_poses!r}")
    if target_accuracy_m is not None and not (np.isfinite(target_accuracy_m) and target_accuracy_m > 0):
        raise ConfigError(f"--target-accuracy: expected a positive length, got {target_accuracy_m!r} m")
    n = int(n_poses)
    frames = int(frames or scene.measurement.frames)
    V, v_what = validation_poses(scene, validate_on, seed)
    cand = candidate_poses(scene, source, n_candidates, rng)
    model, checker = collision_setup(scene)
    scr = screen(scene, cand, checker)
    kept = scr["kept"]
    if kept.size < (n if target_accuracy_m is None else 1):
        raise DataError(f"{scene.path}: only {kept.size} of {len(cand)} candidates are reachable, measurable and "
                        f"collision-free ({_screen_line(scr['counts'])}), fewer than the {n} poses asked: widen the "
                        "region (poses.spread), relax planning limits, or ask for fewer poses")
    pool = cand[kept]
    sub = np.arange(len(pool)) if len(pool) <= D.MAX_INFO else np.sort(rng.choice(len(pool), D.MAX_INFO, replace=False))
    base, rep0 = D.base_mask(scene, pool[sub], rng)
    info = D.information(scene, pool[sub], base, rep0, frames)
    W = D.validation_weight(D.validation_blocks(scene, V, base))
    n_min = -(-info.A.shape[2] // info.A.shape[1])
    tilts = D.with_axis_tilts(scene, pool[sub], base, info.cov, V)
    if tilts is not None:  # the H4: the exchange and the predictions also carry the tilts and their axis prior
        info = dc_replace(info, A=tilts[0], names=info.names + tuple(setup.tilt_names))
        W = tilts[1]
    picks, curve = {}, {}

    def pick_of(c):
        if c not in picks:
            picks[c] = _select(scene, info, pool[sub], c, np.random.default_rng([int(seed), 27, c]), W)
        return picks[c]

    def quantiles(c):
        if c not in curve:
            curve[c] = D.validation_rms_quantiles(info.A, pick_of(c), W, np.random.default_rng([int(seed), 29, c]))
        return curve[c]

    if target_accuracy_m is not None:
        n = smallest_count(quantiles, target_accuracy_m * 1e3, n_min, min(len(sub), MAX_TARGET_POSES))
    elif kept.size < n:
        raise DataError(f"{scene.path}: only {kept.size} candidates kept, fewer than the {n} poses asked")
    check = None
    if checker is not None:
        def check(qs):
            return checker.screen(setup.link_frames(setup.commanded_from_joints(qs)))
    pick, excluded = pick_of(n), set()
    for round_ in range(MOVE_REPLANS + 1):  # a move no order frees: select again without one of its ends
        chosen = sub[pick]
        P = pool[chosen]
        joints = setup.joints(P, setup.params.nominal)
        tour = plan_tour(joints, scene.planning.max_joint_speed_rad_s, scene.planning.move_step_rad, check)
        if not tour["colliding"] or round_ == MOVE_REPLANS:
            break
        excluded |= {int(pick[max(a, b)]) for a, b, _ in tour["colliding"]}
        allowed = np.setdiff1d(np.arange(len(sub)), sorted(excluded))
        if allowed.size < n:
            break
        pick = picks[n] = _select(scene, info, pool[sub], n, np.random.default_rng([int(seed), 27, n, round_ + 1]), W,
                                  candidates=allowed)
        curve.pop(n, None)
    quantiles(n)
    order = tour["order"]
    P, joints, chosen, pick = P[order], joints[order], chosen[order], pick[order]
    ids = [f"{i:03d}" for i in range(n)]  # the recording's pose ids (io.recording.write_recording), in tour order
    figs = {k: scr["figures"][k][kept[chosen]] for k in FIGURES}
    clear = checker.clearances(setup.link_frames(P)) if checker is not None else None
    A_sel = info.A[pick]
    lev = D.leverages(A_sel, D.info_matrix(A_sel))
    design = _efficiency(info.A, pick, rng, n)
    rep = D.identifiability(scene, P, base, frames)
    cts = _counts(n, n_min, len(sub), counts)
    memo = {n: P}

    def plan_of_count(c):
        if c not in memo:
            memo[c] = pool[sub[pick_of(c)]]
        return memo[c]

    for c in cts:
        quantiles(c)
    acc_curve = {"of": "first-order validation position RMS [mm] over noise draws (median, 95th percentile) of the "
                       "planned poses of each count and, median over random sets of as many screened candidates, of "
                       "random poses", "target_mm": None if target_accuracy_m is None else target_accuracy_m * 1e3,
                 "rows": [{"count": int(c), "plan": curve[c],
                           "random": _random_quantiles(info.A, c, W, np.random.default_rng([int(seed), 30, c]))}
                          for c in sorted(curve)]}

    t_pred = time.perf_counter()
    pred = None
    if draws:  # 0: no prediction (tests)
        pred = predicted_accuracy(scene, plan_of_count, pool, cts, base, draws, seed, frames=frames,
                                  validation=None if validate_on is None else V)
        pred["seconds"] = time.perf_counter() - t_pred
    tb = _tour_block(tour, ids, joints)
    warnings = [] if model is None else list(model.warnings)
    mine = next((r["plan"] for r in (pred or {}).get("rows", []) if r["count"] == n), None)
    if mine is not None and mine["failed_draws"]:
        warnings.append(f"the synthetic identification of the {n} planned poses failed in {mine['failed_draws']} of "
                        f"{draws} draws ({mine['first_error']}): plan more poses")
    for a, b, (w, frac) in tour["colliding"]:
        ia, ib = order.index(a), order.index(b)
        k = min(ia, ib)
        tb["moves"][k]["collides"] = True
        tb["moves"][k]["why"] = f"{contact_words(w)} at {100 * frac:.0f} % of the move"
        warnings.append(f"move {ids[k]} -> {ids[k + 1]} collides: {tb['moves'][k]['why']} (no order avoids it: "
                        "insert a via point, or plan again with another seed)")
    notes = [] if checker is not None else [no_collision_note(setup)]
    if model is not None:
        notes += list(model.notes)
        notes.append("the move from the robot's current joint values to the first pose is not checked: start from a "
                     "pose near it, or jog there")
    plan = {
        "format": FORMAT, "kind": "plan",
        "scene": {"name": scene.name, "path": str(scene.path), "robot_kind": setup.kind, "mount": setup.mount},
        "settings": plan_settings(scene, source, len(cand), seed),
        "screening": {**scr["counts"], "seconds": scr["seconds"], "rate_per_s": scr["rate_per_s"],
                      "fcl_queries": scr["fcl_queries"]},
        "collision_model": None if model is None else {**model.to_dict(), "clearance_leaves_out": checker.fixed},
        "n_poses": n,
        "poses": pose_rows(scene, ids, P, joints, figs, clear, lev),
        "tour": tb,
        "design": {**design, "criterion": "D-optimal start (log det of the base parameters' information under the "
                                          "image measurement, scaled units), then exchange on the predicted validation "
                                          "position RMS sqrt(tr(W M^-1))", "validation_poses": v_what,
                   "predicted_validation_rms": {
                       "plan": curve[n], "random": next(r["random"] for r in acc_curve["rows"] if r["count"] == n),
                       "of": acc_curve["of"]},
                   "frames": frames, "base_parameters": list(info.names),
                   "pool": f"{len(sub)} screened candidates; exchange on the {D.POOL_TOP} of largest leverage + "
                           f"{D.POOL_RANDOM} random"},
        "identifiability": identifiability_block(rep, setup, base),
        "accuracy_vs_count": acc_curve,
        "predicted_accuracy": pred,
        "notes": notes, "warnings": warnings,
        "seconds": None,
    }
    from ..experiment.accuracy_map import add_planned_map  # the accuracy map before any image

    add_planned_map(plan, scene, info.names, D.info_matrix(A_sel), joints, rep0.to_dict())
    plan["seconds"] = time.perf_counter() - t0
    if out_dir is not None:
        from .report import write_plan

        write_plan(out_dir, scene, plan, P, joints, model, plots=plots)
    return plan


def _random_quantiles(A: np.ndarray, n: int, W: np.ndarray, rng: np.random.Generator) -> dict:
    """Median over EFFICIENCY_DRAWS random designs of n of the blocks A of each first-order RMS quantile."""
    q = [D.validation_rms_quantiles(A, rng.choice(A.shape[0], n, replace=False), W, rng, 1000)
         for _ in range(EFFICIENCY_DRAWS)]
    return {k: (float(np.median([v[k] for v in q if v[k] is not None])) if any(v[k] is not None for v in q) else None)
            for k in ("median_mm", "p95_mm")}


def identifiability_block(rep, setup, base) -> dict:
    """The identifiability of the poses for the base parameters, and the parameters no candidate identifies."""
    d = rep.to_dict()
    out = {k: d[k] for k in ("n_params", "n_obs", "rank", "condition_number", "condition_number_of",
                             "non_identifiable", "base_parameters")}
    out["not_in_base_set"] = [nm for nm, b, f in zip(setup.params.names, base, setup.params.free) if f and not b]
    out["of"] = ("the base parameters (identifiable from the candidate region), whitened by the image measurement's "
                 "pose covariance; "
                 "not_in_base_set: the scene's free parameters no pose of the region identifies (fixed at nominal)")
    return out


def _screen_line(c: dict) -> str:
    parts = [f"{c['unreachable']} unreachable", f"{c['not_measurable']} target not measurable"]
    if c.get("colliding") is not None:
        parts.append(f"{c['colliding']} colliding")
    return ", ".join(parts)


def contact_words(w) -> str:
    """A collision finding (body, other, distance m) in words: "a within 6.3 mm of b" or "a 12.0 mm into b"."""
    a, b, d = w
    return f"{a} within {d * 1e3:.1f} mm of {b}" if d >= 0 else f"{a} {-d * 1e3:.1f} mm into {b}"


__all__ = ["plan_cell", "CandidateSource", "screen", "candidate_poses", "read_pose_list",
           "DEFAULT_CANDIDATES", "H4_NOTE"]
