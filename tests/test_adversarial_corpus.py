"""An adversarial corpus for the command line (issue 8, "Safety", point 7): one named case per attack.

Every case builds its files in ``tmp_path`` with the small helpers below, runs the real
CLI in a fresh interpreter (tests/cli_run.py) and expects exit status 1, exactly one
line on stderr holding the expected text, no traceback, no warning, and a child peak
resident memory under 500 MB. The families follow issue 8:

0. device files whose circuit or amplifier extremes would bypass the voltage cap;
1. bad finger samples through the inputs (CSV rows, scripted:// options);
2. textures that would render NaN;
3. absurd sizes (counts, speeds, rates, files of tens of MB, /dev/zero, FIFOs, zip bombs);
4. tracebacks of old and their relatives (paths: NUL, too long, newlines, symlink loops;
   images: FIFOs, directories, oversized, bomb headers, bad arrays; recordings);
5. stall and duration flags of play;
6. outputs that cannot be written (directories, FIFOs, devices, missing folders).

``{tmp}`` in an expected text stands for the case's ``tmp_path``. Play only ever runs on
``null://`` with ``--duration 0.2`` (or fails before it starts); renders are tiny.
A NUL byte in a path *argument* cannot be tested here: execve itself refuses it, so it
never reaches tpad-rt (the URL form, ``%00``, is covered).
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from cli_run import REPO, tpad_rt, warm_numba_cache
from tpad_rt.limits import MAX_TRAJECTORY_BYTES

PEAK_MB = 500
GRATING = str(REPO / "textures" / "grating.yaml")
DEFAULT_DEVICE = (REPO / "tpad_rt" / "devices" / "default.yaml").read_text()
BAD_FILES = REPO / "tests" / "bad_files"
SWIPE = "scripted://swipe?speed_mm_s=100"
SHORT = "scripted://still?duration_s=0.01"

Build = Callable[[Path], list[str]]


# --- helpers: files ----------------------------------------------------------------------------------------

def _write(path: Path, text: str | bytes) -> str:
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return str(path)


def device(tmp: Path, old: str, new: str) -> str:
    """The default device with ``old`` replaced by ``new`` (which must occur), as ``tmp/device.yaml``."""
    assert old in DEFAULT_DEVICE, old
    return _write(tmp / "device.yaml", DEFAULT_DEVICE.replace(old, new, 1))


def texture(tmp: Path, body: str, name: str = "texture.yaml") -> str:
    """A texture file ``description: adversarial`` + ``body``."""
    return _write(tmp / name, "description: adversarial\n" + body)


def bitmap(tmp: Path, image: str) -> str:
    """A bitmap texture whose image is ``image`` (relative to tmp)."""
    return texture(tmp, f"kind: bitmap\nimage: {image}\nsize_mm: [10, 10]\nfriction: {{low: 0.5, high: 1}}\n")


def csv(tmp: Path, rows: str, header: str = "t,x_mm,y_mm,force_n") -> str:
    """A trajectory CSV, returned as its file:// URL."""
    return "file://" + _write(tmp / "trajectory.csv", header + "\n" + rows)


def fifo(tmp: Path, name: str) -> str:
    os.mkfifo(tmp / name)
    return str(tmp / name)


def symlink(tmp: Path, name: str, target: str) -> str:
    (tmp / name).symlink_to(target)
    return str(tmp / name)


def png(tmp: Path, name: str, size: tuple[int, int]) -> str:
    Image.new("L", size).save(tmp / name)
    return name


def png_bomb(tmp: Path, name: str) -> str:
    """A 1 x 1 PNG whose header claims 100000 x 100000 pixels (CRC fixed)."""
    Image.new("L", (1, 1)).save(tmp / name)
    data = bytearray((tmp / name).read_bytes())
    data[16:24] = (100_000).to_bytes(4, "big") * 2
    data[29:33] = zlib.crc32(data[12:29]).to_bytes(4, "big")
    (tmp / name).write_bytes(bytes(data))
    return name


def recording(tmp: Path, change: Callable[[dict[str, np.ndarray], dict], None] = lambda entries, meta: None) -> str:
    """A tiny valid recording (rendered once per session), with ``change(entries, metadata)`` applied."""
    entries = dict(np.load(_good_recording()))
    meta = json.loads(str(entries["metadata_json"]))
    change(entries, meta)
    entries["metadata_json"] = np.array(json.dumps(meta))
    np.savez(tmp / "recording.npz", **entries)
    return str(tmp / "recording.npz")


