"""The README's promises: its Python block runs as written from a folder outside the checkout (on the example
shipped with the package, which it leaves unchanged) and prints what its comments say, and so does the library block
of vision_calib/docs/extending.md; .ci/run calls exactly the README's test command; every relative link of the README
and of the documentation pages leads to a file."""

import os
import re
import subprocess
import sys
from pathlib import Path

from readme_block import check_python_block_output, readme_python_block, tree_digest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
DOCS = ROOT / "vision_calib" / "docs"


def _blocks(lang: str, text: str = README) -> list:
    return re.findall(rf"^```{lang}\n(.*?)^```", text, flags=re.S | re.M)


def test_python_block_runs_from_any_folder(tmp_path):
    """From a temporary folder (nothing of the checkout in it, the package on the path): the block finds the example
    through vision_calib.shipped and writes only into its own out/."""
    from vision_calib.shipped import examples_dir

    example = examples_dir() / "rx90_eye_in_hand"
    before = tree_digest(example)
    work = tmp_path / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "VISION_CALIB_ALLOW_PATHS"} | {"PYTHONPATH": str(ROOT)}
    p = subprocess.run([sys.executable, "-c", readme_python_block()], cwd=work, capture_output=True, text=True,
                       timeout=300, env=env)
    assert p.returncode == 0, p.stderr[-3000:]
    check_python_block_output(p.stdout, work / "out")
    assert tree_digest(example) == before  # the shipped example is read, never written
    assert sorted(x.name for x in work.iterdir()) == ["out"]


def test_library_block_of_docs_runs():
    (code,) = _blocks("python", (ROOT / "vision_calib" / "docs" / "extending.md").read_text())
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert p.returncode == 0, p.stderr[-3000:]
    first, second = p.stdout.strip().splitlines()
    assert "rank 30" in first and "condition number" in first
    err, std = float(second.split()[2]), float(second.split()[5])
    assert abs(err) < 4 * std  # the 1 mm error on a2 recovered within the reported std


def test_ci_runs_the_readme_test_command():
    bash = _blocks("bash")
    test_cmd = next(b.strip() for b in bash if "pytest" in b)
    ci = [ln.strip() for ln in (ROOT / ".ci" / "run").read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    assert test_cmd in ci


def test_relative_links_exist():
    for folder, text in [(ROOT, README)] + [(DOCS, p.read_text()) for p in DOCS.glob("*.md")]:
        for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", text):
            assert (folder / target).exists(), f"{folder}: link to missing {target}"
