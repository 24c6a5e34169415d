"""Starting a cell: init (a new cell folder) and target (a printable target sheet)."""

from __future__ import annotations

from pathlib import Path

from ..errors import ConfigError
from .options import add_command, count


def add_cell_parsers(sub) -> None:
    """Subcommands target and init."""
    p = add_command(sub, "target", "export a printable target: a sheet with the board, a label and a 100 mm scale "
                    "bar", """
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
    p.add_argument("--dpi", type=count, default=None,
                   help="resolution of a .png [dots per inch] (default 300); refused for .pdf / .svg")

    p = add_command(sub, "init", "start your own cell (or a copy of the example recording) in a new folder", """
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


def cmd_target(args) -> int:
    from ..targets import export_printable, load_target

    out = export_printable(load_target(args.target), args.out, dpi=args.dpi, paper=args.paper,
                           source=Path(args.target).name)
    print(f"wrote {out}; print it at 100 % (actual size), then measure the 100 mm scale bar and a square"
          if args.paper is not None or out.suffix.lower() != ".png" else f"wrote {out}")
    return 0


def cmd_init(args) -> int:
    from ..io.init_cell import init_cell, list_starters

    if args.list:
        print(list_starters())
        return 0
    if (args.dir is None) == (args.out is None):
        raise ConfigError("init: give the new folder, as DIR or --out DIR (or --list to see the starting points)")
    res = init_cell(args.dir or args.out, args.from_name, urdf=args.urdf, base_link=args.base_link, tip_link=args.tip_link)
    print("\n".join(res["notes"]))
    return 0
