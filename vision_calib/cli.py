"""Command-line interface: thin wrappers over library functions (one ``_cmd_*`` per subcommand, dispatched
through :data:`COMMANDS`).

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
from pathlib import Path  # noqa: E402

from . import __version__  # noqa: E402
from .errors import ConfigError, VisionCalibError  # noqa: E402

EXIT_CODES = """exit codes:
  0    done (also a "warning" verdict: calibrated model written, reason on stderr)
  2    bad input or usage (one line "vision-calib: error: ..." on stderr)
  3    outputs written but the result is not good (failed fit, gross input error): no calibrated model
  130  interrupted (Ctrl-C); results already written are kept"""


def _chessboard(text: str) -> tuple[int, int]:
    """argparse type: 'COLSxROWS' inner corners, e.g. 9x6 -> (9, 6)."""
    try:
        c, r = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected COLSxROWS (inner corners, e.g. 9x6), got {text!r}") from None
    if c < 2 or r < 2:
        raise argparse.ArgumentTypeError(f"expected at least 2x2 inner corners, got {text!r}")
    return c, r


def _int_at_least(minimum: int):
    """argparse type: an integer >= minimum."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {v}")
        return v

    return parse


_count = _int_at_least(1)  # poses, frames, workers, dpi
_seed = _int_at_least(0)  # seeds, tag ids


def _sigma(text: str) -> float:
    """argparse type: a finite number >= 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (v >= 0 and v < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text}")
    return v


def _scheduler(text: str) -> str:
    """argparse type: a Dask scheduler address ``tcp://host:port`` (or tls://) or an existing scheduler file."""
    import re

    if re.fullmatch(r"(tcp|tls)://[A-Za-z0-9.\-_]+:\d{1,5}|(tcp|tls)://\[[0-9A-Fa-f:.]+\]:\d{1,5}", text):
        if 0 < int(text.rsplit(":", 1)[1]) < 65536:
            return text
        raise argparse.ArgumentTypeError(f"port out of range in {text!r}")
    if text.startswith(("http://", "https://")):
        raise argparse.ArgumentTypeError(f"{text!r} looks like the Dask dashboard (http); give the scheduler "
                                         "address tcp://host:port (default port 8786)")
    if "://" not in text and Path(text).is_file():  # a scheduler file: its JSON "address" is read (study/run.py)
        from .errors import ConfigError
        from .study.run import scheduler_address

        try:
            scheduler_address(text)
        except ConfigError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text
    raise argparse.ArgumentTypeError(f"expected tcp://host:port or an existing scheduler file (JSON written by "
                                     f"dask-scheduler --scheduler-file), got {text!r}")


_METHOD_HELP = ("identification method: lse (least squares), ekf (extended Kalman filter), igm (H4: joint "
                "residuals through the inverse model) (default: the scene's identification.method)")
_RESIDUAL_HELP = ("what the residual compares: pose (6 components), position (3), joint (H4 joint values) "
                  "(default: the scene's)")


def _add_common(p, poses=True):
    p.add_argument("scene", help="scene YAML file (see scenes/)")
    if poses:
        p.add_argument("--poses", type=_count, default=None, help="number of identification poses (default: scene's)")
        _add_yes(p)
    p.add_argument("--seed", type=_seed, default=None, help="random seed (default: scene's, else 0)")
    _add_json(p)


def _add_yes(p):
    p.add_argument("--yes", action="store_true", help="run even when the estimated time or memory exceeds this "
                                                      "machine's (otherwise: exit 2 with the estimate)")


def _add_json(p):
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout instead of the summary")


def _tcp(text: str) -> tuple[float, float, float]:
    """argparse type: a tool point ``x,y,z`` in the flange frame [m]."""
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 3 or not all(abs(v) < 10 for v in vals):
        raise argparse.ArgumentTypeError(f"expected x,y,z of the tool point in the flange frame in metres (|v| < 10), "
                                         f"got {text!r}")
    return vals


def _add_holdout(p, folds=True):
    if folds:
        p.add_argument("--folds", type=_int_at_least(2), default=None,
                       help="k of the held-out k-fold validation (default 5, fewer with fewer poses)")
    p.add_argument("--tcp", type=_tcp, default=None, metavar="X,Y,Z",
                   help="a tool point in the flange frame [m] where the held-out and predicted accuracy are given "
                        "too (serial arms)")


def _add_run_options(p):
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--fix-unidentifiable", action="store_true",
                   help="when these poses cannot identify parameters that varied poses would, keep those at their "
                        "nominal values and go on (by default the run stops with exit code 2 naming them)")


