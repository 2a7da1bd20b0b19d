"""The ahead-of-time library (tpad_rt.aot): built with the system C compiler, bit-identical to numba's JIT
callbacks over thousands of blocks, refused when its stamp is stale, and loaded without numba; a file cut short,
damaged or foreign is refused in one line and never mapped (each tried in a child process: before the checks, such
a file killed the process with SIGBUS), and ``tpad-rt warm`` rebuilds it.

Where the library lives here: the ``aot`` fixture builds it once per session into a temporary folder laid out as a
``NUMBA_CACHE_DIR`` (``<tmp>/tpad_rt_aot``; child processes are given that ``NUMBA_CACHE_DIR``), never into the
checkout, so what the other tests run does not depend on whether this file ran first: they run what ``tpad-rt warm``
left beside numba's cache (tests/run warms before pytest, so under tests/run and in CI every test renders with the
library; in a checkout nobody warmed, with numba's JIT callbacks).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from conftest import REPO_ROOT, require_system
from jack_server import server_process
from tpad_rt.aot import library as aot_library
from tpad_rt.aot import stamp as aot_stamp
from tpad_rt.aot import build
from tpad_rt.aot.build import build_library, find_compiler
from tpad_rt.aot.library import SEAL_BYTES, AotLibrary, LibraryProblem, open_library, seal
from tpad_rt.device import Device
from tpad_rt.kernel import callback as cb
from tpad_rt.kernel import table as tab
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.realtime import CallbackTable
from tpad_rt.texture import load_compiled

TEXTURES = REPO_ROOT / "textures"
DEVICES = REPO_ROOT / "tpad_rt" / "devices"
RATE_HZ = 192000
#: Blocks rendered per configuration.
BLOCKS = 2500
#: Block record columns that hold times (they differ between any two runs).
TIMED_COLUMNS = (tab.BLOCK_ENTRY_NS, tab.BLOCK_COMPUTE_NS)


@dataclass(frozen=True)
class Built:
    """The session's library (``.library``) and the folder laid out as a NUMBA_CACHE_DIR that holds it."""

    library: AotLibrary
    cache_dir: Path


@pytest.fixture(scope="session")
def built(tmp_path_factory: pytest.TempPathFactory) -> Built:
    """The library for the current sources, built once per session into ``<tmp>/tpad_rt_aot`` (module docstring)."""
    require_system(find_compiler() is not None, "a C compiler (cc, gcc or clang)")
    cache_dir = tmp_path_factory.mktemp("numba-cache")
    path = build_library(folders=[cache_dir / "tpad_rt_aot"])
    assert path == cache_dir / "tpad_rt_aot" / aot_stamp.library_name(aot_stamp.library_stamp())
    return Built(open_library(path, aot_stamp.library_stamp()), cache_dir)


@pytest.fixture(scope="session")
def aot(built: Built) -> AotLibrary:
    """The session's library, loaded in this process."""
    return built.library


def _pipeline(device: str, texture: str, options: RenderOptions) -> Pipeline:
    device_model = Device.default() if device == "default" else Device.from_file(DEVICES / device)
    pipeline = Pipeline(device_model, load_compiled(TEXTURES / texture), RATE_HZ, options)
    pipeline.start()
    return pipeline


def _write_finger(pipeline: Pipeline, row: tuple[float, ...]) -> None:
    """Append a finger row straight into the ring, past push_finger's checks (the kernel's guard sees it)."""
    arrays = pipeline.arrays
    arrays.finger[arrays.finger_count[0] % arrays.finger.shape[0]] = row
    arrays.finger_count[0] += 1


