"""A command-line fuzzer (issue 8, "Safety", point 7): random bad files, flags and URLs at every subcommand.

Each example runs the real CLI in a fresh interpreter (tests/cli_run.py) and asserts the
error contract of ``tpad_rt.cli``:

- exit status 0 (the mutation left a valid file or value: then stderr is empty) or 1;
- never a traceback, never a Python warning;
- on 1, one message: a single line starting ``tpad-rt COMMAND: `` (``check`` prints the
  bare breadcrumb). A bad file with several problems gives one breadcrumb line per
  problem (README "Errors", the format ``check`` documents); every further line is then
  a breadcrumb of the same file, never a stray line.

Inputs: the shipped textures and devices mutated (byte flips, truncation, numbers replaced
by 1e308, 5e-324, -0.0, .nan, .inf and huge integers, deep nesting, long strings, binary
junk, empty files, non-UTF-8, alias bombs, images swapped for special files), special
paths (directories, FIFOs, /dev/null, /dev/zero, missing files, symlink loops, unreadable
files when not root), random input and output URLs (unknown schemes, bad options, absurd
values, percent escapes, over-long), random flag values, and mutated recordings for plot.

Play never runs long: it always gets ``--input`` (never ``auto``), an ``--output`` of
``null://``, ``sim://`` or a broken URL (never ``auto`` or ``audio://``; ``serial://`` only to
what is not an amplifier) and ``--duration 0.2`` unless the duration itself is fuzzed from
values that are all refused. ``amp emulate`` always ends: ``--duration 0.2`` unless that is
fuzzed from refused values. Renders get
``--duration 0.05`` unless it is fuzzed, show ``--resolution-mm 2``.

Every command that writes a file the user names (render, play --record, wav://, show,
schema, calibrate build, convert and --plot) is also run against an attacker's folder
(issue 20): a victim file elsewhere, links to it planted at the target and at the names
a temporary file could take, the target a FIFO, a directory or a dangling link. The
victim must stay as it was and no temporary file may stay behind.

The examples are derandomized (the same on every run, so CI is reproducible); a failure
prints the falsifying example. Each test counts its outcomes and asserts that most
examples were errors, so the fuzzer is known to reach the error paths.
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import shlex
import shutil
import stat
import string
import subprocess
import tempfile
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st

from cli_run import REPO, Run, tpad_rt, warm_numba_cache
from tpad_rt.errors import printable

TEXTURES = sorted((REPO / "textures").glob("*.yaml")) + sorted((REPO / "tests" / "good_files").glob("*.yaml"))
DEVICES = sorted((REPO / "tpad_rt" / "devices").glob("*.yaml"))
GRATING = str(REPO / "textures" / "grating.yaml")
IS_ROOT = os.geteuid() == 0

# Hypothesis: each example is a subprocess (1-3 s), so few examples and no deadline; derandomized for CI.
# About 100 examples in all: under 3 minutes on 2 cores.
FUZZ = settings(max_examples=14, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
FUZZ_SLOW = settings(FUZZ, max_examples=10)  # play (0.2 s of audio each) and show (a figure each)
FUZZ_FEW = settings(FUZZ, max_examples=8)  # schema, design, devices: little to find

WEIRD_NUMBERS = ["1.0e+308", "5.0e-324", "-0.0", ".nan", ".inf", "-.inf", "1e308", "0", "-1", "1.0e-300",
                 "99999999999999999999999999", "'abc'", "null", "[]", "{}", "true", "0x7fffffff", "1_000", "NaN"]
FLAG_VALUES = ["nan", "inf", "-inf", "-1", "0", "-0", "1e308", "5e-324", "abc", "", "1e9", "99999999999999999999",
               " 5", "0x10", "1_000", "1e-300"]
PERCENT = ["%00", "%0a", "%ff", "%", "%zz", "%2e%2e%2f", "%25", "%0d%0a", "%7f"]


@pytest.fixture(autouse=True, scope="module")
def _warm() -> None:
    """Kernels in numba's cache first, so no example pays a cold compile."""
    warm_numba_cache()


# --- the error contract ------------------------------------------------------------------------------------

def check_contract(done: Run, command: str, files: list[str]) -> int:
    """Assert the contract (module docstring) for a run of ``command`` given ``files``; the exit status."""
    err = done.stderr
    assert done.returncode in (0, 1), (done.returncode, err[-2000:])
    assert "Traceback" not in err and "Warning" not in err, err[-3000:]
    if done.returncode == 0:
        assert err == "", err
        return 0
    lines = err.splitlines()
    assert lines and err.endswith("\n"), repr(err)
    if command != "check":  # argparse names the whole program for arguments no subcommand knows
        assert lines[0].startswith((f"tpad-rt {command}: ", "tpad-rt: error: ")), lines[0]
    if len(lines) > 1:  # several problems of one bad file: a breadcrumb each
        shown = [printable(name) for name in files]
        breadcrumbs = lines if command == "check" else lines[1:]
        for line in breadcrumbs:
            assert any(line.startswith(f"{name}: ") for name in shown), (line, shown, err[-2000:])
    return 1