def _command(sub, name: str, help: str, examples: str, description: str | None = None):
    """A subparser with its one-line help, a description and an ``examples:`` epilog (kept as written)."""
    return sub.add_parser(name, help=help, description=description or help[:1].upper() + help[1:] + ".",
                          epilog="examples:\n" + examples.strip("\n"),
                          formatter_class=argparse.RawDescriptionHelpFormatter)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="vision-calib", description="Vision-based geometric calibration of robots.",
        epilog="examples:\n  vision-calib demo --out out/demo\n  vision-calib process recording/ --out out/run\n"
               "  vision-calib simulate --help\n\n" + EXIT_CODES,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--version", action="version", version=f"%(prog)s {__version__}",
                    help="print the version and exit")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = _command(sub, "identifiability", "rank, base parameters, couplings, condition number of a scene", """
  vision-calib identifiability scenes/rx90_eye_in_hand.yaml --poses 12
  vision-calib identifiability scenes/h4_vision.yaml --residual joint --all --json""")
    _add_common(p)
    p.add_argument("--residual", choices=["pose", "position", "joint"], default=None, help=_RESIDUAL_HELP)
    p.add_argument("--all", action="store_true", dest="all_params",
                   help="analyse every model parameter, also those fixed by default (Hayati d, M_T_E.z...)")

    p = _command(sub, "identify-synthetic", "truth -> synthetic pose measurements (no images) -> identify -> "
                 "evaluate", """
  vision-calib identify-synthetic scenes/rx90_eye_in_hand.yaml --poses 30 --sigma-mm 0.1 --sigma-deg 0.02
  vision-calib identify-synthetic scenes/h4_vision.yaml --method igm --seed 4 --json""")
    _add_common(p)
    p.add_argument("--method", choices=["lse", "ekf", "igm"], default=None, help=_METHOD_HELP)
    p.add_argument("--residual", choices=["pose", "position", "joint"], default=None, help=_RESIDUAL_HELP)
    p.add_argument("--sigma-mm", type=_sigma, default=None, help="translation noise per component [mm]")
    p.add_argument("--sigma-deg", type=_sigma, default=None, help="rotation noise per component [deg]")

    p = _command(sub, "simulate", "end-to-end: render + effects + measure + identify + evaluate", """
  vision-calib simulate scenes/rx90_eye_in_hand.yaml --poses 12 --frames 2 --out out/rx90
  vision-calib simulate scenes/h4_vision.yaml --out out/h4 --export-recording out/h4_rec --no-plots""")
    _add_common(p)
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (report.json, summary.txt, plots, calibrated model)")
    p.add_argument("--frames", type=_count, default=None, help="frames per pose (default: scene's)")
    p.add_argument("--method", choices=["lse", "ekf", "igm"], default=None, help=_METHOD_HELP)
    p.add_argument("--export-recording", default=None, metavar="DIR",
                   help="also write the rendered images as a recorded folder (input of `process`)")
    p.add_argument("--workers", type=_count, default=None, help="processes for rendering/measurement (default: cores)")
    _add_run_options(p)
    _add_holdout(p)

    p = _command(sub, "demo", "the default scene end to end (README's main command)", """
  vision-calib demo
  vision-calib demo --out out/demo2 --seed 1 --method lse""")
    p.add_argument("--out", default="out/demo", metavar="DIR",
                   help="output folder (report.json, summary.txt, plots, calibrated model; default out/demo)")
    p.add_argument("--seed", type=_seed, default=None, help="random seed (default: the scene's)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--method", choices=["igm", "lse", "ekf"], default=None,
                   help="H4 identification: igm (joint residuals, default), lse (pose residuals), ekf")
    _add_holdout(p)
    _add_json(p)

    p = _command(sub, "process", "measure -> identify -> report on a recorded image folder", """
  vision-calib process recording/ --out out/run
  vision-calib process recording/ --out out/run --camera camera.yaml --no-plots --json""")
    p.add_argument("folder", help="recorded folder (recording.yaml, poses.csv, images; format: docs/formats.md)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (report.json, summary.txt, plots, calibrated model)")
    p.add_argument("--method", choices=["lse", "ekf", "igm"], default=None, help=_METHOD_HELP)
    _add_run_options(p)
    p.add_argument("--allow-symlinks", action="store_true",
                   help="follow symbolic links that lead out of the recorded folder (refused by default)")
    p.add_argument("--refine-intrinsics", action="store_true",
                   help="calibrate the camera from the recording's images even when recording.yaml gives intrinsics")
    p.add_argument("--camera", default=None, metavar="CAMERA_YAML",
                   help="camera intrinsics from this camera.yaml (calibrate-camera's output) instead of recording.yaml's")
    _add_holdout(p)
    _add_json(p)

    p = _command(sub, "calibrate-camera", "camera intrinsics + distortion from images of a target", """
  vision-calib calibrate-camera images/ --target targets/charuco_a5.yaml --out camera.yaml""")
    p.add_argument("folder", help="folder of images (searched recursively: png, jpg, jpeg, bmp, tif, tiff)")
    p.add_argument("--target", required=True, help="target YAML (see targets/)")
    p.add_argument("--out", required=True, metavar="FILE", help="camera YAML to write (format: docs/workflows.md)")
    _add_json(p)

    p = _command(sub, "process-poses", "joints + measured poses (no images) -> identify -> k-fold report "
                 "(format: docs/measured_poses.md)", """
  vision-calib process-poses measured.yaml --out out/poses
  vision-calib process-poses measured.yaml --out out/poses --method ekf --folds 5 --json""")
    p.add_argument("file", help="measured-pose YAML (with its CSV beside it)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (report.json with the k-fold validation, summary.txt, plots, calibrated model)")
    p.add_argument("--method", choices=["lse", "ekf"], default=None,
                   help="identification method: lse (least squares) or ekf (default: its scene's "
                        "identification.method)")
    p.add_argument("--folds", type=_int_at_least(2), default=None,
                   help="k of the held-out validation (default: the file's)")
    _add_holdout(p, folds=False)
    _add_run_options(p)
    _add_json(p)

    p = _command(sub, "study", "parameter sweep x Monte Carlo (local processes or a Dask cluster)", """
  vision-calib study scenes/studies/h4_noise.yaml --out out/study --workers 2
  vision-calib study scenes/studies/h4_noise.yaml --out out/study --scheduler tcp://10.0.0.5:8786""")
    p.add_argument("spec", help="study YAML (see scenes/studies/)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (results table, summary, plots)")
    p.add_argument("--workers", type=_count, default=None, help="local worker processes (default: cores)")
    p.add_argument("--scheduler", type=_scheduler, default=None,
                   help="Dask scheduler address (tcp://host:port) or scheduler file")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    _add_yes(p)
    _add_json(p)

    p = _command(sub, "import-visp", "convert a ViSP hand-eye folder into a recorded folder", """
  vision-calib import-visp visp_data/ --out recording/
  vision-calib import-visp visp_chessboard/ --out recording/ --chessboard 9x6 --square-m 0.025""", description="""\
Convert a ViSP hand-eye folder into a recorded folder. The files, as ViSP's acquisition apps write them
(visp-acquire-franka-calib-data and the like):
  franka_camera.xml       intrinsics (any *camera*.xml)
  franka_image-N.png      one image per pose (any *image-N.png|jpg|bmp|tif)
  franka_pose_rPe_N.yaml  flange pose in the robot base, t [m] + theta-u [rad] (also *pose_fPe_N.yaml,
                          *w_P_ee-N.yaml)
  chessboard-data.txt     "Chessboard / 9 x 6 / square size: 0.0236 m": a chessboard (eye-in-hand unless --mount)
  apriltag-data.txt       "36h11 ... / size: 0.048 m": one AprilTag on the flange, fixed camera (eye-to-hand)
The pattern is read from the folder's own chessboard-data.txt or apriltag-data.txt; --chessboard /
--square-m / --tag-size-m give or override it.""")
    p.add_argument("src", metavar="SRC", help="ViSP data folder (images, poses, camera XML, pattern file)")
    p.add_argument("--out", required=True, metavar="DIR", help="recorded folder to write")
    p.add_argument("--tag-size-m", type=_sigma, default=None,
                   help="AprilTag side [m] (default: from apriltag-data.txt)")
    p.add_argument("--tag-id", type=_seed, default=None, help="tag id (default: detected in the first image)")
    # --- importers (io/visp.py chessboard variant, io/rosi.py)
    p.add_argument("--chessboard", type=_chessboard, default=None, metavar="COLSxROWS",
                   help="chessboard inner corners as ViSP's -w x -h (e.g. 9x6; default: from chessboard-data.txt); "
                        "the target has one more square each way")
    p.add_argument("--square-m", type=_sigma, default=None,
                   help="chessboard square side [m] (ViSP's --square-size; default: from chessboard-data.txt)")
    p.add_argument("--mount", choices=("eye_in_hand", "fixed"), default=None,
                   help="chessboard folders: where the camera is (default eye_in_hand, ViSP's tutorial)")

    p = _command(sub, "import-rosi", "convert a ROS-I industrial_calibration hand-eye data set into a recorded "
                 "folder", """
  vision-calib import-rosi rosi_data/ --out recording/
  vision-calib import-rosi rosi_data/cal_data.yaml --out recording/
  (the old spelling `import-rosi SRC DST` still works; it is deprecated)""")
    p.add_argument("src", metavar="SRC", help="folder with cal_data.yaml (or that file)")
    p.add_argument("dst", nargs="?", default=None, metavar="DST", help="deprecated: use --out DIR")
    p.add_argument("--out", default=None, metavar="DIR", help="recorded folder to write")
    p.add_argument("--allow-symlinks", action="store_true", help="follow symlinks leading out of SRC")

    p = _command(sub, "export-rosi", "write a recorded folder (flange poses, ChArUco) as a ROS-I data set", """
  vision-calib export-rosi recording/ --out rosi_data/
  (the old spelling `export-rosi SRC DST` still works; it is deprecated)""")
    p.add_argument("src", metavar="SRC", help="recorded folder")
    p.add_argument("dst", nargs="?", default=None, metavar="DST", help="deprecated: use --out DIR")
    p.add_argument("--out", default=None, metavar="DIR", help="folder to write (cal_data.yaml, poses/, images/)")

    p = _command(sub, "noise", "camera noise from repeated frames of a static target: corner and pose scatter, and "
                 "the simulator settings that reproduce it (docs/noise.md)", """
  vision-calib noise rosi_noise_qualification/ --out out/noise
  vision-calib noise frames/ --target targets/charuco_a5.yaml --camera camera.yaml --out out/noise --json""")
    p.add_argument("folder", help="ROS-I noise-qualification folder (cal_data.yaml), or a folder of images of one "
                                  "static target (with --target and --camera)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (noise.json, sensor.yaml, summary.txt)")
    p.add_argument("--target", default=None, help="target YAML (see targets/; overrides cal_data.yaml's target_finder)")
    p.add_argument("--camera", default=None, metavar="CAMERA_YAML",
                   help="camera.yaml (calibrate-camera's output; overrides cal_data.yaml's intrinsics)")
    p.add_argument("--sim-frames", type=_int_at_least(2), default=30,
                   help="frames the simulator draws to check the fitted settings (default 30)")
    p.add_argument("--seed", type=_seed, default=0, help="seed of the simulator's noise (default 0)")
    p.add_argument("--allow-symlinks", action="store_true", help="follow symlinks leading out of the folder")
    _add_json(p)

    p = _command(sub, "target", "export a printable target: a sheet with the board, a label and a 100 mm scale bar", """
  vision-calib target targets/charuco_a5.yaml --paper A4 --out charuco_a5.pdf
  vision-calib target targets/charuco_a5.yaml --paper 300x200 --out charuco_a5.svg
  vision-calib target targets/charuco_a5.yaml --out charuco_a5.png --dpi 600""")
    p.add_argument("target", help="target YAML (see targets/)")
    p.add_argument("--out", required=True, metavar="FILE",
                   help="file to write: .pdf or .svg (vectors), .png (pixels); print it at 100 %% scale")
    p.add_argument("--paper", default=None, metavar="SIZE",
                   help="sheet: A2..A6, letter, legal or WxH in mm (e.g. 300x200); the board is centred, portrait "
                        "or landscape as it fits (default: a sheet just big enough for the board and its label; "
                        "a .png without --paper is the board alone)")
    p.add_argument("--dpi", type=_count, default=None,
                   help="resolution of a .png [dots per inch] (default 300); refused for .pdf / .svg")

    p = _command(sub, "init", "start your own cell (or a copy of the example recording) in a new folder", """
  vision-calib init --list
  vision-calib init my_cell --from ur5e
  vision-calib init my_cell --urdf my_robot.urdf
  vision-calib init my_recording --from example""", description=(
        "Write a self-contained folder from a shipped starting point: DIR/scene.yaml (its entry point), the robot "
        "file in DIR/robot/ and the target in DIR/target.yaml, each key you edit commented; for the example "
        "recording, DIR is the recording (process it). With --urdf, your URDF replaces the robot (base and tip "
        "links guessed and printed; --base-link / --tip-link override)."))
    p.add_argument("dir", nargs="?", metavar="DIR", help="new folder to write (must not exist, or be empty)")
    p.add_argument("--out", metavar="DIR", default=None, help="the same as DIR")
    p.add_argument("--from", dest="from_name", metavar="NAME", default=None,
                   help="starting point (default ur5e): see --list")
    p.add_argument("--list", action="store_true", help="list the starting points and exit")
    p.add_argument("--urdf", metavar="FILE", default=None, help="your robot's URDF (copied into DIR/robot/)")
    p.add_argument("--base-link", default=None, help="with --urdf: the chain's base link (default: the root link)")
    p.add_argument("--tip-link", default=None,
                   help="with --urdf: the chain's tip link, the flange (default: the leaf with most movable joints)")
    _add_deploy_commands(sub)
    _add_import_bag(sub)
    _add_import_pairs(sub)
    _add_plan_parser(sub)
    for p in sub.choices.values():  # the one rule for paths named in files (config.confine): the user's allowance
        p.add_argument("--allow-path", action="append", default=[], metavar="DIR",
                       help="let files (scene, measured-pose, recording, study, ROS-I files) name files in DIR too "
                            "(by default only in their own folder and the shipped scenes/ and targets/)")
    return ap