def _finger_rows(rng: np.random.Generator, t_s: float, step: int) -> list[tuple[float, ...]]:
    """The finger samples written before block ``step`` at stream time ``t_s``: a swipe back and forth with
    lifts (touch-downs after them), speed and force changes, and now and then a NaN or absurd value, a
    stale time, or nothing (the watchdog)."""
    phase = step % 400
    if 300 <= phase < 330:
        return []  # silence: the watchdog closes the gate, the next sample is a touch-down
    down = 0.0 if 250 <= phase < 270 else 1.0
    x_mm = 60.0 + 40.0 * np.sin(step * 0.013)
    y_mm = 30.0 + 10.0 * np.cos(step * 0.007)
    force_n = 0.2 + 1.5 * (0.5 + 0.5 * np.sin(step * 0.021))
    row = [t_s - 2e-4, x_mm, y_mm, force_n if step % 5 else np.nan, down]
    draw = rng.random()
    if draw < 0.01 or step % 97 == 50:
        row[1 + rng.integers(3)] = np.nan  # a NaN position or force the boundary would refuse
    elif draw < 0.015:
        row[1] = 1e9  # an absurd position
    elif draw < 0.02:
        row[3] = -4.0  # a negative force
    elif draw < 0.025:
        row[0] = np.inf
    return [tuple(row)]


def _run(pipelines: tuple[Pipeline, Pipeline], callbacks: tuple[Any, Any], seed: int, scratch_frames: int,
         channels: int) -> None:
    """Render BLOCKS blocks through each callback on its own pipeline, fed the same finger rows, block sizes,
    reported delays and texture swaps; assert the outputs, kernel arrays and records are identical."""
    rng = np.random.default_rng(seed)
    tables = [CallbackTable(p.arrays, p.texture, channels=channels, channel=channels - 1,
                            scratch_frames=scratch_frames, block_rows=BLOCKS) for p in pipelines]
    for table in tables:
        table.set_lead_bound_s(0.004)
    outputs: list[list[np.ndarray]] = [[], []]
    for step in range(BLOCKS):
        frames = int(rng.choice([1, 16, 64, 64, 64, 256, 700]))
        delay_s = float(rng.choice([0.0, 0.002, 0.003, 0.05, -0.01, np.nan]))
        rows = _finger_rows(rng, pipelines[0].stream_time_s, step)
        swap = step % 700 == 699
        for pipeline, table, callback, out in zip(pipelines, tables, callbacks, outputs):
            for row in rows:
                _write_finger(pipeline, row)
            if swap:
                texture = "temporal_pulse.yaml" if table.active_slot == 0 else "bumps_grid.yaml"
                table.set_texture(load_compiled(TEXTURES / texture), pipeline.stream_time_s, running=False)
            block = np.full((frames, channels), np.nan, dtype=np.float32)
            table.call(block, callback, dac_delay_s=delay_s)
            out.append(block)
    jit, native = (np.concatenate(out) for out in outputs)
    assert jit.tobytes() == native.tobytes()
    assert np.abs(jit).max() > 0.05  # it rendered a drive, not only zeros
    for name in ("cfg", "state", "power_ring", "finger", "finger_count", "telem", "telem_count"):
        assert getattr(pipelines[0].arrays, name).tobytes() == getattr(pipelines[1].arrays, name).tobytes(), name
    assert tables[0].stats.tobytes() == tables[1].stats.tobytes()
    assert tables[0].drive.tobytes() == tables[1].drive.tobytes()
    untimed = [c for c in range(tab.BLOCK_COLS) if c not in TIMED_COLUMNS]
    assert np.array_equal(tables[0].blocks[:, untimed], tables[1].blocks[:, untimed])


@pytest.mark.parametrize(("device", "texture", "options", "scratch_frames", "channels"), [
    ("default", "grating.yaml", RenderOptions(), 4096, 1),
    ("SLG_0.56.yaml", "bitmap_logo.yaml", RenderOptions(track=True, braking=False), 256, 2),
    ("Gorilla_0.8.yaml", "layers_modulated.yaml", RenderOptions(preemphasis=False, control_interval=7), 4096, 3),
    ("default", "edges_buttons.yaml", RenderOptions(watchdog_ms=5.0, ramp_ms=0.5), 100, 1),
])
def test_library_render_callback_is_bit_identical_to_the_jit(aot: AotLibrary, device: str, texture: str,
                                                              options: RenderOptions, scratch_frames: int,
                                                              channels: int) -> None:
    pipelines = (_pipeline(device, texture, options), _pipeline(device, texture, options))
    _run(pipelines, (cb.render_callback, aot.render_callback), zlib.crc32(texture.encode()), scratch_frames, channels)
    faults = pipelines[1].faults()
    assert faults["faults"] != 0  # the guard met the bad finger rows on both sides alike
    assert aot.errors() == 0  # and no raise reached the error path (the JIT would have printed "unraisable")


