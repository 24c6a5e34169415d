"""Image files are sized from their headers before anything is decoded (measure/image_header.py, io/images.py;
issue 28): a small file declaring a huge image is refused by name, never decoded; the limit can be raised through
the environment; in a folder without intrinsics the majority size wins and the odd files are named and skipped.
Every test uses small files that DECLARE sizes: nothing here allocates more than a few MB."""

from __future__ import annotations

import importlib
import struct
import zlib

import cv2
import numpy as np
import pytest

from vision_calib.config import MAX_IMAGE_ENV, max_image_pixels
from vision_calib.errors import ConfigError, DataError
from vision_calib.io.images import check_image_sizes, folder_sizes, image_size
from vision_calib.measure.image_header import header_size, majority_size, pixel_refusal

D = importlib.import_module("vision_calib.measure.detect")  # the module (vision_calib.measure.detect is also a function)


def _chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_declaring(w, h) -> bytes:
    """A 69-byte grey PNG whose header says w x h px."""
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
            + _chunk(b"IDAT", zlib.compress(b"\x00" * 16)) + _chunk(b"IEND", b""))


def tiff_declaring(w, h, big=False, order="<") -> bytes:
    """A TIFF (classic or BigTIFF) whose first IFD holds ImageWidth w and ImageLength h (LONG), nothing else."""
    e = order
    mark = b"II" if e == "<" else b"MM"
    if not big:
        head = mark + struct.pack(e + "HI", 42, 8)
        ifd = struct.pack(e + "H", 2) + struct.pack(e + "HHII", 256, 4, 1, w) + struct.pack(e + "HHII", 257, 4, 1, h)
        return head + ifd + b"\0\0\0\0"
    head = mark + struct.pack(e + "HHHQ", 43, 8, 0, 16)
    ifd = struct.pack(e + "Q", 2) + struct.pack(e + "HHQQ", 256, 16, 1, w) + struct.pack(e + "HHQQ", 257, 16, 1, h)
    return head + ifd + b"\0" * 8


def jpeg_declaring(w, h) -> bytes:
    """SOI, an APP0 segment, then a SOF0 declaring w x h (no scan data)."""
    app0 = b"\xff\xe0" + struct.pack(">H", 16) + b"JFIF\x00\x01\x01\x00\x00\x01\x00\x01\x00\x00"
    sof = b"\xff\xc0" + struct.pack(">HBHHB", 11, 8, h, w, 1) + b"\x01\x11\x00"
    return b"\xff\xd8" + app0 + sof + b"\xff\xd9"


@pytest.mark.parametrize("ext", [".png", ".jpg", ".bmp", ".tif"])
@pytest.mark.parametrize("shape", [(48, 64), (31, 17), (48, 64, 3)])
def test_header_size_of_real_files(tmp_path, ext, shape):
    """The header readers agree with the decoder on files OpenCV writes (grey and colour)."""
    f = tmp_path / f"a{ext}"
    assert cv2.imwrite(str(f), np.random.default_rng(0).integers(0, 255, shape, dtype=np.uint8))
    assert header_size(f) == (shape[1], shape[0]) == image_size(f)


@pytest.mark.parametrize("data,size", [
    (png_declaring(30000, 30000), (30000, 30000)),
    (tiff_declaring(40000, 20000), (40000, 20000)),
    (tiff_declaring(40000, 20000, order=">"), (40000, 20000)),
    (tiff_declaring(70000, 9, big=True), (70000, 9)),
    (jpeg_declaring(65000, 65000), (65000, 65000)),
])
def test_header_size_of_files_declaring_huge_images(tmp_path, data, size):
    f = tmp_path / "bomb.img"
    f.write_bytes(data)
    assert len(data) < 200 and header_size(f) == size


@pytest.mark.parametrize("data", [b"", b"\x89PNG\r\n\x1a\n garbage", b"\xff\xd8\xff", b"II*\x00\xff\xff\xff\x7f",
                                  b"not an image at all"])
def test_header_size_of_unreadable_files_is_none(tmp_path, data):
    f = tmp_path / "x.png"
    f.write_bytes(data)
    assert header_size(f) is None
    img, why = D.load_gray(f)
    assert img is None and "unreadable or corrupt image file" in why


def test_load_gray_refuses_a_declared_bomb_without_decoding(tmp_path, monkeypatch):
    f = tmp_path / "bomb.png"
    f.write_bytes(png_declaring(30000, 30000))

    def never(*a, **k):
        raise AssertionError("decoded")
    monkeypatch.setattr(D.np, "fromfile", never)
    monkeypatch.setattr(D.cv2, "imdecode", never)
    img, why = D.load_gray(f)
    assert img is None
    assert why.startswith(f"{f}: image 30000x30000 px (900 Mpx) exceeds the limit of 50 Mpx") and MAX_IMAGE_ENV in why


def test_load_checked_compares_the_header_with_the_intrinsics_before_decoding(tmp_path, monkeypatch):
    from vision_calib.camera import CameraIntrinsics

    f = tmp_path / "small.png"
    cv2.imwrite(str(f), np.zeros((48, 64), np.uint8))
    monkeypatch.setattr(D, "load_gray", lambda *a, **k: (_ for _ in ()).throw(AssertionError("decoded")))
    cam = CameraIntrinsics(1024, 768, 1000.0, 1000.0, 512.0, 384.0)
    img, size, _, bad = D.load_checked(str(f), cam, 3)
    assert img is None and size == (64, 48) and not bad.valid and bad.frame_index == 3
    assert "image size 64x48 does not match the camera intrinsics 1024x768" in bad.reason


