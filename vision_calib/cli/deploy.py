"""Using a result on the robot: compensate, inverse, export, and the ``--export NAME`` option of the runs."""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import VisionCalibError
from .options import add_command, add_json, tcp


#: the export formats (``deploy.export.FORMATS``, named here so that parsing imports nothing)
EXPORT_FORMATS = ("urdf", "dh", "ur_yaml", "ros_tf")
#: the runs that take ``--export NAME`` (the export runs on their output folder after them)
EXPORTING_RUNS = ("simulate", "process", "process-poses")


def add_deploy_parsers(sub) -> None:
    """Subcommands compensate, inverse, export, and the ``--export NAME`` option of :data:`EXPORTING_RUNS`."""
    result_help = "result folder (or its calibrated_model.yaml) of simulate / process / process-poses"
    p = add_command(sub, "compensate", "joint commands meant for the nominal model -> joints that put the tool "
                    "there on the calibrated model", """
  vision-calib compensate out/run joints.csv --out corrected.csv
  vision-calib compensate out/run joints.csv --out corrected.csv --report corrected_report.csv
  (joints.csv: pose_id,q1_deg,...,q6_deg or q1_rad..; corrected.csv: the same columns and units)""",
                    description="Joint commands meant for the nominal model -> the smallest joint correction that "
                                "puts the calibrated model's tool within its predicted accuracy of the nominal tool "
                                "pose: exact along well-conditioned joint directions, damped along near-singular ones "
                                "(those rows flagged with their joint change per mm). Rows outside the joint limits "
                                "or that cannot be corrected are named and left out; the others are always written "
                                "(exit 3 only when no row is corrected). A per-row report (correction, remaining "
                                "tool error, predicted accuracy, amplification) goes to --report.")
    p.add_argument("result", metavar="RESULT", help=result_help)
    p.add_argument("joints", metavar="JOINTS_CSV", help="joint table: [pose_id,]q1_<rad|deg>,..,qn_<unit> (m|mm for "
                   "prismatic joints), one row per joint set")
    p.add_argument("--out", required=True, metavar="FILE", dest="out_file", help="corrected joint table to write")
    p.add_argument("--report", default=None, metavar="FILE",
                   help="per-row report CSV to write (default: <out stem>_report.csv next to --out)")
    p = add_command(sub, "inverse", "tool poses -> joint values on the calibrated model (inverse kinematics)", """
  vision-calib inverse out/run poses.csv --out joints.csv
  vision-calib inverse out/run poses.csv --out joints.csv --tcp 0,0,0.12 --unit deg
  vision-calib inverse out/run poses.csv --out joints.csv --near current_joints.csv
  (poses.csv: pose_id,x_m,y_m,z_m,qx,qy,qz,qw: the tool in the model's base frame, quaternion scalar last)""")
    p.add_argument("result", metavar="RESULT", help=result_help)
    p.add_argument("poses", metavar="POSES_CSV", help="pose table: [pose_id,]x_<m|mm|cm>,y_..,z_..,qx,qy,qz,qw")
    p.add_argument("--out", required=True, metavar="FILE", dest="out_file", help="joint table to write")
    p.add_argument("--tcp", type=tcp, default=None, metavar="X,Y,Z",
                   help="tool centre point in the flange frame [m] (default 0 0 0: the flange)")
    p.add_argument("--unit", choices=("rad", "deg"), default="rad", help="angle unit of the joint table (default rad)")
    p.add_argument("--near", default=None, metavar="JOINTS_CSV",
                   help="joint table (one row for all poses, or one per pose in the same order): the solution nearest "
                        "it (the branch you ask for); default: the one nearest the nominal model's solution")
    p = add_command(sub, "export", "write a calibration result in a format a controller reads", """
  vision-calib export out/run --format urdf --out robot.urdf
  vision-calib export out/run --format dh --out dh.csv
  vision-calib export out/ur5e --format ur_yaml --out my_robot_calibration.yaml
  vision-calib export out/handeye --format ros_tf --out camera_tf.yaml""",
                    description="Write a calibration result in a format a controller reads: urdf (the calibrated "
                                "arm), dh (modified-DH table CSV), ur_yaml (ur_description kinematics YAML), ros_tf "
                                "(ROS static transforms of the identified mounts, also from hand-eye results).")
    p.add_argument("result", metavar="RESULT", help=result_help + ", or a hand-eye result (ros_tf)")
    p.add_argument("--format", required=True, choices=EXPORT_FORMATS, dest="fmt", help="what to write")
    p.add_argument("--out", required=True, metavar="FILE", dest="out_file", help="file to write")
    add_json(p)
    for name in EXPORTING_RUNS:
        sub.choices[name].add_argument(
            "--export", choices=EXPORT_FORMATS, default=None, metavar="NAME",
            help=f"after the run, also export the result ({', '.join(EXPORT_FORMATS)}) into the output folder "
                 "(the file names of `vision-calib export`)")


