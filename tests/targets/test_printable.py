"""Printable export: the PNG's stored physical size matches the board; the PDF / SVG sheets are vectors (no embedded
image) of the paper's size with the board centred, a label and a 100 mm scale bar; read back (the PDF's content
stream and the SVG's elements parsed here, independently of the writer, and rasterised) the board is found by the
package's own detector at the paper's scale, marker bits as OpenCV's dictionary has them."""

import re
import shutil
import subprocess
import xml.etree.ElementTree as ET
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from vision_calib.cli import main
from vision_calib.errors import ConfigError
from vision_calib.measure import detect
from vision_calib.targets import TargetSpec, export_printable, layout, load_target, parse_paper, read_png_phys
from vision_calib.targets.coverage import accumulate_coverage
from vision_calib.targets.sheet import EDGE_MM, text_width_mm

ROOT = Path(__file__).resolve().parents[2]
SPEC = TargetSpec(kind="charuco", name="t", rows=5, cols=7, dictionary="DICT_5X5_100", square_m=0.025, marker_m=0.018)
SHIPPED = sorted(p.stem for p in (ROOT / "targets").glob("*.yaml"))
A4_PT = (595.28, 841.89)
PX_PER_MM = 6.0  # raster of the read-back sheets (152 dpi)


def shipped(name):
    return load_target(ROOT / "targets" / f"{name}.yaml")


# ------------------------------------------------------------------------------------------ readers (test-only)
def pdf_page(data: bytes) -> tuple[tuple[float, float], bytes]:
    """((width, height) [pt] of the MediaBox, the page's content stream, inflated when compressed)."""
    box = [float(v) for v in re.search(rb"/MediaBox \[([^\]]+)\]", data).group(1).split()]
    n = int(re.search(rb"/Contents (\d+) 0 R", data).group(1))
    obj = data[data.index(f"\n{n} 0 obj".encode()):]
    length = int(re.search(rb"/Length (\d+)", obj).group(1))
    start = obj.index(b"stream\n") + len(b"stream\n")
    stream = obj[start:start + length]
    if b"/FlateDecode" in obj[:start]:
        stream = zlib.decompress(stream)
    return (box[2] - box[0], box[3] - box[1]), stream


def _bezier(p0, p1, p2, p3, n=24):
    t = np.linspace(0, 1, n + 1)[1:, None]
    return (1 - t) ** 3 * p0 + 3 * (1 - t) ** 2 * t * p1 + 3 * (1 - t) * t ** 2 * p2 + t ** 3 * p3


def pdf_shapes(stream: bytes) -> tuple[list, list]:
    """(filled polygons [(V, 2) in pt, PDF page space, y up], text strings) of a content stream using
    q Q cm re m l c h f g and text operators (what a single-page drawing needs)."""
    tokens = re.findall(rb"\((?:\\.|[^\\)])*\)|%[^\n]*|[^\s()]+", stream)
    ctm, stack, args, sub, path, fills, texts = np.eye(3), [], [], [], [], [], []

    def dev(x, y):
        return (np.array([x, y, 1.0]) @ ctm)[:2]

    for tok in tokens:
        if tok.startswith(b"%"):
            continue
        if tok.startswith(b"("):
            texts.append(re.sub(rb"\\(.)", rb"\1", tok[1:-1]).decode("cp1252"))
            continue
        try:
            args.append(float(tok))
            continue
        except ValueError:
            pass
        op = tok.decode()
        if op == "q":
            stack.append(ctm.copy())
        elif op == "Q":
            ctm = stack.pop()
        elif op == "cm":
            a, b, c, d, e, f = args[-6:]
            ctm = np.array([[a, b, 0], [c, d, 0], [e, f, 1]]) @ ctm
        elif op == "re":
            x, y, w, h = args[-4:]
            path.append(np.array([dev(x, y), dev(x + w, y), dev(x + w, y + h), dev(x, y + h)]))
        elif op == "m":
            sub = [dev(*args[-2:])]
        elif op == "l":
            sub.append(dev(*args[-2:]))
        elif op == "c":
            x1, y1, x2, y2, x3, y3 = args[-6:]
            sub.extend(_bezier(sub[-1], dev(x1, y1), dev(x2, y2), dev(x3, y3)))
        elif op == "h":
            path.append(np.array(sub))
            sub = []
        elif op == "f":
            fills += path
            path = []
        args = [] if not op.startswith("/") else args
    return fills, texts


