"""Regenerate the image and array assets used by the example textures.

Run from anywhere::

    python textures/assets/make_assets.py

It writes, next to this script:

- ``logo.png``  260 x 120 8-bit greyscale: the letters "TPaD" in a blocky 5x7
  font, white on black, inside a thin white frame (used by ``bitmap_logo.yaml``,
  which maps it to 130 x 60 mm, i.e. 2 px/mm).
- ``noise.npy`` 64 x 128 float32 array in [0, 1]: seeded white noise smoothed
  with a periodic Gaussian filter, so it tiles without seams
  (``bitmap_noise.yaml``, 32 x 16 mm per tile, 0.25 mm per sample).
- ``hills.pgm`` 260 x 120 16-bit binary PGM (maxval 65535): a sum of four
  Gaussian hills, normalised so the highest point is 65535
  (``gradient_image.yaml``, 130 x 60 mm).

Everything is drawn with numpy only (no fonts, no antialiasing that depends on
the Pillow version), and the only randomness is a seeded ``numpy.random.Generator``,
so the output is the same on every run. Pillow is used only to write the PNG.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

HERE = Path(__file__).resolve().parent

# --------------------------------------------------------------------------
# logo.png
# --------------------------------------------------------------------------

LOGO_W, LOGO_H = 260, 120  # pixels; 2 px/mm on the 130 x 60 mm plate

# 5 x 7 glyphs, '#' = ink.
GLYPHS = {
    "T": [
        "#####",
        "..#..",
        "..#..",
        "..#..",
        "..#..",
        "..#..",
        "..#..",
    ],
    "P": [
        "####.",
        "#...#",
        "#...#",
        "####.",
        "#....",
        "#....",
        "#....",
    ],
    "a": [
        ".....",
        ".....",
        ".###.",
        "....#",
        ".####",
        "#...#",
        ".####",
    ],
    "D": [
        "####.",
        "#...#",
        "#...#",
        "#...#",
        "#...#",
        "#...#",
        "####.",
    ],
}


def make_logo() -> np.ndarray:
    """White "TPaD" (strokes 8 px = 4 mm wide) and frame on black, uint8."""
    img = np.zeros((LOGO_H, LOGO_W), dtype=np.uint8)
    cell = 8  # px per glyph dot: 4 mm, wide enough to feel as a bar
    gap = 16  # px between letters
    text = "TPaD"
    text_w = len(text) * 5 * cell + (len(text) - 1) * gap
    x0 = (LOGO_W - text_w) // 2
    y0 = (LOGO_H - 7 * cell) // 2
    for k, ch in enumerate(text):
        gx = x0 + k * (5 * cell + gap)
        for r, row in enumerate(GLYPHS[ch]):
            for c, v in enumerate(row):
                if v == "#":
                    img[y0 + r * cell : y0 + (r + 1) * cell, gx + c * cell : gx + (c + 1) * cell] = 255
    # A 4 px (2 mm) frame, 10 px (5 mm) in from the image edge.
    m, t = 10, 4
    img[m : m + t, m : LOGO_W - m] = 255
    img[LOGO_H - m - t : LOGO_H - m, m : LOGO_W - m] = 255
    img[m : LOGO_H - m, m : m + t] = 255
    img[m : LOGO_H - m, LOGO_W - m - t : LOGO_W - m] = 255
    return img


# --------------------------------------------------------------------------
# noise.npy
# --------------------------------------------------------------------------

NOISE_SHAPE = (64, 128)  # rows (y), cols (x): 16 x 32 mm at 0.25 mm/sample
NOISE_SEED = 20240521
NOISE_SIGMA_SAMPLES = 2.0  # 0.5 mm smoothing: grains about 1-2 mm across


def make_noise() -> np.ndarray:
    """Seeded, periodically smoothed noise rescaled to exactly [0, 1], float32."""
    rng = np.random.default_rng(NOISE_SEED)
    white = rng.standard_normal(NOISE_SHAPE)
    ky = np.fft.fftfreq(NOISE_SHAPE[0])[:, None]
    kx = np.fft.fftfreq(NOISE_SHAPE[1])[None, :]
    # Gaussian filter in the frequency domain = circular convolution: seamless tiling.
    kernel = np.exp(-2.0 * (np.pi * NOISE_SIGMA_SAMPLES) ** 2 * (kx**2 + ky**2))
    smooth = np.real(np.fft.ifft2(np.fft.fft2(white) * kernel))
    smooth -= smooth.min()
    smooth /= smooth.max()
    return np.clip(smooth, 0.0, 1.0).astype(np.float32)


# --------------------------------------------------------------------------
# hills.pgm
# --------------------------------------------------------------------------

HILLS_W, HILLS_H = 260, 120  # 2 px/mm on 130 x 60 mm
# (x_mm, y_mm, sigma_mm, relative height)
HILLS = [
    (25.0, 20.0, 7.0, 1.0),
    (60.0, 40.0, 10.0, 0.8),
    (95.0, 18.0, 6.0, 0.6),
    (112.0, 44.0, 8.0, 0.9),
]


def make_hills() -> np.ndarray:
    """Sum of Gaussian hills, uint16 with the peak at 65535."""
    px_per_mm = HILLS_W / 130.0
    # Pixel centres in mm.
    x = (np.arange(HILLS_W) + 0.5) / px_per_mm
    y = (np.arange(HILLS_H) + 0.5) / px_per_mm
    xx, yy = np.meshgrid(x, y)
    h = np.zeros_like(xx)
    for cx, cy, s, a in HILLS:
        h += a * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2.0 * s * s))
    h /= h.max()
    return np.round(h * 65535.0).astype(np.uint16)


def write_pgm16(path: Path, img: np.ndarray) -> None:
    """Binary (P5) PGM, maxval 65535, big-endian samples as the format requires."""
    rows, cols = img.shape
    header = f"P5\n{cols} {rows}\n65535\n".encode("ascii")
    path.write_bytes(header + img.astype(">u2").tobytes())


def main() -> None:
    Image.fromarray(make_logo()).save(HERE / "logo.png", optimize=True)
    np.save(HERE / "noise.npy", make_noise(), allow_pickle=False)
    write_pgm16(HERE / "hills.pgm", make_hills())
    for name in ("logo.png", "noise.npy", "hills.pgm"):
        print(f"{name}: {(HERE / name).stat().st_size} bytes")


if __name__ == "__main__":
    main()
