"""Argument types (chessboard size, noise, tool point, Dask scheduler...) and the options several commands share."""

from __future__ import annotations

import argparse
from pathlib import Path


# ------------------------------------------------------------------------------------------------------- argparse types
def chessboard(text: str) -> tuple[int, int]:
    """argparse type: 'COLSxROWS' inner corners, e.g. 9x6 -> (9, 6)."""
    try:
        c, r = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected COLSxROWS (inner corners, e.g. 9x6), got {text!r}") from None
    if c < 2 or r < 2:
        raise argparse.ArgumentTypeError(f"expected at least 2x2 inner corners, got {text!r}")
    return c, r


def int_at_least(minimum: int):
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


count = int_at_least(1)  # poses, frames, workers, dpi
seed = int_at_least(0)  # seeds, tag ids


def sigma(text: str) -> float:
    """argparse type: a finite number >= 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (v >= 0 and v < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text}")
    return v


def scheduler(text: str) -> str:
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
        from ..errors import ConfigError
        from ..study.run import scheduler_address

        try:
            scheduler_address(text)
        except ConfigError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text
    raise argparse.ArgumentTypeError(f"expected tcp://host:port or an existing scheduler file (JSON written by "
                                     f"dask-scheduler --scheduler-file), got {text!r}")


def tcp(text: str) -> tuple[float, float, float]:
    """argparse type: a tool point ``x,y,z`` in the flange frame [m]."""
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 3 or not all(abs(v) < 10 for v in vals):
        raise argparse.ArgumentTypeError(f"expected x,y,z of the tool point in the flange frame in metres (|v| < 10), "
                                         f"got {text!r}")
    return vals


def floats_list(n: int | None, what: str):
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


# --------------------------------------------------------------------------------------- options several commands share
METHOD_HELP = ("identification method: lse (least squares), ekf (extended Kalman filter), igm (H4: joint "
               "residuals through the inverse model) (default: the scene's identification.method)")
RESIDUAL_HELP = ("what the residual compares: pose (6 components), position (3), joint (H4 joint values) "
                 "(default: the scene's)")


def add_common(p, poses=True):
    p.add_argument("scene", help="scene YAML file (see scenes/)")
    if poses:
        p.add_argument("--poses", type=count, default=None, help="number of identification poses (default: scene's)")
        add_yes(p)
    p.add_argument("--seed", type=seed, default=None, help="random seed (default: scene's, else 0)")
    add_json(p)


def add_yes(p):
    p.add_argument("--yes", action="store_true", help="run even when the estimated time or memory exceeds this "
                                                      "machine's (otherwise: exit 2 with the estimate)")


def add_json(p):
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout instead of the summary")


def add_holdout(p, folds=True):
    if folds:
        p.add_argument("--folds", type=int_at_least(2), default=None,
                       help="k of the held-out k-fold validation (default 5, fewer with fewer poses)")
    p.add_argument("--tcp", type=tcp, default=None, metavar="X,Y,Z",
                   help="a tool point in the flange frame [m] where the held-out and predicted accuracy are given "
                        "too (serial arms)")


def add_run_options(p):
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--fix-unidentifiable", action="store_true",
                   help="when these poses cannot identify parameters that varied poses would, keep those at their "
                        "nominal values and go on (by default the run stops with exit code 2 naming them)")


def add_command(sub, name: str, help: str, examples: str, description: str | None = None):
    """A subparser with its one-line help, a description and an ``examples:`` epilog (kept as written)."""
    return sub.add_parser(name, help=help, description=description or help[:1].upper() + help[1:] + ".",
                          epilog="examples:\n" + examples.strip("\n"),
                          formatter_class=argparse.RawDescriptionHelpFormatter)
