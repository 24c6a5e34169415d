"""The documentation pages (vision_calib/docs/*.md, shipped with the package) cannot drift: every figure block of a
page is what docs/figures.py generates now (one test per block; rendering, studies and real data under ``slow``),
every module path, dotted name and test named in the pages exists, every ``vision-calib`` flag quoted in the pages is
one of that command's options, and every ``--help`` text points only to pages and README headings that exist."""

import ast
import importlib
import importlib.util
import re
import sys
from pathlib import Path

import pytest

from vision_calib.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted((ROOT / "vision_calib" / "docs").glob("*.md"))
README = ROOT / "README.md"


def _load_figures():
    spec = importlib.util.spec_from_file_location("docs_figures", ROOT / "docs" / "figures.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


F = _load_figures()


def _param(name):
    fig = F.FIGURES[name]
    marks = [pytest.mark.slow] if fig.slow else []
    return pytest.param(name, marks=marks, id=name)


def test_figure_markers_known_balanced_and_used():
    used = F.markers()  # raises on an unknown name or an unbalanced block
    assert sorted(used) == sorted(F.FIGURES), f"generators quoted by no page: {sorted(set(F.FIGURES) - set(used))}"


@pytest.mark.parametrize("name", [_param(n) for n in F.FIGURES])
def test_figure_block_is_current(name):
    if not F.available(name):
        pytest.skip(f"{F.FIGURES[name].needs} not here")
    problems = F.check(name)
    assert not problems, "\n".join(problems)


def test_figures_compare_numbers_only_with_a_tolerance():
    assert F.same("a 1.000 b", "a 1.0004 b", 1e-3) and not F.same("a 1.000 b", "a 1.01 b", 1e-3)
    assert not F.same("a 1.000 b", "a 1.000 c", 1e-3) and not F.same("a 1.000 b", "a 1.0004 b", None)


# ----------------------------------------------------------------------------------------------- names in the pages
def _code_spans(text: str) -> list[str]:
    """Inline code spans and the lines of fenced blocks."""
    fenced = re.findall(r"^```\w*\n(.*?)^```", text, flags=re.S | re.M)
    rest = re.sub(r"^```\w*\n.*?^```", "", text, flags=re.S | re.M)
    return re.findall(r"`([^`\n]+)`", rest) + [ln for b in fenced for ln in b.splitlines()]


def _docs_text():
    return [(p.name, p.read_text()) for p in DOCS]


def test_paths_in_docs_exist():
    """``vision_calib/...py``, ``tests/...py[::test]``, ``benchmarks/...py`` and package-relative ``x/y.py``."""
    missing = []
    for page, text in _docs_text():
        for m in re.finditer(r"(?<![\w/.])((?:[\w.-]+/)*[\w-]+\.py)(?:::(\w+))?", text):
            rel, test = m[1], m[2]
            where = [ROOT / rel, ROOT / "vision_calib" / rel, ROOT / "benchmarks" / rel]
            found = next((w for w in where if w.is_file()), None)
            if found is None:
                missing.append(f"{page}: {rel}")
            elif test and not re.search(rf"^\s*def {test}\(", found.read_text(), flags=re.M):
                missing.append(f"{page}: {rel}::{test}")
    assert not missing, missing


SUBPACKAGES = sorted(p.name for p in (ROOT / "vision_calib").iterdir() if (p / "__init__.py").exists())
FILE_SUFFIXES = {"md", "py", "yaml", "yml", "json", "csv", "png", "html", "urdf", "txt", "parquet", "pdf", "xml"}


def _resolve(dotted: str) -> bool:
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for a in parts[i:]:
                obj = getattr(obj, a)
        except AttributeError:
            return False
        return True
    return False


def test_dotted_names_in_docs_exist():
    """``vision_calib.x.y`` anywhere, and ``x.y`` in code spans where x is a vision_calib subpackage (a folder): an
    importable module, or a module and the attribute chain below it. Names the package itself uses as strings
    (entry-point groups such as vision_calib.robots) and format ids (``vision_calib.camera/1``) are not modules."""
    source = "\n".join(p.read_text() for p in (ROOT / "vision_calib").rglob("*.py"))
    bad = []
    for page, text in _docs_text():
        names = set(re.findall(r"(?<![\w.])(vision_calib(?:\.[A-Za-z_]\w*)+)(?![\w/])", text))
        for span in _code_spans(text):
            m = re.fullmatch(r"\s*([a-z_]\w*(?:\.[A-Za-z_]\w*)+)(?:\(.*\))?\s*", span)
            if m and m[1].split(".")[0] in SUBPACKAGES:
                names.add("vision_calib." + m[1])
        for n in sorted(names):
            if n.rsplit(".", 1)[1] in FILE_SUFFIXES or f'"{n}"' in source:
                continue
            if not _resolve(n):
                bad.append(f"{page}: {n}")
    assert not bad, bad


def _options(parser) -> dict:
    """{subcommand: its option strings}, with "" for the top-level parser."""
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    out = {"": {s for a in parser._actions for s in a.option_strings}}
    for name, p in sub.choices.items():
        out[name] = {s for a in p._actions for s in a.option_strings}
    return out


def test_cli_flags_in_docs_exist():
    """A flag after ``vision-calib SUB`` (or in a code span starting with SUB; continuation lines of a fenced
    command included) is one of SUB's options; any other flag in a code span that is not a python / pytest / pip / dask
    command is an option of some subcommand."""
    opts = _options(build_parser())
    every = set().union(*opts.values())
    bad = []
    for page, text in _docs_text():
        for block in re.findall(r"^```\w*\n(.*?)^```", text, flags=re.S | re.M) + re.findall(r"`([^`\n]+)`", text):
            sub = None
            for line in block.splitlines():
                if not line.startswith((" ", "\t")):
                    sub = None
                words = [w for w in re.findall(r"--[a-z][\w-]*|[^\s\[\]|()=]+", line) if w != "$"]
                for i, w in enumerate(words):
                    if w.endswith("vision-calib") and i + 1 < len(words) and words[i + 1] in opts:
                        sub = words[i + 1]
                    elif i == 0 and w in opts and w:
                        sub = w
                    elif re.fullmatch(r"--[a-z][\w-]*", w):
                        if sub is not None:
                            ok = w in opts[sub] or w in opts[""]
                        elif re.match(r"\s*(\$\s*)?(PYTHONPATH=\S*\s+)?(\S*python\S*|pytest|pip|\S*pip|OMP_\S+|LP_\S+|bash|dask)\b", line):
                            ok = True  # a benchmark's or a tool's own option
                        else:
                            ok = w in every
                        if not ok:
                            bad.append(f"{page}: {w} ({line.strip()[:80]})")
    assert not bad, sorted(set(bad))


# ----------------------------------------------------------------------------------------------- --help texts
def _readme_headings() -> set[str]:
    return {m.strip() for m in re.findall(r"^#{1,4} (.+)$", README.read_text(), flags=re.M)}


def _help_texts(parser) -> list[tuple[str, str]]:
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    out = [("vision-calib", t) for t in (parser.description, parser.epilog) if t]
    for a in sub._choices_actions:
        out.append((a.dest, a.help or ""))
    for name, p in sub.choices.items():
        out += [(name, t) for t in (p.description, p.epilog, p.usage) if t]
        out += [(f"{name} {'/'.join(a.option_strings) or a.dest}", a.help or "") for a in p._actions]
    return out


TOPICS = {p.stem for p in DOCS}


def _docs_topics(text: str) -> list[str]:
    """The topics of the ``vision-calib docs TOPIC`` commands a text names."""
    return re.findall(r"vision-calib docs ([a-z_][\w-]*)", text)


def test_help_texts_point_to_existing_docs_and_readme_headings():
    headings = _readme_headings()
    bad = []
    for where, text in _help_texts(build_parser()):
        for heading in re.findall(r"README: ([^)\];,]+)", text):
            if heading.strip() not in headings:
                bad.append(f"{where}: README heading {heading.strip()!r} (README has: {sorted(headings)})")
        for path in re.findall(r"(?<![\w/])((?:docs|scenes|targets)/[\w./-]*)", text):
            if path.startswith("docs/"):  # a checkout's path: an installed package has `vision-calib docs TOPIC`
                bad.append(f"{where}: {path} (name the page as `vision-calib docs TOPIC`)")
            elif not (ROOT / path.rstrip(".")).exists():
                bad.append(f"{where}: {path}")
        bad += [f"{where}: vision-calib docs {topic}: no such page" for topic in _docs_topics(text)
                if topic not in TOPICS]
        if re.search(r"README(?!: |'s)", text):
            bad.append(f"{where}: README named without a heading ({text[:80]!r})")
    assert not bad, bad



def test_package_strings_name_pages_by_topic():
    """Every string of the package (messages, help texts, docstrings) names a documentation page as ``vision-calib
    docs TOPIC`` (an installed package has no docs/ folder), and each such topic is a page; so do the pages and the
    README."""
    bad = []
    for path in sorted((ROOT / "vision_calib").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                where = f"{path.relative_to(ROOT)}:{node.lineno}"
                bad += [f"{where}: {m}" for m in re.findall(r"(?<![\w/])docs/\w+\.md", node.value)]
                bad += [f"{where}: vision-calib docs {topic}" for topic in _docs_topics(node.value)
                        if topic not in TOPICS]
    for page in [*DOCS, README]:
        bad += [f"{page.name}: vision-calib docs {topic}" for topic in _docs_topics(page.read_text())
                if topic not in TOPICS]
    assert not bad, bad
