"""Printable export: the physical size stored in the file matches the board's outline."""

import re

import cv2
import numpy as np
import pytest

from vision_calib.errors import ConfigError
from vision_calib.targets import TargetSpec, export_printable, read_png_phys

SPEC = TargetSpec(kind="charuco", name="t", rows=5, cols=7, dictionary="DICT_5X5_100", square_m=0.025, marker_m=0.018)


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


def test_pdf_page_is_true_size(tmp_path):
    out = export_printable(SPEC, tmp_path / "board.pdf", dpi=200)
    data = out.read_bytes()
    assert data.startswith(b"%PDF-")
    box = [float(v) for v in re.search(rb"/MediaBox \[([^\]]+)\]", data).group(1).split()]
    w_m, h_m = (box[2] - box[0]) / 72 * 0.0254, (box[3] - box[1]) / 72 * 0.0254
    assert (w_m, h_m) == pytest.approx(SPEC.outline_m(), abs=1e-6)
    # xref offsets point at the objects
    xref = int(re.search(rb"startxref\n(\d+)", data).group(1))
    assert data[xref:xref + 4] == b"xref"
    offs = [int(m) for m in re.findall(rb"(\d{10}) 00000 n", data)]
    for i, o in enumerate(offs, start=1):
        assert data[o:].startswith(f"{i} 0 obj".encode())


def test_bad_export_arguments(tmp_path):
    with pytest.raises(ConfigError, match="suffix"):
        export_printable(SPEC, tmp_path / "board.jpg")
    with pytest.raises(ConfigError, match="dpi"):
        export_printable(SPEC, tmp_path / "board.png", dpi=0)
