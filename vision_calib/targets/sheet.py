"""The printed sheet of a target: paper sizes, the board placed on the sheet, and its label (what the board is,
a 100 mm scale bar and how to check the print). numpy only; written out by :mod:`.vector` (PDF, SVG, PNG).

Sheet frame: millimetres, origin at the sheet's top-left corner, x to the right, y down (as the target frame:
the board is drawn upright, target x along sheet x). With a paper size the board is centred on the sheet,
portrait or landscape as it fits, the label below it (or, where there is not room for all of it below, the scale
bar above and the text below); without one the sheet is just big enough for the board and the label below it.
Nothing is drawn closer than :data:`EDGE_MM` to the sheet's edge (printers leave it blank) nor inside the board's
outline (its white margin ``margin_m`` stays clear).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, fields

import numpy as np

from ..errors import ConfigError
from .kinds.base import COMMON_KEYS

#: named paper sizes, (width, height) [mm] portrait
PAPERS = {"A2": (420.0, 594.0), "A3": (297.0, 420.0), "A4": (210.0, 297.0), "A5": (148.0, 210.0),
          "A6": (105.0, 148.0), "letter": (215.9, 279.4), "legal": (215.9, 355.6)}
EDGE_MM = 5.0  # blank border of the sheet (printers' unprintable edge)
GAP_MM = 2.0  # between the board's outline (its white margin: the quiet zone) and the label, and in it
LABEL_MM = 120.0  # least width of the label block (the 100 mm scale bar and its numbers)
BAR_MM, BAR_H_MM, LINE_MM = 100.0, 3.0, 0.2  # scale bar: length, height, outline width of its white segments
TEXT_MM, LEAD_MM, SMALL_MM = 2.5, 3.2, 2.5  # font size (em) of the label, line spacing, the bar's numbers
_FIT_TOL_MM = 1e-6

#: Helvetica advance widths [1/1000 em] of the characters 32..126 (Adobe's AFM); others count 556
_HELVETICA = [int(w) for w in """278 278 355 556 556 889 667 191 333 333 389 584 278 333 278 278 556 556 556 556 556
556 556 556 556 556 278 278 584 584 584 556 1015 667 667 722 722 667 611 778 722 278 500 667 556 833 722 778 667 778
722 667 611 722 667 944 667 667 611 278 278 278 469 556 333 556 556 500 556 556 278 556 556 222 222 500 222 833 556
556 556 556 333 500 278 556 500 722 500 500 500 334 260 334 584""".split()]


def text_width_mm(text: str, size_mm: float) -> float:
    """Width [mm] of ``text`` set in Helvetica of font size size_mm [mm]."""
    return size_mm / 1000.0 * sum(_HELVETICA[ord(ch) - 32] if 32 <= ord(ch) < 127 else 556 for ch in text)


@dataclass(frozen=True)
class Paper:
    """A paper size: name as given ("A4", "300x200"), width and height [mm] as given (named sizes: portrait)."""

    name: str
    width_mm: float
    height_mm: float


def parse_paper(text) -> Paper:
    """A Paper from "A2".."A6", "letter", "legal" (any case) or "WxH" in mm ("300x200", "300 x 200 mm").
    ConfigError naming the value otherwise."""
    s = str(text).strip()
    named = {k.lower(): k for k in PAPERS}
    if s.lower() in named:
        name = named[s.lower()]
        return Paper(name, *PAPERS[name])
    m = re.fullmatch(r"(\d+(?:\.\d*)?)\s*[xX*]\s*(\d+(?:\.\d*)?)\s*(?:mm)?", s)
    if m:
        w, h = float(m.group(1)), float(m.group(2))
        if 0 < w <= 10_000 and 0 < h <= 10_000:
            return Paper(s, w, h)
    raise ConfigError(f"paper {text!r}: expected one of {', '.join(PAPERS)} or WIDTHxHEIGHT in mm (e.g. 300x200; "
                      "each 0 < size <= 10000 mm)")


@dataclass(frozen=True)
class Text:
    """One line of text: left end of its baseline (x_mm, y_mm) [mm, sheet frame], font size size_mm [mm]."""

    x_mm: float
    y_mm: float
    size_mm: float
    text: str


@dataclass(frozen=True, eq=False)
class Sheet:
    """What is printed, in mm in the sheet frame: black axis-aligned rectangles rects (N, 4) (x0, y0, x1, y1),
    black discs circles (M, 3) (cx, cy, r), further black polygons (each (V, 2), non-overlapping), text lines;
    board_mm: the board's outline (x0, y0, x1, y1) incl. its white margin; title: what the sheet shows."""

    width_mm: float
    height_mm: float
    rects: np.ndarray
    circles: np.ndarray
    polygons: tuple
    texts: tuple
    board_mm: tuple
    title: str


