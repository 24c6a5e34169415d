"""Printable export of a target: a PDF or SVG sheet drawn as vectors (the board centred on a paper size, a label,
a 100 mm scale bar; :mod:`.sheet`, :mod:`.vector`), or a PNG with its physical resolution in the file (pHYs chunk).
cv2 + numpy + stdlib only.

Print at 100 % scale ("actual size", no "fit to page"), then measure the scale bar and a square: the printed size
is what the calibration uses.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np

from ..errors import ConfigError
from ..serialize import write_bytes_atomic
from .sheet import layout, parse_paper
from .spec import TargetSpec
from .vector import render_sheet, sheet_pdf, sheet_svg

M_PER_INCH = 0.0254


def _png_chunk(ctype: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + ctype + data + struct.pack(">I", zlib.crc32(ctype + data) & 0xFFFFFFFF)


def png_with_phys(img: np.ndarray, px_per_m: int) -> bytes:
    """Encode a uint8 (H, W) image as PNG bytes with a pHYs chunk of px_per_m pixels per metre."""
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise ConfigError("PNG encoding failed")
    b = buf.tobytes()
    ihdr_end = 8 + 4 + 4 + 13 + 4  # signature + IHDR (length, type, 13 data bytes, crc)
    phys = _png_chunk(b"pHYs", struct.pack(">IIB", int(px_per_m), int(px_per_m), 1))
    return b[:ihdr_end] + phys + b[ihdr_end:]


def read_png_phys(path) -> tuple[int, int, int, int]:
    """(width_px, height_px, px_per_m_x, px_per_m_y) from a PNG's IHDR and pHYs chunks (0 if no pHYs)."""
    b = Path(path).read_bytes()
    if b[:8] != b"\x89PNG\r\n\x1a\n":
        raise ConfigError(f"{path}: not a PNG file")
    pos, w, h, ppx, ppy = 8, 0, 0, 0, 0
    while pos + 8 <= len(b):
        n, ctype = struct.unpack(">I4s", b[pos:pos + 8])
        data = b[pos + 8:pos + 8 + n]
        if ctype == b"IHDR":
            w, h = struct.unpack(">II", data[:8])
        elif ctype == b"pHYs":
            ppx, ppy, unit = struct.unpack(">IIB", data)
            if unit != 1:
                ppx = ppy = 0
        elif ctype == b"IEND":
            break
        pos += 12 + n
    return w, h, ppx, ppy


def export_printable(spec: TargetSpec, out_path, dpi: float | None = None, paper=None,
                     source: str | None = None) -> Path:
    """Write the target for printing; the format follows the suffix of out_path (.pdf, .svg, .png); atomic write.

    ``.pdf`` / ``.svg``: vector drawings (:mod:`.vector`) of the sheet (:func:`.sheet.layout`): the board
    centred on ``paper`` (a :class:`~.sheet.Paper` or its text: "A4", "letter", "300x200"; None: a sheet just
    big enough) with a label naming the target and its sizes, a 100 mm scale bar and how to check the print;
    ``dpi`` is refused (no resolution). ``.png``: dpi [dots per inch] (default 300) stored in the pHYs chunk as
    round(dpi / 0.0254) px/m; without paper the board alone (:meth:`TargetSpec.texture`, width_px / px_per_m =
    outline width within half a pixel), with paper the sheet. source: the target file's name on the label
    (default: spec.name). Returns the written path. ConfigError on an unknown suffix, a bad dpi or paper, or a
    board that does not fit the paper.
    """
    out_path = Path(out_path)
    suffix = out_path.suffix.lower()
    if suffix not in (".png", ".pdf", ".svg"):
        raise ConfigError(f"export_printable: {out_path}: suffix must be .pdf, .svg or .png")
    if dpi is not None and suffix != ".png":
        raise ConfigError(f"export_printable: dpi ({dpi}) applies to .png only; {out_path.name} is drawn as vectors "
                          "(no resolution): leave dpi out")
    dpi = 300 if dpi is None else dpi
    if not (np.isfinite(dpi) and dpi > 0):
        raise ConfigError(f"export_printable: dpi must be > 0, got {dpi}")
    if isinstance(paper, str):
        paper = parse_paper(paper)
    if suffix == ".png" and paper is None:
        px_per_m = int(round(dpi / M_PER_INCH))
        return write_bytes_atomic(out_path, png_with_phys(spec.texture(px_per_m), px_per_m))
    sheet = layout(spec, paper, source)
    if suffix == ".pdf":
        return write_bytes_atomic(out_path, sheet_pdf(sheet))
    if suffix == ".svg":
        return write_bytes_atomic(out_path, sheet_svg(sheet).encode("utf-8"))
    px_per_m = int(round(dpi / M_PER_INCH))
    return write_bytes_atomic(out_path, png_with_phys(render_sheet(sheet, px_per_m / 1000.0), px_per_m))