def svg_shapes(text: str) -> tuple[tuple[float, float], list, list, list]:
    """((width, height) of the viewBox [mm], black polygons [(V, 2) mm], circles (cx, cy, r) [mm], texts) of
    an SVG using absolute M H V L Z paths, circles, rects (white ones skipped) and text."""
    root = ET.fromstring(text)
    ns = "{http://www.w3.org/2000/svg}"
    W, H = (float(v) for v in root.get("viewBox").split()[2:])
    polys, circles, texts = [], [], []
    for el in root.iter():
        if el.tag == ns + "path":
            for part in re.findall(r"M[^M]+", el.get("d")):
                pts, x, y = [], 0.0, 0.0
                for cmd, nums in re.findall(r"([MHVLZ])([^MHVLZ]*)", part):
                    v = [float(s) for s in nums.split()]
                    if cmd in "ML":
                        x, y = v
                    elif cmd == "H":
                        x = v[0]
                    elif cmd == "V":
                        y = v[0]
                    if cmd != "Z":
                        pts.append((x, y))
                polys.append(np.array(pts))
        elif el.tag == ns + "circle":
            circles.append(tuple(float(el.get(k)) for k in ("cx", "cy", "r")))
        elif el.tag == ns + "rect" and el.get("fill") not in ("#fff", "#ffffff", "white"):
            x, y, w, h = (float(el.get(k)) for k in ("x", "y", "width", "height"))
            polys.append(np.array([(x, y), (x + w, y), (x + w, y + h), (x, y + h)]))
        elif el.tag == ns + "text":
            texts.append(el.text)
    return (W, H), polys, circles, texts


def rasterise(polys: list, width_px: int, height_px: int) -> np.ndarray:
    """uint8 image, white with the polygons (px, y down, any orientation, not overlapping) black: exact coverage."""
    cover = np.zeros((height_px, width_px))
    for n in sorted({len(p) for p in polys}):
        g = np.stack([p for p in polys if len(p) == n])
        area = np.sum(g[:, :, 0] * np.roll(g[:, :, 1], -1, 1) - np.roll(g[:, :, 0], -1, 1) * g[:, :, 1], axis=1)
        cover += accumulate_coverage(g, -np.sign(area), height_px, width_px)  # each counts + its area
    return np.round(255 * np.clip(1 - cover, 0, 1)).astype(np.uint8)


def read_pdf_raster(data: bytes, px_per_mm: float = PX_PER_MM) -> tuple[np.ndarray, float, float, list]:
    """(image, width [mm], height [mm], texts) of a PDF sheet rasterised from its content stream."""
    (w_pt, h_pt), stream = pdf_page(data)
    fills, texts = pdf_shapes(stream)
    s = 25.4 / 72 * px_per_mm
    polys = [np.column_stack([p[:, 0] * s, (h_pt - p[:, 1]) * s]) for p in fills]
    W, H = w_pt * 25.4 / 72, h_pt * 25.4 / 72
    return rasterise(polys, round(W * px_per_mm), round(H * px_per_mm)), W, H, texts


def read_svg_raster(text: str, px_per_mm: float = PX_PER_MM) -> tuple[np.ndarray, float, float, list]:
    (W, H), polys, circles, texts = svg_shapes(text)
    a = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    polys = polys + [np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a)]) for cx, cy, r in circles]
    return rasterise([p * px_per_mm for p in polys], round(W * px_per_mm), round(H * px_per_mm)), W, H, texts