def as_circle(poly: np.ndarray) -> tuple[float, float, float] | None:
    """(cx, cy, r) when the polygon (V, 2) is a regular polygon of >= 16 vertices (a kind's dot), r the radius of
    the circle of the same area (the kinds draw dots as area-preserving polygons); None otherwise."""
    p = np.asarray(poly, dtype=float)
    if len(p) < 16:
        return None
    c = p.mean(axis=0)
    d = np.hypot(*(p - c).T)
    chords = np.hypot(*(np.roll(p, -1, axis=0) - p).T)
    if d.max() <= 0 or np.ptp(d) > 1e-6 * d.max() or np.ptp(chords) > 1e-6 * chords.max():
        return None
    area = 0.5 * abs(np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(p[:, 1], np.roll(p[:, 0], -1)))
    return float(c[0]), float(c[1]), math.sqrt(area / math.pi)


def _mm(v: float) -> str:
    return f"{v * 1000:.6g} mm"


def describe(spec) -> tuple[str, list[str]]:
    """(the spec's keys as text, its length keys besides margin_m) for the label: lengths in mm, other keys when
    set (e.g. "dictionary DICT_5X5_100, square_m 25 mm, marker_m 18 mm, margin_m 10 mm")."""
    parts, lengths = [], []
    for f in fields(spec):
        if f.name in COMMON_KEYS[:4]:
            continue
        v = getattr(spec, f.name)
        if f.type == "float" and f.name.endswith("_m"):
            if v != 0 or f.name == "margin_m":
                parts.append(f"{f.name} {_mm(v)}")
            if f.name != "margin_m" and v != 0:
                lengths.append(f.name)
        elif v != f.default and v not in ("", {}, (), []):
            parts.append(f"{f.name} {v}")
    margin = next(p for p in parts if p.startswith("margin_m"))  # margin last
    return ", ".join([p for p in parts if p != margin] + [margin]), lengths


def label_paragraphs(spec, source: str) -> list[str]:
    """The label's paragraphs: the target (file, kind, rows x cols, its keys in mm) and how to check the print."""
    keys, lengths = describe(spec)
    head = f"{source}: {spec.kind}, {spec.rows} x {spec.cols} (rows x cols), {keys}."
    check = "Print at 100 % (actual size, no fit to page). The bar must measure 100 mm"
    if not lengths:
        return [head, check + "."]
    key = lengths[0]
    rest = f"; scale {', '.join(lengths[1:])} by the same ratio" if len(lengths) > 1 else ""
    return [head, f"{check} and {key} {_mm(getattr(spec, key))}. If it does not, measure {key} on the print and write "
                  f"it, in metres, as {key} in {source}{rest}."]


def wrap(paragraph: str, width_mm: float, size_mm: float) -> list[str]:
    """Lines of at most width_mm [mm] in Helvetica of size_mm (a word longer than a line is cut)."""
    lines, line, words = [], "", paragraph.split()[::-1]
    while words:
        word = words.pop()
        if len(word) > 1 and text_width_mm(word, size_mm) > width_mm:
            k = 1  # the longest head that fits (at least one character)
            while k < len(word) - 1 and text_width_mm(word[:k + 1], size_mm) <= width_mm:
                k += 1
            words += [word[k:], word[:k]]
            continue
        cand = f"{line} {word}" if line else word
        if line and text_width_mm(cand, size_mm) > width_mm:
            lines.append(line)
            cand = word
        line = cand
    return lines + ([line] if line else [])


def _label_lines(spec, source: str, width_mm: float) -> list[str]:
    return [ln for p in label_paragraphs(spec, source) for ln in wrap(p, width_mm, TEXT_MM)]


BAR_BLOCK_MM = BAR_H_MM + 0.8 + 0.75 * SMALL_MM  # the scale bar and its numbers under it


def _bar(x0: float, y0: float) -> tuple[list, list]:
    """(rects, texts) of the scale bar whose top-left corner is (x0, y0) [mm]: 100 mm of ten 10 mm segments,
    black and (outlined) white in turn, with its numbers under it (:data:`BAR_BLOCK_MM` high)."""
    rects, t, h = [], LINE_MM, BAR_H_MM
    for i in range(10):
        a, b = x0 + 10.0 * i, x0 + 10.0 * (i + 1)
        if i % 2 == 0:
            rects.append((a, y0, b, y0 + h))
        else:  # outline, not overlapping the black segments
            rects += [(a, y0, b, y0 + t), (a, y0 + h - t, b, y0 + h)]
    rects.append((x0 + BAR_MM - t, y0 + t, x0 + BAR_MM, y0 + h - t))  # the right end (segment 10 is white)
    y, end = y0 + BAR_BLOCK_MM, "100 mm"
    return rects, [Text(x0, y, SMALL_MM, "0"), Text(x0 + 50 - text_width_mm("50", SMALL_MM) / 2, y, SMALL_MM, "50"),
                   Text(x0 + BAR_MM - text_width_mm(end, SMALL_MM), y, SMALL_MM, end)]


def _text(x0: float, y0: float, lines: list[str]) -> list:
    """Text lines below y0 [mm] (``len(lines) * LEAD_MM`` high), left end at x0."""
    return [Text(x0, y0 + 0.75 * TEXT_MM + k * LEAD_MM, TEXT_MM, ln) for k, ln in enumerate(lines)]


