"""Other tools' data sets in and out: import-visp, import-rosi, export-rosi, import-bag, import-pairs."""

from __future__ import annotations

import sys
from pathlib import Path

from .locking import output_path
from .options import add_command, chessboard, count, int_at_least, seed, sigma


def add_visp_rosi_parsers(sub) -> None:
    """Subcommands import-visp, import-rosi, export-rosi."""
    p = add_command(sub, "import-visp", "convert a ViSP hand-eye folder into a recorded folder", """
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
    p.add_argument("--tag-size-m", type=sigma, default=None,
                   help="AprilTag side [m] (default: from apriltag-data.txt)")
    p.add_argument("--tag-id", type=seed, default=None, help="tag id (default: detected in the first image)")
    # --- importers (io/visp.py chessboard variant, io/rosi.py)
    p.add_argument("--chessboard", type=chessboard, default=None, metavar="COLSxROWS",
                   help="chessboard inner corners as ViSP's -w x -h (e.g. 9x6; default: from chessboard-data.txt); "
                        "the target has one more square each way")
    p.add_argument("--square-m", type=sigma, default=None,
                   help="chessboard square side [m] (ViSP's --square-size; default: from chessboard-data.txt)")
    p.add_argument("--mount", choices=("eye_in_hand", "fixed"), default=None,
                   help="chessboard folders: where the camera is (default eye_in_hand, ViSP's tutorial)")

    p = add_command(sub, "import-rosi", "convert a ROS-I industrial_calibration hand-eye data set into a recorded "
                    "folder", """
  vision-calib import-rosi rosi_data/ --out recording/
  vision-calib import-rosi rosi_data/cal_data.yaml --out recording/
  (the old spelling `import-rosi SRC DST` still works; it is deprecated)""")
    p.add_argument("src", metavar="SRC", help="folder with cal_data.yaml (or that file)")
    p.add_argument("dst", nargs="?", default=None, metavar="DST", help="deprecated: use --out DIR")
    p.add_argument("--out", default=None, metavar="DIR", help="recorded folder to write")
    p.add_argument("--allow-symlinks", action="store_true", help="follow symlinks leading out of SRC")

    p = add_command(sub, "export-rosi", "write a recorded folder (flange poses, ChArUco) as a ROS-I data set", """
  vision-calib export-rosi recording/ --out rosi_data/
  (the old spelling `export-rosi SRC DST` still works; it is deprecated)""")
    p.add_argument("src", metavar="SRC", help="recorded folder")
    p.add_argument("dst", nargs="?", default=None, metavar="DST", help="deprecated: use --out DIR")
    p.add_argument("--out", default=None, metavar="DIR", help="folder to write (cal_data.yaml, poses/, images/)")


def positional_out(args, parser) -> None:
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


def cmd_import_visp(args) -> int:
    from ..io.visp import import_visp

    notes = []
    path = import_visp(args.src, args.out, chessboard=args.chessboard, square_m=args.square_m,
                       tag_m=args.tag_size_m, tag_id=args.tag_id, mount=args.mount, notes=notes)
    for n in notes:
        print(f"vision-calib: warning: {n}", file=sys.stderr)
    print(f"wrote recorded folder {path}")
    return 0


def cmd_import_rosi(args) -> int:
    from ..io.rosi import import_rosi

    print(f"wrote recorded folder {import_rosi(args.src, output_path(args), allow_symlinks=args.allow_symlinks)}")
    return 0


def cmd_export_rosi(args) -> int:
    from ..io.rosi import export_rosi

    print(f"wrote ROS-I data set {export_rosi(args.src, output_path(args))}")
    return 0


# ------------------------------------------------------- import-bag: a recorded folder from a ROS bag (io/rosbag.py)
def add_import_bag_parser(sub) -> None:
    p = add_command(sub, "import-bag", "a recorded folder from a ROS 1 / ROS 2 bag: images + joint states, one pose "
                    "per standstill (needs the [ros] extra)", """
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
    p.add_argument("--still-speed", type=sigma, default=1e-3, metavar="RAD_S",
                   help="standstill: mean joint speed below this over the window [rad/s, m/s] (default 0.001)")
    p.add_argument("--still-window", type=sigma, default=0.5, metavar="S",
                   help="standstill window and shortest standstill [s] (default 0.5)")
    p.add_argument("--max-gap", type=sigma, default=1.0, metavar="S",
                   help="longest gap of the joint states [s] before the bag counts as damaged (default 1)")
    p.add_argument("--max-frames", type=count, default=None, help="frames kept per pose (default: all)")
    p.add_argument("--out", required=True, metavar="DIR", help="recorded folder to write (new or empty)")


def cmd_import_bag(args) -> int:
    from ..config import check_output_apart
    from ..io.rosbag import StillSettings, import_bag

    check_output_apart(args.out, [(args.bag, "folder" if Path(args.bag).is_dir() else "file")])
    names = None if args.joint_names is None else args.joint_names.split(",")
    res = import_bag(args.bag, args.scene, args.image_topic, args.joints_topic, args.out,
                     camera_info_topic=args.camera_info_topic, joint_names=names,
                     settings=StillSettings(args.still_speed, args.still_window, args.max_gap, args.max_frames))
    print(res.summary())
    return 0


# -------------------------------------- import-pairs: hand-eye pose pairs of other tools (io/transform_pairs.py)
def add_import_pairs_parser(sub) -> None:
    p = add_command(sub, "import-pairs", "a pose-pair file for process-poses from a TransformPairs YAML "
                    "(handeye_calib_camodocal, easy_handeye-style samplers: T1_i base->end effector, T2_i "
                    "camera->marker)", """
  vision-calib import-pairs TransformPairsInput.yml --mount fixed --out pairs/pairs.yaml
  vision-calib process-poses pairs/pairs.yaml --out out/handeye""")
    p.add_argument("file", help="TransformPairs YAML (OpenCV FileStorage: %%YAML:1.0, ---, frameCount, T1_i, T2_i)")
    p.add_argument("--mount", required=True, choices=("eye_in_hand", "fixed"),
                   help="eye_in_hand: camera on the flange, marker fixed; fixed: camera on a stand, marker on the "
                        "flange")
    p.add_argument("--folds", type=int_at_least(2), default=5, help="k of process-poses' held-out validation "
                                                                     "(default 5)")
    # dest out_file: a file output, written atomically (no folder lock: the lock would make FILE.yaml a folder)
    p.add_argument("--out", dest="out_file", required=True, metavar="FILE.yaml",
                   help="pose-pair file to write (its two CSVs beside it); the measured poses' noise is estimated "
                        "per axis by process-poses")


def cmd_import_pairs(args) -> int:
    from ..config import check_output_apart
    from ..io.transform_pairs import import_pairs

    check_output_apart(args.out_file, [(args.file, "file")], "--out")
    path = import_pairs(args.file, args.mount, args.out_file, folds=args.folds, progress=True)
    print(f"wrote pose-pair file {path} (process it: vision-calib process-poses {path} --out DIR)")
    return 0