def check_detected_at_scale(img, spec, W_mm, H_mm, px_per_mm, tol_px=0.3):
    """Every corner of the board found where the board centred on a W x H mm sheet puts it at px_per_mm (within
    tol_px; AprilTag corners: 0.5 px, OpenCV's AprilTag refinement is off by up to ~0.3 px on sharp axis-aligned
    edges), and the board's scale (px per metre, fitted over all corners) equal to the paper's."""
    tol_px = max(tol_px, 0.5) if spec.kind == "apriltag_grid" else tol_px
    d = detect(cv2.GaussianBlur(img, (0, 0), 0.7), spec)
    assert d.valid, d.reason
    ids, p = spec.corner_points()
    assert sorted(d.ids) == list(ids)  # every corner found
    bw, bh = spec.outline_m()
    x_min, y_min, _, _ = spec.texture_extent_m()
    origin = np.array([(W_mm - bw * 1000) / 2, (H_mm - bh * 1000) / 2]) - 1000 * np.array([x_min, y_min])
    expect = (origin + 1000 * p[d.ids, :2]) * px_per_mm - 0.5  # pixel centres at integers
    np.testing.assert_allclose(d.uv_px, expect, atol=tol_px)  # a wrong id is a square off
    A = np.zeros((2 * len(d.ids), 3))  # uv = scale * p + shift
    A[0::2, 0], A[1::2, 0] = p[d.ids, 0], p[d.ids, 1]
    A[0::2, 1], A[1::2, 2] = 1, 1
    scale_px_per_m = np.linalg.lstsq(A, d.uv_px.reshape(-1), rcond=None)[0][0]
    assert scale_px_per_m == pytest.approx(px_per_mm * 1000, rel=5e-4)
    return d


# ------------------------------------------------------------------------------------------ PNG of the board alone
@pytest.mark.parametrize("dpi", [150, 300, 600])
def test_png_dpi_times_pixels_is_physical_size(tmp_path, dpi):
    out = export_printable(SPEC, tmp_path / "board.png", dpi=dpi)
    w_px, h_px, ppm_x, ppm_y = read_png_phys(out)
    assert ppm_x == ppm_y == round(dpi / 0.0254)
    w_m, h_m = SPEC.outline_m()
    assert abs(w_px / ppm_x - w_m) <= 0.5 / ppm_x + 1e-12
    assert abs(h_px / ppm_y - h_m) <= 0.5 / ppm_y + 1e-12
    img = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)  # the extra chunk keeps the PNG valid
    assert img.shape == (h_px, w_px)
    assert np.array_equal(img, SPEC.texture(ppm_x))


def test_png_dpi_read_by_pillow(tmp_path):
    Image = pytest.importorskip("PIL.Image")
    out = export_printable(SPEC, tmp_path / "board.png", dpi=300)
    with Image.open(out) as im:
        assert im.info["dpi"][0] == pytest.approx(300, abs=0.05)


# ------------------------------------------------------------------------------------------ vector sheets
def test_pdf_is_a_vector_a4_sheet_with_its_label(tmp_path):
    out = export_printable(shipped("charuco_a5"), tmp_path / "board.pdf", paper="A4", source="charuco_a5.yaml")
    data = out.read_bytes()
    assert data.startswith(b"%PDF-1.4")
    assert b"/Image" not in data and b"/XObject" not in data  # no raster anywhere
    (w_pt, h_pt), stream = pdf_page(data)
    assert sorted((w_pt, h_pt)) == pytest.approx(A4_PT, abs=0.01)
    assert b" re" in stream and b"/Helvetica" in data
    label = " ".join(pdf_shapes(stream)[1])
    for s in ("charuco_a5.yaml", "charuco", "5 x 7", "DICT_5X5_100", "square_m 25 mm", "marker_m 18 mm", "100 mm",
              "as square_m in charuco_a5.yaml", "Print at 100 %"):
        assert s in label, s
    xref = int(re.search(rb"startxref\n(\d+)", data).group(1))  # xref offsets point at the objects
    assert data[xref:xref + 4] == b"xref"
    offs = [int(m) for m in re.findall(rb"(\d{10}) 00000 n", data)]
    for i, o in enumerate(offs, start=1):
        assert data[o:].startswith(f"{i} 0 obj".encode())


def test_svg_is_a_vector_sheet_with_its_label(tmp_path):
    spec = shipped("circles_asymmetric_a4")
    out = export_printable(spec, tmp_path / "board.svg", paper="A4", source="circles_asymmetric_a4.yaml")
    text = out.read_text(encoding="utf-8")
    assert "<image" not in text and "base64" not in text
    (W, H), polys, circles, texts = svg_shapes(text)
    assert sorted((W, H)) == [210, 297]
    root = ET.fromstring(text)
    assert {root.get("width"), root.get("height")} == {"210mm", "297mm"}
    assert len(circles) == spec.n_corners  # every dot a true circle of the file's diameter
    np.testing.assert_allclose([c[2] for c in circles], 1000 * spec.diameter_m / 2, rtol=1e-9, atol=1e-4)
    label = " ".join(texts)
    assert "spacing_m 18 mm" in label and "diameter_m 10 mm" in label and "as spacing_m in" in label
    charuco = export_printable(SPEC, tmp_path / "c.svg", paper="A4").read_text(encoding="utf-8")
    assert "DICT_5X5_100" in charuco and "<image" not in charuco