def _place(bw: float, bh: float, W: float, H: float, n_lines) -> tuple[str, float] | None:
    """Where the label goes with a board bw x bh [mm] centred on a W x H sheet: ("below", width) when bar and text
    fit below the board, ("split", width) when the bar fits above and the text below; None when the board or
    the label does not fit. n_lines(width) -> the text's lines at that width [mm]."""
    lw = min(W - 2 * EDGE_MM, max(bw, LABEL_MM))
    if bw > W - 2 * EDGE_MM + _FIT_TOL_MM or lw < LABEL_MM - _FIT_TOL_MM:
        return None
    room = (H - bh) / 2 - EDGE_MM - GAP_MM + _FIT_TOL_MM  # above and below the board
    text_h = n_lines(lw) * LEAD_MM
    if room >= BAR_BLOCK_MM + GAP_MM + text_h:
        return "below", lw
    if room >= max(BAR_BLOCK_MM, text_h):
        return "split", lw
    return None


def layout(spec, paper: Paper | None = None, source: str | None = None) -> Sheet:
    """The sheet of target ``spec`` (a TargetSpec) on ``paper`` (None: a sheet just big enough, the label below
    the board); source: the target file's name on the label (default: spec.name). On a paper the board is
    centred, the label below it (or the scale bar above and the text below when there is not room for both
    below); orientation: the board's (landscape for a board wider than high) first, the other if only that
    fits (a WxH paper: as given first). ConfigError naming the board's and the paper's sizes when they do not fit."""
    source = source or spec.name
    bw, bh = (v * 1000.0 for v in spec.outline_m())
    n_lines = lambda w: len(_label_lines(spec, source, w))  # noqa: E731
    if paper is None:
        lw = max(bw, LABEL_MM)
        W, H = lw + 2 * EDGE_MM, bh + 2 * GAP_MM + BAR_BLOCK_MM + n_lines(lw) * LEAD_MM + 2 * EDGE_MM
        bx, by, where, name = (W - bw) / 2, EDGE_MM, "below", f"{W:.1f} x {H:.1f} mm"
    else:
        w, h = paper.width_mm, paper.height_mm
        cands = [(w, h), (h, w)]
        if paper.name in PAPERS:
            cands = [(max(w, h), min(w, h)), (min(w, h), max(w, h))][::1 if bw >= bh else -1]
        for W, H in cands:
            fit = _place(bw, bh, W, H, n_lines)
            if fit:
                break
        else:
            raise ConfigError(_no_fit(source, paper, bw, bh, n_lines))
        where, lw = fit
        bx, by = (W - bw) / 2, (H - bh) / 2
        name = f"{paper.name} {'landscape' if W > H else 'portrait'}" if paper.name in PAPERS else f"{W:g} x {H:g} mm"
    x_min, y_min, _, _ = spec.texture_extent_m()
    to_mm = lambda x, y: (bx + (x - x_min) * 1000.0, by + (y - y_min) * 1000.0)  # noqa: E731
    rects = [(*to_mm(x0, y0), *to_mm(x1, y1)) for x0, y0, x1, y1 in spec.black_rects()]
    circles, polygons = [], []
    for poly in spec.black_polygons():
        p = np.column_stack(to_mm(poly[:, 0], poly[:, 1]))
        c = as_circle(p)
        circles.append(c) if c else polygons.append(p)
    lx, below = (W - lw) / 2, by + bh + GAP_MM
    if where == "below":
        bar_rects, bar_texts = _bar(lx, below)
        texts = bar_texts + _text(lx, below + BAR_BLOCK_MM + GAP_MM, _label_lines(spec, source, lw))
    else:
        bar_rects, bar_texts = _bar(lx, by - GAP_MM - BAR_BLOCK_MM)
        texts = bar_texts + _text(lx, below, _label_lines(spec, source, lw))
    return Sheet(W, H, np.array(rects + bar_rects, dtype=float).reshape(-1, 4),
                 np.array(circles, dtype=float).reshape(-1, 3), tuple(polygons), tuple(texts),
                 (bx, by, bx + bw, by + bh), f"{source}: {spec.kind} target, {name}")


def _no_fit(source, paper, bw, bh, n_lines) -> str:
    fits = [n for n, (w, h) in sorted(PAPERS.items(), key=lambda kv: kv[1][0] * kv[1][1])
            if _place(bw, bh, w, h, n_lines) or _place(bw, bh, h, w, n_lines)]
    hint = f"named papers that fit: {', '.join(fits)}" if fits else "no named paper fits"
    return (f"target {source}: the board is {bw:.1f} x {bh:.1f} mm (its margin included) and does not fit, centred "
            f"with its label and 100 mm scale bar and {EDGE_MM:g} mm edges, on paper {paper.name} of "
            f"{paper.width_mm:g} x {paper.height_mm:g} mm (either orientation): {hint}, or leave out --paper for a "
            "sheet of the board's size")
