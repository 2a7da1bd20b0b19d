"""The bad-file corpus: every file fails with exactly the breadcrumbs in its header."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tpad_rt.config import check_file, load_any
from tpad_rt.config.yaml_io import MAX_FILE_BYTES, MAX_LIST_ITEMS, load_yaml
from tpad_rt.errors import ConfigError

BAD_FILES = Path(__file__).parent / "bad_files"
_EXPECT = "# expect: "


def expected_lines(path: Path) -> list[str]:
    """The ``# expect:`` lines of ``path``, prefixed with the path as the loader shows it."""
    folder = str(path.parent)
    lines = path.read_text().splitlines()
    expected = [line.removeprefix(_EXPECT).replace("{dir}", folder) for line in lines if line.startswith(_EXPECT)]
    return [f"{path}: {line}" for line in expected]


@pytest.mark.parametrize("path", sorted(BAD_FILES.glob("*.yaml")), ids=lambda path: path.stem)
def test_bad_file_reports_exactly_its_expected_lines(path: Path) -> None:
    expected = expected_lines(path)
    assert expected, f"{path.name} has no '# expect:' header"
    with pytest.raises(ConfigError) as caught:
        load_any(path)
    assert caught.value.errors == expected
    assert check_file(path) == expected


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_list_too_long(tmp_path: Path) -> None:
    items = ", ".join(["0.5"] * (MAX_LIST_ITEMS + 1))
    path = _write(tmp_path / "long.yaml", f"description: long\nkind: grating\n\nperiod_mm: [{items}]\n")
    assert check_file(path) == [f"{path}: list longer than 100,000 items (line 4)"]


def test_list_at_the_limit_is_read(tmp_path: Path) -> None:
    items = ", ".join(["0.5"] * MAX_LIST_ITEMS)
    path = _write(tmp_path / "long.yaml", f"force_n: [{items}]\n")
    assert len(load_yaml(path, "long.yaml").data["force_n"]) == MAX_LIST_ITEMS


def test_file_too_large(tmp_path: Path) -> None:
    path = _write(tmp_path / "big.yaml", "description: big\n" + "#" * MAX_FILE_BYTES)
    assert check_file(path) == [f"{path}: file is larger than 4 MiB"]


@pytest.mark.parametrize("size", [(4097, 1), (1, 4097)])
def test_image_too_big(tmp_path: Path, size: tuple[int, int]) -> None:
    Image.new("L", size).save(tmp_path / "huge.png")
    path = _write(
        tmp_path / "huge.yaml",
        "description: huge\nkind: bitmap\nimage: huge.png\nsize_mm: [10, 10]\nfriction: {low: 0.5, high: 1}\n",
    )
    width, height = size
    message = f"image is {width} x {height} pixels; sides must be 1 to 4096"
    assert check_file(path) == [f"{path}: image: {message} (line 3)"]


def test_huge_npy_is_refused_from_its_header(tmp_path: Path) -> None:
    np.lib.format.open_memmap(tmp_path / "huge.npy", mode="w+", dtype=np.float32, shape=(5000, 2)).flush()
    path = _write(
        tmp_path / "huge.yaml",
        "description: huge\nkind: bitmap\nimage: huge.npy\nsize_mm: [10, 10]\nfriction: {low: 0.5, high: 1}\n",
    )
    assert check_file(path) == [f"{path}: image: image is 2 x 5000 pixels; sides must be 1 to 4096 (line 3)"]


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "absent.yaml"
    assert check_file(path) == [f"{path}: cannot read: no such file or directory"]


def test_directory(tmp_path: Path) -> None:
    assert check_file(tmp_path) == [
        f"{tmp_path}: not a regular file (a directory); tpad-rt reads texture and device files from regular files only"
    ]


def test_empty_file(tmp_path: Path) -> None:
    path = _write(tmp_path / "empty.yaml", "# only a comment\n")
    assert check_file(path) == [f"{path}: top level must be a mapping of keys to values, got an empty file"]