@pytest.mark.parametrize("name", SHIPPED)
def test_pdf_read_back_is_detected_at_paper_scale(tmp_path, name):
    spec = shipped(name)
    out = export_printable(spec, tmp_path / "board.pdf", paper="A3")
    img, W, H, _ = read_pdf_raster(out.read_bytes())
    assert sorted((W, H)) == pytest.approx([297, 420], abs=1e-3)
    check_detected_at_scale(img, spec, W, H, PX_PER_MM)


@pytest.mark.parametrize("name", ["charuco_a5", "apriltag_grid", "modified_circle_grid_a4"])
def test_svg_read_back_is_detected_at_paper_scale(tmp_path, name):
    spec = shipped(name)
    out = export_printable(spec, tmp_path / "board.svg", paper="letter")
    img, W, H, _ = read_svg_raster(out.read_text(encoding="utf-8"))
    assert sorted((W, H)) == pytest.approx([215.9, 279.4], abs=1e-3)
    check_detected_at_scale(img, spec, W, H, PX_PER_MM)


@pytest.mark.parametrize("name", ["charuco_a5", "apriltag_grid"])
def test_marker_bits_are_the_dictionary_s(tmp_path, name):
    """Every bit cell of every marker, read at its centre on the read-back PDF, is the bit of OpenCV's own
    marker image (generateImageMarker at 1 px per bit): no decoding slack (error correction) hides a wrong bit."""
    spec = shipped(name)
    img, W, H, _ = read_pdf_raster(export_printable(spec, tmp_path / "b.pdf", paper="A4").read_bytes())
    d = spec.cv_dictionary()
    nb = d.markerSize + 2
    bw, bh = spec.outline_m()
    x_min, y_min, _, _ = spec.texture_extent_m()
    origin = np.array([(W - bw * 1000) / 2 - 1000 * x_min, (H - bh * 1000) / 2 - 1000 * y_min])
    for mid, c in zip(spec.marker_ids(), spec.marker_corners()):
        side = 1000 * (c[1, 0] - c[0, 0])
        centres = (np.arange(nb) + 0.5) * side / nb
        u = ((origin[0] + 1000 * c[0, 0] + centres) * PX_PER_MM).astype(int)
        v = ((origin[1] + 1000 * c[0, 1] + centres) * PX_PER_MM).astype(int)
        printed = np.where(img[np.ix_(v, u)] > 127, 255, 0)
        assert np.array_equal(printed, cv2.aruco.generateImageMarker(d, int(mid), nb)), f"marker {mid}"


def test_png_sheet_is_the_paper_at_dpi_and_detected(tmp_path):
    spec = shipped("charuco_a5")
    out = export_printable(spec, tmp_path / "sheet.png", dpi=150, paper="A4")
    w_px, h_px, ppm, _ = read_png_phys(out)
    assert ppm == round(150 / 0.0254)
    assert sorted((w_px, h_px)) == [round(210 * ppm / 1000), round(297 * ppm / 1000)]
    img = cv2.imread(str(out), cv2.IMREAD_GRAYSCALE)
    check_detected_at_scale(img, spec, w_px * 1000 / ppm, h_px * 1000 / ppm, ppm / 1000)


@pytest.mark.skipif(not shutil.which("pdftoppm"), reason="pdftoppm (poppler) not installed")
def test_pdf_rendered_by_poppler_is_detected(tmp_path):
    """The same check on the page as a real PDF renderer draws it."""
    spec = shipped("charuco_a5")
    out = export_printable(spec, tmp_path / "b.pdf", paper="A4")
    subprocess.run(["pdftoppm", "-r", "200", "-gray", "-png", str(out), str(tmp_path / "r")], check=True)
    img = cv2.imread(str(next(tmp_path.glob("r*.png"))), cv2.IMREAD_GRAYSCALE)
    ppmm = img.shape[1] / 297.0  # landscape A4
    check_detected_at_scale(img, spec, 297.0, 210.0, ppmm, tol_px=0.5)