def _positional_out(args, parser) -> None:
    """``import-rosi SRC DST`` / ``export-rosi SRC DST``: the old positional output, taken as ``--out`` with a
    deprecation note on stderr; exactly one of the two must be given (argparse error, exit 2, otherwise)."""
    if args.command not in ("import-rosi", "export-rosi"):
        return
    if args.dst is not None and args.out is not None:
        parser.error(f"{args.command}: give the output folder once: --out DIR (DST is the deprecated spelling)")
    if args.dst is None and args.out is None:
        parser.error(f"{args.command}: the output folder is required: --out DIR")
    if args.dst is not None:
        print(f"vision-calib: warning: `{args.command} SRC DST` is deprecated; write `{args.command} SRC --out DST`",
              file=sys.stderr)


# --------------------------------------------------------------------------------------------- the commands
def _check_size(args) -> None:
    """--poses against the machine (study/budget.py check_pose_count): exit 2 with the estimate unless --yes."""
    from .study.budget import check_pose_count

    check_pose_count(args.command, getattr(args, "poses", None), getattr(args, "frames", None),
                     getattr(args, "workers", None) or os.cpu_count() or 1, getattr(args, "yes", False),
                     scene=getattr(args, "scene", None))


def _cmd_identifiability(args) -> int:
    from .experiment.synthetic import identifiability_json
    from .serialize import to_json

    _check_size(args)
    out = identifiability_json(args.scene, residual=args.residual, n_poses=args.poses, seed=args.seed,
                               all_params=args.all_params)
    print(to_json(out) if args.json else _summary_identifiability(out))
    return 0