def test_library_silence_callback_matches_the_jit(aot: AotLibrary) -> None:
    pipelines = (_pipeline("default", "grating.yaml", RenderOptions()),
                 _pipeline("default", "grating.yaml", RenderOptions()))
    tables = [CallbackTable(p.arrays, p.texture, channels=2) for p in pipelines]
    for callback, table in zip((cb.silence_callback, aot.silence_callback), tables):
        out = np.ones((96, 2), dtype=np.float32)
        for _ in range(50):
            table.call(out, callback, dac_delay_s=0.5)
        assert not out.any()
    assert tables[0].stats.tobytes() == tables[1].stats.tobytes()
    assert tables[1].stats[tab.STAT_CALLBACKS] == 50 and tables[1].stats[tab.STAT_LEAD_OVER] == 50


def test_library_publish_is_a_store(aot: AotLibrary) -> None:
    array = np.zeros(4, dtype=np.int64)
    aot.publish(array, 2, -7)
    assert array.tolist() == [0, 0, -7, 0]
    with pytest.raises(IndexError):
        aot.publish(array, 4, 1)
    with pytest.raises(ValueError):
        aot.publish(np.zeros(4), 0, 1)


def test_library_needs_only_libc_and_libm(aot: AotLibrary) -> None:
    nm = shutil.which("nm")
    require_system(nm is not None, "program 'nm' (binutils)")
    symbols = subprocess.run([str(nm), "-D", "--undefined-only", str(aot.path)], capture_output=True, text=True,
                             check=True).stdout.split()
    undefined = {name.split("@")[0] for name in symbols if name not in ("U", "w")}
    weak_runtime = {"_ITM_deregisterTMCloneTable", "_ITM_registerTMCloneTable", "__cxa_finalize", "__gmon_start__"}
    libc_libm = {"clock_gettime", "memset", "memcpy", "memmove", "sin", "cos", "exp", "expm1", "log1p", "hypot",
                 "pow", "sqrt", "floor", "fmod", "log", "atan2", "tan", "sinh", "cosh", "tanh"}
    assert undefined - weak_runtime <= libc_libm
    assert not any(name.startswith(("Py", "numba", "NRT", "_Py")) for name in undefined)
    exported = subprocess.run([str(nm), "-D", "--defined-only", str(aot.path)], capture_output=True, text=True,
                              check=True).stdout.split()[2::3]
    assert sorted(exported) == sorted((aot_library.RENDER_SYMBOL, aot_library.SILENCE_SYMBOL,
                                       aot_library.PUBLISH_SYMBOL, aot_library.STAMP_SYMBOL,
                                       aot_library.ERRORS_SYMBOL))


def test_the_stamp_covers_every_source_compiled_into_the_callbacks() -> None:
    compiled = {Path(source).resolve() for source in (cb.__file__, *tab.COMPILED_SOURCES)}
    assert compiled <= set(aot_stamp.SOURCES)