def run_cli(argv: list[str], command: str, files: list[str], timeout_s: float = 300.0) -> int:
    """Run ``tpad-rt ARGV`` and check the contract; the command line and the files' first bytes are noted,
    so a falsifying example prints how to reproduce it."""
    note("tpad-rt " + " ".join(shlex.quote(word) for word in argv))
    for name in files:
        try:
            data = Path(name).read_bytes() if name and Path(name).is_file() else None
        except OSError:  # too long a name, a loop, unreadable
            data = None
        if data is not None:
            note(f"{name} ({len(data):,} bytes) begins {data[:300]!r}")
    return check_contract(tpad_rt(*argv, timeout_s=timeout_s), command, files)


class Outcomes:
    """Counts exit statuses over a test's examples; most must be errors."""

    def __init__(self) -> None:
        self.counts: Counter[int] = Counter()

    def add(self, status: int) -> None:
        self.counts[status] += 1

    def assert_mostly_errors(self) -> None:
        total = sum(self.counts.values())
        print(f"fuzz outcomes: {self.counts[1]} errors, {self.counts[0]} valid of {total}")
        assert total >= 8, self.counts
        assert self.counts[1] > total / 2, self.counts


@contextmanager
def workdir() -> Iterator[Path]:
    """A fresh folder per example, with the images the shipped textures name (assets/, checker.png, ramp.npy)."""
    folder = Path(tempfile.mkdtemp(prefix="tpad-fuzz-"))
    try:
        (folder / "assets").symlink_to(REPO / "textures" / "assets")
        for name in ("checker.png", "ramp.npy"):
            (folder / name).symlink_to(REPO / "tests" / "good_files" / name)
        yield folder
    finally:
        if (folder / "u.yaml").exists():
            (folder / "u.yaml").chmod(0o600)
        shutil.rmtree(folder, ignore_errors=True)


# --- strategies: files -------------------------------------------------------------------------------------

Mutation = Callable[[bytes], bytes]


def _mutation() -> st.SearchStrategy[Mutation]:
    """One random edit of a YAML file's bytes."""
    number = r"(?<![\w.])-?\d+(\.\d+)?(e[-+]?\d+)?(?![\w.])"

    def replace_number(k: int, value: str) -> Mutation:
        def edit(data: bytes) -> bytes:
            import re

            text = data.decode("utf-8", "replace")
            spots = list(re.finditer(number, text))
            if not spots:
                return data
            spot = spots[k % len(spots)]
            return (text[:spot.start()] + value + text[spot.end():]).encode()
        return edit

    def flip(k: int, byte: int) -> Mutation:
        return lambda data: data[:k % max(len(data), 1)] + bytes([byte]) + data[k % max(len(data), 1) + 1:]

    def truncate(k: int) -> Mutation:
        return lambda data: data[:k % max(len(data), 1)]

    def line_edit(k: int, how: str) -> Mutation:
        def edit(data: bytes) -> bytes:
            lines = data.split(b"\n")
            i = k % len(lines)
            if how == "delete":
                del lines[i]
            elif how == "duplicate":
                lines.insert(i, lines[i])
            else:  # indent: breaks the structure
                lines[i] = b"   " + lines[i]
            return b"\n".join(lines)
        return edit

    def append(text: bytes) -> Mutation:
        return lambda data: data + b"\n" + text

    def describe(text: bytes) -> Mutation:  # control characters, escapes, a long or broken text
        def edit(data: bytes) -> bytes:
            import re

            return re.sub(rb"(?m)^description: .*$", lambda match: b"description: " + text, data, count=1)
        return edit

    def image_to(target: str) -> Mutation:
        def edit(data: bytes) -> bytes:
            import re

            return re.sub(rb"image: [^,}\n]+", b"image: " + target.encode(), data)
        return edit

    return st.one_of(
        st.builds(replace_number, st.integers(0, 200), st.sampled_from(WEIRD_NUMBERS)),
        st.builds(flip, st.integers(0, 4000), st.integers(0, 255)),
        st.builds(truncate, st.integers(0, 4000)),
        st.builds(line_edit, st.integers(0, 100), st.sampled_from(["delete", "duplicate", "indent"])),
        st.builds(append, st.sampled_from([
            b"nested: " + b"[" * 200 + b"]" * 200,
            b"nested: " + b"{a: " * 60 + b"1" + b"}" * 60,
            b"description: '" + b"x" * 5_000_000 + b"'",
            b"a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
            b"c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
            b"e: [*d, *d, *d, *d, *d, *d, *d, *d, *d, *d, *d, *d, *d, *d, *d, *d, *d, *d]",
            b"evil: !!python/object/apply:os.system ['true']",
            b"kind: grating",
            b"\xff\xfe\xfa bad utf-8",
            "friction: {low: 0.5, high: 1.0} # caf\u00e9".encode("latin-1"),
            b"\x00\x01\x02",
        ])),
        st.builds(describe, st.sampled_from([b'"a\\0b"', b'"\\x1b[31mred"', b"'" + b"d" * 100_000 + b"'",
                                             b'"\\u202e\\ud800"', b"|\n  two\n  lines"])),
        st.builds(image_to, st.sampled_from(["/dev/zero", "/dev/null", "fifo.png", "dir.png", "missing.png",
                                             "/etc/passwd", "loop.png", "assets"])),
    )