def _cmd_identify_synthetic(args) -> int:
    from .experiment.synthetic import identify_synthetic_json
    from .serialize import to_json

    _check_size(args)
    out = identify_synthetic_json(
        args.scene, method=args.method, residual=args.residual, n_poses=args.poses,
        sigma_mm=args.sigma_mm, sigma_deg=args.sigma_deg, seed=args.seed,
    )
    print(to_json(out) if args.json else _summary_synthetic(out))
    return _status(out["verdict"])


def _cmd_simulate(args) -> int:
    """simulate and demo (demo: the default scene, no --poses / --frames / --workers)."""
    from .experiment.image_chain import start_fork_server

    _check_size(args)
    start_fork_server()  # the image workers' imports run beside ours (issue 11: demo wall time)
    from .experiment.simulate import run_simulation, DEFAULT_SCENE

    scene = DEFAULT_SCENE if args.command == "demo" else args.scene
    report = run_simulation(
        scene, out_dir=args.out, seed=args.seed,
        n_poses=getattr(args, "poses", None), frames=getattr(args, "frames", None),
        method=getattr(args, "method", None), export_recording=getattr(args, "export_recording", None),
        workers=getattr(args, "workers", None), progress=not args.json, plots=not args.no_plots,
        fix_unidentifiable=getattr(args, "fix_unidentifiable", False), folds=args.folds, tcp=args.tcp,
    )
    return _print_report(args, report)


def _print_report(args, report: dict) -> int:
    from .serialize import to_json

    print(to_json(report) if args.json else report["summary_text"])
    return _status(report["verdict"])


def _cmd_process(args) -> int:
    from .experiment.process import process_folder

    report = process_folder(args.folder, out_dir=args.out, method=args.method, progress=not args.json,
                            plots=not args.no_plots, fix_unidentifiable=args.fix_unidentifiable,
                            allow_symlinks=args.allow_symlinks, refine_intrinsics=args.refine_intrinsics,
                            camera_file=args.camera, folds=args.folds, tcp=args.tcp)
    return _print_report(args, report)


def _cmd_calibrate_camera(args) -> int:
    from .serialize import to_json
    from .io.camera_file import write_camera_yaml
    from .measure.intrinsics import calibrate_from_images, find_images, summary_text
    from .targets import load_target

    target = load_target(args.target)
    res = calibrate_from_images(find_images(args.folder), target, progress=not args.json)
    write_camera_yaml(args.out, res)
    print(to_json(res.to_dict()) if args.json else summary_text(res) + f"\nwrote {args.out}")
    return 0


def _cmd_process_poses(args) -> int:
    from .experiment.poses import process_poses

    report = process_poses(args.file, out_dir=args.out, method=args.method, folds=args.folds,
                           plots=not args.no_plots, fix_unidentifiable=args.fix_unidentifiable, tcp=args.tcp)
    return _print_report(args, report)


def _cmd_study(args) -> int:
    from .serialize import to_json
    from .study import run_study

    res = run_study(args.spec, out_dir=args.out, workers=args.workers, scheduler=args.scheduler,
                    progress=not args.json, plots=not args.no_plots, yes=args.yes)
    print(to_json(res) if args.json else res["summary_text"])
    return 0


def _cmd_import_visp(args) -> int:
    from .io.visp import import_visp

    notes = []
    path = import_visp(args.src, args.out, chessboard=args.chessboard, square_m=args.square_m,
                       tag_m=args.tag_size_m, tag_id=args.tag_id, mount=args.mount, notes=notes)
    for n in notes:
        print(f"vision-calib: warning: {n}", file=sys.stderr)
    print(f"wrote recorded folder {path}")
    return 0


