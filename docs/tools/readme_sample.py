"""Regenerate the README's sample ``tpad-rt play`` output from a real run, or check that it has a real run's shape.

    python docs/tools/readme_sample.py           # run COMMAND, write its output between the README's markers
    python docs/tools/readme_sample.py --check   # run it, exit 1 (with both shapes) unless the README's block fits

The run is the README's: ``tpad-rt play textures/grating.yaml --duration 1`` from the
repository, on a machine with no display and no audio device at 192 kHz (the environment
leaves out ``DISPLAY`` and points JACK at a server nobody runs, so the output is ``sim://``),
with a warm numba cache (the README shows a second run: a run that compiled is run again).
A run on an audio device is refused: the README shows one on ``sim://``.

A block fits a run when their :func:`shape` is the same: every line, with the numbers a run
measures masked (times, counts, latencies, volts, power) and the settings kept (rates,
block size, the power cap and budget, the volt limit, the departure judge's tolerance,
everything in the first line). Segments only some runs print are left out of the shape
(:data:`OPTIONAL`: departures in a touch's start ramp, the shaper's kicks at the drive's limit
(a touch-down's, in most runs), a stalled output, a host-reported DAC delay). The first clause
of the first line's input reason reads the same whether pynput is missing or the display is
(the README's text says both); the rest of the reason (the finger the swipe takes, and why)
is kept.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
README = REPO / "README.md"
#: The README's command, after ``tpad-rt``.
COMMAND = ("play", "textures/grating.yaml", "--duration", "1")
BEGIN = "<!-- readme_sample: begin (docs/tools/readme_sample.py writes this block from a real run) -->"
END = "<!-- readme_sample: end -->"
#: No display, and a JACK server nobody runs (never auto-started): sim:// and the scripted swipe.
ENVIRONMENT = {**{name: value for name, value in os.environ.items() if name != "DISPLAY"},
               "JACK_DEFAULT_SERVER": "tpadrt-absent", "JACK_NO_START_SERVER": "1"}
#: Numbers that are settings, not measurements: kept in the shape.
SETTINGS = re.compile(r"\d+ Hz|of \d+ frames|cap [\d.]+ W|budget [\d.]+ W|of [\d.]+ V max|further than [\d.]+")
#: Segments some runs print and others do not (how the host's timing fell): not part of the shape.
OPTIONAL = (re.compile(r"; [\d,]+ of them in a touch's start ramp \(the drive fading in\)"),
            re.compile(r", in the shaper's kicks \([\d,]+ blocks? at the limit to move the plate as fast as it "
                       r"allows\), [\d.]+ V outside them"),
            re.compile(r"; the output stalled for [\d.]+ s"),
            re.compile(r" \(of which the host reports [^)]*\)"))
#: The first clause of the first line's input reason without pynput (what to install; it holds no ';'), which
#: the README's text names beside "no display".
NO_PYNPUT = re.compile(r"\(no pynput for the mouse: [^;]*;")


def run_sample() -> list[str]:
    """The lines COMMAND prints on a warm cache (run twice when the first compiled). Raises RuntimeError when it
    fails or plays on another output than sim://."""
    for _ in range(2):
        done = subprocess.run([sys.executable, "-m", "tpad_rt", *COMMAND], capture_output=True, text=True,
                              cwd=REPO, env=ENVIRONMENT, timeout=600)
        if done.returncode != 0:
            raise RuntimeError(f"tpad-rt {' '.join(COMMAND)} failed: {done.stderr.strip()}")
        if "compiling" not in done.stderr:
            break
    lines = done.stdout.splitlines()
    if not lines or not lines[0].startswith("output sim:// "):
        raise RuntimeError(f"the README shows a run on sim://, this one began: {lines[:1]}")
    return lines


def readme_block(text: str) -> list[str]:
    """The lines of the fenced block between BEGIN and END in ``text``. Raises ValueError without the markers."""
    start, end = text.find(BEGIN), text.find(END)
    if start < 0 or end < start:
        raise ValueError(f"README.md: no block between '{BEGIN}' and '{END}'")
    fenced = text[start + len(BEGIN):end].strip().splitlines()
    return fenced[1:-1]  # inside the ``` fence


def with_block(text: str, lines: list[str]) -> str:
    """``text`` with the block between BEGIN and END made of ``lines`` (fenced)."""
    start, end = text.index(BEGIN) + len(BEGIN), text.index(END)
    return text[:start] + "\n```\n" + "\n".join(lines) + "\n```\n" + text[end:]


def shape(lines: list[str]) -> list[str]:
    """``lines`` with the measured numbers masked as ``#`` and the optional segments left out (module docstring);
    the first line whole but for the input's reason."""
    shaped = []
    for number, line in enumerate(lines):
        for segment in OPTIONAL:
            line = segment.sub("", line)
        if number == 0:
            shaped.append(NO_PYNPUT.sub("(no display;", line))
            continue
        pieces, kept = SETTINGS.split(line), SETTINGS.findall(line)
        masked = [re.sub(r"(?<![\w.])\d+(?:[.,]\d+)*", "#", piece) for piece in pieces]  # not p50's
        shaped.append("".join(part for pair in zip(masked, [*kept, ""]) for part in pair))
    return shaped


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="check the README's block instead of writing it")
    args = parser.parse_args(argv)
    text = README.read_text()
    try:
        current = readme_block(text)
        lines = run_sample()
    except (RuntimeError, ValueError) as error:
        print(f"readme_sample: {error}", file=sys.stderr)
        return 1
    if args.check:
        if shape(current) == shape(lines):
            return 0
        print("readme_sample: README.md's sample output is not the shape of a run; "
              "run python docs/tools/readme_sample.py", file=sys.stderr)
        for name, block in (("README", current), ("run", lines)):
            print(f"--- {name}\n" + "\n".join(shape(block)), file=sys.stderr)
        return 1
    README.write_text(with_block(text, lines))
    print(f"wrote {len(lines)} lines of tpad-rt {' '.join(COMMAND)} into {README.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
