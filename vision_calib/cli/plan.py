"""The plan command: the poses of a calibration, planned or checked (planning/)."""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import ConfigError
from .exits import EXIT_NOT_CONVERGED
from .options import add_command, add_json, count, floats_list, seed, sigma


def add_plan_parser(sub) -> None:
    p = add_command(sub, "plan", "the joint values to command for a calibration: reachable, collision-free, the target "
                    "measurable, chosen for the accuracy over the validation poses, in a drivable order, with the accuracy they predict", """
  vision-calib plan scenes/ur5e_cell.yaml --poses 20 --out out/plan
  vision-calib plan scenes/h4_vision.yaml --poses 15 --out out/plan_h4
  vision-calib plan scenes/ur5e_cell.yaml --poses 20 --around 0,-90,90,-90,-90,0 --delta 25 --out out/plan2
  vision-calib plan scenes/ur5e_cell.yaml --check my_poses.csv --out out/check""", description=(
        "Plan the poses of a calibration: candidates in the scene's pose region (or --from-list, --box, --around), "
        "kept when within the joint limits, collision-free with the scene's clearance (obstacles: and the robot's "
        "own links; FCL, extra [plan]) and the target measurable (whole board in the image, distance, incidence, "
        "square size: the scene's planning: section); N chosen D-optimal for the base parameters under the image "
        "measurement (--frames), then for the predicted position error over the validation poses (--validate-on); "
        "ordered into a short joint-space tour whose moves are checked for collisions. Writes DIR/poses.csv, "
        "recording.yaml and images/<pose_id>/ (a recording to fill, then `process DIR`), plan.json and report.html "
        "(the predicted accuracy against random poses). --check reports your own poses.csv the same way (exit 3 "
        "when a pose is not usable or a move collides)."))
    p.add_argument("scene", help="scene YAML file of the cell (obstacles: and planning: keys; vision-calib docs "
                                 "formats)")
    p.add_argument("--poses", type=count, default=None, help="number of poses to plan (default: the scene's "
                                                              "poses.count, else 20)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (poses.csv, recording.yaml, images/, plan.json, report.html)")
    p.add_argument("--check", default=None, metavar="POSES_CSV",
                   help="report this list of poses (pose_id,q1..qn; the recording layout) instead of planning")
    p.add_argument("--candidates", type=count, default=None, help="candidates drawn (default 20000)")
    p.add_argument("--from-list", default=None, metavar="POSES_CSV", help="candidates: the poses of this list")
    p.add_argument("--box", type=floats_list(6, "x0,y0,z0,x1,y1,z1 in metres"), default=None,
                   metavar="X0,Y0,Z0,X1,Y1,Z1",
                   help="candidates: the region's poses whose flange (H4: nacelle point) lies in this box [m, robot "
                        "base frame]")
    p.add_argument("--around", type=floats_list(None, "joint values q1,..,qn in degrees"), default=None,
                   metavar="Q1,..,QN", help="candidates: joint sets within +-DELTA of these joint values [deg]")
    p.add_argument("--delta", type=sigma, default=20.0, help="with --around: half-width per joint [deg] (default 20)")
    p.add_argument("--angle-unit", choices=("deg", "rad"), default=None,
                   help="unit of the joint values in --check / --from-list files (default: the recording.yaml beside "
                        "the file, else the scene's units)")
    p.add_argument("--draws", type=count, default=None, help="Monte Carlo draws of the predicted accuracy (default 10)")
    p.add_argument("--frames", type=count, default=None,
                   help="frames you will record per pose (default: the scene's measurement.frames): the image "
                        "measurement's noise the design and the prediction assume")
    p.add_argument("--target-accuracy", type=length_m, default=None, metavar="LENGTH",
                   help="plan the fewest poses whose predicted validation position RMS (95th percentile over noise "
                        "draws) reaches this, e.g. 0.1mm (units mm, um, m; a bare number: mm); instead of --poses")
    p.add_argument("--validate-on", default=None, metavar="POSES_CSV",
                   help="the poses where the accuracy matters (pose_id,q1..qn): the design criterion and the "
                        "prediction are taken over them (default: the scene's validation poses)")
    p.add_argument("--seed", type=seed, default=None, help="random seed (default 0)")
    p.add_argument("--no-plots", action="store_true", help="skip the 3-D picture")
    add_json(p)


LENGTH_UNITS = {"mm": 1e-3, "um": 1e-6, "m": 1.0}