def _cmd_import_rosi(args) -> int:
    from .io.rosi import import_rosi

    print(f"wrote recorded folder {import_rosi(args.src, _out(args), allow_symlinks=args.allow_symlinks)}")
    return 0


def _cmd_export_rosi(args) -> int:
    from .io.rosi import export_rosi

    print(f"wrote ROS-I data set {export_rosi(args.src, _out(args))}")
    return 0


def _cmd_noise(args) -> int:
    from .experiment.noise import measure_noise
    from .serialize import to_json

    res = measure_noise(args.folder, args.out, target=args.target, camera=args.camera, sim_frames=args.sim_frames,
                        seed=args.seed, allow_symlinks=args.allow_symlinks)
    print(to_json({k: v for k, v in res.items() if k != "summary_text"}) if args.json else res["summary_text"])
    return 0


def _cmd_target(args) -> int:
    from .targets import export_printable, load_target

    out = export_printable(load_target(args.target), args.out, dpi=args.dpi, paper=args.paper,
                           source=Path(args.target).name)
    print(f"wrote {out}; print it at 100 % (actual size), then measure the 100 mm scale bar and a square"
          if args.paper is not None or out.suffix.lower() != ".png" else f"wrote {out}")
    return 0


def _cmd_init(args) -> int:
    from .io.init_cell import init_cell, list_starters

    if args.list:
        print(list_starters())
        return 0
    if (args.dir is None) == (args.out is None):
        raise ConfigError("init: give the new folder, as DIR or --out DIR (or --list to see the starting points)")
    res = init_cell(args.dir or args.out, args.from_name, urdf=args.urdf, base_link=args.base_link, tip_link=args.tip_link)
    print("\n".join(res["notes"]))
    return 0


# --------------------------------------------------------------------------------------------- deploy (issue 26)
#: the export formats (``io.controller_export.FORMATS``, named here so that parsing imports nothing)
EXPORT_FORMATS = ("urdf", "dh", "ur_yaml", "ros_tf")
#: the runs that take ``--export NAME`` (the export runs on their output folder after them)
EXPORTING_RUNS = ("simulate", "process", "process-poses")


def _add_deploy_commands(sub) -> None:
    """Subcommands compensate, inverse, export, and the ``--export NAME`` option of :data:`EXPORTING_RUNS`."""
    result_help = "result folder (or its calibrated_model.yaml) of simulate / process / process-poses"
    p = _command(sub, "compensate", "joint commands meant for the nominal model -> joints that put the tool there on "
                 "the calibrated model", """
  vision-calib compensate out/run joints.csv --out corrected.csv
  (joints.csv: pose_id,q1_deg,...,q6_deg or q1_rad..; corrected.csv: the same columns and units)""")
    p.add_argument("result", metavar="RESULT", help=result_help)
    p.add_argument("joints", metavar="JOINTS_CSV", help="joint table: [pose_id,]q1_<rad|deg>,..,qn_<unit> (m|mm for "
                   "prismatic joints), one row per joint set")
    p.add_argument("--out", required=True, metavar="FILE", dest="out_file", help="corrected joint table to write")
    p = _command(sub, "inverse", "tool poses -> joint values on the calibrated model (inverse kinematics)", """
  vision-calib inverse out/run poses.csv --out joints.csv
  vision-calib inverse out/run poses.csv --out joints.csv --tcp 0 0 0.12 --unit deg
  (poses.csv: pose_id,x_m,y_m,z_m,qx,qy,qz,qw: the tool in the model's base frame, quaternion scalar last)""")
    p.add_argument("result", metavar="RESULT", help=result_help)
    p.add_argument("poses", metavar="POSES_CSV", help="pose table: [pose_id,]x_<m|mm|cm>,y_..,z_..,qx,qy,qz,qw")
    p.add_argument("--out", required=True, metavar="FILE", dest="out_file", help="joint table to write")
    p.add_argument("--tcp", type=_tcp, default=None, metavar="X,Y,Z",
                   help="tool centre point in the flange frame [m] (default 0 0 0: the flange)")
    p.add_argument("--unit", choices=("rad", "deg"), default="rad", help="angle unit of the joint table (default rad)")
    p = _command(sub, "export", "write a calibration result in a format a controller reads", """
  vision-calib export out/run --format urdf --out robot.urdf
  vision-calib export out/run --format dh --out dh.csv
  vision-calib export out/ur5e --format ur_yaml --out my_robot_calibration.yaml
  vision-calib export out/handeye --format ros_tf --out camera_tf.yaml""",
                 description="Write a calibration result in a format a controller reads: urdf (the calibrated arm), "
                             "dh (modified-DH table CSV), ur_yaml (ur_description kinematics YAML), ros_tf (ROS static "
                             "transforms of the identified mounts, also from hand-eye results).")
    p.add_argument("result", metavar="RESULT", help=result_help + ", or a hand-eye result (ros_tf)")
    p.add_argument("--format", required=True, choices=EXPORT_FORMATS, dest="fmt", help="what to write")
    p.add_argument("--out", required=True, metavar="FILE", dest="out_file", help="file to write")
    _add_json(p)
    for name in EXPORTING_RUNS:
        sub.choices[name].add_argument(
            "--export", choices=EXPORT_FORMATS, default=None, metavar="NAME",
            help=f"after the run, also export the result ({', '.join(EXPORT_FORMATS)}) into the output folder "
                 "(the file names of `vision-calib export`)")


def _cmd_compensate(args) -> int:
    from .deploy.files import compensate_file

    out = compensate_file(args.result, args.joints, args.out_file)
    m = out["max_correction"]
    print(f"wrote {out['out']} ({out['rows']} joint sets; largest correction {m['value']:+.4g} {m['unit']} on "
          f"{m['joint']}, {m['row']})")
    return 0


def _cmd_inverse(args) -> int:
    from .deploy.files import inverse_file

    out = inverse_file(args.result, args.poses, args.out_file, tcp=args.tcp, angle_unit=args.unit)
    print(f"wrote {out['out']} ({out['rows']} joint sets)")
    return 0


