"""Image files in recorded folders and importers: the accepted formats and an up-front size check.

Pixels are decoded by :func:`vision_calib.measure.load_gray` (PNG, JPEG, BMP, TIFF; 8 or 16 bit; grey or
colour). Here only the file *headers* are read (Pillow, lazily: about 0.1 ms per file) so that an image
whose size differs from the camera intrinsics is refused before anything is computed.
"""

from __future__ import annotations

import warnings
from pathlib import Path

from ..errors import DataError

#: image file suffixes accepted everywhere images are read (lower case)
IMAGE_EXT = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def is_image(path) -> bool:
    return Path(path).suffix.lower() in IMAGE_EXT


def image_size(path) -> tuple[int, int] | None:
    """(width, height) [px] from the file header, or None when the header cannot be read (a corrupt or
    truncated file: the measurement stage then rejects that image with its reason)."""
    from PIL import Image, UnidentifiedImageError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(path) as im:
                return int(im.size[0]), int(im.size[1])
    except (OSError, UnidentifiedImageError, ValueError, SyntaxError):
        return None


def check_image_sizes(paths, camera, where: str) -> None:
    """DataError naming the first image of ``paths`` whose header size differs from ``camera``
    (CameraIntrinsics: width, height) -- wrong intrinsics or a wrong camera; ``where`` names the file
    that declares the intrinsics. Unreadable headers are left to the measurement stage."""
    want = (int(camera.width), int(camera.height))
    for p in paths:
        size = image_size(p)
        if size is not None and size != want:
            raise DataError(f"{p}: image size {size[0]}x{size[1]} does not match the camera intrinsics "
                            f"{want[0]}x{want[1]} ({where}); wrong camera file, or images resized?")


__all__ = ["IMAGE_EXT", "is_image", "image_size", "check_image_sizes"]
