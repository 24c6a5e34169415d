"""The docs command: the documentation pages shipped with the package (``vision_calib/docs/*.md``), listed or
printed, so that every ``--help`` can point to a page that an installed package has."""

from __future__ import annotations

import difflib

from ..errors import UnknownTopicError
from .options import add_command


def add_docs_parser(sub) -> None:
    p = add_command(sub, "docs", "print a documentation page (without TOPIC: list the pages)", """
  vision-calib docs
  vision-calib docs validate
  vision-calib docs formats | less""", description=(
        "Print a documentation page (markdown) on stdout: TOPIC is the page's name as listed by `vision-calib "
        "docs` (the pages are installed with the package, in vision_calib/docs/)."))
    p.add_argument("topic", nargs="?", metavar="TOPIC", help="the page to print (default: list the pages)")


def title(page) -> str:
    """The first heading of a page (its file name when it has none)."""
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            return line.lstrip("#").strip()
    return page.name


def topic_list(pages: dict) -> str:
    """One line per page: topic and title."""
    width = max(map(len, pages))
    return "\n".join(f"  {t:<{width}}  {title(p)}" for t, p in pages.items())


def find_page(topic: str, pages: dict):
    """The page of ``topic`` (a page name, with or without ``.md``, ``-`` for ``_``); UnknownTopicError listing the
    topics otherwise."""
    key = topic.removesuffix(".md").replace("-", "_").lower()
    if key in pages:
        return pages[key]
    close = difflib.get_close_matches(key, list(pages), n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    raise UnknownTopicError(f"docs: no page {topic!r}{hint} (topics: {', '.join(pages)}; `vision-calib docs` "
                            "lists them with their titles)")


def cmd_docs(args) -> int:
    from ..shipped import doc_pages

    pages = doc_pages()
    if args.topic is None:
        print("documentation pages (vision-calib docs TOPIC prints one):\n" + topic_list(pages))
        return 0
    text = find_page(args.topic, pages).read_text(encoding="utf-8")
    print(text, end="" if text.endswith("\n") else "\n")
    return 0
