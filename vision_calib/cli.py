"""Command-line interface: thin wrappers over library functions.

Every user error (VisionCalibError) becomes one line ``vision-calib: error: ...`` on stderr
and exit code 2; results are printed as JSON with ``--json``.
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

from .errors import VisionCalibError  # noqa: E402


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
    if "://" not in text and Path(text).is_file():
        return text
    raise argparse.ArgumentTypeError(f"expected tcp://host:port or an existing scheduler file (JSON written by "
                                     f"dask-scheduler --scheduler-file), got {text!r}")


def _add_common(p, poses=True):
    p.add_argument("scene", help="scene YAML file (see scenes/)")
    if poses:
        p.add_argument("--poses", type=_count, default=None, help="number of identification poses (default: scene's)")
    p.add_argument("--seed", type=_seed, default=None, help="random seed (default: scene's, else 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")


def _add_run_options(p):
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--fix-unidentifiable", action="store_true",
                   help="accept a pose set that loses parameters varied poses identify (they stay at nominal)")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="vision-calib", description="Vision-based geometric calibration of robots.")
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("identifiability", help="rank, base parameters, couplings, condition number of a scene")
    _add_common(p)
    p.add_argument("--residual", choices=["pose", "position", "joint"], default=None)
    p.add_argument("--all", action="store_true", dest="all_params",
                   help="analyse every model parameter, also those fixed by default (Hayati d, M_T_E.z...)")

    p = sub.add_parser("identify-synthetic", help="truth -> synthetic pose measurements (no images) -> identify -> evaluate")
    _add_common(p)
    p.add_argument("--method", choices=["lse", "ekf", "igm"], default=None)
    p.add_argument("--residual", choices=["pose", "position", "joint"], default=None)
    p.add_argument("--sigma-mm", type=_sigma, default=None, help="translation noise per component [mm]")
    p.add_argument("--sigma-deg", type=_sigma, default=None, help="rotation noise per component [deg]")

    p = sub.add_parser("simulate", help="end-to-end: render + effects + measure + identify + evaluate")
    _add_common(p)
    p.add_argument("--out", required=True, help="output folder (report.json, plots, calibrated model)")
    p.add_argument("--frames", type=_count, default=None, help="frames per pose (default: scene's)")
    p.add_argument("--method", choices=["lse", "ekf", "igm"], default=None)
    p.add_argument("--export-recording", default=None, metavar="DIR", help="also write a recorded folder")
    p.add_argument("--workers", type=_count, default=None, help="processes for rendering/measurement (default: cores)")
    _add_run_options(p)

    p = sub.add_parser("demo", help="the default scene end to end (README's main command)")
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_argument("--seed", type=_seed, default=None)
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--method", choices=["igm", "lse", "ekf"], default=None,
                   help="H4 identification: igm (joint residuals, default), lse (pose residuals), ekf")
    p.add_argument("--json", action="store_true")

    p = sub.add_parser("process", help="measure -> identify -> report on a recorded image folder")
    p.add_argument("folder")
    p.add_argument("--out", required=True)
    p.add_argument("--method", choices=["lse", "ekf", "igm"], default=None)
    _add_run_options(p)
    p.add_argument("--allow-symlinks", action="store_true",
                   help="follow symbolic links that lead out of the recorded folder (refused by default)")
    p.add_argument("--refine-intrinsics", action="store_true",
                   help="calibrate the camera from the recording's images even when recording.yaml gives intrinsics")
    p.add_argument("--camera", default=None, metavar="CAMERA_YAML",
                   help="camera intrinsics from this camera.yaml (calibrate-camera's output) instead of recording.yaml's")
    p.add_argument("--json", action="store_true")

    p = sub.add_parser("calibrate-camera", help="camera intrinsics + distortion from images of a target")
    p.add_argument("folder", help="folder of images (searched recursively: png, jpg, jpeg, bmp, tif, tiff)")
    p.add_argument("--target", required=True, help="target YAML (see targets/)")
    p.add_argument("--out", required=True, help="camera YAML to write (README: File formats)")
    p.add_argument("--json", action="store_true")

    p = sub.add_parser("process-poses", help="joints + measured poses (no images) -> identify -> k-fold report "
                       "(format: docs/measured_poses.md)")
    p.add_argument("file", help="measured-pose YAML (with its CSV beside it)")
    p.add_argument("--out", required=True)
    p.add_argument("--method", choices=["lse", "ekf"], default=None)
    p.add_argument("--folds", type=_int_at_least(2), default=None,
                   help="k of the held-out validation (default: the file's)")
    _add_run_options(p)
    p.add_argument("--json", action="store_true")

    p = sub.add_parser("study", help="parameter sweep x Monte Carlo (local processes or a Dask cluster)")
    p.add_argument("spec", help="study YAML (see scenes/studies/)")
    p.add_argument("--out", required=True)
    p.add_argument("--workers", type=_count, default=None)
    p.add_argument("--scheduler", type=_scheduler, default=None,
                   help="Dask scheduler address (tcp://host:port) or scheduler file")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--json", action="store_true")

    p = sub.add_parser("import-visp", help="convert a ViSP eye-to-hand folder into a recorded folder")
    p.add_argument("src")
    p.add_argument("--out", required=True)
    p.add_argument("--tag-size-m", type=_sigma, default=None, help="tag side [m] (default: from apriltag-data.txt)")
    p.add_argument("--tag-id", type=_seed, default=None, help="tag id (default: detected in the first image)")
    # --- importers (io/visp.py chessboard variant, io/rosi.py)
    p.add_argument("--chessboard", type=_chessboard, default=None, metavar="COLSxROWS",
                   help="chessboard folder: inner corners as ViSP's -w x -h (e.g. 9x6); the target has one more "
                        "square each way")
    p.add_argument("--square-m", type=_sigma, default=None, help="chessboard square side [m] (ViSP's --square_size)")
    p.add_argument("--mount", choices=("eye_in_hand", "fixed"), default="eye_in_hand",
                   help="chessboard folders: where the camera is (default eye_in_hand, ViSP's tutorial)")

    p = sub.add_parser("import-rosi", help="convert a ROS-I industrial_calibration hand-eye data set into a "
                                           "recorded folder")
    p.add_argument("src", help="folder with cal_data.yaml (or that file)")
    p.add_argument("dst", help="recorded folder to write")
    p.add_argument("--allow-symlinks", action="store_true", help="follow symlinks leading out of SRC")

    p = sub.add_parser("export-rosi", help="write a recorded folder (flange poses, ChArUco) as a ROS-I data set")
    p.add_argument("src", help="recorded folder")
    p.add_argument("dst", help="folder to write (cal_data.yaml, poses/, images/)")

    p = sub.add_parser("target", help="export a printable target image")
    p.add_argument("target", help="target YAML (see targets/)")
    p.add_argument("--out", required=True, help="PNG or PDF file")
    p.add_argument("--dpi", type=_count, default=300)
    for p in sub.choices.values():  # the one rule for paths named in files (config.confine): the user's allowance
        p.add_argument("--allow-path", action="append", default=[], metavar="DIR",
                       help="let files (scene, measured-pose, recording, study, ROS-I files) name files in DIR too "
                            "(by default only in their own folder and the shipped scenes/ and targets/)")
    return ap


def _dispatch(args) -> int:
    from .io.atomic import to_json

    if args.command == "identifiability":
        from .experiment.synthetic import identifiability_json

        out = identifiability_json(args.scene, residual=args.residual, n_poses=args.poses, seed=args.seed,
                                  all_params=args.all_params)
        print(to_json(out) if args.json else _summary_identifiability(out))
        return 0
    if args.command == "identify-synthetic":
        from .experiment.synthetic import identify_synthetic_json

        out = identify_synthetic_json(
            args.scene, method=args.method, residual=args.residual, n_poses=args.poses,
            sigma_mm=args.sigma_mm, sigma_deg=args.sigma_deg, seed=args.seed,
        )
        print(to_json(out) if args.json else _summary_synthetic(out))
        return _status(out["verdict"])
    if args.command in ("simulate", "demo"):
        from .experiment.image_chain import start_fork_server

        start_fork_server()  # the image workers' imports run beside ours (issue 11: demo wall time)
        from .experiment.simulate import run_simulation, DEFAULT_SCENE

        scene = DEFAULT_SCENE if args.command == "demo" else args.scene
        report = run_simulation(
            scene, out_dir=args.out, seed=args.seed,
            n_poses=getattr(args, "poses", None), frames=getattr(args, "frames", None),
            method=getattr(args, "method", None), export_recording=getattr(args, "export_recording", None),
            workers=getattr(args, "workers", None), progress=not args.json, plots=not args.no_plots,
            fix_unidentifiable=getattr(args, "fix_unidentifiable", False),
        )
        print(to_json(report) if args.json else report["summary_text"])
        return _status(report["verdict"])
    if args.command == "process":
        from .experiment.process import process_folder

        report = process_folder(args.folder, out_dir=args.out, method=args.method, progress=not args.json,
                                plots=not args.no_plots, fix_unidentifiable=args.fix_unidentifiable,
                                allow_symlinks=args.allow_symlinks, refine_intrinsics=args.refine_intrinsics,
                                camera_file=args.camera)
        print(to_json(report) if args.json else report["summary_text"])
        return _status(report["verdict"])
    if args.command == "calibrate-camera":
        from .measure.intrinsics import calibrate_from_images, find_images, summary_text
        from .io.camera_file import write_camera_yaml
        from .targets import load_target

        target = load_target(args.target)
        res = calibrate_from_images(find_images(args.folder), target, progress=not args.json)
        write_camera_yaml(args.out, res)
        print(to_json(res.to_dict()) if args.json else summary_text(res) + f"\nwrote {args.out}")
        return 0
    if args.command == "process-poses":
        from .experiment.poses import process_poses

        report = process_poses(args.file, out_dir=args.out, method=args.method, folds=args.folds,
                               plots=not args.no_plots, fix_unidentifiable=args.fix_unidentifiable)
        print(to_json(report) if args.json else report["summary_text"])
        return _status(report["verdict"])
    if args.command == "study":
        from .study import run_study

        res = run_study(args.spec, out_dir=args.out, workers=args.workers, scheduler=args.scheduler,
                        progress=not args.json, plots=not args.no_plots)
        print(to_json(res) if args.json else res["summary_text"])
        return 0
    if args.command == "import-visp":
        from .errors import ConfigError
        from .io.visp import import_visp_chessboard, import_visp_eye_to_hand

        if args.chessboard is not None:
            if args.square_m is None:
                raise ConfigError("--chessboard needs --square-m (the square side in metres)")
            notes = []
            path = import_visp_chessboard(args.src, args.out, *args.chessboard, args.square_m, mount=args.mount,
                                          notes=notes)
            for n in notes:
                print(f"vision-calib: warning: {n}", file=sys.stderr)
        else:
            path = import_visp_eye_to_hand(args.src, args.out, tag_m=args.tag_size_m, tag_id=args.tag_id)
        print(f"wrote recorded folder {path}")
        return 0
    if args.command in ("import-rosi", "export-rosi"):
        from .io.rosi import export_rosi, import_rosi

        if args.command == "import-rosi":
            path = import_rosi(args.src, args.dst, allow_symlinks=args.allow_symlinks)
            print(f"wrote recorded folder {path}")
        else:
            print(f"wrote ROS-I data set {export_rosi(args.src, args.dst)}")
        return 0
    if args.command == "target":
        from .targets import load_target, export_printable

        path = export_printable(load_target(args.target), args.out, dpi=args.dpi)
        print(f"wrote {path}")
        return 0
    raise AssertionError(args.command)


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
        f"{out['scene']}: {out['n_params']} parameters, rank {out['rank']}, condition number {out['condition_number']:.4g}",
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
    out = getattr(args, "out", None)
    if out is not None:
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
    if c == "process-poses":
        return [(args.file, "file")]
    if c in ("simulate", "identifiability", "identify-synthetic"):
        return [(args.scene, "file")]
    if c == "study":
        return [(args.spec, "file")]
    if c == "target":
        return [(args.target, "file")]
    return []


def _check_outputs(args) -> None:
    """Outputs never inside inputs (issue 21): --out / DST / --export-recording against every input."""
    from .config import check_output_apart

    ins = _inputs(args)
    for flag in ("out", "dst", "export_recording"):
        out = getattr(args, flag, None)
        if out is not None and not (args.command == "export-rosi" and flag == "out"):
            check_output_apart(out, ins, "--" + flag.replace("_", "-") if flag != "dst" else "DST")


def _run_locked(args) -> int:
    from .config import allow_paths

    _check_outputs(args)
    held = []
    try:
        for lock in _locks(args):
            held.append(lock.acquire())
        with allow_paths(args.allow_path):
            return _dispatch(args)
    finally:
        for lock in reversed(held):
            lock.release()


def main(argv=None) -> int:
    import warnings

    args = build_parser().parse_args(argv)
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