# ------------------------------------------------------------------------------------------ layout
@pytest.mark.parametrize("paper", [None, "A4", "A3", "letter"])
@pytest.mark.parametrize("name", SHIPPED)
def test_everything_inside_the_printable_area_and_apart(name, paper):
    """Board centred on a paper (top-centred without one), every shape and text line >= EDGE_MM from the sheet's
    edge, the label outside the board's outline (its white margin kept clear)."""
    spec = shipped(name)
    try:
        s = layout(spec, parse_paper(paper) if paper else None, f"{name}.yaml")
    except ConfigError as exc:
        assert "does not fit" in str(exc) and paper is not None
        return
    bx0, by0, bx1, by1 = s.board_mm
    assert (bx1 - bx0, by1 - by0) == pytest.approx(tuple(1000 * v for v in spec.outline_m()))
    assert (bx0 + bx1) / 2 == pytest.approx(s.width_mm / 2)
    if paper:
        assert (by0 + by1) / 2 == pytest.approx(s.height_mm / 2)
    boxes = [tuple(r) for r in s.rects] + [(cx - r, cy - r, cx + r, cy + r) for cx, cy, r in s.circles]
    boxes += [(t.x_mm, t.y_mm - t.size_mm, t.x_mm + text_width_mm(t.text, t.size_mm), t.y_mm + 0.25 * t.size_mm)
              for t in s.texts]
    b = np.array(boxes)
    e = EDGE_MM - 1e-9
    assert b[:, 0].min() >= e and b[:, 1].min() >= e
    assert b[:, 2].max() <= s.width_mm - e and b[:, 3].max() <= s.height_mm - e
    n_board = len(spec.black_rects()) + len(s.circles)
    label = np.concatenate([b[len(spec.black_rects()):len(s.rects)], b[len(s.rects) + len(s.circles):]])
    inside = (label[:, 2] > bx0) & (label[:, 0] < bx1) & (label[:, 3] > by0) & (label[:, 1] < by1)
    assert not inside.any() and n_board > 0


def test_orientation_follows_the_board():
    wide = shipped("charuco_a5")
    tall = TargetSpec(kind="chessboard", name="tall", rows=11, cols=8, square_m=0.02)
    assert layout(wide, parse_paper("A4")).width_mm == 297  # landscape first for a wide board
    assert layout(tall, parse_paper("A4")).width_mm == 210
    s = layout(wide, parse_paper("210x290"))  # the given orientation fits: kept
    assert (s.width_mm, s.height_mm) == (210, 290)
    s = layout(tall, parse_paper("300x200"))  # 240 mm high does not fit 200: turned
    assert (s.width_mm, s.height_mm) == (200, 300)


def test_default_sheet_is_just_big_enough():
    spec = shipped("charuco_a5")
    s = layout(spec)
    bw, bh = (1000 * v for v in spec.outline_m())
    assert s.board_mm[1] == EDGE_MM and s.width_mm <= max(bw, 130) + 2 * EDGE_MM
    assert bh < s.height_mm <= bh + 50


@pytest.mark.parametrize("text, size", [("A4", (210, 297)), ("a3", (297, 420)), ("Letter", (215.9, 279.4)),
                                        ("300x200", (300, 200)), (" 300 X 200.5 mm", (300, 200.5))])
def test_paper_sizes(text, size):
    p = parse_paper(text)
    assert (p.width_mm, p.height_mm) == size


@pytest.mark.parametrize("bad", ["A9", "0x100", "300x", "x200", "abc", "-30x40", "3e2x200", "20000x100", ""])
def test_bad_paper_is_named(bad):
    with pytest.raises(ConfigError) as ei:
        parse_paper(bad)
    assert repr(bad) in str(ei.value) and "300x200" in str(ei.value)


