"""Command-line interface: thin wrappers over library functions (one ``cmd_*`` per subcommand, dispatched
through :data:`COMMANDS`), cut by command family: ``runs`` (identifiability, identify-synthetic, simulate, demo,
process, calibrate-camera, process-poses, study, noise), ``imports`` (import-visp, import-rosi, export-rosi,
import-bag, import-pairs), ``cell`` (init, target), ``deploy`` (compensate, inverse, export, ``--export``),
``plan``, ``docs`` (the documentation pages), ``compare``; shared by them: ``options`` (argument types, common
options), ``locking`` (inputs, outputs, the output lock), ``exits`` (exit codes).

Outputs: every command that writes a folder takes ``--out DIR`` (``import-rosi SRC DST`` / ``export-rosi SRC
DST`` still accept the old positional DST, with a deprecation note on stderr); ``target`` and
``calibrate-camera`` write one file, also named by ``--out``. Results are printed as JSON with ``--json``.

Exit codes (the same for every command; :data:`EXIT_CODES` is the ``--help`` text)::

    0    done: outputs written and the result is good, or a "warning" verdict (the calibrated model is
         written; the reason is printed on stderr); also output piped into a closed reader (``| head``)
    2    bad input or usage: a command-line error (argparse), any user error (a file, key, pose or parameter
         named in one line ``vision-calib: error: ...`` on stderr, never a traceback), an output folder in use
         by another run, an unwritable output, out of memory
    3    outputs written but the result is not good: the identification failed (not converged, not finite) or
         a gross input error was found after the fit; no calibrated model is written
    130  interrupted (Ctrl-C); results already written are kept
"""

from __future__ import annotations

import os

# Our matrices are small (hundreds x tens): a multi-threaded BLAS only adds overhead, and on a
# loaded 2-core machine it made one 300 x 37 SVD take 100 ms instead of 0.4 ms. Set before numpy loads.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402

from .. import __version__  # noqa: E402
from ..errors import VisionCalibError  # noqa: E402
from . import cell, compare, deploy, docs, imports, plan, runs  # noqa: E402
from .deploy import EXPORT_FORMATS, EXPORTING_RUNS, exporting  # noqa: E402
from .exits import EXIT_CODES, EXIT_NOT_CONVERGED  # noqa: E402
from .locking import run_locked  # noqa: E402

__all__ = ["COMMANDS", "EXIT_CODES", "EXIT_NOT_CONVERGED", "EXPORT_FORMATS", "EXPORTING_RUNS", "build_parser", "main",
           "run"]


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="vision-calib", description="Vision-based geometric calibration of robots.",
        epilog="examples:\n  vision-calib demo --out out/demo\n  vision-calib process recording/ --out out/run\n"
               "  vision-calib simulate --help\n\n" + EXIT_CODES,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--version", action="version", version=f"%(prog)s {__version__}",
                    help="print the version and exit")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    # the order of the subcommands in `vision-calib --help`
    runs.add_run_parsers(sub)
    imports.add_visp_rosi_parsers(sub)
    runs.add_noise_parser(sub)
    cell.add_cell_parsers(sub)
    deploy.add_deploy_parsers(sub)  # also --export NAME of the runs added above
    imports.add_import_bag_parser(sub)
    imports.add_import_pairs_parser(sub)
    plan.add_plan_parser(sub)
    docs.add_docs_parser(sub)
    compare.add_compare_parser(sub)
    for p in sub.choices.values():  # the one rule for paths named in files (config.confine): the user's allowance
        p.add_argument("--allow-path", action="append", default=[], metavar="DIR",
                       help="let files (scene, measured-pose, recording, study, ROS-I files) name files in DIR too "
                            "(by default only in their own folder and the shipped scenes/ and targets/)")
    return ap


#: subcommand -> function(args) -> exit code
COMMANDS = {
    "identifiability": runs.cmd_identifiability,
    "identify-synthetic": runs.cmd_identify_synthetic,
    "simulate": exporting(runs.cmd_simulate),
    "demo": runs.cmd_simulate,
    "process": exporting(runs.cmd_process),
    "calibrate-camera": runs.cmd_calibrate_camera,
    "process-poses": exporting(runs.cmd_process_poses),
    "study": runs.cmd_study,
    "import-visp": imports.cmd_import_visp,
    "import-rosi": imports.cmd_import_rosi,
    "export-rosi": imports.cmd_export_rosi,
    "noise": runs.cmd_noise,
    "target": cell.cmd_target,
    "init": cell.cmd_init,
    "compensate": deploy.cmd_compensate,
    "inverse": deploy.cmd_inverse,
    "export": deploy.cmd_export,
    "import-bag": imports.cmd_import_bag,
    "import-pairs": imports.cmd_import_pairs,
    "plan": plan.cmd_plan,
    "docs": docs.cmd_docs,
    "compare": compare.cmd_compare,
}


def main(argv=None) -> int:
    import warnings

    parser = build_parser()
    args = parser.parse_args(argv)
    imports.positional_out(args, parser)
    try:
        with warnings.catch_warnings():  # numpy's floating-point warnings never reach the user: every bad value
            # they come from is refused by a named check (file, line, pose id) or ends in a named failure
            warnings.filterwarnings("ignore", r"(overflow|invalid value|divide by zero|underflow) encountered",
                                    RuntimeWarning)
            return run_locked(args, COMMANDS)
    except VisionCalibError as exc:
        print(f"vision-calib: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except BrokenPipeError:  # output piped into `head` & co.
        return 0
    except OSError as exc:  # output folder not writable, a file where a folder should be, ...
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        print(f"vision-calib: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except MemoryError as exc:
        from .exits import memory_message

        print(f"vision-calib: error: {memory_message(exc, getattr(args, 'command', None))}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("vision-calib: interrupted (results already written are kept)", file=sys.stderr)
        return 130


def run() -> None:
    """Console-script entry point: :func:`main`, then leave at once. Every output is already written (atomically)
    and closed, locks released, the image workers gone with their pool: the interpreter's own teardown
    (finalising every imported module: OpenCV, scipy, matplotlib) would only add ~0.2 s to each command."""
    code = main()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (BrokenPipeError, ValueError):  # output piped into `head`, or a closed stream
        pass
    os._exit(code)