def test_a_stale_or_foreign_library_is_not_loaded(aot: AotLibrary, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    sources = tmp_path / "sources"
    sources.mkdir()
    copies = []
    for source in aot_stamp.SOURCES:
        copies.append(sources / source.name)
        shutil.copyfile(source, copies[-1])
    folder = tmp_path / "libraries"
    folder.mkdir()
    monkeypatch.setattr(aot_stamp, "SOURCES", tuple(copies))
    stamp = aot_stamp.library_stamp()
    shutil.copyfile(aot.path, folder / aot_stamp.library_name(stamp))
    found = aot_library.find([folder])
    assert found.library is not None and found.path == folder / aot_stamp.library_name(stamp)
    with copies[0].open("a") as edited:
        edited.write("\n")  # a source changed since the build: a new stamp, no library for it
    assert aot_library.find([folder]) == aot_library.Found(None, None, None)
    renamed = folder / aot_stamp.library_name(aot_stamp.library_stamp())
    shutil.copyfile(aot.path, renamed)  # a library under another stamp's name carries its own stamp
    found = aot_library.find([folder])
    assert found.library is None and found.path == renamed
    assert found.problem == "was built for other sources, numba or CPU (another stamp)"


def test_the_stamp_follows_numbas_code_settings_and_the_cpus_instruction_sets_only(
        monkeypatch: pytest.MonkeyPatch) -> None:
    before = aot_stamp.library_stamp()
    monkeypatch.setenv("NUMBA_BOUNDSCHECK", "1")
    assert aot_stamp.library_stamp() != before
    x86 = ("processor\t: 0\nvendor_id\t: GenuineIntel\ncpu family\t: 6\nmodel\t\t: 167\nstepping\t: 1\n"
           "microcode\t: 0x{microcode}\nflags\t\t: fpu sse2 avx2 fma {extra}\nbugs\t\t: {bugs}\n\nprocessor\t: 1\n")
    base = aot_stamp.cpu_identity(x86.format(microcode="5e", extra="rtm hle", bugs="spectre_v1"))
    # a microcode update: another revision, TSX taken away, a mitigation flag and a bug added
    assert aot_stamp.cpu_identity(x86.format(microcode="62", extra="md_clear flush_l1d", bugs="spectre_v1 mds")) == base
    assert aot_stamp.cpu_identity(x86.format(microcode="5e", extra="rtm hle avx512f", bugs="spectre_v1")) != base
    arm = "processor\t: 0\nFeatures\t: fp asimd {extra}\nCPU implementer\t: 0x41\nCPU part\t: 0xd0c\n"
    assert aot_stamp.cpu_identity(arm.format(extra="sve")) != aot_stamp.cpu_identity(arm.format(extra=""))


#: A child process: load() beside numba's cache in NUMBA_CACHE_DIR; prints whether it loaded and whether it imported
#: numba.
LOAD = """
import json, sys
from tpad_rt.aot import library
print(json.dumps({"loaded": library.load() is not None, "numba": "numba" in sys.modules}))
"""


def _child_load(cache_dir: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", LOAD], cwd=REPO_ROOT, capture_output=True, text=True, timeout=60,
                          env={**os.environ, "NUMBA_CACHE_DIR": str(cache_dir)})


def _forged(body: bytes, cut: int) -> bytes:
    """The first ``cut`` bytes of ``body`` with a seal that matches them: only the ELF check stands in the way."""
    return seal(body[:cut])


#: Files put at the library's path: (what, its bytes from the sealed library, what the loader says it found).
DAMAGE = [
    ("cut at 0x800", lambda sealed: sealed[:0x800], "has no seal at its end (2048 bytes: cut short"),
    ("cut at 0x4000", lambda sealed: sealed[:0x4000], "has no seal at its end (16384 bytes: cut short"),
    ("cut at 0xc000", lambda sealed: sealed[:0xc000], "has no seal at its end (49152 bytes: cut short"),
    ("its last byte gone", lambda sealed: sealed[:-1], "has no seal at its end"),
    ("empty", lambda sealed: b"", "has no seal at its end (0 bytes"),
    ("a byte flipped", lambda sealed: sealed[:0x3000] + bytes([sealed[0x3000] ^ 1]) + sealed[0x3001:],
     "does not match its seal (damaged)"),
    ("the seal's tag and digest of a cut body", lambda sealed: _forged(sealed[:-SEAL_BYTES], 0x4000),
     "has a segment ending at byte"),
    ("the seal over a few bytes", lambda sealed: _forged(sealed[:-SEAL_BYTES], 0x30), "is not an ELF file"),
    ("text", lambda sealed: seal(b"not a library\n" * 10), "is not an ELF file"),
]


@pytest.mark.parametrize(("what", "damage", "problem"), DAMAGE, ids=[case[0] for case in DAMAGE])
def test_a_damaged_library_is_refused_in_one_line_and_never_mapped(built: Built, tmp_path: Path, what: str,
                                                                   damage: Any, problem: str) -> None:
    folder = tmp_path / "tpad_rt_aot"
    folder.mkdir()
    path = folder / built.library.path.name
    path.write_bytes(damage(built.library.path.read_bytes()))
    done = _child_load(tmp_path)
    assert done.returncode == 0, (what, done.returncode, done.stderr)  # -7 (SIGBUS) before the checks
    assert json.loads(done.stdout) == {"loaded": False, "numba": False}
    line, = done.stderr.splitlines()
    assert line.startswith(f"tpad-rt: ignored the ahead-of-time library {path}: it {problem}"), line
    assert line.endswith("; the audio callbacks run on numba's JIT (tpad-rt warm builds it again)")


def test_a_fifo_or_a_folder_at_the_librarys_path_is_refused_without_waiting(built: Built, tmp_path: Path) -> None:
    for kind, make in (("fifo", os.mkfifo), ("folder", os.mkdir)):
        cache_dir = tmp_path / kind
        (cache_dir / "tpad_rt_aot").mkdir(parents=True)
        path = cache_dir / "tpad_rt_aot" / built.library.path.name
        make(path)
        done = _child_load(cache_dir)
        assert done.returncode == 0 and json.loads(done.stdout)["loaded"] is False, done.stderr
        assert done.stderr == f"tpad-rt: ignored the ahead-of-time library {path}: it is not a regular file; the " \
                              "audio callbacks run on numba's JIT (tpad-rt warm builds it again)\n"


def test_the_sealed_library_loads_in_a_child_without_numba(built: Built) -> None:
    done = _child_load(built.cache_dir)
    assert done.returncode == 0 and done.stderr == ""
    assert json.loads(done.stdout) == {"loaded": True, "numba": False}


def test_a_library_without_the_callbacks_is_refused(tmp_path: Path) -> None:
    compiler = find_compiler()
    require_system(compiler is not None, "a C compiler (cc, gcc or clang)")
    assert compiler is not None
    stamp = aot_stamp.library_stamp()
    (tmp_path / "other.c").write_text(f'const char tpad_rt_aot_stamp[] = "{stamp}";\n')
    subprocess.run([*compiler, "-shared", "-fPIC", "-o", str(tmp_path / "other.so"), str(tmp_path / "other.c")],
                   check=True, timeout=60)
    path = tmp_path / "sealed.so"
    path.write_bytes(seal((tmp_path / "other.so").read_bytes()))
    with pytest.raises(LibraryProblem, match="^lacks the symbol tpad_rt_render$"):
        open_library(path, stamp)


#: A child process: loads the library, cuts the file it came from short, then renders blocks with it.
CUT_WHILE_LOADED = """
import sys
import numpy as np
from pathlib import Path
from tpad_rt.aot import library
from tpad_rt.device import Device
from tpad_rt.pipeline import Pipeline, RenderOptions
from tpad_rt.realtime import CallbackTable
from tpad_rt.texture import load_compiled

loaded = library.find([Path(sys.argv[1])]).library
assert loaded is not None
with open(loaded.path, "r+b") as file:
    file.truncate(0x800)
pipeline = Pipeline(Device.default(), load_compiled(Path("textures/grating.yaml")), 192000, RenderOptions())
pipeline.start()
table = CallbackTable(pipeline.arrays, pipeline.texture)
out = np.zeros((256, 1), dtype=np.float32)
for _ in range(20):
    table.call(out, loaded.render_callback)
print(int(table.stats[0]))
"""


def test_a_library_cut_short_on_disk_after_it_loaded_keeps_rendering(built: Built, tmp_path: Path) -> None:
    shutil.copyfile(built.library.path, tmp_path / built.library.path.name)
    done = subprocess.run([sys.executable, "-c", CUT_WHILE_LOADED, str(tmp_path)], cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, (done.returncode, done.stderr)  # -7 (SIGBUS) when the file itself is mapped
    assert done.stdout.split() == ["20"]


#: A child process: warm's ahead-of-time part with the library folder given on the command line.
WARM = """
import sys
from pathlib import Path
from tpad_rt.cli import warm
warm._build_ahead_of_time([Path(sys.argv[1])])
"""


def test_warm_rebuilds_a_refused_library_saying_what_it_found(built: Built, tmp_path: Path) -> None:
    folder = tmp_path / "tpad_rt_aot"
    folder.mkdir()
    path = folder / built.library.path.name
    path.write_bytes(built.library.path.read_bytes()[:0x4000])
    done = subprocess.run([sys.executable, "-c", WARM, str(folder)], cwd=REPO_ROOT, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, (done.returncode, done.stderr)  # -7 (SIGBUS) when warm loaded it to look
    assert done.stdout.splitlines() == [
        f"tpad-rt warm: the ahead-of-time library {path} has no seal at its end (16384 bytes: cut short, or not "
        "written by the builder): building it again",
        f"tpad-rt warm: built the ahead-of-time audio callbacks: {path}"]
    assert path.read_bytes() == built.library.path.read_bytes()  # the same build, bit for bit
    assert sorted(folder.iterdir()) == [path]  # no temporary file left
    again = _child_load(tmp_path)
    assert json.loads(again.stdout)["loaded"] and again.stderr == ""


#: A child process: a Renderer on audio:// (the JACK server JACK_DEFAULT_SERVER names) renders a finger sample; it
#: prints which tpad_rt.kernel modules it imported, which module first imported numba, and the blocks rendered.
RENDERER_START = """
import json, sys, time, traceback

class FirstImporter:
    module = None
    def find_spec(self, name, path=None, target=None):
        if name == "numba" and self.module is None:
            frames = [f.filename for f in traceback.extract_stack() if "/tpad_rt/" in f.filename]
            self.module = frames[-1].split("/tpad_rt/")[-1] if frames else "?"
        return None

watch = FirstImporter()
sys.meta_path.insert(0, watch)
from tpad_rt.aot import library
from tpad_rt.engine import Renderer
with Renderer(output="audio://", texture="textures/grating.yaml") as renderer:
    renderer.push_finger(40.0, 20.0)
    deadline = time.monotonic() + 30.0
    while renderer.stats()["blocks"] == 0 and time.monotonic() < deadline:
        time.sleep(0.001)
    rendered = renderer.stats()["blocks"]
print(json.dumps({"aot": library.load() is not None, "numba_imported_by": watch.module,
                  "kernels": sorted(m for m in sys.modules if m.startswith("tpad_rt.kernel.") and
                                    m not in ("tpad_rt.kernel.layout", "tpad_rt.kernel.table_layout")),
                  "compiling": "tpad_rt.compiling" in sys.modules, "blocks": rendered}))
"""


def test_a_renderer_on_audio_starts_without_numba_when_the_library_is_there(built: Built) -> None:
    with server_process(RATE_HZ, 64) as server:
        result = subprocess.run([sys.executable, "-c", RENDERER_START], cwd=REPO_ROOT, capture_output=True,
                                text=True, timeout=120, env={**os.environ, "JACK_DEFAULT_SERVER": server.name,
                                                             "NUMBA_CACHE_DIR": str(built.cache_dir)})
    assert result.returncode == 0, result.stderr
    seen = json.loads(result.stdout.strip().splitlines()[-1])
    assert seen["aot"] and seen["blocks"] > 0
    assert seen["kernels"] == [] and not seen["compiling"] and seen["numba_imported_by"] is None


def test_the_build_command_says_in_one_line_when_there_is_no_compiler_or_it_fails(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("CC", "/no/such/cc -m64")
    assert build.main() == 1
    assert capsys.readouterr().err.strip().splitlines() == [
        "aot: no C compiler (CC=/no/such/cc -m64 names no program on PATH): the kernels stay on numba's JIT"]
    false = shutil.which("false")
    require_system(false is not None, "program 'false'")
    monkeypatch.setenv("CC", str(false))
    assert build.main() == 1
    assert capsys.readouterr().err.strip().splitlines()[-1] == f"aot: linking with {false} failed (exit 1): no message"
    monkeypatch.setenv("PATH", "/nonexistent")
    monkeypatch.delenv("CC")
    assert build.main() == 1
    assert capsys.readouterr().err.strip().splitlines() == [
        "aot: no C compiler (set CC, or install cc, gcc or clang): the kernels stay on numba's JIT"]


def test_the_build_takes_cc_with_flags_as_make_does(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    compiler = find_compiler()
    require_system(compiler is not None, "a C compiler (cc, gcc or clang)")
    assert compiler is not None
    monkeypatch.setenv("CC", f"{Path(compiler[0]).name} -O2 -g0")
    said: list[str] = []
    path = build_library(said.append, folders=[tmp_path])
    assert path is not None and f"linking with {compiler[0]} -O2 -g0" in said
    assert open_library(path, aot_stamp.library_stamp()).path == path


@pytest.mark.parametrize("name", ["channels", "scratch_frames", "drive_frames", "block_rows"])
@pytest.mark.parametrize("value", [0, -1, 2.5, True])
def test_the_callback_table_refuses_an_empty_ring_or_scratch(name: str, value: Any) -> None:
    """Before the check, 0 made the callback loop for ever (scratch) or write past an empty ring (drive, blocks)."""
    pipeline = _pipeline("default", "grating.yaml", RenderOptions())
    with pytest.raises(ValueError, match=f"^{name}: must be a whole number of at least 1, got {value!r}$"):
        CallbackTable(pipeline.arrays, pipeline.texture, **{name: value})


def test_the_build_says_in_one_line_when_this_llvmlite_lacks_what_it_reaches(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    require_system(find_compiler() is not None, "a C compiler (cc, gcc or clang)")
    import llvmlite
    import llvmlite.binding
    import numba

    monkeypatch.delattr(llvmlite.binding, "create_new_module_pass_manager")  # as llvmlite before 0.44 lacks it
    assert build.main() == 1
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        f"aot: numba {numba.__version__} with llvmlite {llvmlite.__version__} cannot build it (AttributeError: module "
        "'llvmlite.binding' has no attribute 'create_new_module_pass_manager'); the JIT stays")


def test_ctrl_c_stops_the_build_in_one_line(tmp_path: Path) -> None:
    """SIGINT while the C compiler runs (a stand-in that waits, so the signal lands there and not by chance):
    exit 130, one line, no traceback."""
    compiler = tmp_path / "cc"
    compiler.write_text(f"#!/bin/sh\necho $$ > {tmp_path / 'pid'}\nexec sleep 120\n")
    compiler.chmod(0o755)
    child = subprocess.Popen([sys.executable, "-m", "tpad_rt.aot.build"], cwd=REPO_ROOT, stdin=subprocess.DEVNULL,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env={**os.environ, "CC": str(compiler)})
    assert child.stderr is not None
    seen = []
    for line in child.stderr:
        seen.append(line)
        if line.startswith("aot: linking with"):
            break
    deadline = time.monotonic() + 60.0
    while not (tmp_path / "pid").is_file() and time.monotonic() < deadline:
        time.sleep(0.01)
    child.send_signal(signal.SIGINT)
    out, err = child.communicate(timeout=60)
    stand_in = int((tmp_path / "pid").read_text())
    with contextlib.suppress(OSError):  # orphaned when the signal landed inside Popen() itself (Python's own race)
        if Path(f"/proc/{stand_in}/cmdline").read_bytes() == b"sleep\0" b"120\0":
            os.kill(stand_in, signal.SIGKILL)
    assert child.returncode == 130, "".join(seen) + err
    assert err == "aot: interrupted\n" and out == ""


def test_the_exception_types_the_error_path_reads_are_pointers(aot: AotLibrary) -> None:
    nm = shutil.which("nm")
    require_system(nm is not None, "program 'nm' (binutils)")
    listed = subprocess.run([str(nm), "-S", str(aot.path)], capture_output=True, text=True, check=True).stdout
    sizes = {fields[3]: int(fields[1], 16) for fields in map(str.split, listed.splitlines()) if len(fields) == 4}
    assert {name: sizes[name] for name in build._ERROR_PATH_DATA} == dict.fromkeys(build._ERROR_PATH_DATA, 8)