@st.composite
def bad_file(draw: st.DrawFn, bases: list[Path]) -> Callable[[Path], str]:
    """A maker of a file (path as text) in a folder: a mutated shipped file, junk, or a special path."""
    kind = draw(st.sampled_from(["mutated", "mutated", "mutated", "mutated", "junk", "special"]))
    if kind == "mutated":
        base = draw(st.sampled_from(bases)).read_bytes()
        for edit in draw(st.lists(_mutation(), min_size=1, max_size=3)):
            base = edit(base)
        return lambda folder: _put(folder / "fuzzed.yaml", base)
    if kind == "junk":
        junk = draw(st.one_of(st.binary(max_size=300), st.just(b""), st.text(max_size=200).map(str.encode)))
        return lambda folder: _put(folder / "junk.yaml", junk)
    return draw(special_path())


def special_path() -> st.SearchStrategy[Callable[[Path], str]]:
    """A directory, FIFO, device, missing file, symlink loop or (not as root) unreadable file."""
    makers: list[Callable[[Path], str]] = [_dir, _fifo, lambda f: "/dev/null", lambda f: "/dev/zero",
                                          lambda f: str(f / "missing.yaml"), _loop, lambda f: "",
                                          lambda f: str(f / ("n" * 300)), lambda f: str(f / "new\nline.yaml")]
    if not IS_ROOT:  # root reads a chmod 000 file anyway
        makers.append(_unreadable)
    return st.sampled_from(makers)


def _put(path: Path, data: bytes) -> str:
    path.write_bytes(data)
    for name, make in (("fifo.png", os.mkfifo), ("dir.png", os.mkdir)):
        if not (path.parent / name).exists():
            make(path.parent / name)
    if not (path.parent / "loop.png").is_symlink():
        (path.parent / "loop.png").symlink_to(path.parent / "loop.png")
    return str(path)


def _dir(folder: Path) -> str:
    (folder / "d.yaml").mkdir()
    return str(folder / "d.yaml")


def _fifo(folder: Path) -> str:
    os.mkfifo(folder / "f.yaml")
    return str(folder / "f.yaml")


def _loop(folder: Path) -> str:
    (folder / "l.yaml").symlink_to(folder / "l.yaml")
    return str(folder / "l.yaml")


def _unreadable(folder: Path) -> str:
    shutil.copy(GRATING, folder / "u.yaml")
    (folder / "u.yaml").chmod(0)
    return str(folder / "u.yaml")


# --- strategies: URLs and flags ----------------------------------------------------------------------------

INPUT_OPTIONS = ["speed_mm_s", "from_mm", "to_mm", "y_mm", "force_n", "rate_hz", "repeat", "back_and_forth", "lift_s",
                 "center_mm", "radius_mm", "turns", "x_mm", "duration_s", "down_s", "up_s", "count", "speeed", "q"]


@st.composite
def url(draw: st.DrawFn, schemes: list[str], targets: list[str], options: list[str]) -> str:
    """A URL: a scheme (known, misspelt or missing), a target, options with absurd values, escapes."""
    scheme = draw(st.sampled_from(schemes))
    target = draw(st.sampled_from(targets))
    value = st.one_of(st.sampled_from(FLAG_VALUES + ["1,2,3", "nan,30", "1e308,1e308", "65,30"]),
                      st.sampled_from(PERCENT).map(lambda escape: "1" + escape),
                      st.integers(-10**30, 10**30).map(str))
    pairs = draw(st.lists(st.tuples(st.sampled_from(options), value), max_size=3))
    query = "&".join(f"{name}={text}" for name, text in pairs)
    if draw(st.booleans()) and pairs:
        query = draw(st.sampled_from([query + "&", query + "&&x", query.replace("=", "", 1), "=" + query]))
    text = f"{scheme}{target}" + (f"?{query}" if query else "")
    return draw(st.sampled_from([text, text, text, text + "0" * 5000, text + draw(st.sampled_from(PERCENT))]))


def input_url(folder_csv: bool = True) -> st.SearchStrategy[str]:
    return url(["scripted://", "scripted://", "scripted://", "file://", "scriptd://", "SCRIPTED://", "http://", "",
                "scripted:", "sim://", "null://"],
               ["swipe", "circle", "still", "tap", "", "swipe/", "wobble", "/tmp/none.csv", "/dev/zero",
                "/tmp/a%00b.csv"], INPUT_OPTIONS)


