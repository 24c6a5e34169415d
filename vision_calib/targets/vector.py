"""Writing a :class:`~.sheet.Sheet` out: a one-page PDF 1.4 and an SVG drawn as vectors (filled rectangles,
Bezier circles, polygons, Helvetica text; no raster image anywhere), and a grey raster of it for PNG.
numpy + cv2 + stdlib only.

PDF: the page is the sheet (MediaBox in points, 1/72 inch); its one content stream is uncompressed text: the
black shapes as one path filled once (``re`` rectangles, ``c`` Bezier quarter circles, ``l`` polygons; one fill
leaves no seams between touching shapes), in mm with y down by one ``cm``, then the text lines (Helvetica,
WinAnsiEncoding; not embedded). SVG: user units are mm (``viewBox`` = sheet size, width/height in mm).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from .coverage import accumulate_coverage
from .kinds.base import check_memory
from .sheet import Sheet, text_width_mm

PT_PER_MM = 72.0 / 25.4
KAPPA = 0.5522847498307936  # Bezier control distance of a quarter circle (unit radius)
N_RING = 128  # vertices of a circle in the raster (area-preserving, as the kinds' dots)


def _n(v: float) -> str:
    """A number for PDF / SVG: 4 decimals (0.1 um in mm), trailing zeros dropped."""
    s = f"{v:.4f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _pdf_string(text: str) -> bytes:
    b = text.encode("cp1252", errors="replace")
    return b"(" + b.replace(b"\\", b"\\\\").replace(b"(", b"\\(").replace(b")", b"\\)") + b")"


def _circle_path(cx: float, cy: float, r: float) -> str:
    k = KAPPA * r
    pts = [(cx + r, cy + k, cx + k, cy + r, cx, cy + r), (cx - k, cy + r, cx - r, cy + k, cx - r, cy),
           (cx - r, cy - k, cx - k, cy - r, cx, cy - r), (cx + k, cy - r, cx + r, cy - k, cx + r, cy)]
    return f"{_n(cx + r)} {_n(cy)} m\n" + "".join(" ".join(map(_n, p)) + " c\n" for p in pts) + "h\n"


def sheet_pdf(sheet: Sheet) -> bytes:
    """One-page PDF 1.4 of the sheet: page width_mm x height_mm, shapes and text as vectors."""
    w_pt, h_pt = sheet.width_mm * PT_PER_MM, sheet.height_mm * PT_PER_MM
    path = [f"{_n(x0)} {_n(y0)} {_n(x1 - x0)} {_n(y1 - y0)} re\n" for x0, y0, x1, y1 in sheet.rects]
    path += [_circle_path(*c) for c in sheet.circles]
    path += [f"{_n(p[0, 0])} {_n(p[0, 1])} m\n" + "".join(f"{_n(x)} {_n(y)} l\n" for x, y in p[1:]) + "h\n"
             for p in sheet.polygons]
    content = (f"% black shapes [mm, y down]\nq\n{PT_PER_MM:.10f} 0 0 {-PT_PER_MM:.10f} 0 {h_pt:.4f} cm\n0 g\n"
               + "".join(path) + "f\nQ\n% text\n0 g\n").encode("ascii")
    for t in sheet.texts:
        content += (f"BT /F1 {t.size_mm * PT_PER_MM:.3f} Tf {t.x_mm * PT_PER_MM:.3f} "
                    f"{h_pt - t.y_mm * PT_PER_MM:.3f} Td ").encode() + _pdf_string(t.text) + b" Tj ET\n"
    objs = [
        b"<< /Type /Catalog /Pages 2 0 R >>",
        b"<< /Type /Pages /Kids [3 0 R] /Count 1 >>",
        f"<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {w_pt:.4f} {h_pt:.4f}] "
        f"/Resources << /Font << /F1 5 0 R >> >> /Contents 4 0 R >>".encode(),
        f"<< /Length {len(content)} >>\nstream\n".encode() + content + b"\nendstream",
        b"<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica /Encoding /WinAnsiEncoding >>",
        b"<< /Title " + _pdf_string(sheet.title) + b" /Creator (vision-calib target) >>",
    ]
    out = bytearray(b"%PDF-1.4\n%\xe2\xe3\xcf\xd3\n")
    offsets = []
    for i, o in enumerate(objs, start=1):
        offsets.append(len(out))
        out += f"{i} 0 obj\n".encode() + o + b"\nendobj\n"
    xref = len(out)
    out += f"xref\n0 {len(objs) + 1}\n0000000000 65535 f \n".encode()
    for off in offsets:
        out += f"{off:010d} 00000 n \n".encode()
    out += (f"trailer\n<< /Size {len(objs) + 1} /Root 1 0 R /Info {len(objs)} 0 R >>\nstartxref\n{xref}\n"
            "%%EOF\n").encode()
    return bytes(out)


def _xml(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def sheet_svg(sheet: Sheet) -> str:
    """SVG of the sheet in mm (viewBox = sheet, white background rectangle): the rectangles as one path,
    circles as ``<circle>``, polygons as paths, text in Helvetica."""
    W, H = _n(sheet.width_mm), _n(sheet.height_mm)
    rects = "".join(f"M{_n(x0)} {_n(y0)}H{_n(x1)}V{_n(y1)}H{_n(x0)}Z" for x0, y0, x1, y1 in sheet.rects)
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}mm" height="{H}mm" viewBox="0 0 {W} {H}">',
           f"<title>{_xml(sheet.title)}</title>",
           f'<rect x="0" y="0" width="{W}" height="{H}" fill="#fff"/>',
           f'<path fill="#000" d="{rects}"/>' if rects else ""]
    out += [f'<circle cx="{_n(cx)}" cy="{_n(cy)}" r="{_n(r)}" fill="#000"/>' for cx, cy, r in sheet.circles]
    out += ['<path fill="#000" d="M' + "L".join(f"{_n(x)} {_n(y)}" for x, y in p) + 'Z"/>' for p in sheet.polygons]
    out += [f'<text x="{_n(t.x_mm)}" y="{_n(t.y_mm)}" font-family="Helvetica, Arial, sans-serif" '
            f'font-size="{_n(t.size_mm)}" fill="#000">{_xml(t.text)}</text>' for t in sheet.texts]
    return "\n".join(ln for ln in out if ln) + "\n</svg>\n"


def render_sheet(sheet: Sheet, px_per_mm: float) -> np.ndarray:
    """uint8 (H, W) grey image of the sheet at px_per_mm [px/mm], (H, W) = round(size * px_per_mm); pixel
    (0, 0) covers [0, 1/px_per_mm]^2 mm. Shapes with their exact area coverage (circles as area-preserving
    128-gons), text in OpenCV's Hershey font scaled to Helvetica's width (for reading, not for measuring)."""
    H, W = max(1, round(sheet.height_mm * px_per_mm)), max(1, round(sheet.width_mm * px_per_mm))
    check_memory(H * W * 9, f"a {W} x {H} px sheet ({px_per_mm * 25.4:.0f} dpi)")
    r = sheet.rects
    groups = [np.stack([r[:, [0, 1]], r[:, [2, 1]], r[:, [2, 3]], r[:, [0, 3]]], axis=1)]  # TL, TR, BR, BL
    if len(sheet.circles):
        a = -0.75 * math.pi + 2 * math.pi * np.arange(N_RING) / N_RING  # increasing angle, as TL -> TR -> BR -> BL
        s = math.sqrt(2 * math.pi / (N_RING * math.sin(2 * math.pi / N_RING)))
        c = sheet.circles
        groups.append(c[:, None, :2] + s * c[:, None, 2:] * np.stack([np.cos(a), np.sin(a)], axis=1)[None])
    for n in sorted({len(p) for p in sheet.polygons}):
        groups.append(np.stack([p for p in sheet.polygons if len(p) == n]))
    cover = np.zeros((H, W))
    for g in groups:
        if len(g):
            cover += accumulate_coverage(g * px_per_mm, -np.ones(len(g)), H, W)
    img = np.round(255.0 * np.clip(1.0 - cover, 0.0, 1.0)).astype(np.uint8)
    font = cv2.FONT_HERSHEY_SIMPLEX
    for t in sheet.texts:
        cap_px = 0.718 * t.size_mm * px_per_mm  # Helvetica's cap height
        thick = max(1, round(cap_px / 12))
        (tw, _), _ = cv2.getTextSize(t.text, font, 1.0, thick)
        (_, th), _ = cv2.getTextSize("H", font, 1.0, thick)
        scale = min(cap_px / th, text_width_mm(t.text, t.size_mm) * px_per_mm / max(tw, 1))
        org = (round(t.x_mm * px_per_mm - 0.5), round(t.y_mm * px_per_mm - 0.5))
        cv2.putText(img, t.text, org, font, scale, 0, thick, cv2.LINE_AA)
    return img
