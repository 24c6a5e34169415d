"""The runs: identifiability, identify-synthetic, simulate, demo, process(-poses), calibrate-camera, study, noise."""

from __future__ import annotations

import os

from .exits import status
from .options import (METHOD_HELP, RESIDUAL_HELP, add_command, add_common, add_holdout, add_json, add_run_options,
                      add_yes, count, int_at_least, scheduler, seed, sigma)


def add_run_parsers(sub) -> None:
    """Subcommands identifiability, identify-synthetic, simulate, demo, process, calibrate-camera, process-poses,
    study."""
    p = add_command(sub, "identifiability", "rank, base parameters, couplings, condition number of a scene", """
  vision-calib identifiability scenes/rx90_eye_in_hand.yaml --poses 12
  vision-calib identifiability scenes/h4_vision.yaml --residual joint --all --json""")
    add_common(p)
    p.add_argument("--residual", choices=["pose", "position", "joint"], default=None, help=RESIDUAL_HELP)
    p.add_argument("--all", action="store_true", dest="all_params",
                   help="analyse every model parameter, also those fixed by default (Hayati d, M_T_E.z...)")

    p = add_command(sub, "identify-synthetic", "truth -> synthetic pose measurements (no images) -> identify -> "
                    "evaluate", """
  vision-calib identify-synthetic scenes/rx90_eye_in_hand.yaml --poses 30 --sigma-mm 0.1 --sigma-deg 0.02
  vision-calib identify-synthetic scenes/h4_vision.yaml --method igm --seed 4 --json""")
    add_common(p)
    p.add_argument("--method", choices=["lse", "ekf", "igm"], default=None, help=METHOD_HELP)
    p.add_argument("--residual", choices=["pose", "position", "joint"], default=None, help=RESIDUAL_HELP)
    p.add_argument("--sigma-mm", type=sigma, default=None, help="translation noise per component [mm]")
    p.add_argument("--sigma-deg", type=sigma, default=None, help="rotation noise per component [deg]")

    p = add_command(sub, "simulate", "end-to-end: render + effects + measure + identify + evaluate", """
  vision-calib simulate scenes/rx90_eye_in_hand.yaml --poses 12 --frames 2 --out out/rx90
  vision-calib simulate scenes/h4_vision.yaml --out out/h4 --export-recording out/h4_rec --no-plots""")
    add_common(p)
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (report.json, summary.txt, plots, calibrated model)")
    p.add_argument("--frames", type=count, default=None, help="frames per pose (default: scene's)")
    p.add_argument("--method", choices=["lse", "ekf", "igm"], default=None, help=METHOD_HELP)
    p.add_argument("--export-recording", default=None, metavar="DIR",
                   help="also write the rendered images as a recorded folder (input of `process`)")
    p.add_argument("--workers", type=count, default=None, help="processes for rendering/measurement (default: cores)")
    add_run_options(p)
    add_holdout(p)

    p = add_command(sub, "demo", "the default scene end to end (README's main command)", """
  vision-calib demo
  vision-calib demo --out out/demo2 --seed 1 --method lse""")
    p.add_argument("--out", default="out/demo", metavar="DIR",
                   help="output folder (report.json, summary.txt, plots, calibrated model; default out/demo)")
    p.add_argument("--seed", type=seed, default=None, help="random seed (default: the scene's)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--method", choices=["igm", "lse", "ekf"], default=None,
                   help="H4 identification: igm (joint residuals, default), lse (pose residuals), ekf")
    add_holdout(p)
    add_json(p)

    p = add_command(sub, "process", "measure -> identify -> report on a recorded image folder", """
  vision-calib process recording/ --out out/run
  vision-calib process recording/ --out out/run --camera camera.yaml --no-plots --json""")
    p.add_argument("folder", help="recorded folder (recording.yaml, poses.csv, images; format: vision-calib docs "
                                  "formats)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (report.json, summary.txt, plots, calibrated model)")
    p.add_argument("--method", choices=["lse", "ekf", "igm"], default=None, help=METHOD_HELP)
    add_run_options(p)
    p.add_argument("--allow-symlinks", action="store_true",
                   help="follow symbolic links that lead out of the recorded folder (refused by default)")
    p.add_argument("--refine-intrinsics", action="store_true",
                   help="calibrate the camera from the recording's images even when recording.yaml gives intrinsics")
    p.add_argument("--camera", default=None, metavar="CAMERA_YAML",
                   help="camera intrinsics from this camera.yaml (calibrate-camera's output) instead of recording.yaml's")
    add_holdout(p)
    add_json(p)

    p = add_command(sub, "calibrate-camera", "camera intrinsics + distortion from images of a target", """
  vision-calib calibrate-camera images/ --target targets/charuco_a5.yaml --out camera.yaml""")
    p.add_argument("folder", help="folder of images (searched recursively: png, jpg, jpeg, bmp, tif, tiff)")
    p.add_argument("--target", required=True, help="target YAML (see targets/)")
    p.add_argument("--out", required=True, metavar="FILE",
                   help="camera YAML to write (format: vision-calib docs workflows)")
    add_json(p)

    p = add_command(sub, "process-poses", "joints + measured poses (no images) -> identify -> k-fold report "
                    "(format: vision-calib docs measured_poses)", """
  vision-calib process-poses measured.yaml --out out/poses
  vision-calib process-poses measured.yaml --out out/poses --method ekf --folds 5 --json""")
    p.add_argument("file", help="measured-pose YAML (with its CSV beside it)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (report.json with the k-fold validation, summary.txt, plots, calibrated model)")
    p.add_argument("--method", choices=["lse", "ekf"], default=None,
                   help="identification method: lse (least squares) or ekf (default: its scene's "
                        "identification.method)")
    p.add_argument("--folds", type=int_at_least(2), default=None,
                   help="k of the held-out validation (default: the file's)")
    add_holdout(p, folds=False)
    add_run_options(p)
    add_json(p)

    p = add_command(sub, "study", "parameter sweep x Monte Carlo (local processes or a Dask cluster)", """
  vision-calib study scenes/studies/h4_noise.yaml --out out/study --workers 2
  vision-calib study scenes/studies/h4_noise.yaml --out out/study --scheduler tcp://10.0.0.5:8786""")
    p.add_argument("spec", help="study YAML (see scenes/studies/)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (results table, summary, plots)")
    p.add_argument("--workers", type=count, default=None, help="local worker processes (default: cores)")
    p.add_argument("--scheduler", type=scheduler, default=None,
                   help="Dask scheduler address (tcp://host:port) or scheduler file")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    add_yes(p)
    add_json(p)