def output_url() -> st.SearchStrategy[str]:
    """Outputs, never audio:// (nor auto): null://, sim:// with bad options, wav:// to bad places, serial:// to
    things that are not serial ports (or with absurd options), junk."""
    return url(["null://", "sim://", "wav://", "wave://", "nul://", "", "file://", "serial://", "serial://"],
               ["", "/dev/zero", "/tmp", "/nonexistent/dir/x.wav", "x", "/dev/null", "/tmp/f.npz"],
               ["q", "rate", "block", "bogus", "envelope_hz", "buffer_ms", "frame_ms", "baud"])


def flags(names: list[str]) -> st.SearchStrategy[list[str]]:
    """One to three of ``names``, each with an absurd value."""
    return st.lists(st.tuples(st.sampled_from(names), st.sampled_from(FLAG_VALUES)), min_size=1, max_size=3,
                    unique_by=lambda pair: pair[0]).map(lambda pairs: [part for name, value in pairs
                                                                       for part in (name, value)])


# --- the fuzz tests ----------------------------------------------------------------------------------------

def test_fuzz_check() -> None:
    outcomes = Outcomes()

    @FUZZ
    @given(make=bad_file(TEXTURES + DEVICES))
    def run(make: Callable[[Path], str]) -> None:
        with workdir() as folder:
            path = make(folder)
            outcomes.add(run_cli(["check", "--quiet", path], "check", [path]))

    run()
    outcomes.assert_mostly_errors()


@st.composite
def render_case(draw: st.DrawFn) -> tuple[str, Callable[[Path], tuple[list[str], list[str]]]]:
    """What to fuzz in a render (texture, device, input, output, flags or --out) and a maker of its argv."""
    part = draw(st.sampled_from(["texture", "device", "input", "output", "flags", "out"]))
    texture = draw(bad_file(TEXTURES)) if part == "texture" else None
    device = draw(bad_file(DEVICES)) if part == "device" else None
    source = draw(input_url()) if part == "input" else "scripted://swipe?speed_mm_s=100"
    output = draw(output_url()) if part == "output" else "sim://"
    extra = draw(flags(["--rate", "--block", "--duration", "--power-budget", "--power-avg", "--force"])) \
        if part == "flags" else []
    if "--duration" in extra and extra[extra.index("--duration") + 1] == "1_000":  # a valid 1000 s: too long
        extra[extra.index("--duration") + 1] = "5e-324"
    out = draw(st.sampled_from(["x.txt", "d.npz", "f.npz", "z.npz", "missing/x.npz", "", "x.NPZ", "x.wav",
                                "n" * 300 + ".npz"])) if part == "out" else "x.npz"

    def make(folder: Path) -> tuple[list[str], list[str]]:
        argv, files = command_argv(folder, ["render", "--input", source], texture, device, output, extra, None,
                                   duration="0.05")
        return [*argv, "--out", str(folder / out) if out else ""], files

    return part, make


def test_fuzz_render() -> None:
    outcomes = Outcomes()

    @FUZZ
    @given(case=render_case())
    def run(case: tuple[str, Callable[[Path], tuple[list[str], list[str]]]]) -> None:
        with workdir() as folder:
            argv, files = case[1](folder)
            outcomes.add(run_cli(argv, "render", files))

    run()
    outcomes.assert_mostly_errors()


#: --duration values every real-time command refuses.
REFUSED_DURATIONS = ("nan", "inf", "-inf", "-1", "0", "-0", "1e308", "abc", "", "1e9", "99999999999999999999", "0x10")


def only_refused_duration(extra: list[str]) -> None:
    """Make a fuzzed ``--duration`` in ``extra`` one that is refused (a valid one could run long)."""
    if "--duration" in extra and extra[extra.index("--duration") + 1] not in REFUSED_DURATIONS:
        extra[extra.index("--duration") + 1] = "1e308"


def command_argv(folder: Path, command: list[str], texture: Callable[[Path], str] | None,
                 device: Callable[[Path], str] | None, output: str, extra: list[str],
                 record: str | None, duration: str = "0.2") -> tuple[list[str], list[str]]:
    """``(argv, files)`` of a render, play or serve in ``folder``: ``command`` (its name and own arguments), the
    texture (a bad one, or the grating), ``--output``, a bad ``--device``, ``--duration DURATION`` unless fuzzed,
    and ``--record`` to ``record`` (None: none) among a folder, a FIFO and /dev/zero made there; then ``extra``."""
    files = [texture(folder) if texture else GRATING]
    argv = [command[0], files[0], *command[1:], "--output", output.replace("/tmp", str(folder))]
    if device:
        files.append(device(folder))
        argv += ["--device", files[-1]]
    if "--duration" not in extra:
        argv += ["--duration", duration]
    (folder / "d.npz").mkdir()
    os.mkfifo(folder / "f.npz")
    (folder / "z.npz").symlink_to("/dev/zero")
    if record is not None:
        argv += ["--record", str(folder / record) if record else ""]
    return [*argv, *extra], files


