"""FIFOs, devices, directories and sockets, given where tpad-rt reads or writes a file: one line, exit 1.

Each case runs the real CLI (tests/cli_run.py). A FIFO with no writer would block a
plain ``open`` forever; the subprocess timeout is only a safety net (a hang shows as
return code -9, not a pass).
"""

from __future__ import annotations

import os
import socket
import zlib
from collections.abc import Iterator
from pathlib import Path

import pytest
from PIL import Image

from cli_run import REPO, tpad_rt, warm_numba_cache

GRATING = str(REPO / "textures" / "grating.yaml")
SWIPE = "scripted://swipe?speed_mm_s=100"
_KIND = {"fifo": "a FIFO", "dir": "a directory", "socket": "a socket", "chardev": "a character device"}


@pytest.fixture(autouse=True, scope="module")
def _warm() -> None:
    """Compile the kernels into numba's cache first (cli_run.warm_numba_cache)."""
    warm_numba_cache()


@pytest.fixture
def special(tmp_path: Path) -> Iterator[dict[str, Path]]:
    """One file of each non-regular kind, named with a texture's suffix: ``{kind: path}``."""
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    directory = tmp_path / "dir.yaml"
    directory.mkdir()
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(tmp_path / "socket.yaml"))
    try:
        yield {"fifo": fifo, "dir": directory, "socket": tmp_path / "socket.yaml", "chardev": Path("/dev/null")}
    finally:
        sock.close()


def _refused(path: Path, kind: str, what: str) -> str:
    return f"{path}: not a regular file ({_KIND[kind]}); tpad-rt reads {what} from regular files only"


@pytest.mark.parametrize("kind", list(_KIND))
def test_check_refuses_a_non_regular_texture(special: dict[str, Path], kind: str) -> None:
    done = tpad_rt("check", str(special[kind]))
    done.assert_one_line_error(_refused(special[kind], kind, "texture and device files"))


@pytest.mark.parametrize("kind", ["fifo", "dir", "chardev"])
def test_render_refuses_a_non_regular_texture_or_device(special: dict[str, Path], kind: str, tmp_path: Path) -> None:
    out = str(tmp_path / "x.npz")
    done = tpad_rt("render", str(special[kind]), "--input", SWIPE, "--out", out)
    done.assert_one_line_error(_refused(special[kind], kind, "texture and device files"))
    done = tpad_rt("render", GRATING, "--device", str(special[kind]), "--input", SWIPE, "--out", out)
    done.assert_one_line_error(_refused(special[kind], kind, "texture and device files"))


@pytest.mark.parametrize("kind", ["fifo", "socket"])
def test_show_refuses_a_non_regular_texture_or_device(special: dict[str, Path], kind: str, tmp_path: Path) -> None:
    out = str(tmp_path / "x.png")
    done = tpad_rt("show", str(special[kind]), "--out", out)
    done.assert_one_line_error(_refused(special[kind], kind, "texture and device files"))
    done = tpad_rt("show", GRATING, "--device", str(special[kind]), "--out", out)
    done.assert_one_line_error(_refused(special[kind], kind, "texture and device files"))


def test_play_refuses_a_fifo_texture(special: dict[str, Path]) -> None:
    done = tpad_rt("play", str(special["fifo"]), "--output", "null://", "--input", SWIPE, "--duration", "1")
    done.assert_one_line_error(_refused(special["fifo"], "fifo", "texture and device files"))


def test_render_refuses_a_fifo_trajectory(tmp_path: Path) -> None:
    fifo = tmp_path / "traj.csv"
    os.mkfifo(fifo)
    done = tpad_rt("render", GRATING, "--input", f"file://{fifo}", "--out", str(tmp_path / "x.npz"))
    done.assert_one_line_error(_refused(fifo, "fifo", "trajectories"))