def _bar(what: str):
    """(callback(rows_done, rows_total), close()) of a progress bar on stderr (tqdm; silent when stderr is not a
    terminal)."""
    from tqdm import tqdm

    bar = tqdm(desc=what, unit="row", file=sys.stderr, disable=None, leave=False)

    def update(done: int, total: int) -> None:
        bar.total = total
        bar.update(done)

    return update, bar.close


def _warn_rows(kind: str, messages: list, report) -> None:
    from ..deploy.files import N_NAMED

    for m in messages[:N_NAMED]:
        print(f"vision-calib: warning: {m}", file=sys.stderr)
    if len(messages) > N_NAMED:
        where = f" (all in {report})" if report is not None else ""
        print(f"vision-calib: warning: ... {len(messages) - N_NAMED} more rows {kind}{where}", file=sys.stderr)


def cmd_compensate(args) -> int:
    from ..deploy.files import compensate_file

    update, close = _bar("compensate")
    try:
        out = compensate_file(args.result, args.joints, args.out_file, report=args.report, progress=update)
    finally:
        close()
    _warn_rows("near a singularity", out["flagged"], out["report"])
    _warn_rows("not corrected", out["not_corrected"], out["report"])
    m = out["max_correction"]
    print(f"wrote {out['out']} ({out['written']} of {out['rows']} joint sets; largest correction {m['value']:+.4g} "
          f"{m['unit']} on {m['joint']}, {m['row']}; {len(out['flagged'])} near a singularity, "
          f"{len(out['not_corrected'])} not corrected) and the per-row report {out['report']}")
    return 0


def cmd_inverse(args) -> int:
    from ..deploy.files import inverse_file

    update, close = _bar("inverse")
    try:
        out = inverse_file(args.result, args.poses, args.out_file, tcp=args.tcp, angle_unit=args.unit,
                           near=args.near, progress=update)
    finally:
        close()
    _warn_rows("not reached", out["not_reached"], None)
    n = len(out["not_reached"])
    print(f"wrote {out['out']} ({out['written']} of {out['rows']} joint sets; {n} pose{'' if n == 1 else 's'} not "
          "reached)")
    return 0


def cmd_export(args) -> int:
    from ..config import check_output_apart
    from ..deploy.export import export_verified, verified_text
    from ..serialize import to_json

    r = Path(args.result)
    check_output_apart(args.out_file, [(r, "folder" if r.is_dir() else "file")])
    out = export_verified(args.result, args.fmt, args.out_file)
    out["out"] = str(out["out"])
    print(to_json(out) if args.json else f"wrote {out['out']} ({args.fmt}); {verified_text(out['verified'])}")
    return 0


def exporting(run):
    """``run`` followed by ``--export NAME`` on its output folder (when the run ended with exit code 0)."""

    def run_then_export(args) -> int:
        code = run(args)
        fmt = getattr(args, "export", None)
        if fmt is None:
            return code
        if code != 0:
            print(f"vision-calib: warning: --export {fmt} skipped: the run did not give a usable result", file=sys.stderr)
            return code
        from ..deploy.export import FORMATS, export_verified, verified_text

        try:
            done = export_verified(args.out, fmt, Path(args.out) / FORMATS[fmt].file)
        except VisionCalibError as exc:  # the calibration is good: its outputs stand, the export is a warning
            print(f"vision-calib: warning: --export {fmt} not written: {exc} (the run's outputs in {args.out} are "
                  f"kept; `vision-calib export {args.out} --format ...` writes another format)", file=sys.stderr)
            return code
        print(f"vision-calib: exported {done['out']} ({fmt}; {verified_text(done['verified'])})", file=sys.stderr)
        return code

    return run_then_export