@st.composite
def play_case(draw: st.DrawFn) -> Callable[[Path], tuple[list[str], list[str]]]:
    """A play that ends by itself within a second or is refused: null:// or sim://, a finite input, 0.2 s."""
    part = draw(st.sampled_from(["texture", "device", "input", "output", "flags", "record"]))
    texture = draw(bad_file(TEXTURES)) if part == "texture" else None
    device = draw(bad_file(DEVICES)) if part == "device" else None
    source = draw(input_url()) if part == "input" else "scripted://swipe?speed_mm_s=100"
    if source.startswith(("mouse", "audio")) or "auto" in source:
        source = "scripted://swipe"
    output = draw(output_url()) if part == "output" else draw(st.sampled_from(["null://", "sim://"]))
    extra = draw(flags(["--rate", "--block", "--duration", "--power-budget", "--power-avg", "--force",
                        "--stall-timeout"])) if part == "flags" else []
    only_refused_duration(extra)  # a fuzzed play must not run long
    record = draw(st.sampled_from(["d.npz", "f.npz", "z.npz", "missing/x.npz", "x.wav", ""])) \
        if part == "record" else None

    def make(folder: Path) -> tuple[list[str], list[str]]:
        return command_argv(folder, ["play", "--input", source], texture, device, output, extra, record)

    return make


def test_fuzz_play() -> None:
    outcomes = Outcomes()

    @FUZZ_SLOW
    @given(make=play_case())
    def run(make: Callable[[Path], tuple[list[str], list[str]]]) -> None:
        with workdir() as folder:
            argv, files = make(folder)
            outcomes.add(run_cli(argv, "play", files, timeout_s=120))

    run()
    outcomes.assert_mostly_errors()


#: Values for serve's own flags that take a string: addresses, tokens, origins, folders.
SERVE_STRINGS = ["0.0.0.0", "::", "example.com", "256.1.1.1", "", "localhost", "::1", "short", "x" * 300, "to ken!",
                 "http://", "null", "evil.example", "/nonexistent", "/dev/null", "/tmp", "\u00e9"]


@st.composite
def serve_case(draw: st.DrawFn) -> Callable[[Path], tuple[list[str], list[str]]]:
    """A serve that stops by itself within a second or is refused: null:// or sim://, any free port, no OSC
    unless fuzzed, ``--duration 0.2`` unless only refused durations are fuzzed."""
    part = draw(st.sampled_from(["texture", "device", "output", "flags", "strings", "record"]))
    texture = draw(bad_file(TEXTURES)) if part == "texture" else None
    device = draw(bad_file(DEVICES)) if part == "device" else None
    output = draw(output_url()) if part == "output" else draw(st.sampled_from(["null://", "sim://"]))
    extra = draw(flags(["--rate", "--block", "--duration", "--power-budget", "--port", "--osc-port",
                        "--velocity-window-ms", "--stall-timeout"])) if part == "flags" else []
    if part == "strings":
        extra = draw(st.lists(st.tuples(st.sampled_from(["--host", "--token", "--allow-origin", "--texture-dir"]),
                                        st.sampled_from(SERVE_STRINGS)), min_size=1, max_size=3, unique_by=lambda p: p[0])
                     .map(lambda pairs: [part for name, value in pairs for part in (name, value)]))
    only_refused_duration(extra)
    for port_flag in ("--port", "--osc-port"):  # a valid fixed port could be taken: any free one instead
        if port_flag in extra and extra[extra.index(port_flag) + 1].isdigit():
            extra[extra.index(port_flag) + 1] = "0"
    record = draw(st.sampled_from(["d.npz", "f.npz", "z.npz", "missing/x.npz", "x.wav", ""])) \
        if part == "record" else None

    ports = ([] if "--port" in extra else ["--port", "0"]) + ([] if "--osc-port" in extra else ["--no-osc"])

    def make(folder: Path) -> tuple[list[str], list[str]]:
        return command_argv(folder, ["serve", *ports], texture, device, output, extra, record)

    return make


def test_fuzz_serve() -> None:
    outcomes = Outcomes()

    @settings(FUZZ, max_examples=8)  # a valid example serves 0.2 s
    @given(make=serve_case())
    def run(make: Callable[[Path], tuple[list[str], list[str]]]) -> None:
        with workdir() as folder:
            argv, files = make(folder)
            outcomes.add(run_cli(argv, "serve", files, timeout_s=120))

    run()
    outcomes.assert_mostly_errors()


@st.composite
def show_case(draw: st.DrawFn) -> Callable[[Path], tuple[list[str], list[str]]]:
    part = draw(st.sampled_from(["texture", "texture", "device", "flags", "out"]))
    texture = draw(bad_file(TEXTURES)) if part == "texture" else None
    device = draw(bad_file(DEVICES)) if part == "device" else None
    extra = draw(flags(["--speed-mm-s", "--force-n", "--direction-deg", "--t-s", "--resolution-mm"])) \
        if part == "flags" else []
    out = draw(st.sampled_from(["x.txt", "d.png", "f.png", "n.png", "missing/x.png", "", "x.PDF"])) \
        if part == "out" else "x.png"

    def make(folder: Path) -> tuple[list[str], list[str]]:
        files = [texture(folder) if texture else GRATING]
        argv = ["show", files[0]]
        if device:
            files.append(device(folder))
            argv += ["--device", files[-1]]
        if "--resolution-mm" not in extra:
            argv += ["--resolution-mm", "2"]
        (folder / "d.png").mkdir()
        os.mkfifo(folder / "f.png")
        (folder / "n.png").symlink_to("/dev/null")
        return [*argv, *extra, "--out", str(folder / out) if out else ""], files

    return make


