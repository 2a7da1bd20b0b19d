"""The compile notice: printed at once when numba's cache holds nothing for a kernel about to run
(announce_if_uncached), and not at all when everything is cached."""

from __future__ import annotations

import io
from pathlib import Path
from types import SimpleNamespace

import pytest
from rich.console import Console

from tpad_rt.compiling import NOTICE, announce_if_uncached, compile_notice
from tpad_rt.kernel.render import render_block


def _kernel_with_index(path: Path) -> SimpleNamespace:
    """An object shaped as numba's dispatcher is where announce_if_uncached looks: its cache's index file."""
    return SimpleNamespace(_cache=SimpleNamespace(_cache_file=SimpleNamespace(_index_path=str(path))))


def _printed(*kernels: object) -> str:
    out = io.StringIO()
    with compile_notice(Console(file=out, force_terminal=False, width=200)):
        announce_if_uncached(*kernels)
    return out.getvalue()


def test_a_kernel_without_a_cache_index_is_announced_at_once(tmp_path: Path) -> None:
    cached = tmp_path / "cached.nbi"
    cached.write_bytes(b"")
    assert _printed(_kernel_with_index(cached)) == ""
    printed = _printed(_kernel_with_index(cached), _kernel_with_index(tmp_path / "missing.nbi"))
    assert printed.splitlines()[0] == NOTICE
    assert printed.splitlines()[1].startswith("tpad-rt: compiled 0 functions in ")


def test_a_real_kernel_is_found_and_nothing_is_said_outside_a_notice(capsys: pytest.CaptureFixture[str]) -> None:
    """The private path announce_if_uncached reads exists on numba's dispatchers (a numba upgrade that moves it
    fails here, not silently)."""
    assert Path(render_block._cache._cache_file._index_path).name.startswith("render.render_block-")
    announce_if_uncached(_kernel_with_index(Path("/nonexistent.nbi")))  # no compile_notice active: nothing
    assert capsys.readouterr() == ("", "")


def test_an_object_numba_does_not_shape_so_counts_as_cached() -> None:
    assert _printed(object()) == ""
