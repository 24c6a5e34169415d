"""Running a command safely: shipped paths resolved, outputs kept apart from inputs, the output locked."""

from __future__ import annotations

from pathlib import Path


def output_path(args):
    """The command's output path: --out, else the deprecated positional DST."""
    out = getattr(args, "out", None)
    return out if out is not None else getattr(args, "dst", None)


def _locks(args) -> list:
    """Exclusive lock on the command's --out, see io/lock.py. (--export-recording is not locked here:
    simulate refuses a non-empty folder, and a lock file inside would make it non-empty.)"""
    from ..io.lock import OutputLock

    locks = []
    out = output_path(args)
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
    if c == "compare":
        return [(args.a, "folder"), (args.b, "folder")]
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
    from ..config import check_output_apart

    ins = _inputs(args)
    for flag in ("out", "dst", "export_recording"):
        out = getattr(args, flag, None)
        if out is not None:
            check_output_apart(out, ins, "--" + flag.replace("_", "-") if flag != "dst" else "DST")


def run_locked(args, commands: dict) -> int:
    """Run ``commands[args.command]`` on ``args``: shipped paths resolved, outputs checked apart from the inputs,
    the output locked while it runs, files allowed to name files in ``--allow-path`` folders."""
    from ..config import allow_paths
    from ..shipped import shipped_path

    for key in ("scene", "target", "folder", "src", "spec"):  # the README's shipped paths work from any folder
        if isinstance(getattr(args, key, None), str):
            setattr(args, key, str(shipped_path(getattr(args, key))))
    _check_outputs(args)
    held = []
    try:
        for lock in _locks(args):
            held.append(lock.acquire())
        with allow_paths(args.allow_path):
            return commands[args.command](args)
    finally:
        for lock in reversed(held):
            lock.release()