def test_fuzz_show() -> None:
    outcomes = Outcomes()

    @FUZZ_SLOW
    @given(make=show_case())
    def run(make: Callable[[Path], tuple[list[str], list[str]]]) -> None:
        with workdir() as folder:
            argv, files = make(folder)
            outcomes.add(run_cli(argv, "show", files))

    run()
    outcomes.assert_mostly_errors()


_RECORDING: list[dict[str, np.ndarray]] = []


def _good_recording() -> dict[str, np.ndarray]:
    """The entries of a tiny valid recording, rendered once."""
    if not _RECORDING:
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "good.npz"
            done = tpad_rt("render", GRATING, "--input", "scripted://still?duration_s=0.01", "--out", str(path))
            assert done.returncode == 0, done.stderr
            with np.load(path) as archive:
                _RECORDING.append({name: archive[name] for name in archive.files})
    return _RECORDING[0]


@st.composite
def recording_case(draw: st.DrawFn) -> Callable[[Path], tuple[list[str], list[str]]]:
    """A mutated recording (an entry or a metadata value replaced, bytes flipped, cut) or a special path."""
    part = draw(st.sampled_from(["entry", "metadata", "bytes", "special", "flags"]))
    entry_names = ["drive", "fs", "format", "format_version", "t", "power_w", "voltage_v", "x_mm", "saturated",
                   "metadata_json", "achieved_mu"]
    weird_arrays = [np.array(np.nan), np.array([np.inf, 1.0]), np.zeros((2, 2)), np.array("text"),
                    np.zeros(0), np.array(10**18), np.array([1e308] * 3), np.array([-1], dtype=np.int8)]
    weird_json = [None, "abc", -1, 0, 1e308, [], {}, True, float("nan"), 10**30]
    name = draw(st.sampled_from(entry_names))
    array = draw(st.sampled_from(range(len(weird_arrays))))
    key = draw(st.sampled_from(["max_voltage_v", "power_budget_w", "power_avg_w", "power_window_s", "block_frames",
                                "carrier_hz", "texture_description", "device_label"]))
    value = draw(st.sampled_from(weird_json))
    where = draw(st.integers(0, 10**6))
    byte = draw(st.integers(0, 255))
    special = draw(special_path()) if part == "special" else None
    extra = draw(st.lists(st.sampled_from([["--start", "nan"], ["--end", "-inf"], ["--start", "1e308"],
                                          ["--along", "y"], ["--start", "abc"], ["--end", ""],
                                          ["--along", "x", "--start", "5e-324"]]), min_size=1, max_size=2)) \
        if part == "flags" else []

    def make(folder: Path) -> tuple[list[str], list[str]]:
        path = folder / "rec.npz"
        entries = dict(_good_recording())
        if part == "entry":
            entries[name] = weird_arrays[array]
        elif part == "metadata":
            meta = json.loads(str(entries["metadata_json"]))
            meta[key] = value
            entries["metadata_json"] = np.array(json.dumps(meta))
        np.savez(path, **entries)
        if part == "bytes":
            data = bytearray(path.read_bytes())
            data[where % len(data)] = byte
            path.write_bytes(bytes(data[: len(data) - where % 7 * 100]))
        target = special(folder) if special else str(path)
        return ["plot", target, *[word for pair in extra for word in pair], "--out", str(folder / "x.png")], [target]

    return make


def test_fuzz_plot() -> None:
    outcomes = Outcomes()

    @FUZZ
    @given(make=recording_case())
    def run(make: Callable[[Path], tuple[list[str], list[str]]]) -> None:
        with workdir() as folder:
            argv, files = make(folder)
            outcomes.add(run_cli(argv, "plot", files))

    run()
    outcomes.assert_mostly_errors()


@st.composite
def misc_case(draw: st.DrawFn) -> tuple[str, Callable[[Path], list[str]]]:
    """schema, design and devices with bad arguments (devices: only bad flags; it lists real hardware)."""
    command = draw(st.sampled_from(["schema", "design", "devices", "none"]))
    value = draw(st.sampled_from(FLAG_VALUES))
    if command == "schema":
        kind = draw(st.sampled_from(["texture", "device", "textures", "", "sound"]))
        out = draw(st.sampled_from(["fifo.json", "dir", "missing/x.json", "/dev/zero", ""]))
        return command, lambda folder: ["schema", kind, "--out", str(folder / out) if out else ""]
    if command == "design":
        args = draw(st.sampled_from([["--length-mm", value], ["--mode", value], ["--reference", value],
                                     ["--plate", f"x:{value}:2.5:70"], ["--plate", value], ["--json", value]]))
        return command, lambda folder: ["design", *args]
    if command == "devices":
        flag = draw(st.sampled_from(["--rate", "extra", "-x", "--json"]))
        return command, lambda folder: ["devices", flag]
    word = draw(st.sampled_from(["chek", "", "--bogus", "render --help"]))
    return "", lambda folder: [word, value]


