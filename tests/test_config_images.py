"""Image files of bitmap and height-map textures: formats, modes, limits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tpad_rt.config.images import ImageError, read_image


def test_8_bit_png(tmp_path: Path) -> None:
    Image.fromarray(np.array([[0, 51], [255, 102]], np.uint8)).save(tmp_path / "a.png")
    np.testing.assert_allclose(read_image(tmp_path / "a.png"), [[0, 0.2], [1, 0.4]])


def test_16_bit_png(tmp_path: Path) -> None:
    Image.fromarray(np.array([[0, 65535, 13107]], np.uint16)).save(tmp_path / "a.png")
    np.testing.assert_allclose(read_image(tmp_path / "a.png"), [[0, 1, 0.2]])


@pytest.mark.parametrize(("dtype", "full"), [(np.uint8, 255), (np.uint16, 65535)])
def test_pgm(tmp_path: Path, dtype: type, full: int) -> None:
    Image.fromarray(np.array([[0, full]], dtype)).save(tmp_path / "a.pgm")
    np.testing.assert_allclose(read_image(tmp_path / "a.pgm"), [[0, 1]])


def test_rgb_is_converted_to_luminance(tmp_path: Path) -> None:
    Image.fromarray(np.array([[[255, 255, 255], [0, 0, 0], [255, 0, 0]]], np.uint8)).save(tmp_path / "a.png")
    pixels = read_image(tmp_path / "a.png")
    assert pixels.shape == (1, 3)
    np.testing.assert_allclose(pixels[0, :2], [1, 0])
    assert 0.25 < pixels[0, 2] < 0.35  # ITU-R 601-2 luma of pure red


def test_row_zero_is_the_top(tmp_path: Path) -> None:
    Image.fromarray(np.array([[255], [0]], np.uint8)).save(tmp_path / "a.png")
    assert read_image(tmp_path / "a.png")[0, 0] == 1.0


def test_npy_of_bools_and_ints(tmp_path: Path) -> None:
    np.save(tmp_path / "b.npy", np.array([[True, False]]))
    np.save(tmp_path / "i.npy", np.array([[0, 1]], np.int8))
    np.testing.assert_array_equal(read_image(tmp_path / "b.npy"), [[1.0, 0.0]])
    np.testing.assert_array_equal(read_image(tmp_path / "i.npy"), [[0.0, 1.0]])


def test_pixels_are_read_only(tmp_path: Path) -> None:
    np.save(tmp_path / "a.npy", np.zeros((2, 2)))
    assert not read_image(tmp_path / "a.npy").flags.writeable


def test_extension_is_case_insensitive(tmp_path: Path) -> None:
    np.save(tmp_path / "a.npy", np.zeros((1, 1)))
    (tmp_path / "a.npy").rename(tmp_path / "A.NPY")
    assert read_image(tmp_path / "A.NPY").shape == (1, 1)


def _error(path: Path) -> str:
    with pytest.raises(ImageError) as caught:
        read_image(path)
    return str(caught.value)


def test_complex_npy(tmp_path: Path) -> None:
    np.save(tmp_path / "c.npy", np.zeros((2, 2), complex))
    assert _error(tmp_path / "c.npy") == f"{tmp_path / 'c.npy'} must hold real numbers, got dtype complex128"


def test_empty_npy(tmp_path: Path) -> None:
    np.save(tmp_path / "e.npy", np.zeros((0, 3)))
    assert _error(tmp_path / "e.npy") == "image is 3 x 0 pixels; sides must be 1 to 4096"


def test_npz_is_not_npy(tmp_path: Path) -> None:
    np.savez(tmp_path / "z.npz", a=np.zeros(2))
    (tmp_path / "z.npz").rename(tmp_path / "z.npy")
    assert _error(tmp_path / "z.npy").startswith(f"cannot read {tmp_path / 'z.npy'} as a NumPy .npy array: ")


def test_png_that_is_not_a_png(tmp_path: Path) -> None:
    (tmp_path / "fake.png").write_bytes(b"GIF89a not really")
    assert _error(tmp_path / "fake.png").startswith(f"cannot read {tmp_path / 'fake.png'} as a PNG or PGM image: ")


def test_other_picture_formats_are_not_decoded(tmp_path: Path) -> None:
    Image.new("L", (2, 2)).save(tmp_path / "a.gif")
    (tmp_path / "a.gif").rename(tmp_path / "a.png")
    assert "as a PNG or PGM image" in _error(tmp_path / "a.png")


@pytest.mark.parametrize(("layers", "refused"), [(2, False), (3, True)])
def test_a_texture_holds_at_most_one_4096_x_4096_image_worth_of_pixels(
    tmp_path: Path, layers: int, refused: bool
) -> None:
    """Every image reference is loaded once rendered, so their pixels count together (the same file too)."""
    from tpad_rt.config import check_file

    np.save(tmp_path / "half.npy", np.zeros((4096, 2048)))  # half the budget
    entries = "".join(
        "  - kind: bitmap\n    image: half.npy\n    size_mm: [130.0, 60.0]\n    friction: {low: 0.5, high: 1.0}\n"
        for _ in range(layers))
    (tmp_path / "t.yaml").write_text(f"kind: layers\ndescription: images\nlayers:\n{entries}")
    errors = check_file(tmp_path / "t.yaml")
    expected = ("layers[2].image: the texture's images hold 25,165,824 pixels with this one, more than the "
                "16,777,216 a texture may hold in all")
    assert [error for error in errors if expected in error] == ([errors[0]] if refused else []), errors
    assert len(errors) == (1 if refused else 0), errors
