"""`vision-calib docs [TOPIC]`: the documentation pages are package data (vision_calib/docs/*.md, where this checkout
keeps them), listed with their titles, printed as they are; an unknown topic is a one-line error (exit 2) that lists
the topics."""

import subprocess
import sys
from pathlib import Path

import pytest

import vision_calib
from vision_calib.cli import main
from vision_calib.shipped import doc_pages, docs_dir

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted((ROOT / "vision_calib" / "docs").glob("*.md"))


def test_pages_are_the_package_data_of_the_imported_package():
    pkg = Path(vision_calib.__file__).resolve().parent
    assert docs_dir().resolve() == (pkg / "docs").resolve()
    assert list(doc_pages()) == [p.stem for p in PAGES] and len(PAGES) >= 10
    assert all(page.read_text() == p.read_text() for page, p in zip(doc_pages().values(), PAGES))


def test_no_topic_lists_every_page_with_its_title(capsys):
    assert main(["docs"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = {ln.split()[0]: ln.split(None, 1)[1] for ln in lines[1:]}
    assert "vision-calib docs TOPIC" in lines[0]
    titles = {p.stem: next(ln.lstrip("#").strip() for ln in p.read_text().splitlines() if ln.startswith("#"))
              for p in PAGES}
    assert rows == titles


@pytest.mark.parametrize("topic", ["validate", "validate.md", "measured-poses", "Formats"])
def test_a_topic_prints_its_page_unchanged(topic, capsys):
    assert main(["docs", topic]) == 0
    name = topic.removesuffix(".md").replace("-", "_").lower()
    assert capsys.readouterr().out == (ROOT / "vision_calib" / "docs" / f"{name}.md").read_text()


def test_an_unknown_topic_exits_2_naming_it_and_listing_the_topics():
    p = subprocess.run([sys.executable, "-m", "vision_calib.cli", "docs", "validat"], capture_output=True, text=True)
    assert p.returncode == 2 and p.stdout == ""
    (line,) = p.stderr.splitlines()
    assert line.startswith("vision-calib: error: docs: no page 'validat'; did you mean 'validate'?")
    assert all(page.stem in line for page in PAGES)
