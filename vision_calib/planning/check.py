"""``vision-calib plan CELL --check poses.csv``: a user's own pose list reported the way a plan is (per pose
reachability, collisions, view figures; the moves in the list's order; the D criterion against random and D-optimal
sets of as many poses from the scene's region; the predicted accuracy of the list's usable poses)."""

from __future__ import annotations

import time

import numpy as np

from . import design as D
from .plan import (DEFAULT_CANDIDATES, EFFICIENCY_DRAWS, FORMAT, CandidateSource, as_scene, candidate_poses,
                   collision_setup, contact_words, identifiability_block, no_collision_note, plan_settings, pose_rows,
                   read_pose_list, screen)
from .predict import DRAWS, predicted_accuracy
from .view import FIGURES, ViewLimits


def check_poses(scene, csv_path, out_dir=None, seed: int = 0, n_candidates: int = DEFAULT_CANDIDATES,
                draws: int = DRAWS, angle_factor: float | None = None, plots: bool = True,
                frames: int | None = None) -> dict:
    """Report a user's own pose list (``poses.csv``, recording layout) the way a plan is reported: per pose joint
    limits, collisions (clearance), view figures; the moves in the list's order; the D criterion against random
    and D-optimal sets of as many poses from the scene's region; the predicted accuracy of the list's usable poses.
    ``verdict``: ok when every pose is usable and no move collides. frames: per pose, the image measurement's noise
    (default the scene's)."""
    t0 = time.perf_counter()
    scene = as_scene(scene)
    frames = int(frames or scene.measurement.frames)
    setup = scene.setup
    rng = np.random.default_rng([int(seed), 27])
    ids, q, P, units_from = read_pose_list(scene, csv_path, angle_factor)
    model, checker = collision_setup(scene)
    own = screen(scene, P, checker)
    usable = np.zeros(len(P), bool)
    usable[own["kept"]] = True
    figs = own["figures"]
    clear = checker.clearances(setup.link_frames(P)) if checker is not None else None
    problems = {}
    lim = setup.reachable(P)
    col_ok, col_why = (checker.screen(setup.link_frames(P)) if checker is not None
                       else (np.ones(len(P), bool), [None] * len(P)))
    for i, pid in enumerate(ids):
        why = []
        if not lim[i]:
            why.append(f"not reachable ({setup.reach_check})")
        else:
            if not col_ok[i]:
                why.append(f"collides: {contact_words(col_why[i])}")
            if not own["measurable"][i]:
                why.append(_view_why(figs, i, ViewLimits.of_scene(scene)))
        if why:
            problems[pid] = "; ".join(why)
    check = None
    if checker is not None:
        def check(qs):
            return checker.screen(setup.link_frames(setup.commanded_from_joints(qs)))
    joints = np.asarray(q, float)
    from .tour import move_samples, travel_times

    C = travel_times(joints, scene.planning.max_joint_speed_rad_s)
    moves, warnings = [], ([] if model is None else list(model.warnings))
    for k in range(len(ids) - 1):
        m = {"from": ids[k], "to": ids[k + 1], "time_s": float(C[k, k + 1]),
             "largest_joint_change_deg": float(np.degrees(np.max(np.abs(joints[k + 1] - joints[k])))),
             "collides": None}
        if check is not None and lim[k] and lim[k + 1]:
            S = move_samples(joints[k], joints[k + 1], scene.planning.move_step_rad)
            ok, why = check(S) if len(S) else (np.ones(0, bool), [])
            m["collides"] = bool(not np.all(ok))
            if m["collides"]:
                j = int(np.flatnonzero(~ok)[0])
                w = why[j]
                m["why"] = f"{contact_words(w)} at {100 * (j + 1) / (len(S) + 1):.0f} % of the move"
                warnings.append(f"move {ids[k]} -> {ids[k + 1]} collides: {m['why']}")
        moves.append(m)
    for pid, w in problems.items():
        warnings.append(f"pose {pid}: {w}")
    # the scene's region for the comparisons (random and D-optimal sets of as many poses)
    region = candidate_poses(scene, CandidateSource(), n_candidates, rng)
    scr = screen(scene, region, checker)
    pool = region[scr["kept"]]
    U = P[usable]
    n = int(usable.sum())
    out_design, pred, rep = None, None, None
    if n and len(pool) >= n:
        sub = np.arange(len(pool)) if len(pool) <= D.MAX_INFO else np.sort(rng.choice(len(pool), D.MAX_INFO, replace=False))
        base, rep0 = D.base_mask(scene, pool[sub], rng)
        both = np.concatenate([U, pool[sub]])
        info = D.information(scene, both, base, rep0, frames)
        mine = np.arange(n)
        others = np.arange(n, len(both))
        crit = D.d_criterion(info.A, mine)
        L = info.A.shape[2]
        rand = [D.d_criterion(info.A, n + rng.choice(len(others), n, replace=False))["logdet"]
                for _ in range(EFFICIENCY_DRAWS)]
        out_design = {**crit, "n_base_parameters": int(L), "base_parameters": list(info.names),
                      "d_efficiency_vs_random": float(np.median([D.d_efficiency(crit["logdet"], r, L) for r in rand])),
                      "leverage": {pid: float(v) for pid, v in zip(np.array(ids)[usable],
                                                                    D.leverages(info.A[mine], D.info_matrix(info.A, mine)))}}
        n_min = -(-L // info.A.shape[1])
        if n >= n_min:
            opt = D.select(scene, info, both, n, rng, candidates=others)  # indices into both
            opt_logdet = D.d_criterion(info.A, opt)["logdet"]
            out_design["d_efficiency_vs_plan"] = D.d_efficiency(crit["logdet"], opt_logdet, L)
            plan_n = both[opt]
            pred = predicted_accuracy(scene, lambda c: plan_n, pool, [n], base, draws, seed, given=U,
                                      frames=frames) if draws else None
            rep = identifiability_block(D.identifiability(scene, U, base, frames), setup, base)
        else:
            warnings.append(f"{n} usable poses give fewer equations than the {L} base parameters: nothing identifiable "
                            f"to predict (at least {n_min} poses)")
    rows = pose_rows(scene, ids, P, joints, figs, clear, None)
    for r in rows:
        r["usable"] = r["id"] not in problems
        if r["id"] in problems:
            r["problem"] = problems[r["id"]]
        if out_design and r["id"] in out_design["leverage"]:
            r["leverage"] = out_design["leverage"][r["id"]]
    notes = [] if checker is not None else [no_collision_note(setup)]
    if model is not None:
        notes += list(model.notes)
    notes.append(f"joint values read in the unit of {units_from}")
    res = {
        "format": FORMAT, "kind": "check",
        "scene": {"name": scene.name, "path": str(scene.path), "robot_kind": setup.kind, "mount": setup.mount},
        "source": {"file": str(csv_path)},
        "settings": plan_settings(scene, CandidateSource(), n_candidates, seed),
        "verdict": {"ok": not problems and not any(m.get("collides") for m in moves),
                    "usable_poses": n, "n_poses": len(ids),
                    "message": "every pose usable, no move collides" if not warnings else "; ".join(warnings[:3])
                               + (f" (+{len(warnings) - 3} more)" if len(warnings) > 3 else "")},
        "screening": {**scr["counts"], "seconds": scr["seconds"], "rate_per_s": scr["rate_per_s"],
                      "fcl_queries": scr["fcl_queries"], "what": "the scene's region, for the comparisons"},
        "collision_model": None if model is None else model.to_dict(),
        "n_poses": len(ids), "poses": rows,
        "tour": {"total_s": float(sum(m["time_s"] for m in moves)), "moves": moves,
                 "moves_checked": check is not None, "order": "as given"},
        "design": out_design, "identifiability": rep, "predicted_accuracy": pred,
        "notes": notes, "warnings": warnings, "seconds": time.perf_counter() - t0,
    }
    if out_dir is not None:
        from .report import write_plan

        write_plan(out_dir, scene, res, P, joints, model, plots=plots, recording=False)
    return res


def _view_why(figs, i, lim: ViewLimits) -> str:
    f = {k: figs[k][i] for k in FIGURES}
    if not np.isfinite(f["margin_px"]):
        return "target behind the camera or seen from its back"
    out = []
    if not f["margin_px"] >= lim.margin_px:
        out.append(f"board {f['margin_px']:.0f} px from the image border (< {lim.margin_px:g})")
    if not lim.distance_m[0] <= f["distance_m"] <= lim.distance_m[1]:
        out.append(f"distance {f['distance_m']:.3f} m outside [{lim.distance_m[0]:g}, {lim.distance_m[1]:g}]")
    if f["incidence_deg"] > np.degrees(lim.max_incidence_rad):
        out.append(f"incidence {f['incidence_deg']:.1f} deg > {np.degrees(lim.max_incidence_rad):g}")
    if not f["square_px"] >= lim.min_square_px:
        out.append(f"squares {f['square_px']:.1f} px < {lim.min_square_px:g}")
    return "target not measurable: " + ", ".join(out)


__all__ = ["check_poses"]
