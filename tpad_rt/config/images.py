"""Reading the pixel files of ``bitmap`` and image height maps.

A picture (``.png``, ``.pgm``) is read with Pillow: 8-bit greyscale is divided
by 255, 16-bit greyscale by 65535, and any other mode (RGB, palette, with
alpha) is first converted to 8-bit luminance (alpha is ignored). A ``.npy``
file must hold one 2-D array of real numbers in [0, 1]; it is read with
``allow_pickle=False``. Either way the size in the header is checked (sides 1 to
MAX_IMAGE_SIDE pixels) before any pixel is decoded: pictures are opened by the
PNG and PGM plugins' header readers, not ``Image.open``, so Pillow's own
decompression-bomb warning or error never reaches the user. Only regular files
are read (:func:`tpad_rt.files.open_regular`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

import numpy as np

from tpad_rt.errors import ConfigError
from tpad_rt.files import open_regular

if TYPE_CHECKING:  # Pillow loads with the first picture read, not with every texture file
    from PIL import ImageFile

IMAGE_SUFFIXES = (".png", ".pgm", ".npy")
MAX_IMAGE_SIDE = 4096

_SIXTEEN_BIT_MODES = ("I;16", "I;16B", "I;16L", "I")


class ImageError(Exception):
    """An image file is missing, unreadable, too large or holds unusable values."""


def read_image(path: Path) -> np.ndarray:
    """The image at ``path`` as a read-only float64 array in [0, 1], row 0 at the top.

    Raises ImageError for another extension, a missing, unreadable or non-regular
    file, a side of 0 or more than 4096 pixels, or (``.npy``) an array that is not
    2-D, not real-valued, not finite or outside [0, 1].
    """
    if path.suffix.lower() not in IMAGE_SUFFIXES:
        raise ImageError(f"must be a .png, .pgm or .npy file, got '{path.name}'")
    if not path.exists():
        raise ImageError(f"no such file: {path}")
    try:
        stream = open_regular(path, "images")
    except ConfigError as err:
        raise ImageError(str(err)) from None
    with stream:
        pixels = _read_array(path, stream) if path.suffix.lower() == ".npy" else _read_picture(path, stream)
    pixels.flags.writeable = False
    return pixels


def _open_picture(stream: BinaryIO) -> ImageFile.ImageFile:
    """The picture in ``stream``, its header read and nothing decoded; SyntaxError if no plugin knows it."""
    from PIL import PngImagePlugin, PpmImagePlugin

    # The decoders tried, in turn (Pillow reads PGM with its PPM plugin); each reads only the header when opening.
    for plugin in (PngImagePlugin.PngImageFile, PpmImagePlugin.PpmImageFile):
        stream.seek(0)
        try:
            return plugin(stream)
        except SyntaxError:
            continue
    raise SyntaxError("not a PNG or PGM file")


def _read_picture(path: Path, stream: BinaryIO) -> np.ndarray:
    try:
        with _open_picture(stream) as picture:
            _check_size(picture.height, picture.width)
            if picture.mode in _SIXTEEN_BIT_MODES:
                return np.asarray(picture, dtype=np.float64) / 65535.0
            return np.asarray(picture.convert("L"), dtype=np.float64) / 255.0
    except (OSError, ValueError, SyntaxError, EOFError) as err:
        raise ImageError(f"cannot read {path} as a PNG or PGM image: {err}") from None


def _read_array(path: Path, stream: BinaryIO) -> np.ndarray:
    try:
        major, _ = np.lib.format.read_magic(stream)
        read_header = np.lib.format.read_array_header_1_0 if major == 1 else np.lib.format.read_array_header_2_0
        shape, _, dtype = read_header(stream)
    except (OSError, ValueError, EOFError) as err:
        raise ImageError(f"cannot read {path} as a NumPy .npy array: {err}") from None
    if dtype.hasobject:
        raise ImageError(f"{path} holds Python objects; only plain numeric arrays are loaded (never pickles)")
    if len(shape) != 2:
        raise ImageError(f"{path} must hold a 2-D array, got shape {shape}")
    if dtype.kind not in "biuf":
        raise ImageError(f"{path} must hold real numbers, got dtype {dtype}")
    _check_size(*shape)
    try:
        stream.seek(0)
        values = np.load(stream, allow_pickle=False).astype(np.float64)
    except (OSError, ValueError, EOFError) as err:
        raise ImageError(f"cannot read {path} as a NumPy .npy array: {err}") from None
    if not np.isfinite(values).all():
        raise ImageError(f"{path} holds NaN or infinite values")
    low, high = float(values.min()), float(values.max())
    if low < 0 or high > 1:
        raise ImageError(f"{path} must hold values in [0, 1], got {low:g} to {high:g}")
    return values


def _check_size(height: int, width: int) -> None:
    """Raises ImageError unless both sides are 1 to MAX_IMAGE_SIDE pixels."""
    if not (1 <= width <= MAX_IMAGE_SIDE and 1 <= height <= MAX_IMAGE_SIDE):
        raise ImageError(f"image is {width} x {height} pixels; sides must be 1 to {MAX_IMAGE_SIDE}")
