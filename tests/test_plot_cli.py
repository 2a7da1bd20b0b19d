"""tpad-rt plot: a recording becomes a decodable image; bad inputs are one-line errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tpad_rt.cli import main

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short render of the grating on the simulated plate."""
    out = tmp_path_factory.mktemp("plot") / "g.npz"
    grating = str(REPO / "textures" / "grating.yaml")
    assert main(["render", grating, "--input", "scripted://swipe?to_mm=40", "--out", str(out)]) == 0
    return out


@pytest.mark.parametrize("extra", [[], ["--along", "x"], ["--start", "0.05", "--end", "0.1"]])
def test_writes_a_png(recording: Path, tmp_path: Path, extra: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "g.png"
    assert main(["plot", str(recording), "--out", str(out), *extra]) == 0
    assert capsys.readouterr().out.endswith(f"wrote {out}\n")
    with Image.open(out) as image:
        assert image.format == "PNG" and image.size == (1650, 1425)
        pixels = np.asarray(image.convert("RGB"))
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 100  # lines, shading and text, not a blank canvas


def test_other_formats(recording: Path, tmp_path: Path) -> None:
    assert main(["plot", str(recording), "--out", str(tmp_path / "g.svg")]) == 0
    assert (tmp_path / "g.svg").read_text().lstrip().startswith("<?xml")


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--out", "g.jpg"], "tpad-rt plot: --out: must end in .png, .pdf, .svg, got 'g.jpg'"),
        (["--out", "g.png", "--start", "5"], "tpad-rt plot: --start/--end: no block between 5 s and inf s"),
    ],
)
def test_argument_errors(recording: Path, args: list[str], expected: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plot", str(recording), *args]) == 1
    assert capsys.readouterr().err.startswith(expected)


def test_not_a_recording(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "x.npz").write_text("not an archive")
    assert main(["plot", str(tmp_path / "x.npz"), "--out", str(tmp_path / "x.png")]) == 1
    assert capsys.readouterr().err == f"tpad-rt plot: {tmp_path}/x.npz: not a tpad-rt recording (not an .npz archive)\n"
    assert not (tmp_path / "x.png").exists()


def test_an_amplifier_emulators_recording_gets_a_pointer_to_the_doc_that_checks_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The emulator's recording (written by its own writer) is not a render's: one line says what it is, what plot
    draws instead, and where docs/amplifiers.md checks it; no image is written."""
    from tpad_rt.amp.emulator import RECORDED_COLUMNS, Recorder, write_recording

    recorder = Recorder()
    recorder.add(**{name: np.arange(4).astype(dtype) for name, dtype in RECORDED_COLUMNS.items()})
    write_recording(str(tmp_path / "e.npz"), recorder, {"envelope_hz": 16000, "frames_ok": 4})
    assert main(["plot", str(tmp_path / "e.npz"), "--out", str(tmp_path / "e.png")]) == 1
    assert capsys.readouterr().err == (
        f"tpad-rt plot: {tmp_path}/e.npz: an amplifier emulator's recording (tpad-rt amp emulate --record): plot draws "
        "the recordings of render and of play --record (play --output serial://PORT --record FILE.npz records the "
        "same run on the host's side); docs/amplifiers.md, 'Checking a recording', shows how to check this one\n")
    assert not (tmp_path / "e.png").exists()


def test_along_x_on_a_path_whose_x_turns_back_plots_along_the_path_and_says_so(
        recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A circle's x goes forth and back: plotted against x it folds onto itself, so plot takes the distance along
    the path (one turn of radius 10 mm: about 62.8 mm) and says so; a swipe's x only rises and stays the axis."""
    from tpad_rt.cli.plot import plot_recording
    from tpad_rt.recording import read_recording

    circle = tmp_path / "c.npz"
    grating = str(REPO / "textures" / "grating.yaml")
    assert main(["render", grating, "--input", "scripted://circle?radius_mm=10&turns=1", "--out", str(circle)]) == 0
    assert main(["plot", str(circle), "--along", "x", "--out", str(tmp_path / "c.png")]) == 0
    assert capsys.readouterr().out.endswith(
        "(x turns back, which would fold the path onto itself: plotted along the finger's path instead)\n")
    figure, note = plot_recording(read_recording(circle), along="x")
    assert note is not None and figure.axes[3].get_xlabel().startswith("distance along the finger's path (mm)")
    assert np.nanmax(figure.axes[0].lines[0].get_xdata()) == pytest.approx(2 * np.pi * 10, rel=0.03)
    figure, note = plot_recording(read_recording(recording), along="x")
    assert note is None and figure.axes[3].get_xlabel() == "finger x (mm)"


def test_along_x_where_the_finger_never_touches_is_refused_in_one_line(
        recording: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Past 0.3 s the swipe has lifted: no block of that span has an x to plot along (an empty figure, x from
    -0.05 to 0.05 mm, was written); along time the same span plots, shaded as lifted."""
    args = ["plot", str(recording), "--along", "x", "--start", "0.301", "--out", str(recording.with_suffix(".png"))]
    assert main(args) == 1
    assert capsys.readouterr().err == ("tpad-rt plot: --along x: the finger touches in no block of that span: there "
                                       "is no x to plot along (plot along time, the default)\n")
    assert main(args[:2] + args[4:]) == 0


def test_departures_are_a_strip_at_the_friction_panels_foot_not_marks_over_the_curve(recording: Path) -> None:
    """Blocks marked departed (here every fourth touching one of a real render) are shaded in the bottom
    DEPARTED_STRIP of the friction panel, below its lowest curve; no marker is drawn on the curves."""
    from dataclasses import replace

    from matplotlib.colors import to_hex

    from tpad_rt.cli.plot import _DEPARTED, DEPARTED_STRIP, plot_recording
    from tpad_rt.recording import read_recording

    real = read_recording(recording)
    departed = np.zeros(len(real.blocks["t"]))
    departed[::4] = 1
    figure, _ = plot_recording(replace(real, blocks={**real.blocks, "departed": departed}))
    friction = figure.axes[0]
    strips = [c for c in friction.collections if to_hex(c.get_facecolor()[0][:3]) == _DEPARTED]
    assert len(strips) == 1
    top = max(path.vertices[:, 1].max() for path in strips[0].get_paths())
    assert top == pytest.approx(DEPARTED_STRIP)  # axes fraction: the foot of the panel
    low = friction.get_ylim()[0] + DEPARTED_STRIP * np.diff(friction.get_ylim())[0]
    assert np.nanmin(friction.lines[1].get_ydata()) > low  # the achieved curve stays above the strip
    assert all(line.get_marker() in ("None", None, "") for line in friction.lines)
    assert any("departed > " in text.get_text() for text in friction.get_legend().get_texts())