def test_fuzz_schema_design_devices_and_unknown_commands() -> None:
    outcomes = Outcomes()

    @FUZZ_FEW
    @given(case=misc_case())
    def run(case: tuple[str, Callable[[Path], list[str]]]) -> None:
        command, make = case
        with workdir() as folder:
            os.mkfifo(folder / "fifo.json")
            (folder / "dir").mkdir()
            argv = make(folder)
            if command:
                outcomes.add(run_cli(argv, command, []))
            else:  # no subcommand: argparse's own prefix
                note("tpad-rt " + " ".join(shlex.quote(word) for word in argv))
                done = tpad_rt(*argv)
                assert done.returncode == 1 and done.stderr.count("\n") == 1, done.stderr
                assert done.stderr.startswith("tpad-rt: error: ") and "Traceback" not in done.stderr
                outcomes.add(1)

    run()
    outcomes.assert_mostly_errors()


@st.composite
def amp_case(draw: st.DrawFn) -> Callable[[Path], tuple[list[str], list[str]]]:
    """``amp emulate`` with a bad device file, a port that is not a serial port, a bad recording path, or absurd
    flags and fault specs; it ends by itself (``--duration 0.2``) when nothing is refused."""
    part = draw(st.sampled_from(["device", "port", "record", "flags", "fault"]))
    device = draw(bad_file(DEVICES)) if part == "device" else None
    port = draw(special_path()) if part == "port" else None
    record = draw(st.sampled_from(["d.npz", "f.npz", "z.npz", "missing/x.npz", "x.wav", ""])) \
        if part == "record" else None
    extra = draw(flags(["--duration", "--seed"])) if part == "flags" else []
    if "--duration" in extra:  # only refused durations: a fuzzed emulator must not run long
        index = extra.index("--duration") + 1
        if extra[index] not in ("nan", "inf", "-inf", "-1", "0", "-0", "1e308", "abc", "", "1e9",
                                "99999999999999999999", "0x10"):
            extra[index] = "-1"
    if part == "fault":
        kind = draw(st.sampled_from(["drop", "corrupt", "delay", "stall", "overcurrent", "disconnect", "jam", ""]))
        values = draw(st.lists(st.sampled_from(FLAG_VALUES), min_size=0, max_size=3))
        extra = ["--fault", ":".join([kind, *values])]

    def make(folder: Path) -> tuple[list[str], list[str]]:
        files = []
        argv = ["amp", "emulate"]
        if device:
            files.append(device(folder))
            argv += ["--device", files[-1]]
        if port:
            argv += ["--port", port(folder)]
        (folder / "d.npz").mkdir()
        os.mkfifo(folder / "f.npz")
        (folder / "z.npz").symlink_to("/dev/zero")
        if record is not None:
            argv += ["--record", str(folder / record) if record else ""]
        if "--duration" not in extra:
            argv += ["--duration", "0.2"]
        return [*argv, *extra], files

    return make


def test_fuzz_amp_emulate() -> None:
    outcomes = Outcomes()

    @FUZZ_FEW
    @given(make=amp_case())
    def run(make: Callable[[Path], tuple[list[str], list[str]]]) -> None:
        with workdir() as folder:
            argv, files = make(folder)
            outcomes.add(run_cli(argv, "amp emulate", files, timeout_s=60))

    run()
    outcomes.assert_mostly_errors()


# --- writers against planted links (issue 20) ----------------------------------------------------------------

EXAMPLE = REPO / "examples" / "calibration"
STILL = "scripted://still?duration_s=0.01"
PRECIOUS = b"the victim's own bytes\n"
#: Every command that writes a file the user names: (suffix, argv with OUT where the path goes).
WRITERS: dict[str, tuple[str, list[str]]] = {
    "render --out .npz": (".npz", ["render", GRATING, "--input", STILL, "--out", "OUT"]),
    "render --out .wav": (".wav", ["render", GRATING, "--input", STILL, "--out", "OUT"]),
    "render --output wav://": (".wav", ["render", GRATING, "--input", STILL, "--output", "wav://OUT", "--out",
                                        "RECORDING"]),
    "play --record": (".npz", ["play", GRATING, "--input", STILL, "--output", "null://", "--duration", "0.05",
                               "--record", "OUT"]),
    "show --out": (".svg", ["show", GRATING, "--resolution-mm", "4", "--out", "OUT"]),
    "schema --out": (".json", ["schema", "device", "--out", "OUT"]),
    "calibrate build": (".yaml", ["calibrate", "build", "--impedance", str(EXAMPLE / "sweeps.csv"), "--amplitude",
                                  str(EXAMPLE / "amplitudes.csv"), "--out", "OUT"]),
    "calibrate convert": (".yaml", ["calibrate", "convert", str(REPO / "tests" / "bad_files" / "device_format_1.yaml"),
                                    "--out", "OUT"]),
    "calibrate impedance --plot": (".png", ["calibrate", "impedance", str(EXAMPLE / "sweep_0n_polar.csv"),
                                            "--plot", "OUT"]),
}
#: What is at the target before the command runs.
TARGET_STATES = ["nothing", "old file", "link to the victim", "dangling link", "link to a FIFO", "FIFO", "directory"]
#: Links planted at the names a writer's temporary file could take.
TEMPORARY_PLANTS = ["the next PIDs", "guessed random names"]


