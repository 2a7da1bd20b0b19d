"""Shipped textures and devices by name (tpad_rt.shipped): what a bare name, a path and a missing path resolve to."""

from __future__ import annotations

from pathlib import Path

import pytest

from tpad_rt import shipped
from tpad_rt.errors import ConfigError


@pytest.fixture
def elsewhere(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working folder outside the repository (relative paths resolve against it), for this test only."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_names_list_every_shipped_file() -> None:
    assert "grating" in shipped.texture_names() and "default" in shipped.device_names()
    assert len(shipped.texture_names()) == len(list(shipped.TEXTURES_DIR.glob("*.yaml")))
    assert shipped.DEFAULT_DEVICE.is_file()


def test_a_bare_name_is_the_shipped_file(elsewhere: Path) -> None:
    assert shipped.texture_file("grating") == shipped.TEXTURES_DIR / "grating.yaml"
    assert shipped.device_file("SLG_0.4") == shipped.DEVICES_DIR / "SLG_0.4.yaml"
    assert shipped.any_file("SLG_0.4") == shipped.DEVICES_DIR / "SLG_0.4.yaml"
    assert shipped.any_file("grating") == shipped.TEXTURES_DIR / "grating.yaml"


def test_a_file_of_that_name_wins_over_the_shipped_one(elsewhere: Path) -> None:
    (elsewhere / "grating").write_text("kind: grating\n")
    assert shipped.texture_file("grating") == "grating"
    assert shipped.any_file("grating") == "grating"


def test_a_path_is_taken_as_given_even_when_missing(elsewhere: Path) -> None:
    assert shipped.texture_file("foo/bar.yaml") == "foo/bar.yaml"
    assert shipped.any_file("foo/bar.yaml") == "foo/bar.yaml"


@pytest.mark.parametrize(("resolve", "ref", "message"), [
    (shipped.texture_file, "textures/grating.yaml",
     "textures/grating.yaml: no such file; the package ships a texture of that name: give just 'grating'"),
    (shipped.any_file, "devices/SLG_0.4.yaml",
     "devices/SLG_0.4.yaml: no such file; the package ships a device of that name: give just 'SLG_0.4'"),
    (shipped.texture_file, "gratin",
     "gratin: no such file, nor a shipped texture of that name; did you mean 'grating'? (shipped: "),
    (shipped.texture_file, "nosuch", "nosuch: no such file, nor a shipped texture of that name (shipped: "),
    (shipped.device_file, "SLG_9", "SLG_9: no such file, nor a shipped device of that name; did you mean "),
    (shipped.any_file, "nosuch", "nosuch: no such file, nor a shipped texture or device of that name (textures: "),
    (shipped.any_file, "bumps_gird",
     "bumps_gird: no such file, nor a shipped texture or device of that name; did you mean 'bumps_grid'? "),
])
def test_what_names_nothing_says_what_exists(elsewhere: Path, resolve, ref: str, message: str) -> None:
    with pytest.raises(ConfigError) as raised:
        resolve(ref)
    assert str(raised.value).startswith(message)


def test_a_name_close_to_a_file_in_its_folder_says_which(elsewhere: Path) -> None:
    """The working folder's YAML files are candidates for a bare name; a missing path's folder's for the path."""
    (elsewhere / "my_texture.yaml").write_text("kind: grating\n")
    (elsewhere / "mine").mkdir()
    (elsewhere / "mine" / "stripes.yaml").write_text("kind: grating\n")
    for ref, meant in (("my_texture", "my_texture.yaml"), ("my_textur.yaml", "my_texture.yaml"),
                       ("mine/stripe.yaml", "mine/stripes.yaml")):
        with pytest.raises(ConfigError) as raised:
            shipped.texture_file(ref)
        assert f"did you mean '{meant}'?" in str(raised.value)
    assert shipped.texture_file("mine/other.yaml") == "mine/other.yaml"  # nothing close: the reader says it is missing


@pytest.mark.parametrize("ref", ["a" * 5000, "a" * 5000 + ".yaml", "a\0b", "x/" + "y" * 300])
def test_a_name_the_system_refuses_is_answered_not_raised(elsewhere: Path, ref: str) -> None:
    """Too long for the file system, or holding a NUL byte: pathlib's exists() raises for these, and a
    refused name must still end in one ConfigError line (or pass through to the reader's own message)."""
    for resolve in (shipped.texture_file, shipped.device_file, shipped.any_file):
        try:
            resolved = resolve(ref)
        except ConfigError as error:
            assert "no such file" in str(error)
        else:
            assert resolved == ref  # a path: reading it says what is wrong


def test_play_misspelt_says_did_you_mean_in_one_line(elsewhere: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from tpad_rt.cli import main

    assert main(["play", "gratin", "--output", "null://", "--duration", "0.1"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("tpad-rt play: gratin: no such file, nor a shipped texture of that name; did you mean "
                          "'grating'? (shipped: ") and err.count("\n") == 1, err


def test_play_help_names_the_shipped_textures_and_every_output(capsys: pytest.CaptureFixture[str]) -> None:
    from tpad_rt.cli import main

    with pytest.raises(SystemExit):
        main(["play", "--help"])
    text = " ".join(capsys.readouterr().out.split())  # as one line: argparse wraps it
    assert all(name in text for name in shipped.texture_names())
    for url in ("audio://", "serial://PORT", "sim://", "wav://", "null://", "scripted://swipe", "mouse://"):
        assert url in text
