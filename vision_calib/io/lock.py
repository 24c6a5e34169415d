"""An exclusive lock on an output folder, so that two runs never write into the same ``--out``.

``with OutputLock(out_dir): ...`` opens ``out_dir/.vision_calib.lock``, takes an exclusive
``fcntl.flock`` on it and writes the holder's pid into it. A second run into the same folder gets a
:class:`LockedError` (exit code 2) naming the holder's pid. The kernel drops a flock when its
process dies, so a lock file left by a killed run (a dead pid) is simply taken over. The lock file
is removed on exit (also on an exception). A file output (``target --out x.png``) is locked with
``x.png.lock`` beside it (``OutputLock(parent, lock_path=...)``).

Limits: flock is per host; on a network file system two hosts may not see each other's lock.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from ..errors import VisionCalibError

LOCK_NAME = ".vision_calib.lock"


class LockedError(VisionCalibError):
    """The output folder is in use by another run (exit code 2)."""


def _read_pid(path: Path) -> int | None:
    try:
        text = path.read_text().strip()
    except (OSError, UnicodeDecodeError):
        return None
    return int(text) if text.isdigit() else None


class OutputLock:
    """Context manager holding ``folder/.vision_calib.lock`` (or ``lock_path``); the folder is created if needed."""

    def __init__(self, folder, what: str = "output folder", lock_path=None):
        self.folder = Path(folder)
        self.path = Path(lock_path) if lock_path is not None else self.folder / LOCK_NAME
        self.what = what
        self._fd: int | None = None

    def acquire(self) -> "OutputLock":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(10):
            fd = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                pid = _read_pid(self.path)
                raise LockedError(f"{self.folder}: {self.what} is in use by another vision-calib run "
                                  f"(pid {pid if pid is not None else 'unknown'}, lock file {self.path}); "
                                  "wait for it to finish or choose another --out") from None
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:  # the previous holder removed it between our open and flock
                same = False
            if not same:
                os.close(fd)
                continue
            os.ftruncate(fd, 0)  # a stale pid of a dead run is overwritten
            os.write(fd, f"{os.getpid()}\n".encode())
            self._fd = fd
            return self
        raise LockedError(f"{self.folder}: could not take the lock {self.path} (contended)")

    def release(self) -> None:
        if self._fd is not None:
            try:
                self.path.unlink()  # unlink before unlocking: a waiting run then re-opens a fresh file
            except FileNotFoundError:
                pass
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "OutputLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