def _cmd_export(args) -> int:
    from .config import check_output_apart
    from .io.controller_export import export
    from .serialize import to_json

    r = Path(args.result)
    check_output_apart(args.out_file, [(r, "folder" if r.is_dir() else "file")])
    path = export(args.result, args.fmt, args.out_file)
    print(to_json({"format": args.fmt, "out": str(path)}) if args.json else f"wrote {path} ({args.fmt})")
    return 0


def _exporting(run):
    """``run`` followed by ``--export NAME`` on its output folder (when the run ended with exit code 0)."""

    def run_then_export(args) -> int:
        code = run(args)
        fmt = getattr(args, "export", None)
        if fmt is None:
            return code
        if code != 0:
            print(f"vision-calib: warning: --export {fmt} skipped: the run did not give a usable result", file=sys.stderr)
            return code
        from .io.controller_export import FORMATS, export

        try:
            path = export(args.out, fmt, Path(args.out) / FORMATS[fmt].file)
        except VisionCalibError as exc:
            print(f"vision-calib: error: --export {fmt}: {exc} (the run's outputs in {args.out} are kept)",
                  file=sys.stderr)
            return exc.exit_code
        print(f"vision-calib: exported {path} ({fmt})", file=sys.stderr)
        return code

    return run_then_export


#: subcommand -> function(args) -> exit code
COMMANDS = {
    "identifiability": _cmd_identifiability,
    "identify-synthetic": _cmd_identify_synthetic,
    "simulate": _exporting(_cmd_simulate),
    "demo": _cmd_simulate,
    "process": _exporting(_cmd_process),
    "calibrate-camera": _cmd_calibrate_camera,
    "process-poses": _exporting(_cmd_process_poses),
    "study": _cmd_study,
    "import-visp": _cmd_import_visp,
    "import-rosi": _cmd_import_rosi,
    "export-rosi": _cmd_export_rosi,
    "noise": _cmd_noise,
    "target": _cmd_target,
    "init": _cmd_init,
    "compensate": _cmd_compensate,
    "inverse": _cmd_inverse,
    "export": _cmd_export,
}


# ------------------------------------------------------- import-bag: a recorded folder from a ROS bag (io/rosbag.py)
def _add_import_bag(sub) -> None:
    p = _command(sub, "import-bag", "a recorded folder from a ROS 1 / ROS 2 bag: images + joint states, one pose per "
                 "standstill (needs the [ros] extra)", """
  vision-calib import-bag session.bag --scene my_cell/scene.yaml --image-topic /camera/image_raw \\
      --joints-topic /joint_states --camera-info-topic /camera/camera_info --out recording/
  vision-calib import-bag session_ros2/ --scene my_cell --image-topic /cam/image/compressed \\
      --joints-topic /joint_states --joint-names j1,j2,j3,j4,j5,j6 --out recording/""")
    p.add_argument("bag", help="ROS 1 .bag, ROS 2 bag folder (metadata.yaml), .db3 or .mcap")
    p.add_argument("--scene", required=True, metavar="CELL",
                   help="the cell: its scene file, or a folder with scene.yaml (robot, mount, target, camera)")
    p.add_argument("--image-topic", required=True, help="sensor_msgs/Image (mono8, bgr8, rgb8, mono16) or "
                                                        "sensor_msgs/CompressedImage (jpeg, png)")
    p.add_argument("--joints-topic", required=True, help="sensor_msgs/JointState")
    p.add_argument("--camera-info-topic", default=None,
                   help="sensor_msgs/CameraInfo (K, D plumb_bob; default: the cell's camera intrinsics)")
    p.add_argument("--joint-names", default=None, metavar="N1,N2,..",
                   help="the bag's names of the cell's joints, in the cell's order (default: a URDF cell's joint "
                        "names, q1..qn for an MDH robot)")
    p.add_argument("--still-speed", type=_sigma, default=1e-3, metavar="RAD_S",
                   help="standstill: mean joint speed below this over the window [rad/s, m/s] (default 0.001)")
    p.add_argument("--still-window", type=_sigma, default=0.5, metavar="S",
                   help="standstill window and shortest standstill [s] (default 0.5)")
    p.add_argument("--max-gap", type=_sigma, default=1.0, metavar="S",
                   help="longest gap of the joint states [s] before the bag counts as damaged (default 1)")
    p.add_argument("--max-frames", type=_count, default=None, help="frames kept per pose (default: all)")
    p.add_argument("--out", required=True, metavar="DIR", help="recorded folder to write (new or empty)")


def _cmd_import_bag(args) -> int:
    from .config import check_output_apart
    from .io.rosbag import StillSettings, import_bag

    check_output_apart(args.out, [(args.bag, "folder" if Path(args.bag).is_dir() else "file")])
    names = None if args.joint_names is None else args.joint_names.split(",")
    res = import_bag(args.bag, args.scene, args.image_topic, args.joints_topic, args.out,
                     camera_info_topic=args.camera_info_topic, joint_names=names,
                     settings=StillSettings(args.still_speed, args.still_window, args.max_gap, args.max_frames))
    print(res.summary())
    return 0


COMMANDS["import-bag"] = _cmd_import_bag
# ------------------------------------------------------------------------------------------------ end of import-bag


# -------------------------------------- import-pairs: hand-eye pose pairs of other tools (io/transform_pairs.py)
def _add_import_pairs(sub) -> None:
    p = _command(sub, "import-pairs", "a pose-pair file for process-poses from a TransformPairs YAML "
                 "(handeye_calib_camodocal, easy_handeye-style samplers: T1_i base->end effector, T2_i "
                 "camera->marker)", """
  vision-calib import-pairs TransformPairsInput.yml --mount fixed --out pairs/pairs.yaml
  vision-calib process-poses pairs/pairs.yaml --out out/handeye""")
    p.add_argument("file", help="TransformPairs YAML (OpenCV FileStorage: %%YAML:1.0, ---, frameCount, T1_i, T2_i)")
    p.add_argument("--mount", required=True, choices=("eye_in_hand", "fixed"),
                   help="eye_in_hand: camera on the flange, marker fixed; fixed: camera on a stand, marker on the "
                        "flange")
    p.add_argument("--folds", type=_int_at_least(2), default=5, help="k of process-poses' held-out validation "
                                                                     "(default 5)")
    # dest out_file: a file output, written atomically (no folder lock: the lock would make FILE.yaml a folder)
    p.add_argument("--out", dest="out_file", required=True, metavar="FILE.yaml",
                   help="pose-pair file to write (its two CSVs beside it); the measured poses' noise is estimated "
                        "per axis by process-poses")