def _plant(folder: Path, target: Path, state: str, plants: list[str], victim: Path) -> list[Path]:
    """Put ``state`` at ``target`` and the ``plants`` beside it; the links planted at temporary names."""
    if state == "old file":
        target.write_bytes(PRECIOUS)
        target.chmod(0o640)
    elif state == "link to the victim":
        target.symlink_to(victim)
    elif state == "dangling link":
        target.symlink_to(victim.parent / "created-through-the-link")
    elif state == "link to a FIFO":
        os.mkfifo(folder / "fifo")
        target.symlink_to(folder / "fifo")
    elif state == "FIFO":
        os.mkfifo(target)
    elif state == "directory":
        target.mkdir()
    planted = []
    if "the next PIDs" in plants:  # the old '.NAME.PID.tmp' (PIDs are handed out in turn)
        with subprocess.Popen(["true"]) as child:
            start = child.pid
        planted += [folder / f".{target.name}.{start + step}.tmp" for step in range(1, 500)]
    if "guessed random names" in plants:
        guesses = random.Random(target.name)  # mkstemp's alphabet and length, guessed as an attacker could
        planted += [folder / f".{target.name[:64]}.{''.join(guesses.choices(string.ascii_lowercase + string.digits + '_', k=8))}.tmp"
                    for _ in range(200)]
    for path in planted:
        with contextlib.suppress(FileExistsError):
            path.symlink_to(victim)
    return planted


@st.composite
def writer_case(draw: st.DrawFn) -> tuple[str, str, str, list[str]]:
    """(writer, file name, what is at the target, links planted at temporary names)."""
    writer = draw(st.sampled_from(sorted(WRITERS)))
    name = draw(st.sampled_from(["out", "a b", "n" * 180, "-dash", ".hidden", "x.tmp"])) + WRITERS[writer][0]
    state = draw(st.sampled_from(TARGET_STATES + ["link to the victim", "dangling link", "old file"]))  # links more
    plants = draw(st.lists(st.sampled_from(TEMPORARY_PLANTS), unique=True))
    return writer, name, state, plants


def test_fuzz_writers_against_planted_links() -> None:
    """Every writer, a victim file elsewhere and links planted at its target and at the temporary names it could
    take: the victim is never written, nothing is created through a link, no temporary file stays, the target
    is the old file (on an error) or a new regular file (on success, with the old file's permissions), and a
    target that is no regular file is one error line."""
    outcomes = Outcomes()

    @settings(FUZZ, max_examples=16)  # about 1 s an example
    @given(case=writer_case())
    def run(case: tuple[str, str, str, list[str]]) -> None:
        writer, name, state, plants = case
        with workdir() as work:
            folder, elsewhere = work / "shared", work / "elsewhere"
            folder.mkdir()
            elsewhere.mkdir()
            victim = elsewhere / "victim.txt"
            victim.write_bytes(PRECIOUS)
            target = folder / name
            planted = _plant(folder, target, state, plants, victim)
            argv = [word.replace("RECORDING", str(work / "r.npz")).replace("OUT", str(target))
                    for word in WRITERS[writer][1]]
            status = run_cli(argv, " ".join(argv[:2]) if argv[0] == "calibrate" else argv[0], [], timeout_s=120)
            outcomes.add(status)
            assert victim.read_bytes() == PRECIOUS and sorted(os.listdir(elsewhere)) == ["victim.txt"]
            assert all(path.is_symlink() and path.readlink() == victim for path in planted)
            assert [path.name for path in folder.iterdir() if path.name.endswith(".tmp") and not path.is_symlink()] == []
            if state in ("link to a FIFO", "FIFO", "directory"):
                assert status == 1
            elif status == 0:
                assert target.is_file() and not target.is_symlink() and target.stat().st_size > 0
                if state == "old file":
                    assert stat.S_IMODE(target.stat().st_mode) == 0o640 and target.read_bytes() != PRECIOUS
            elif state == "old file":
                assert target.read_bytes() == PRECIOUS

    run()
    print(f"fuzz outcomes: {outcomes.counts}")
    assert outcomes.counts[0] >= 3 and outcomes.counts[1] >= 3, outcomes.counts
