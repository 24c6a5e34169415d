"""Where the shipped data is: the scenes, robots, targets and the example recording installed WITH the package
(package data under ``vision_calib/data/``, found through :mod:`importlib.resources`, so it is the installed
package's data wherever that is: a wheel in site-packages, or an editable checkout), and the documentation pages
(``vision_calib/docs/*.md``: :func:`doc_pages`, printed by ``vision-calib docs TOPIC``).

Layout of ``vision_calib/data/`` (in a checkout, ``scenes/`` and ``targets/`` at the top are links to it)::

    scenes/<name>.yaml            the shipped cells (scene files), robots/ and studies/ beside them
    targets/<name>.yaml           the shipped target definitions
    examples/<name>/              the example recording(s) (recording.yaml, poses.csv, images/)
    SHIPPED.md                    this layout in words; its presence marks a shipped data tree (config.confine)
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

#: the file whose presence marks a folder as a shipped data tree: files inside it may name each other
MARKER = "SHIPPED.md"


def data_dir() -> Path:
    """The installed package's data folder (``vision_calib/data``), as a file-system path."""
    root = resources.files("vision_calib") / "data"
    path = Path(str(root))
    if not (path / MARKER).is_file():  # a zipped install would give no real path: say so instead of guessing
        raise FileNotFoundError(f"vision_calib's shipped data is not on the file system at {path} "
                                f"(install the package from a wheel or a folder, not a zip)")
    return path


def scenes_dir() -> Path:
    """The shipped scenes (``<data>/scenes``)."""
    return data_dir() / "scenes"


def targets_dir() -> Path:
    """The shipped target definitions (``<data>/targets``)."""
    return data_dir() / "targets"


def examples_dir() -> Path:
    """The shipped example recordings (``<data>/examples``)."""
    return data_dir() / "examples"


def shipped_tree_of(path: Path, max_up: int = 4) -> Path | None:
    """The shipped data tree (a folder holding :data:`MARKER`) that ``path`` (resolved) lies in, looking at
    most ``max_up`` folders up; None if none. Lets a checkout's own ``scenes/x.yaml`` name its own
    ``targets/`` even when another copy of the package is the one installed."""
    p = Path(path).resolve()
    for folder in list(p.parents)[:max_up]:
        if (folder / MARKER).is_file():
            return folder
    return None


def shipped_path(path) -> Path:
    """``path`` itself when it exists (or is absolute); else the shipped file or folder of the same relative name
    when there is one (``scenes/x.yaml``, ``targets/x.yaml``, ``examples/x``, or a bare scene file name ``x.yaml``),
    so that the commands of the README work from any folder; else ``path`` (the caller names it missing)."""
    path = Path(path)
    if path.exists() or path.is_absolute():
        return path
    for cand in (data_dir() / path, scenes_dir() / path):
        if cand.exists():
            return cand
    return path


def docs_dir() -> Path:
    """The installed package's documentation pages (``vision_calib/docs``), as a file-system path."""
    path = Path(str(resources.files("vision_calib") / "docs"))
    if not path.is_dir():
        raise FileNotFoundError(f"vision_calib's documentation pages are not on the file system at {path} "
                                f"(install the package from a wheel or a folder, not a zip)")
    return path


def doc_pages() -> dict[str, Path]:
    """{topic: page} of the documentation pages, sorted by topic: the topic is the page's file name without
    ``.md`` (``validate``: the page validate.md)."""
    return {p.stem: p for p in sorted(docs_dir().glob("*.md"))}