def _cmd_import_pairs(args) -> int:
    from .config import check_output_apart
    from .io.transform_pairs import import_pairs

    check_output_apart(args.out_file, [(args.file, "file")], "--out")
    path = import_pairs(args.file, args.mount, args.out_file, folds=args.folds)
    print(f"wrote pose-pair file {path} (process it: vision-calib process-poses {path} --out DIR)")
    return 0


COMMANDS["import-pairs"] = _cmd_import_pairs
# ---------------------------------------------------------------------------------------------- end of import-pairs


# --------------------------------------------------------------------------------------------- plan (issue 27)
def _floats_list(n: int | None, what: str):
    """argparse type: comma-separated numbers (n of them when n is given)."""

    def parse(text: str) -> tuple[float, ...]:
        try:
            vals = tuple(float(v) for v in text.split(","))
        except ValueError:
            vals = ()
        if not vals or (n is not None and len(vals) != n) or not all(abs(v) < 1e6 for v in vals):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return vals

    return parse


def _add_plan_parser(sub) -> None:
    p = _command(sub, "plan", "the joint values to command for a calibration: reachable, collision-free, the target "
                 "measurable, D-optimal, in a drivable order, with the accuracy they predict", """
  vision-calib plan scenes/ur5e_cell.yaml --poses 20 --out out/plan
  vision-calib plan scenes/h4_vision.yaml --poses 15 --out out/plan_h4
  vision-calib plan scenes/ur5e_cell.yaml --poses 20 --around 0,-90,90,-90,-90,0 --delta 25 --out out/plan2
  vision-calib plan scenes/ur5e_cell.yaml --check my_poses.csv --out out/check""", description=(
        "Plan the poses of a calibration: candidates in the scene's pose region (or --from-list, --box, --around), "
        "kept when within the joint limits, collision-free with the scene's clearance (obstacles: and the robot's "
        "own links; FCL, extra [plan]) and the target measurable (whole board in the image, distance, incidence, "
        "square size: the scene's planning: section); N chosen D-optimal for the base parameters at the scene's "
        "noise; ordered into a short joint-space tour whose moves are checked for collisions. Writes DIR/poses.csv, "
        "recording.yaml and images/<pose_id>/ (a recording to fill, then `process DIR`), plan.json and report.html "
        "(the predicted accuracy against random poses). --check reports your own poses.csv the same way (exit 3 "
        "when a pose is not usable or a move collides)."))
    p.add_argument("scene", help="scene YAML file of the cell (obstacles: and planning: keys, docs/formats.md)")
    p.add_argument("--poses", type=_count, default=None, help="number of poses to plan (default: the scene's "
                                                              "poses.count, else 20)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (poses.csv, recording.yaml, images/, plan.json, report.html)")
    p.add_argument("--check", default=None, metavar="POSES_CSV",
                   help="report this list of poses (pose_id,q1..qn; the recording layout) instead of planning")
    p.add_argument("--candidates", type=_count, default=None, help="candidates drawn (default 20000)")
    p.add_argument("--from-list", default=None, metavar="POSES_CSV", help="candidates: the poses of this list")
    p.add_argument("--box", type=_floats_list(6, "x0,y0,z0,x1,y1,z1 in metres"), default=None,
                   metavar="X0,Y0,Z0,X1,Y1,Z1",
                   help="candidates: the region's poses whose flange (H4: nacelle point) lies in this box [m, robot "
                        "base frame]")
    p.add_argument("--around", type=_floats_list(None, "joint values q1,..,qn in degrees"), default=None,
                   metavar="Q1,..,QN", help="candidates: joint sets within +-DELTA of these joint values [deg]")
    p.add_argument("--delta", type=_sigma, default=20.0, help="with --around: half-width per joint [deg] (default 20)")
    p.add_argument("--angle-unit", choices=("deg", "rad"), default=None,
                   help="unit of the joint values in --check / --from-list files (default: the recording.yaml beside "
                        "the file, else the scene's units)")
    p.add_argument("--draws", type=_count, default=None, help="Monte Carlo draws of the predicted accuracy (default 10)")
    p.add_argument("--seed", type=_seed, default=None, help="random seed (default 0)")
    p.add_argument("--no-plots", action="store_true", help="skip the 3-D picture")
    _add_json(p)


def _cmd_plan(args) -> int:
    import numpy as np

    from .config import check_output_apart
    from .planning.plan import DEFAULT_CANDIDATES, CandidateSource, check_poses, plan_cell
    from .planning.predict import DRAWS
    from .rig import load_scene
    from .serialize import to_json

    ins = [(args.scene, "file")] + [(f, "file") for f in (args.check, args.from_list) if f]
    check_output_apart(args.out, ins)
    af = None if args.angle_unit is None else (1.0 if args.angle_unit == "rad" else float(np.pi / 180))
    seed, draws = args.seed or 0, args.draws or DRAWS
    cands = args.candidates or DEFAULT_CANDIDATES
    scene = load_scene(args.scene)
    if args.check:
        res = check_poses(scene, args.check, args.out, seed=seed, n_candidates=cands, draws=draws, angle_factor=af,
                          plots=not args.no_plots)
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
        res = plan_cell(scene, args.poses or scene.poses.count or 20, args.out, seed=seed, n_candidates=cands,
                        source=src, draws=draws, plots=not args.no_plots)
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
    if pred and pred.get("given"):
        lines.append(f"predicted validation position RMS of your list: {mm(pred['given'])}")
    lines += [f"note: {n}" for n in res["notes"]]
    lines.append(f"wrote {', '.join(str(Path(out) / f) for f in res.get('files', {}).values())}")
    return "\n".join(lines)