def test_board_that_does_not_fit_names_both_sizes(tmp_path):
    with pytest.raises(ConfigError) as ei:
        export_printable(shipped("charuco_h4"), tmp_path / "b.pdf", paper="A5", source="charuco_h4.yaml")
    msg = str(ei.value)
    for s in ("charuco_h4.yaml", "241.0 x 166.0 mm", "A5", "148 x 210 mm", "does not fit", "A4"):
        assert s in msg, s
    with pytest.raises(ConfigError, match="250 x 140 mm"):
        export_printable(shipped("charuco_a5"), tmp_path / "b.svg", paper="250x140")
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_bad_export_arguments(tmp_path):
    with pytest.raises(ConfigError, match="suffix"):
        export_printable(SPEC, tmp_path / "board.jpg")
    with pytest.raises(ConfigError, match="dpi"):
        export_printable(SPEC, tmp_path / "board.png", dpi=0)
    for name in ("board.pdf", "board.svg"):  # a vector drawing has no resolution
        with pytest.raises(ConfigError, match="dpi .* applies to .png only"):
            export_printable(SPEC, tmp_path / name, dpi=300)
    assert list(tmp_path.iterdir()) == []


def test_written_atomically_over_an_old_file(tmp_path):
    out = tmp_path / "b.pdf"
    out.write_bytes(b"old")
    export_printable(SPEC, out, paper="A4")
    assert out.read_bytes().startswith(b"%PDF") and [p.name for p in tmp_path.iterdir()] == ["b.pdf"]


# ------------------------------------------------------------------------------------------ command line
def test_cli_paper_and_formats(tmp_path, capsys):
    pdf, svg = tmp_path / "a5.pdf", tmp_path / "a5.svg"
    assert main(["target", str(ROOT / "targets/charuco_a5.yaml"), "--paper", "A4", "--out", str(pdf)]) == 0
    assert "100 mm scale bar" in capsys.readouterr().out
    (w_pt, h_pt), stream = pdf_page(pdf.read_bytes())
    assert sorted((w_pt, h_pt)) == pytest.approx(A4_PT, abs=0.01)
    assert "charuco_a5.yaml" in " ".join(pdf_shapes(stream)[1])
    assert main(["target", str(ROOT / "targets/charuco_a5.yaml"), "--paper", "300x200", "--out", str(svg)]) == 0
    assert 'width="300mm" height="200mm"' in svg.read_text(encoding="utf-8")


@pytest.mark.parametrize("args, needle", [(["--paper", "A9", "--out", "x.pdf"], "'A9'"),
                                          (["--out", "x.pdf", "--dpi", "300"], "dpi"),
                                          (["--out", "x.svg", "--dpi", "300"], "dpi"),
                                          (["--paper", "A6", "--out", "x.pdf"], "does not fit")])
def test_cli_refusals_are_named(tmp_path, capsys, args, needle):
    args = [a if not a.startswith("x.") else str(tmp_path / a) for a in args]
    assert main(["target", str(ROOT / "targets/charuco_a5.yaml")] + args) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err
    assert not any(p.suffix in (".pdf", ".svg") for p in tmp_path.iterdir())


# ------------------------------------------------------------------------------------------ pieces
def test_dots_are_circles_other_polygons_stay_polygons(tmp_path):
    """A kind's dot (a regular area-preserving polygon) is written as the circle of its area; any other polygon
    (a plugin kind's shape) as a polygon path, read back with its area."""
    from vision_calib.targets.kinds.circles import dot_ring
    from vision_calib.targets.sheet import Sheet, as_circle
    from vision_calib.targets.vector import sheet_pdf, sheet_svg

    assert as_circle(dot_ring(0.005) + [0.1, 0.2]) == pytest.approx((0.1, 0.2, 0.005), abs=1e-12)
    assert as_circle(np.array([[0, 0], [1, 0], [1, 1], [0, 1]])) is None
    tri = np.array([[20.0, 20.0], [80.0, 30.0], [40.0, 70.0]])  # area 1400 mm^2
    sheet = Sheet(100.0, 100.0, np.zeros((0, 4)), np.zeros((0, 3)), (tri,), (), (20, 20, 80, 70), "t")
    for img, *_ in (read_pdf_raster(sheet_pdf(sheet), 4.0), read_svg_raster(sheet_svg(sheet), 4.0)):
        assert (255 - img.astype(float)).sum() / 255 / 16 == pytest.approx(1400, rel=1e-3)


def test_long_words_are_cut_to_the_line():
    from vision_calib.targets.sheet import wrap

    lines = wrap("a " + "x" * 400 + " b", 50.0, 2.5)
    assert "".join(lines).replace(" ", "") == "a" + "x" * 400 + "b"
    assert all(text_width_mm(ln, 2.5) <= 50.0 for ln in lines)
