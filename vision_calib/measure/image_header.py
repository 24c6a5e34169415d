"""Image sizes from file headers (no pixel decoded) and the pixel limit that every image reader applies first.

A 69-byte PNG may declare 30000 x 30000 px: decoding it takes 900 MB (grey) and OpenCV's detectors several times
that (the fuzzing session of issue 28 saw 12-16 GB). So every image file is checked from its header before it is
decoded: its width x height against the pixel limit (:func:`vision_calib.config.max_image_pixels`: 50 Mpx, or the
``VISION_CALIB_MAX_IMAGE_MPX`` environment variable) and, where the intrinsics are known, against their width x
height (:func:`vision_calib.measure.detect.load_checked`; ``io.images.check_image_sizes`` for whole folders).

Headers read here directly (the first bytes of the file, no dependency): PNG (IHDR), JPEG (the first SOFn
segment), BMP (BITMAPINFOHEADER and OS/2 core header), TIFF (classic and BigTIFF: the first IFD's ImageWidth and
ImageLength). Any other format: its Pillow plugin's header parser (called directly: Pillow's own
decompression-bomb refusal would hide the size). A header none of them reads gives None: the file is refused as
unreadable, never decoded blind.
"""

from __future__ import annotations

import struct
from collections import Counter
from pathlib import Path

#: bytes a JPEG's segments are scanned for its SOFn marker (EXIF / ICC segments come first; 64 KB each at most)
JPEG_SCAN_BYTES = 4 * 1024 * 1024


def _png(head: bytes):
    if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR" and len(head) >= 24:
        return struct.unpack(">II", head[16:24])
    return None


def _bmp(head: bytes):
    if head[:2] != b"BM" or len(head) < 26:
        return None
    dib = struct.unpack("<I", head[14:18])[0]
    if dib == 12:  # OS/2 BITMAPCOREHEADER
        return struct.unpack("<HH", head[18:22])
    w, h = struct.unpack("<ii", head[18:26])
    return w, abs(h)


def _jpeg(fh) -> tuple[int, int] | None:
    fh.seek(2)
    read = 2
    while read < JPEG_SCAN_BYTES:
        b = fh.read(1)
        if not b:
            return None
        if b != b"\xff":
            continue
        marker = fh.read(1)
        while marker == b"\xff":  # fill bytes
            marker = fh.read(1)
        if not marker:
            return None
        m = marker[0]
        if m in (0x01,) or 0xD0 <= m <= 0xD9:  # standalone markers (RSTn, SOI, EOI, TEM)
            read += 2
            continue
        seg = fh.read(2)
        if len(seg) < 2:
            return None
        n = struct.unpack(">H", seg)[0]
        if 0xC0 <= m <= 0xCF and m not in (0xC4, 0xC8, 0xCC):  # SOF0..SOF15 but DHT, JPG, DAC
            body = fh.read(5)
            if len(body) < 5:
                return None
            h, w = struct.unpack(">HH", body[1:5])
            return w, h
        if n < 2:
            return None
        fh.seek(n - 2, 1)
        read += 2 + n
    return None


def _tiff(fh, head: bytes):
    if head[:4] in (b"II*\x00", b"MM\x00*"):
        big = False
    elif head[:4] in (b"II+\x00", b"MM\x00+"):
        big = True
    else:
        return None
    e = "<" if head[:2] == b"II" else ">"
    if big:
        ifd = struct.unpack(e + "Q", head[8:16])[0]
        fh.seek(ifd)
        count = struct.unpack(e + "Q", fh.read(8))[0]
        size, off = 20, 12
    else:
        ifd = struct.unpack(e + "I", head[4:8])[0]
        fh.seek(ifd)
        count = struct.unpack(e + "H", fh.read(2))[0]
        size, off = 12, 8
    out = {}
    for _ in range(min(count, 4096)):
        entry = fh.read(size)
        if len(entry) < size:
            break
        tag, typ = struct.unpack(e + "HH", entry[:4])
        if tag in (256, 257):
            if typ == 3:  # SHORT
                out[tag] = struct.unpack(e + "H", entry[off:off + 2])[0]
            elif typ == 4:  # LONG
                out[tag] = struct.unpack(e + "I", entry[off:off + 4])[0]
            elif typ == 16 and big:  # LONG8
                out[tag] = struct.unpack(e + "Q", entry[off:off + 8])[0]
    return (out[256], out[257]) if 256 in out and 257 in out else None