COMMANDS["plan"] = _cmd_plan

def _out(args):
    """The command's output path: --out, else the deprecated positional DST."""
    out = getattr(args, "out", None)
    return out if out is not None else getattr(args, "dst", None)


#: exit code when the outputs were written but the result is not good (not converged, not finite)
EXIT_NOT_CONVERGED = 3


def _status(verdict: dict) -> int:
    """0 for a good result, and for a "warning" verdict (outputs and calibrated model written; the model does
    not explain the data: the reason on stderr); 3 (outputs kept, no calibrated model) otherwise."""
    if verdict["ok"]:
        return 0
    if verdict.get("status") == "warning":
        print(f"vision-calib: warning: {verdict.get('message')}", file=sys.stderr)
        return 0
    why = verdict.get("message") or "the identification did not converge"
    print(f"vision-calib: error: the result is not good ({why}); outputs written without a calibrated model",
          file=sys.stderr)
    return EXIT_NOT_CONVERGED


def _summary_identifiability(out: dict) -> str:
    lines = [
        f"{out['scene']}: {out['n_params']} parameters, rank {out['rank']}, condition number {out['condition_number']:.4g}"
        + (f" (of the {out['condition_number_of']})" if out.get("condition_number_of") else ""),
        f"non-identifiable: {', '.join(out['non_identifiable']) or 'none'}",
    ]
    for c in out["couplings"]:
        comb = " ".join(f"{v:+.3g}*{k}" for k, v in c["combination"].items()) or "(no effect on the measurements)"
        lines.append(f"  {c['parameter']} ~ {comb}")
    return "\n".join(lines)


def _summary_synthetic(out: dict) -> str:
    from .io.report import verdict_line

    b, a = out["accuracy"]["before"], out["accuracy"]["after"]
    return (
        f"{verdict_line(out['verdict'])}\n"
        f"{out['scene']} [{out['method']}] converged={out['converged']} iterations={out['iterations']} "
        f"({out['seconds']:.3f} s)\n"
        + "".join(f"warning: {w}\n" for w in out["warnings"]) +
        f"validation position RMS: {b['position_rms_mm']:.4g} mm -> {a['position_rms_mm']:.4g} mm; "
        f"max {b['position_max_mm']:.4g} -> {a['position_max_mm']:.4g} mm; "
        f"rotation RMS {b['rotation_rms_deg']:.4g} -> {a['rotation_rms_deg']:.4g} deg"
    )


def _locks(args) -> list:
    """Exclusive lock on the command's --out, see io/lock.py. (--export-recording is not locked here:
    simulate refuses a non-empty folder, and a lock file inside would make it non-empty.)"""
    from .io.lock import OutputLock

    locks = []
    out = _out(args)
    if out is not None and args.command != "init":  # init refuses a folder that is not empty (a lock is a file)
        if args.command in ("target", "calibrate-camera"):  # a file: lock beside it
            locks.append(OutputLock(Path(out).parent, "output file", lock_path=Path(str(out) + ".lock")))
        else:
            locks.append(OutputLock(out))
    return locks


def _inputs(args) -> list:
    """[(path, "folder" | "file")] the command reads, for ``config.check_output_apart``."""
    c = args.command
    if c in ("process", "calibrate-camera", "import-visp", "export-rosi"):
        ins = [(getattr(args, "folder", None) or args.src, "folder")]
        if c == "calibrate-camera":
            ins.append((args.target, "file"))
        if c == "process" and args.camera:
            ins.append((args.camera, "file"))
        return ins
    if c == "import-rosi":
        src = Path(args.src)
        return [(src if src.is_dir() else src.parent, "folder")]
    if c == "noise":
        src = Path(args.folder)
        return [(src if src.is_dir() else src.parent, "folder")] + [(f, "file") for f in (args.target, args.camera) if f]
    if c == "process-poses":
        return [(args.file, "file")]
    if c in ("simulate", "identifiability", "identify-synthetic"):
        return [(args.scene, "file")]
    if c == "study":
        return [(args.spec, "file")]
    if c == "target":
        return [(args.target, "file")]
    if c == "init" and args.urdf:
        return [(args.urdf, "file")]
    return []


def _check_outputs(args) -> None:
    """Outputs never inside inputs (issue 21): --out / DST / --export-recording against every input."""
    from .config import check_output_apart

    ins = _inputs(args)
    for flag in ("out", "dst", "export_recording"):
        out = getattr(args, flag, None)
        if out is not None:
            check_output_apart(out, ins, "--" + flag.replace("_", "-") if flag != "dst" else "DST")


def _run_locked(args) -> int:
    from .config import allow_paths
    from .shipped import shipped_path

    for key in ("scene", "target", "folder", "src", "spec"):  # the README's shipped paths work from any folder
        if isinstance(getattr(args, key, None), str):
            setattr(args, key, str(shipped_path(getattr(args, key))))
    _check_outputs(args)
    held = []
    try:
        for lock in _locks(args):
            held.append(lock.acquire())
        with allow_paths(args.allow_path):
            return COMMANDS[args.command](args)
    finally:
        for lock in reversed(held):
            lock.release()


def main(argv=None) -> int:
    import warnings

    parser = build_parser()
    args = parser.parse_args(argv)
    _positional_out(args, parser)
    try:
        with warnings.catch_warnings():  # numpy's floating-point warnings never reach the user: every bad value
            # they come from is refused by a named check (file, line, pose id) or ends in a named failure
            warnings.filterwarnings("ignore", r"(overflow|invalid value|divide by zero|underflow) encountered",
                                    RuntimeWarning)
            return _run_locked(args)
    except VisionCalibError as exc:
        print(f"vision-calib: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except BrokenPipeError:  # output piped into `head` & co.
        return 0
    except OSError as exc:  # output folder not writable, a file where a folder should be, ...
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        print(f"vision-calib: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except MemoryError:
        print("vision-calib: error: out of memory (reduce the image size, dpi, poses or workers)", file=sys.stderr)
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


if __name__ == "__main__":
    run()
