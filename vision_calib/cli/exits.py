"""Exit codes: the ``--help`` text, and a run's verdict turned into the command's exit status."""

from __future__ import annotations

import sys

EXIT_CODES = """exit codes:
  0    done (also a "warning" verdict: calibrated model written, reason on stderr)
  2    bad input or usage (one line "vision-calib: error: ..." on stderr)
  3    outputs written but the result is not good (failed fit, gross input error): no calibrated model
  130  interrupted (Ctrl-C); results already written are kept"""


#: exit code when the outputs were written but the result is not good (not converged, not finite)
EXIT_NOT_CONVERGED = 3


def status(verdict: dict) -> int:
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


#: what a module was building when memory ran out, and what to reduce: (module prefix, what, hint); first match
_BUILDING = (
    ("vision_calib.config", "a YAML file's values", "check the file: a value far larger than it looks"),
    ("vision_calib.io.pose_table", "the pose table", "fewer rows (a file of millions of rows?)"),
    ("vision_calib.io.measured_poses", "the measured poses", "fewer rows (a file of millions of rows?)"),
    ("vision_calib.io.recording", "the recording's pose table", "fewer rows (a file of millions of rows?)"),
    ("vision_calib.rig.pose_file", "the pose file", "fewer rows (a file of millions of rows?)"),
    ("vision_calib.io.rosbag", "images from the bag", "smaller images, or fewer frames (--max-frames)"),
    ("vision_calib.targets", "the target's image", "a lower --dpi"),
    ("vision_calib.render", "rendered images", "a smaller image size, fewer frames or --workers"),
    ("vision_calib.sensor", "rendered images", "a smaller image size, fewer frames or --workers"),
    ("vision_calib.measure", "the image measurements", "smaller images, or fewer --workers"),
    ("vision_calib.study", "the study's runs", "fewer runs or workers"),
    ("vision_calib.identify", "the identification's matrices", "fewer poses or frames"),
    ("vision_calib.experiment", "the identification's inputs", "fewer poses, frames or --workers"),
)


def memory_message(exc: BaseException, command: str | None = None) -> str:
    """'out of memory in MODULE.FUNCTION (line N) while building WHAT [for `command`]: reduce HINT' for a
    MemoryError: the innermost frame of the package in its traceback names what was being built (the generic
    advice when none is)."""
    import traceback
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    where = None
    for fr in traceback.extract_tb(exc.__traceback__):
        p = Path(fr.filename).resolve()
        if p.is_relative_to(root) and p.suffix == ".py":
            where = (".".join(("vision_calib",) + p.relative_to(root).with_suffix("").parts), fr.name, fr.lineno)
    cmd = f" for `{command}`" if command else ""
    if where is None:
        return f"out of memory{cmd} (reduce the image size, dpi, poses or workers)"
    mod, func, line = where
    what, hint = next(((w, h) for pre, w, h in _BUILDING if mod.startswith(pre)),
                      ("its data", "the size of the inputs"))
    return f"out of memory in {mod}.{func} (line {line}) while building {what}{cmd}: {hint}"