def test_a_fifo_image_in_a_texture_is_refused(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "map.png")
    texture = tmp_path / "bitmap.yaml"
    texture.write_text("description: d\nkind: bitmap\nimage: map.png\nsize_mm: [10, 10]\n"
                       "friction: {low: 0.5, high: 1}\n")
    done = tpad_rt("check", str(texture))
    done.assert_one_line_error(f"image: {_refused(tmp_path / 'map.png', 'fifo', 'images')}")


@pytest.mark.parametrize("kind", ["fifo", "dir", "chardev"])
def test_plot_refuses_a_non_regular_recording(special: dict[str, Path], kind: str, tmp_path: Path) -> None:
    done = tpad_rt("plot", str(special[kind]), "--out", str(tmp_path / "x.png"))
    done.assert_one_line_error(_refused(special[kind], kind, "recordings"))


def _exists(path: Path, kind: str) -> str:
    return f"{path}: exists and is not a regular file ({_KIND[kind]}); tpad-rt writes"


def test_outputs_that_are_not_regular_files_are_refused(tmp_path: Path) -> None:
    fifo_npz, dir_png, dir_wav = tmp_path / "f.npz", tmp_path / "d.png", tmp_path / "d.wav"
    os.mkfifo(fifo_npz)
    dir_png.mkdir()
    dir_wav.mkdir()
    render = ["render", GRATING, "--input", SWIPE]
    tpad_rt(*render, "--out", str(fifo_npz)).assert_one_line_error(_exists(fifo_npz, "fifo"))
    tpad_rt(*render, "--out", str(dir_wav)).assert_one_line_error(_exists(dir_wav, "dir"))
    done = tpad_rt(*render, "--output", "wav:///dev/null", "--out", str(tmp_path / "x.npz"))
    done.assert_one_line_error(_exists(Path("/dev/null"), "chardev") + " WAV files")
    tpad_rt("show", GRATING, "--out", str(dir_png)).assert_one_line_error(_exists(dir_png, "dir"))
    done = tpad_rt("play", GRATING, "--output", "null://", "--record", str(fifo_npz))
    done.assert_one_line_error(_exists(fifo_npz, "fifo") + " recordings")


@pytest.mark.parametrize(("size", "shown"), [((5000, 10), "5000 x 10"), ((100_000, 100_000), "100000 x 100000")])
def test_oversized_images_name_the_limit_without_pillow_warnings(tmp_path: Path, size: tuple[int, int],
                                                                  shown: str) -> None:
    image = tmp_path / "big.png"
    if size[0] * size[1] < 10**6:
        Image.new("L", size).save(image)
    else:  # a decompression bomb: a header claiming 10^10 pixels over a few bytes
        Image.new("L", (1, 1)).save(image)
        data = bytearray(image.read_bytes())
        data[16:24] = size[0].to_bytes(4, "big") + size[1].to_bytes(4, "big")  # IHDR width, height
        data[29:33] = zlib.crc32(data[12:29]).to_bytes(4, "big")  # the IHDR chunk's CRC
        image.write_bytes(bytes(data))
    texture = tmp_path / "bitmap.yaml"
    texture.write_text("description: d\nkind: bitmap\nimage: big.png\nsize_mm: [10, 10]\n"
                       "friction: {low: 0.5, high: 1}\n")
    done = tpad_rt("check", str(texture))
    done.assert_one_line_error(f"{texture}: image: image is {shown} pixels; sides must be 1 to 4096 (line 3)")
    assert "DecompressionBomb" not in done.stderr


def test_a_nul_byte_in_a_wav_url_is_refused(tmp_path: Path) -> None:
    done = tpad_rt("render", GRATING, "--input", SWIPE, "--output", f"wav://{tmp_path}/a%00.wav",
                   "--out", str(tmp_path / "x.npz"))
    done.assert_one_line_error("holds the control character \\x00 (after unquoting)")


def test_writing_to_a_new_wav_path_still_works(tmp_path: Path) -> None:
    out = tmp_path / "new.wav"
    done = tpad_rt("render", GRATING, "--input", "scripted://still?duration_s=0.01", "--out", str(out))
    assert done.returncode == 0, done.stderr
    assert out.stat().st_size > 58