def add_noise_parser(sub) -> None:
    """Subcommand noise (added after export-rosi: its place in ``vision-calib --help``)."""
    p = add_command(sub, "noise", "camera noise from repeated frames of a static target: corner and pose scatter, and "
                    "the simulator settings that reproduce it (vision-calib docs noise)", """
  vision-calib noise rosi_noise_qualification/ --out out/noise
  vision-calib noise frames/ --target targets/charuco_a5.yaml --camera camera.yaml --out out/noise --json""")
    p.add_argument("folder", help="ROS-I noise-qualification folder (cal_data.yaml), or a folder of images of one "
                                  "static target (with --target and --camera)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (noise.json, sensor.yaml, summary.txt)")
    p.add_argument("--target", default=None, help="target YAML (see targets/; overrides cal_data.yaml's target_finder)")
    p.add_argument("--camera", default=None, metavar="CAMERA_YAML",
                   help="camera.yaml (calibrate-camera's output; overrides cal_data.yaml's intrinsics)")
    p.add_argument("--sim-frames", type=int_at_least(2), default=30,
                   help="frames the simulator draws to check the fitted settings (default 30)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the simulator's noise (default 0)")
    p.add_argument("--allow-symlinks", action="store_true", help="follow symlinks leading out of the folder")
    add_json(p)