def _pillow(path: Path):
    """(width, height) from the header parser of the Pillow plugin that accepts the file, without Pillow's
    decompression-bomb check (we apply our own limit to the size it returns)."""
    from PIL import Image

    Image.init()
    with open(path, "rb") as fp:
        prefix = fp.read(16)
        for fmt in list(Image.ID):
            factory, accept = Image.OPEN[fmt]
            try:
                if accept is not None and not (accept(prefix) is True or accept(prefix) == 1):
                    continue
                fp.seek(0)
                im = factory(fp, str(path))
                return int(im.size[0]), int(im.size[1])
            except Exception:  # noqa: BLE001 -- a plugin that cannot parse this header: try the next
                continue
    return None


def _sniff(fh) -> tuple[int, int] | None:
    """(width, height) of the PNG, BMP, JPEG or TIFF header at the start of the binary file object, or None."""
    head = fh.read(32)
    size = _png(head) or _bmp(head)
    if size is None and head[:2] == b"\xff\xd8":
        size = _jpeg(fh)
    if size is None and head[:2] in (b"II", b"MM"):
        size = _tiff(fh, head)
    return size


def buffer_size(data) -> tuple[int, int] | None:
    """(width, height) [px] declared by an encoded image held in memory (bytes-like: a ROS ``CompressedImage``'s
    data; PNG, JPEG, BMP, TIFF headers, the first :data:`JPEG_SCAN_BYTES` read at most), or None; never decodes,
    never raises."""
    import io

    try:
        size = _sniff(io.BytesIO(bytes(memoryview(data)[:JPEG_SCAN_BYTES])))
    except (struct.error, ValueError, TypeError):
        return None
    return (int(size[0]), int(size[1])) if size is not None and size[0] > 0 and size[1] > 0 else None


def header_size(path) -> tuple[int, int] | None:
    """(width, height) [px] declared by the image file's header, or None when no header parser reads it (missing,
    truncated, corrupt, or an unknown format). Reads a few bytes (JPEG: up to :data:`JPEG_SCAN_BYTES`); never
    decodes pixels, never raises."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            size = _sniff(fh)
    except (OSError, struct.error, ValueError):
        return None
    if size is None:
        try:
            size = _pillow(path)
        except (OSError, ImportError):
            size = None
    if size is None or not (size[0] > 0 and size[1] > 0):
        return None
    return int(size[0]), int(size[1])


def pixel_refusal(path, size, limit: int | None = None) -> str | None:
    """The refusal naming ``path`` (None: the reason alone) when ``size`` (width, height) px exceeds the pixel
    limit (default: :func:`vision_calib.config.max_image_pixels`), else None."""
    from ..config import MAX_IMAGE_ENV, max_image_pixels

    limit = max_image_pixels() if limit is None else limit
    w, h = size
    if w * h <= limit:
        return None
    where = f"{path}: " if path is not None else ""
    return (f"{where}image {w}x{h} px ({w * h / 1e6:.4g} Mpx) exceeds the limit of {limit / 1e6:.4g} Mpx (decoding "
            f"it would take at least {w * h / 2**30:.3g} GiB, the detectors several times that): a damaged or hostile "
            f"file, or a camera beyond the limit (raise it with the environment variable {MAX_IMAGE_ENV}=MPX)")


def majority_size(sizes) -> tuple[tuple[int, int] | None, int]:
    """(the most common (width, height) of ``sizes`` (None entries ignored; a tie goes to the size seen first),
    how many have it)."""
    counts = Counter(s for s in sizes if s is not None)
    if not counts:
        return None, 0
    best = max(counts.values())
    size = next(s for s in sizes if s is not None and counts[s] == best)
    return size, best


__all__ = ["header_size", "buffer_size", "pixel_refusal", "majority_size", "JPEG_SCAN_BYTES"]
