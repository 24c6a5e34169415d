"""The compare command: has the robot changed? Two calibration results of the same robot against their combined
uncertainty (``experiment.compare``)."""

from __future__ import annotations

from .exits import EXIT_NOT_CONVERGED
from .options import add_command, add_json


def add_compare_parser(sub) -> None:
    p = add_command(sub, "compare", "two calibrations of the same robot against their combined uncertainty: has "
                    "the robot changed?", """
  vision-calib compare out/monday out/friday --out out/changed
  vision-calib compare out/before_collision out/after_collision --out out/collision --json""", description=(
        "Compare two result folders of simulate / process of the same robot model (another day, another camera, "
        "after a collision): a chi-square test on the robot parameters identified in both (the camera and target "
        "mounts, and the parameters carrying a mount parameter, left out), the parameters that moved with their z, "
        "and the normalised difference of the tool poses over both accuracy maps. Writes DIR/compare.json and "
        "DIR/report.html. Exit 0 when the results are consistent, 3 when they differ, 2 on bad input (a missing "
        "folder, different robots or models, no or a non-finite covariance)."))
    p.add_argument("a", metavar="A", help="first result folder (calibrated_model.yaml, report.json)")
    p.add_argument("b", metavar="B", help="second result folder, of the same robot")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (compare.json, report.html)")
    add_json(p)


def cmd_compare(args) -> int:
    from ..experiment.compare import compare_results
    from ..serialize import to_json

    out = compare_results(args.a, args.b, args.out)
    print(to_json(out) if args.json else out["summary_text"])
    return 0 if out["decision"]["consistent"] else EXIT_NOT_CONVERGED