def _check_size(args) -> None:
    """--poses against the machine (study/budget.py check_pose_count): exit 2 with the estimate unless --yes."""
    from ..study.budget import check_pose_count

    check_pose_count(args.command, getattr(args, "poses", None), getattr(args, "frames", None),
                     getattr(args, "workers", None) or os.cpu_count() or 1, getattr(args, "yes", False),
                     scene=getattr(args, "scene", None))


def cmd_identifiability(args) -> int:
    from ..experiment.synthetic import identifiability_json
    from ..serialize import to_json

    _check_size(args)
    out = identifiability_json(args.scene, residual=args.residual, n_poses=args.poses, seed=args.seed,
                               all_params=args.all_params)
    print(to_json(out) if args.json else _summary_identifiability(out))
    return 0


def cmd_identify_synthetic(args) -> int:
    from ..experiment.synthetic import identify_synthetic_json
    from ..serialize import to_json

    _check_size(args)
    out = identify_synthetic_json(
        args.scene, method=args.method, residual=args.residual, n_poses=args.poses,
        sigma_mm=args.sigma_mm, sigma_deg=args.sigma_deg, seed=args.seed,
    )
    print(to_json(out) if args.json else _summary_synthetic(out))
    return status(out["verdict"])


def cmd_simulate(args) -> int:
    """simulate and demo (demo: the default scene, no --poses / --frames / --workers)."""
    from ..experiment.image_chain import start_fork_server

    _check_size(args)
    start_fork_server()  # the image workers' imports run beside ours (issue 11: demo wall time)
    from ..experiment.simulate import run_simulation, DEFAULT_SCENE

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
    from ..serialize import to_json

    print(to_json(report) if args.json else report["summary_text"])
    return status(report["verdict"])


def cmd_process(args) -> int:
    from ..experiment.process import process_folder

    report = process_folder(args.folder, out_dir=args.out, method=args.method, progress=not args.json,
                            plots=not args.no_plots, fix_unidentifiable=args.fix_unidentifiable,
                            allow_symlinks=args.allow_symlinks, refine_intrinsics=args.refine_intrinsics,
                            camera_file=args.camera, folds=args.folds, tcp=args.tcp)
    return _print_report(args, report)


def cmd_calibrate_camera(args) -> int:
    from ..serialize import to_json
    from ..io.camera_file import write_camera_yaml
    from ..measure.intrinsics import calibrate_from_images, find_images, summary_text
    from ..targets import load_target

    target = load_target(args.target)
    res = calibrate_from_images(find_images(args.folder), target, progress=not args.json)
    write_camera_yaml(args.out, res)
    print(to_json(res.to_dict()) if args.json else summary_text(res) + f"\nwrote {args.out}")
    return 0


def cmd_process_poses(args) -> int:
    from ..experiment.poses import process_poses

    report = process_poses(args.file, out_dir=args.out, method=args.method, folds=args.folds,
                           plots=not args.no_plots, fix_unidentifiable=args.fix_unidentifiable, tcp=args.tcp)
    return _print_report(args, report)


def cmd_study(args) -> int:
    from ..serialize import to_json
    from ..study import run_study

    res = run_study(args.spec, out_dir=args.out, workers=args.workers, scheduler=args.scheduler,
                    progress=not args.json, plots=not args.no_plots, yes=args.yes)
    print(to_json(res) if args.json else res["summary_text"])
    return 0


def cmd_noise(args) -> int:
    from ..experiment.noise import measure_noise
    from ..serialize import to_json

    res = measure_noise(args.folder, args.out, target=args.target, camera=args.camera, sim_frames=args.sim_frames,
                        seed=args.seed, allow_symlinks=args.allow_symlinks)
    print(to_json({k: v for k, v in res.items() if k != "summary_text"}) if args.json else res["summary_text"])
    return 0


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
    from ..report.summary import verdict_line

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
