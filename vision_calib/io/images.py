"""Image files in recorded folders and importers: the accepted formats and the up-front size checks.

Pixels are decoded by :func:`vision_calib.measure.load_gray` (PNG, JPEG, BMP, TIFF; 8 or 16 bit; grey or
colour). Here only the file *headers* are read (:mod:`vision_calib.measure.image_header`: a few bytes per file)
so that, before anything is decoded or computed, an image is refused when

- its width x height exceeds the pixel limit (``config.max_image_pixels``: 50 Mpx, or
  ``VISION_CALIB_MAX_IMAGE_MPX``): a hostile or damaged file must not cost gigabytes;
- its size differs from the camera intrinsics' (:func:`check_image_sizes`), or, in a folder without intrinsics,
  from the size most of the folder's images have (:func:`folder_sizes`: the majority wins, the odd ones are named).
"""

from __future__ import annotations

from pathlib import Path

from ..errors import DataError
from ..measure.image_header import header_size, majority_size, pixel_refusal

#: image file suffixes accepted everywhere images are read (lower case)
IMAGE_EXT = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def is_image(path) -> bool:
    return Path(path).suffix.lower() in IMAGE_EXT


def image_size(path) -> tuple[int, int] | None:
    """(width, height) [px] from the file header, or None when the header cannot be read (a corrupt or
    truncated file: the measurement stage then rejects that image with its reason). Never decodes."""
    return header_size(path)


def check_pixels(path, size=None) -> tuple[int, int] | None:
    """The header size of ``path`` (or ``size`` when given); DataError naming the file when it exceeds the pixel
    limit. None when the header cannot be read."""
    size = header_size(path) if size is None else size
    if size is not None:
        why = pixel_refusal(path, size)
        if why:
            raise DataError(why)
    return size


def check_image_sizes(paths, camera, where: str) -> None:
    """DataError naming the first image of ``paths`` whose header declares more pixels than the limit, or a size
    other than ``camera``'s (CameraIntrinsics: width, height) -- wrong intrinsics or a wrong camera; ``where``
    names the file that declares the intrinsics. Unreadable headers are left to the measurement stage."""
    want = (int(camera.width), int(camera.height))
    for p in paths:
        size = check_pixels(p)
        if size is not None and size != want:
            raise DataError(f"{p}: image size {size[0]}x{size[1]} does not match the camera intrinsics "
                            f"{want[0]}x{want[1]} ({where}); wrong camera file, or images resized?")


def folder_sizes(paths, what: str = "images") -> tuple[tuple[int, int] | None, dict, list[str]]:
    """Header sizes of a folder's images without intrinsics: (the majority (width, height) -- the size most files
    have, a tie to the first seen --, {path: size} of every readable header, [reason] naming each file of another
    size). DataError naming the file for one beyond the pixel limit. ``what``: the word for the files in the
    reasons ("images", "frames")."""
    sizes = {}
    for p in paths:
        s = check_pixels(p)
        if s is not None:
            sizes[p] = s
    size, count = majority_size(list(sizes.values()))
    odd = [f"{p}: image size {s[0]}x{s[1]} differs from the majority {size[0]}x{size[1]} ({count} of {len(sizes)} "
           f"{what})" for p, s in sizes.items() if s != size]
    return size, sizes, odd


def check_principal_point(k: dict, size, where: str) -> None:
    """Intrinsics given without a size (ROS-I ``intrinsics``: fx, fy, cx, cy) against the images' (width, height):
    ConfigError naming ``where`` unless the principal point lies in the middle half of the image each way (a
    real camera's is within a few percent of the centre; intrinsics of another resolution put it far off)."""
    from ..errors import ConfigError

    w, h = size
    if not (abs(k["cx"] - w / 2) <= w / 4 and abs(k["cy"] - h / 2) <= h / 4):
        raise ConfigError(f"{where}: principal point ({k['cx']:g}, {k['cy']:g}) px lies outside the middle of the "
                          f"{w}x{h} px images (expected within {w / 4:g}, {h / 4:g} px of their centre "
                          f"({w / 2:g}, {h / 2:g})): intrinsics of another camera or resolution?")


__all__ = ["IMAGE_EXT", "is_image", "image_size", "check_pixels", "check_image_sizes", "folder_sizes",
           "check_principal_point"]