def length_m(text: str) -> float:
    """A length "0.1mm", "100um", "0.0001 m" or a bare number (mm) in metres; argparse error otherwise."""
    import argparse
    import math

    t = str(text).strip().lower()
    unit = next((u for u in ("mm", "um", "m") if t.endswith(u)), None)
    try:
        v = float(t[: -len(unit)] if unit else t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a length such as 0.1mm, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a positive length, got {text!r}")
    return v * LENGTH_UNITS[unit or "mm"]


def cmd_plan(args) -> int:
    import numpy as np

    from ..config import check_output_apart
    from ..planning.check import check_poses
    from ..planning.plan import DEFAULT_CANDIDATES, CandidateSource, plan_cell
    from ..planning.predict import DRAWS
    from ..rig import load_scene
    from ..serialize import to_json

    ins = [(args.scene, "file")] + [(f, "file") for f in (args.check, args.from_list, args.validate_on) if f]
    check_output_apart(args.out, ins)
    af = None if args.angle_unit is None else (1.0 if args.angle_unit == "rad" else float(np.pi / 180))
    seed, draws = args.seed or 0, args.draws or DRAWS
    cands = args.candidates or DEFAULT_CANDIDATES
    scene = load_scene(args.scene)
    if args.check:
        res = check_poses(scene, args.check, args.out, seed=seed, n_candidates=cands, draws=draws, angle_factor=af,
                          plots=not args.no_plots, frames=args.frames)
    else:
        given = [k for k, v in (("--from-list", args.from_list), ("--box", args.box), ("--around", args.around))
                 if v is not None]
        if len(given) > 1:
            raise ConfigError(f"plan: give one candidate source, not {' and '.join(given)}")
        if args.from_list:
            src = CandidateSource("list", path=Path(args.from_list), angle_factor=af)
        elif args.box:
            src = CandidateSource("box", box_lo_m=args.box[:3], box_hi_m=args.box[3:])
            if any(lo >= hi for lo, hi in zip(args.box[:3], args.box[3:])):
                raise ConfigError(f"--box: expected x0 < x1, y0 < y1, z0 < z1, got {args.box}")
        elif args.around:
            src = CandidateSource("around", start_rad=tuple(np.radians(args.around)),
                                  delta_rad=float(np.radians(args.delta)))
        else:
            src = CandidateSource()
        if args.target_accuracy is not None and args.poses is not None:
            raise ConfigError("plan: give --poses or --target-accuracy, not both")
        res = plan_cell(scene, args.poses or scene.poses.count or 20, args.out, seed=seed, n_candidates=cands,
                        source=src, draws=draws, plots=not args.no_plots, frames=args.frames,
                        validate_on=args.validate_on, target_accuracy_m=args.target_accuracy)
    if args.json:
        print(to_json(res))
    else:
        print(_summary_plan(res, args.out))
    for w in res["warnings"]:
        print(f"vision-calib: warning: {w}", file=sys.stderr)
    return 0 if not args.check or res["verdict"]["ok"] else EXIT_NOT_CONVERGED


def _summary_plan(res: dict, out) -> str:
    sc, t = res["screening"], res["tour"]
    lines = [f"{res['scene']['name']}: {'checked' if res['kind'] == 'check' else 'planned'} {res['n_poses']} poses"
             + (f" ({res['verdict']['usable_poses']} usable)" if res["kind"] == "check" else ""),
             f"candidates: {sc['candidates']}, kept {sc['kept']} ({sc['unreachable']} unreachable, {sc['not_measurable']} "
             f"target not measurable" + (f", {sc['colliding']} colliding" if sc.get("colliding") is not None else "")
             + f"; {sc['rate_per_s'] or 0:.0f} per s)",
             f"tour: {t['total_s']:.1f} s" + ("" if t["moves_checked"] else " (moves not checked for collisions)")]
    clear = [p["clearance_m"] for p in res["poses"] if p.get("clearance_m") is not None]
    if clear:
        lines.append(f"smallest clearance: {min(clear) * 1e3:.1f} mm")
    pred = res.get("predicted_accuracy")
    def mm(f):
        v = f["rms_median_mm"]
        return f"{v:.3g} mm" if v is not None else f"n/a ({f['failed_draws']} draws failed: {f['first_error']})"

    for r in (pred or {}).get("rows", []):
        lines.append(f"predicted validation position RMS, {r['count']} poses: plan {mm(r['plan'])}, random "
                     f"{mm(r['random'])} (median of {pred['draws']} draws)")
    curve = res.get("accuracy_vs_count") or {}
    if curve.get("target_mm"):
        lines.append(f"--target-accuracy {curve['target_mm']:g} mm: {res['n_poses']} poses are the fewest whose "
                     "predicted validation position RMS reaches it (95 % of noise draws)")
    pv = (res.get("design") or {}).get("predicted_validation_rms")
    if pv and pv["plan"]["median_mm"] is not None and pv["random"]["median_mm"] is not None:
        lines.append(f"predicted validation position RMS (first order, {res['design']['frames']} frames per pose): plan "
                     f"{pv['plan']['median_mm']:.3g} mm (95 %: {pv['plan']['p95_mm']:.3g}), random "
                     f"{pv['random']['median_mm']:.3g} mm")
    if pred and pred.get("given"):
        lines.append(f"predicted validation position RMS of your list: {mm(pred['given'])}")
    lines += [f"note: {n}" for n in res["notes"]]
    lines.append(f"wrote {', '.join(str(Path(out) / f) for f in res.get('files', {}).values())}")
    if res["kind"] == "plan":
        lines.append(f"next: drive the tour in poses.csv's order, save each pose's frames as {Path(out) / 'images'}/"
                     f"<pose_id>/, then `vision-calib process {out}`")
    return "\n".join(lines)