_GOOD: list[Path] = []  # the tiny valid recording, rendered once per module (the _warm fixture)


def _good_recording() -> Path:
    return _GOOD[0]


def zip_bomb(tmp: Path) -> str:
    """An .npz of about 0.4 MB whose drive unpacks to 400 MB of float32 zeros (half as much again as a recording's
    largest entry may: the refusal is judged before anything unpacks, whatever the size)."""
    path = tmp / "bomb.npz"
    samples = 100_000_000
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        with archive.open("drive.npy", "w", force_zip64=True) as entry:
            np.lib.format.write_array_header_1_0(entry, {"descr": "<f4", "fortran_order": False, "shape": (samples,)})
            chunk = bytes(2**24)
            for _ in range(samples * 4 // len(chunk)):
                entry.write(chunk)
            entry.write(bytes(samples * 4 % len(chunk)))
    return str(path)


def npz_header_liar(tmp: Path) -> str:
    """An .npz whose drive header claims 10^13 samples over 1000 bytes."""
    path = tmp / "liar.npz"
    with zipfile.ZipFile(path, "w") as archive, archive.open("drive.npy", "w") as entry:
        np.lib.format.write_array_header_1_0(entry, {"descr": "<f4", "fortran_order": False, "shape": (10**13,)})
        entry.write(bytes(1000))
    return str(path)


def big_csv(tmp: Path) -> str:
    """A real (not sparse) CSV of 10 million rows, over the 64 MiB limit, written in 1 MiB pieces."""
    path = tmp / "big.csv"
    row = b"0.001,10,30\n"
    piece = row * (2**20 // len(row))
    with path.open("wb") as stream:
        stream.write(b"t,x_mm,y_mm\n")
        while stream.tell() <= MAX_TRAJECTORY_BYTES:
            stream.write(piece)
    return "file://" + str(path)


# --- helpers: command lines ------------------------------------------------------------------------------

def render(tmp: Path, *args: str, texture_path: str = GRATING, out: str = "x.npz") -> list[str]:
    """``render`` with a short input and ``--out tmp/out`` unless ``args`` say otherwise."""
    command = ["render", texture_path, *args]
    if "--input" not in args:
        command += ["--input", SHORT]
    if "--out" not in args:
        command += ["--out", str(tmp / out)]
    return command


def play(*args: str, texture_path: str = GRATING) -> list[str]:
    """``play`` on null:// for 0.2 s with a swipe, unless ``args`` say otherwise."""
    command = ["play", texture_path, *args]
    for flag, value in (("--output", "null://"), ("--input", SWIPE), ("--duration", "0.2")):
        if flag not in args:
            command += [flag, value]
    return command


def show(tmp: Path, *args: str, texture_path: str = GRATING) -> list[str]:
    command = ["show", texture_path, *args]
    return command if "--out" in args else [*command, "--out", str(tmp / "x.png")]


def plot(tmp: Path, path: str, *args: str) -> list[str]:
    return ["plot", path, *args] if "--out" in args else ["plot", path, *args, "--out", str(tmp / "x.png")]


# --- the corpus ------------------------------------------------------------------------------------------

CASES: list[tuple[str, Build, str]] = [
    # family 0: devices whose extremes would bypass the voltage cap
    ("dev-c0-1e-300-check", lambda t: ["check", device(t, "c0_nf: 9.88", "c0_nf: 1.0e-300")],
     "circuit.c0_nf: must be >= 0.001, got 1e-300 (line 22)"),
    ("dev-c0-1e-300-render", lambda t: render(t, "--device", device(t, "c0_nf: 9.88", "c0_nf: 1.0e-300")),
     "device.yaml: circuit.c0_nf: must be >= 0.001, got 1e-300 (line 22)"),
    ("dev-motional-l-huge-render",
     lambda t: render(t, "--device", device(t, "motional_l_h: [1.04109", "motional_l_h: [1.0e+300")),
     "circuit.motional_l_h[0]: must be <= 10000, got 1e+300"),
    ("dev-motional-r-huge-check", lambda t: ["check", device(t, "motional_r_ohm: [965.5", "motional_r_ohm: [1.0e+308")],
     "circuit.motional_r_ohm[0]: must be <= 1e+07, got 1e+308"),
    ("dev-q-below-half-check", lambda t: ["check", device(t, "motional_r_ohm: [965.5", "motional_r_ohm: [2000000.0")],
     "the quality factor sqrt(L / C) / R must stay above 0.5 at every force"),
    ("dev-q-below-half-render",
     lambda t: render(t, "--device", device(t, "motional_r_ohm: [965.5", "motional_r_ohm: [2000000.0")),
     "circuit.motional_r_ohm[0]: the quality factor sqrt(L / C) / R must stay above 0.5"),
    ("dev-max-volts-above-full-scale-render",
     lambda t: render(t, "--device", device(t, "max_voltage_v: 40.0", "max_voltage_v: 60.0")),
     "amplifier.max_voltage_v: must be <= volts_per_full_scale (50), got 60 (line 20)"),
    ("dev-max-volts-above-full-scale-play",
     lambda t: play("--device", device(t, "max_voltage_v: 40.0", "max_voltage_v: 60.0")),
     "amplifier.max_voltage_v: must be <= volts_per_full_scale (50), got 60"),
    ("dev-motional-c-subnormal-show",
     lambda t: show(t, "--device", device(t, "motional_c_pf: [24.74227", "motional_c_pf: [5.0e-324")),
     "circuit.motional_c_pf[0]: must be >= 0.001, got 5e-324"),
    ("dev-shunt-nan-render", lambda t: render(t, "--device", device(t, "shunt_ohm: 100.0", "shunt_ohm: .nan")),
     "circuit.shunt_ohm: must be a finite number, got nan"),
    ("dev-carrier-1e308-render",
     lambda t: render(t, "--device", device(t, "carrier_hz: 31360.0", "carrier_hz: 1.0e+308")),
     "carrier_hz: must be <= 200000, got 1e+308"),
    ("dev-gamma-zero-render",
     lambda t: render(t, "--device", device(t, "gamma_n_per_v: 0.0721723", "gamma_n_per_v: 0.0")),
     "circuit.gamma_n_per_v: must be >= 1e-06, got 0.0"),
    ("dev-gamma-negative-zero-play",
     lambda t: play("--device", device(t, "gamma_n_per_v: 0.0721723", "gamma_n_per_v: -0.0")),
     "circuit.gamma_n_per_v: must be >= 1e-06, got -0.0"),
    ("dev-format-missing-render",
     lambda t: render(t, "--device", device(t, "format_version: 2\n", "")),
     "device.yaml: format_version: required key missing (line 2)"),
    ("dev-format-1-play",
     lambda t: play("--device", str(REPO / "tests" / "bad_files" / "device_format_1.yaml")),
     "a device file of format 1 (it has no format_version), which tpad-rt no longer reads"),
    ("dev-format-true-check",
     lambda t: ["check", device(t, "format_version: 2", "format_version: true")],
     "format_version"),
    ("dev-budget-1e308-play", lambda t: play("--device", device(t, "power_budget_w: 0.8", "power_budget_w: 1.0e+308")),
     "power_budget_w: must be <= 1000, got 1e+308"),
    ("dev-psi-subnormal-render", lambda t: render(t, "--device", device(t, "psi_star: 4.69", "psi_star: 5.0e-324")),
     "friction_model.psi_star: must be >= 0.01, got 5e-324"),
    ("dev-mu0-negative-zero-show", lambda t: show(t, "--device", device(t, "mu0: 0.25", "mu0: -0.0")),
     "friction_model.mu0: must be >= 0.01, got -0.0"),
    ("dev-volts-per-full-scale-subnormal-check",
     lambda t: ["check", device(t, "volts_per_full_scale: 50.0", "volts_per_full_scale: 5.0e-324")],
     "amplifier.volts_per_full_scale: must be >= 0.1, got 5e-324"),
    ("dev-speed-floor-nan-render",
     lambda t: render(t, "--device", device(t, "speed_floor_mm_s: 5.0", "speed_floor_mm_s: .nan")),
     "speed_floor_mm_s: must be a finite number, got nan"),
    ("dev-is-a-texture-as-texture", lambda t: render(t, texture_path=str(REPO / "tpad_rt" / "devices" / "default.yaml")),
     "default.yaml: kind: required key missing"),

    # family 1: bad finger samples through the inputs
    ("csv-x-nan", lambda t: render(t, "--input", csv(t, "0,10,30,0.5\n0.01,nan,30,0.5\n")),
     "trajectory.csv:3: column x_mm"),
    ("csv-t-inf", lambda t: render(t, "--input", csv(t, "0,10,30,0.5\ninf,20,30,0.5\n")),
     "trajectory.csv:3: column t"),
    ("csv-y-1e308", lambda t: render(t, "--input", csv(t, "0,10,1e308,0.5\n")), "trajectory.csv:2: column y_mm"),
    ("csv-force-negative", lambda t: render(t, "--input", csv(t, "0,10,30,-0.5\n")),
     "trajectory.csv:2: column force_n"),
    ("csv-force-huge", lambda t: render(t, "--input", csv(t, "0,10,30,1e6\n")), "trajectory.csv:2: column force_n"),
    ("csv-t-backwards", lambda t: render(t, "--input", csv(t, "0,10,30,0.5\n0.5,20,30,0.5\n0.2,30,30,0.5\n")),
     "trajectory.csv:4"),
    ("csv-t-1e12-play", lambda t: play("--input", csv(t, "0,10,30,0.5\n1e12,20,30,0.5\n")),
     "trajectory.csv:3: column t: must be a finite number in [0, 86400] s, got '1e12'"),
    ("csv-x-far-off-plate", lambda t: render(t, "--input", csv(t, "0,10,30,0.5\n0.01,100000,30,0.5\n")),
     "trajectory.csv:3: column x_mm"),
    ("csv-down-not-a-flag", lambda t: render(t, "--input", csv(t, "0,10,30,0.5,2\n", "t,x_mm,y_mm,force_n,down")),
     "trajectory.csv:2: column down"),
    ("url-swipe-speed-nan", lambda t: render(t, "--input", "scripted://swipe?speed_mm_s=nan"),
     "option speed_mm_s: must be a number in [0.01, 10000], got 'nan'"),
    ("url-circle-radius-inf", lambda t: render(t, "--input", "scripted://circle?radius_mm=inf"),
     "option radius_mm"),
    ("url-still-x-1e308", lambda t: render(t, "--input", "scripted://still?x_mm=1e308&duration_s=0.01"),
     "option x_mm: must be in [-130, 260] mm"),
    ("url-tap-force-negative-play", lambda t: play("--input", "scripted://tap?force_n=-1"),
     "option force_n: must be a number in [0, 50], got '-1'"),
    ("url-swipe-lift-nan", lambda t: render(t, "--input", "scripted://swipe?lift_s=nan"), "option lift_s"),
    ("url-swipe-rate-1e308", lambda t: render(t, "--input", "scripted://swipe?rate_hz=1e308"), "option rate_hz"),
    ("url-circle-center-nan", lambda t: render(t, "--input", "scripted://circle?center_mm=nan,30"),
     "option center_mm: must be two numbers x,y, got 'nan,30'"),
    ("url-swipe-repeat-negative", lambda t: render(t, "--input", "scripted://swipe?repeat=-1"), "option repeat"),

    # family 2: textures that would render NaN
    ("tex-grating-period-subnormal-render",
     lambda t: render(t, texture_path=texture(t, "kind: grating\nperiod_mm: 5.0e-324\nfriction: {low: 0.5, high: 1}\n")),
     "period_mm: must be >= 0.01, got 5e-324"),
    ("tex-gradient-gain-1e308-show",
     lambda t: show(t, texture_path=texture(t, "kind: gradient\nheight: {shape: bump, center_mm: [65, 30], "
                                               "radius_mm: 10, height_mm: 1}\ngain: 1.0e+308\n"
                                               "friction: {base: 0.6, low: 0.2, high: 1.0}\n")),
     "gain: must be <= 1000, got 1e+308"),
    ("tex-temporal-frequency-1e308-play",
     lambda t: play(texture_path=texture(t, "kind: temporal\nfrequency_hz: 1.0e+308\nfriction: {low: 0.5, high: 1}\n")),
     "frequency_hz: must be <= 1000, got 1e+308"),
    ("tex-bitmap-size-tiny-render",
     lambda t: render(t, texture_path=texture(t, f"kind: bitmap\nimage: {png(t, 'a.png', (4, 4))}\n"
                                                 "size_mm: [1.0e-300, 10]\nfriction: {low: 0.5, high: 1}\n")),
     "size_mm[0]: must be >= 0.01, got 1e-300"),
    ("tex-bumps-radius-subnormal-render",
     lambda t: render(t, texture_path=texture(t, "kind: bumps\ncenters_mm: [[10, 10]]\nradius_mm: 5.0e-324\n"
                                                 "friction: {inside: 0.5, outside: 1.0}\n")),
     "radius_mm: must be >= 0.01, got 5e-324"),
    ("tex-region-radius-1e308-render",
     lambda t: render(t, texture_path=texture(t, "kind: layers\nlayers:\n  - kind: grating\n    period_mm: 2\n"
                                                 "    friction: {low: 0.5, high: 1.0}\n"
                                                 "    region: {circle: {center_mm: [65, 30], radius_mm: 1.0e+308}}\n")),
     "layers[0].region.circle.radius_mm: must be <= 10000, got 1e+308"),
    ("tex-grating-angle-1e308-render",
     lambda t: render(t, texture_path=texture(t, "kind: grating\nperiod_mm: 2\nangle_deg: 1.0e+308\n"
                                                 "friction: {low: 0.5, high: 1}\n")),
     "angle_deg"),
    ("tex-edges-width-subnormal-show",
     lambda t: show(t, texture_path=texture(t, "kind: edges\nshapes:\n  - rect: {x_mm: 10, y_mm: 10, w_mm: 20, h_mm: 20}\n"
                                               "width_mm: 5.0e-324\nfriction: {edge: 0.5, background: 1.0}\n")),
     "width_mm: must be >= 0.01, got 5e-324"),
    ("tex-phase-nan-render",
     lambda t: render(t, texture_path=texture(t, "kind: grating\nperiod_mm: 2\nphase_deg: .nan\n"
                                                 "friction: {low: 0.5, high: 1}\n")),
     "phase_deg: must be a finite number, got nan"),

    # family 3: absurd sizes
    ("circle-speed-1e-300-play", lambda t: play("--input", "scripted://circle?speed_mm_s=1e-300"),
     "option speed_mm_s: must be a number in [0.01, 10000], got '1e-300'"),
    ("tap-count-1e9-as-float", lambda t: render(t, "--input", "scripted://tap?count=1e9"),
     "option count: must be a whole number in [0, 1000000000], got '1e9'"),
    ("rate-1e9-spelled-float", lambda t: render(t, "--rate", "1e9"),
     "argument --rate: must be a whole number in [1, 768000] (Hz, the highest rate tpad-rt runs at), got '1e9'"),
    ("still-inf-without-duration", lambda t: render(t, "--input", "scripted://still?duration_s=inf"), "--duration"),
    ("render-768khz-hour-recording", lambda t: render(t, "--input", "scripted://swipe?repeat=0", "--duration", "3600",
                                                      "--rate", "768000"),
     "is 43,200,062 blocks, more than the 4,194,304 a render keeps telemetry for"),
    ("csv-ten-million-rows-play", lambda t: play("--input", big_csv(t)), "big.csv: file is larger than 64 MiB"),
    ("dev-zero-trajectory-play", lambda t: play("--input", "file:///dev/zero"),
     "/dev/zero: not a regular file (a character device); tpad-rt reads trajectories from regular files only"),
    ("fifo-trajectory-play", lambda t: play("--input", "file://" + fifo(t, "traj.csv")),
     "traj.csv: not a regular file (a FIFO); tpad-rt reads trajectories from regular files only"),
    ("fifo-device-play", lambda t: play("--device", fifo(t, "device.yaml")),
     "device.yaml: not a regular file (a FIFO); tpad-rt reads texture and device files"),
    ("urandom-texture-check", lambda t: ["check", "/dev/urandom"],
     "/dev/urandom: not a regular file (a character device)"),
    ("texture-over-4-mib-render",
     lambda t: render(t, texture_path=texture(t, "kind: grating\nperiod_mm: 2\nfriction: {low: 0.5, high: 1}\n"
                                                 + "#" * (4 * 2**20))),
     "texture.yaml: file is larger than 4 MiB"),
    ("texture-list-100001-render",
     lambda t: render(t, texture_path=texture(t, "kind: grating\nperiod_mm: [" + ", ".join(["2"] * 100_001) + "]\n")),
     "list longer than 100,000 items"),
    ("alias-bomb-show", lambda t: show(t, texture_path=str(BAD_FILES / "alias_bomb.yaml")),
     "alias_bomb.yaml"),
    ("npz-zip-bomb-plot", lambda t: plot(t, zip_bomb(t)),
     "bomb.npz: entry 'drive.npy' unpacks to 400,000,128 bytes, more than the 268,500,992"),
    ("npz-header-claims-1e13-samples-plot", lambda t: plot(t, npz_header_liar(t)),
     "liar.npz: not a tpad-rt recording (an entry's header claims an array too large to allocate)"),

    # family 4: tracebacks of old and their relatives
    ("block-100000-render", lambda t: render(t, "--block", "100000"),
     "argument --block: must be a whole number in [1, 65536] (frames), got '100000'"),
    ("block-negative-play", lambda t: play("--block", "-1"), "argument --block: must be a whole number in [1, 65536]"),
    ("nul-in-file-url-play", lambda t: play("--input", "file:///tmp/a%00b.csv"),
     "holds the control character \\x00 (after unquoting)"),
    ("percent-escaped-newline-in-wav-url",
     lambda t: render(t, "--output", f"wav://{t}/a%0a.wav"), "holds the control character \\x0a"),
    ("path-longer-than-path-max-check", lambda t: ["check", str(t / ("a" * 5000 + ".yaml"))],
     "cannot read: file name too long"),
    ("path-longer-than-path-max-out", lambda t: render(t, out="b" * 5000 + ".npz"),
     "cannot write recordings and WAV files there: file name too long"),
    ("bad-texture-named-with-newline",
     lambda t: render(t, texture_path=texture(t, "kind: grating\nperiod_mm: -2\nfriction: {low: 0.5, high: 1}\n",
                                              name="bad\nname.yaml")),
     "bad\\x0aname.yaml: period_mm: must be >= 0.01, got -2 (line 3)"),
    ("symlink-loop-texture-render", lambda t: render(t, texture_path=(symlink(t, "a.yaml", str(t / "b.yaml")),
                                                                      symlink(t, "b.yaml", str(t / "a.yaml")))[0]),
     "a.yaml: cannot read: too many levels of symbolic links"),
    ("nul-in-image-path-yaml",
     lambda t: render(t, texture_path=texture(t, 'kind: bitmap\nimage: "a\\0b.png"\nsize_mm: [10, 10]\n'
                                                 "friction: {low: 0.5, high: 1}\n")),
     "image: no such file: {tmp}/a\\x00b.png (line 3)"),
    ("empty-texture-path", lambda t: render(t, texture_path=""), "'': the file name is empty"),
    ("empty-device-path", lambda t: show(t, "--device", ""), "'': the file name is empty"),
    ("image-is-a-directory-render", lambda t: ((t / "d.png").mkdir(), render(t, texture_path=bitmap(t, "d.png")))[1],
     "d.png: not a regular file (a directory); tpad-rt reads images from regular files only"),
    ("image-is-a-fifo-show", lambda t: show(t, texture_path=bitmap(t, Path(fifo(t, "f.png")).name)),
     "f.png: not a regular file (a FIFO)"),
    ("image-links-to-dev-zero", lambda t: render(t, texture_path=bitmap(t, Path(symlink(t, "z.png", "/dev/zero")).name)),
     "z.png: not a regular file (a character device)"),
    ("image-5000x10-render", lambda t: render(t, texture_path=bitmap(t, png(t, "wide.png", (5000, 10)))),
     "image: image is 5000 x 10 pixels; sides must be 1 to 4096 (line 3)"),
    ("png-bomb-header-show", lambda t: show(t, texture_path=bitmap(t, png_bomb(t, "bomb.png"))),
     "image is 100000 x 100000 pixels"),
    ("png-truncated-render", lambda t: (_write(t / "cut.png", (REPO / "tests" / "good_files" / "checker.png")
                                               .read_bytes()[:40]), render(t, texture_path=bitmap(t, "cut.png")))[1],
     "as a PNG or PGM image"),
    ("pgm-maxval-zero-show", lambda t: (_write(t / "z.pgm", b"P5\n4 4\n0\n" + bytes(16)),
                                        show(t, texture_path=bitmap(t, "z.pgm")))[1],
     "maxval must be greater than 0"),
    ("npy-object-dtype-render",
     lambda t: (_write(t / "p.npy", (BAD_FILES / "pickled.npy").read_bytes()), render(t, texture_path=bitmap(t, "p.npy")))[1],
     "holds Python objects; only plain numeric arrays are loaded (never pickles)"),
    ("npy-wrong-shape-show",
     lambda t: (_write(t / "c.npy", (BAD_FILES / "cube.npy").read_bytes()), show(t, texture_path=bitmap(t, "c.npy")))[1],
     "must hold a 2-D array, got shape (2, 3, 4)"),
    ("npy-nan-play",
     lambda t: (_write(t / "n.npy", (BAD_FILES / "has_nan.npy").read_bytes()), play(texture_path=bitmap(t, "n.npy")))[1],
     "holds NaN or infinite values"),
    ("npy-header-claims-4096-squared", lambda t: (_npy_liar(t / "l.npy"), render(t, texture_path=bitmap(t, "l.npy")))[1],
     "Failed to read all data for array"),
    ("npy-complex", lambda t: (np.save(t / "c.npy", np.zeros((3, 3), complex)),
                               render(t, texture_path=bitmap(t, "c.npy")))[1],
     "must hold real numbers, got dtype complex128"),
    ("non-utf8-texture-render", lambda t: render(t, texture_path=_write(t / "x.yaml", b"\xff\xfe\x00junk")),
     "invalid YAML: cannot decode"),
    ("binary-junk-texture-play", lambda t: play(texture_path=_write(t / "x.yaml", bytes(range(256)) * 4)),
     "x.yaml: invalid YAML"),
    ("recording-metadata-text-plot", lambda t: plot(t, recording(t, lambda e, m: m.update(max_voltage_v="abc"))),
     "metadata_json: max_voltage_v: must be a number >= 0, got \"abc\""),
    ("recording-block-frames-zero-plot", lambda t: plot(t, recording(t, lambda e, m: m.update(block_frames=0))),
     "metadata_json: block_frames: must be a number > 0, got 0"),
    ("recording-power-inf-plot",
     lambda t: plot(t, recording(t, lambda e, m: e.update(power_w=np.full_like(e["power_w"], np.inf)))),
     "power_w: the recording holds NaN or infinite values"),
    ("recording-no-blocks-plot",
     lambda t: plot(t, recording(t, lambda e, m: e.update({k: v[:0] for k, v in e.items() if v.ndim == 1 and k != "drive"}))),
     "the recording holds no blocks"),

    # family 5: stall and duration flags
    ("stall-timeout-nan", lambda t: play("--stall-timeout", "nan"), "argument --stall-timeout: must be a number in (0, 60]"),
    ("stall-timeout-zero", lambda t: play("--stall-timeout", "0"), "argument --stall-timeout: must be a number in (0, 60]"),
    ("stall-timeout-negative", lambda t: play("--stall-timeout", "-1"), "argument --stall-timeout"),
    ("stall-timeout-1e308", lambda t: play("--stall-timeout", "1e308"),
     "argument --stall-timeout: must be a number in (0, 60] (s), got '1e308'"),
    ("play-duration-nan", lambda t: play("--duration", "nan"), "argument --duration: must be a number in (0, 86400] (s)"),
    ("play-duration-negative", lambda t: play("--duration", "-1"), "argument --duration"),
    ("play-duration-zero", lambda t: play("--duration", "0"), "argument --duration"),
    ("play-duration-empty", lambda t: play("--duration", ""), "argument --duration"),
    ("play-duration-inf", lambda t: play("--duration", "inf"), "argument --duration"),

    # family 6: outputs that cannot be written
    ("render-out-directory", lambda t: ((t / "d.npz").mkdir(), render(t, out="d.npz"))[1],
     "d.npz: exists and is not a regular file (a directory); tpad-rt writes recordings and WAV files"),
    ("render-out-fifo-wav", lambda t: (fifo(t, "f.wav"), render(t, out="f.wav"))[1],
     "f.wav: exists and is not a regular file (a FIFO)"),
    ("render-out-links-to-dev-zero", lambda t: (symlink(t, "z.npz", "/dev/zero"), render(t, out="z.npz"))[1],
     "z.npz: exists and is not a regular file (a character device)"),
    ("render-out-missing-folder", lambda t: render(t, out="missing/x.npz"),
     "missing/x.npz: cannot write recordings and WAV files there: no folder "),
    ("render-out-wav-missing-folder", lambda t: render(t, out="missing/x.wav"), "x.wav: cannot write"),
    ("render-out-under-a-file", lambda t: (_write(t / "f", ""), render(t, out="f/x.npz"))[1],
     "f/x.npz: cannot write recordings and WAV files there: no folder "),
    ("play-record-directory", lambda t: ((t / "d.npz").mkdir(), play("--record", str(t / "d.npz")))[1],
     "d.npz: exists and is not a regular file (a directory); tpad-rt writes recordings"),
    ("play-record-links-to-dev-zero", lambda t: play("--record", symlink(t, "z.npz", "/dev/zero")),
     "z.npz: exists and is not a regular file (a character device)"),
    ("play-record-missing-folder", lambda t: play("--record", str(t / "missing" / "x.npz")),
     "missing/x.npz: cannot write recordings there: no folder "),
    ("play-record-not-npz", lambda t: play("--record", str(t / "x.wav")), "--record: must end in .npz"),
    ("show-out-missing-folder", lambda t: show(t, "--out", str(t / "missing" / "x.png")),
     "x.png: cannot write figures there: no folder "),
    ("show-out-links-to-dev-null", lambda t: show(t, "--out", symlink(t, "n.png", "/dev/null")),
     "n.png: exists and is not a regular file (a character device); tpad-rt writes figures"),
    ("plot-out-fifo", lambda t: plot(t, recording(t), "--out", fifo(t, "f.svg")),
     "f.svg: exists and is not a regular file (a FIFO)"),
    ("plot-out-under-a-file", lambda t: plot(t, recording(t), "--out", str(Path(_write(t / "f", "")) / "x.png")),
     "x.png: cannot write figures there: no folder "),
    ("schema-out-fifo", lambda t: ["schema", "texture", "--out", fifo(t, "s.json")],
     "s.json: exists and is not a regular file (a FIFO); tpad-rt writes schemas"),
]


def _npy_liar(path: Path) -> None:
    """A .npy whose header claims 4096 x 4096 float64 over 100 bytes of data."""
    with path.open("wb") as stream:
        np.lib.format.write_array_header_1_0(stream, {"descr": "<f8", "fortran_order": False, "shape": (4096, 4096)})
        stream.write(bytes(100))


@pytest.fixture(autouse=True, scope="module")
def _warm(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Kernels in numba's cache before any peak memory is measured (cli_run.warm_numba_cache), and a tiny
    valid recording for the plot cases to break."""
    warm_numba_cache()
    path = tmp_path_factory.mktemp("corpus") / "good.npz"
    done = tpad_rt("render", GRATING, "--input", SHORT, "--out", str(path))
    assert done.returncode == 0, done.stderr
    _GOOD[:] = [path]


def test_the_corpus_is_large_and_its_names_unique() -> None:
    names = [name for name, _, _ in CASES]
    assert len(names) >= 60 and len(set(names)) == len(names)


@pytest.mark.parametrize(("build", "expected"), [pytest.param(build, expected, id=name) for name, build, expected in CASES])
def test_adversarial_case_ends_in_one_line(tmp_path: Path, build: Build, expected: str) -> None:
    args = build(tmp_path)
    done = tpad_rt(*args)  # its timeout is a safety net: a hang shows as -9
    done.assert_one_line_error(expected.replace("{tmp}", str(tmp_path)))
    command = args[0]
    prefix = "" if command == "check" else f"tpad-rt {command}"
    assert done.stderr.startswith(prefix), done.stderr
    assert done.peak_mb < PEAK_MB, done.peak_mb


@pytest.mark.parametrize("command", ["show", "plot"])
def test_control_characters_in_a_description_draw_without_warnings(tmp_path: Path, command: str) -> None:
    """A description holding a NUL is valid YAML ("a\\0b"); the figure shows it escaped, and no
    'Glyph missing' warning reaches stderr."""
    path = texture(tmp_path, "kind: grating\nperiod_mm: 2\nfriction: {low: 0.5, high: 1}\n")
    Path(path).write_text(Path(path).read_text().replace("description: adversarial", 'description: "a\\0b\\x01c"'))
    if command == "plot":
        done = tpad_rt(*render(tmp_path, texture_path=path))
        assert done.returncode == 0, done.stderr
        done = tpad_rt(*plot(tmp_path, str(tmp_path / "x.npz")))
    else:
        done = tpad_rt(*show(tmp_path, "--resolution-mm", "2", texture_path=path))
    assert (done.returncode, done.stderr) == (0, "")
    assert (tmp_path / "x.png").stat().st_size > 1000
