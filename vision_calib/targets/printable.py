"""Printable export of a target: PNG with its physical resolution in the file (pHYs chunk) or a
one-page PDF of the board's true size. cv2 + numpy + stdlib only.

Print at 100 % scale ("actual size", no "fit to page"), then measure a square: the printed size is
what the calibration uses.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np

from ..errors import ConfigError
from .spec import TargetSpec

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


def pdf_bytes(img: np.ndarray, width_m: float, height_m: float) -> bytes:
    """One-page PDF whose page is width_m x height_m [m] (true size), filled by the uint8 (H, W) image."""
    H, W = img.shape
    w_pt = width_m / M_PER_INCH * 72.0
    h_pt = height_m / M_PER_INCH * 72.0
    data = zlib.compress(np.ascontiguousarray(img, dtype=np.uint8).tobytes(), 6)
    content = f"q {w_pt:.4f} 0 0 {h_pt:.4f} 0 0 cm /Im0 Do Q".encode()
    objs = [
        b"<< /Type /Catalog /Pages 2 0 R >>",
        b"<< /Type /Pages /Kids [3 0 R] /Count 1 >>",
        f"<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {w_pt:.4f} {h_pt:.4f}] "
        f"/Resources << /XObject << /Im0 4 0 R >> >> /Contents 5 0 R >>".encode(),
        f"<< /Type /XObject /Subtype /Image /Width {W} /Height {H} /ColorSpace /DeviceGray "
        f"/BitsPerComponent 8 /Interpolate false /Filter /FlateDecode /Length {len(data)} >>\nstream\n".encode()
        + data + b"\nendstream",
        f"<< /Length {len(content)} >>\nstream\n".encode() + content + b"\nendstream",
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
    out += f"trailer\n<< /Size {len(objs) + 1} /Root 1 0 R >>\nstartxref\n{xref}\n%%EOF\n".encode()
    return bytes(out)


def export_printable(spec: TargetSpec, out_path, dpi: float = 300) -> Path:
    """Write the board (incl. margin) for printing; the format follows the suffix of out_path.

    ``.png``: pixels at round(dpi / 0.0254) px/m, stored in the pHYs chunk, so
    width_px / px_per_m = outline width within half a pixel. ``.pdf``: the page is exactly
    :meth:`TargetSpec.outline_m` (in points, 1/72 inch) and holds the image at ``dpi``.
    Returns the written path. ConfigError on an unknown suffix or a non-positive dpi.
    """
    out_path = Path(out_path)
    if not (np.isfinite(dpi) and dpi > 0):
        raise ConfigError(f"export_printable: dpi must be > 0, got {dpi}")
    suffix = out_path.suffix.lower()
    if suffix not in (".png", ".pdf"):
        raise ConfigError(f"export_printable: {out_path}: suffix must be .png or .pdf")
    px_per_m = int(round(dpi / M_PER_INCH))
    img = spec.texture(px_per_m)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".png":
        out_path.write_bytes(png_with_phys(img, px_per_m))
    else:
        w, h = spec.outline_m()
        out_path.write_bytes(pdf_bytes(img, w, h))
    return out_path