def test_the_limit_is_raised_and_checked_through_the_environment(tmp_path, monkeypatch):
    assert max_image_pixels() == 50_000_000
    assert pixel_refusal("f.png", (8000, 8000)) is not None  # 64 Mpx
    monkeypatch.setenv(MAX_IMAGE_ENV, "100")
    assert max_image_pixels() == 100_000_000 and pixel_refusal("f.png", (8000, 8000)) is None
    for bad in ("-1", "0", "many", "nan"):
        monkeypatch.setenv(MAX_IMAGE_ENV, bad)
        with pytest.raises(ConfigError, match=f"{MAX_IMAGE_ENV}={bad!r}: expected a number of megapixels > 0"):
            max_image_pixels()


def test_check_image_sizes_names_the_bomb_before_the_intrinsics(tmp_path):
    from vision_calib.camera import CameraIntrinsics

    good, bomb = tmp_path / "a.png", tmp_path / "b.png"
    cv2.imwrite(str(good), np.zeros((48, 64), np.uint8))
    bomb.write_bytes(png_declaring(30000, 30000))
    cam = CameraIntrinsics(64, 48, 60.0, 60.0, 32.0, 24.0)
    check_image_sizes([good], cam, "cam")
    with pytest.raises(DataError, match=r"b.png: image 30000x30000 px \(900 Mpx\) exceeds the limit of 50 Mpx"):
        check_image_sizes([good, bomb], cam, "cam")


def test_folder_sizes_the_majority_wins_and_the_odd_are_named(tmp_path):
    paths = []
    for k, shape in enumerate([(48, 64), (30, 40), (30, 40), (30, 40), (48, 64)]):
        paths.append(tmp_path / f"{k}.png")
        cv2.imwrite(str(paths[-1]), np.zeros(shape, np.uint8))
    (tmp_path / "corrupt.png").write_bytes(b"garbage")
    size, sizes, odd = folder_sizes(paths + [tmp_path / "corrupt.png"], "frames")
    assert size == (40, 30) and len(sizes) == 5
    assert odd == [f"{paths[i]}: image size 64x48 differs from the majority 40x30 (3 of 5 frames)" for i in (0, 4)]
    assert majority_size([(1, 1), (2, 2)]) == ((1, 1), 1)  # a tie: the first seen
    assert majority_size([None]) == (None, 0)


def test_calibrate_from_images_skips_the_odd_and_the_huge_without_decoding_them(tmp_path, monkeypatch):
    """The first file has an odd size, another declares 900 Mpx: both are rejected views with their reason, named
    in the warnings, and never reach the detector; the calibration gets the majority size."""
    from vision_calib.measure import intrinsics as I

    paths = [tmp_path / "a_odd.png"] + [tmp_path / f"v{k}.png" for k in range(4)] + [tmp_path / "z_bomb.png"]
    cv2.imwrite(str(paths[0]), np.zeros((30, 40), np.uint8))
    for p in paths[1:5]:
        cv2.imwrite(str(p), np.zeros((48, 64), np.uint8))
    paths[5].write_bytes(png_declaring(30000, 30000))
    seen, got = [], {}
    monkeypatch.setattr(D, "detect", lambda p, *a, **k: seen.append(p) or D.Detection(
        False, "no target", np.zeros(0, int), np.zeros((0, 2)), (64, 48)))

    def fake_calibrate(dets, names, target, size, config):
        got.update(dets=dets, size=size)
        return I.IntrinsicsResult(None, {}, 0.0, (), {}, ("coverage",))
    monkeypatch.setattr(I, "calibrate_intrinsics", fake_calibrate)
    from vision_calib.targets.spec import TargetSpec

    board = TargetSpec(kind="charuco", name="board", rows=5, cols=7, dictionary="DICT_5X5_100", square_m=0.025,
                       marker_m=0.018)
    res = I.calibrate_from_images(paths, target=board)
    assert seen == [str(p) for p in paths[1:5]]
    assert got["size"] == (64, 48)
    assert got["dets"][0].reason == "image size 40x30 differs from the majority 64x48 (4 of 5 images)"
    assert got["dets"][5].reason.startswith("image 30000x30000 px (900 Mpx) exceeds the limit of 50 Mpx")
    assert res.warnings[0].startswith(f"2 images of 6 skipped, not decoded: {paths[0]}: image size 40x30")
    assert f"{paths[5]}: image 30000x30000 px" in res.warnings[0] and res.warnings[1] == "coverage"


def test_find_images_refuses_a_symlink_out_of_the_folder(tmp_path):
    from vision_calib.measure.intrinsics import find_images

    d, out = tmp_path / "imgs", tmp_path / "outside"
    d.mkdir()
    out.mkdir()
    cv2.imwrite(str(d / "a.png"), np.zeros((8, 8), np.uint8))
    cv2.imwrite(str(out / "secret.png"), np.zeros((8, 8), np.uint8))
    (d / "b.png").symlink_to(out / "secret.png")
    (d / "c.png").symlink_to(d / "a.png")  # inside: fine
    with pytest.raises(DataError, match=r"b.png: a symbolic link leading out of the folder .*imgs \(to .*secret.png\)"):
        find_images(d)
    assert len(find_images(d, allow_symlinks=True)) == 3
    (d / "b.png").unlink()
    (d / "b.png").symlink_to("/etc/passwd")
    with pytest.raises(DataError, match=r"b.png: a symbolic link leading out"):
        find_images(d)
