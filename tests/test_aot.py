"""The ahead-of-time library (tpad_rt.aot): built with the system C compiler, bit-identical to numba's JIT
callbacks over thousands of blocks, refused when its stamp is stale, and loaded without numba."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zlib
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
from tpad_rt.aot.library import AotLibrary, open_library
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


@pytest.fixture(scope="session")
def aot() -> AotLibrary:
    """The library for the current sources, built (or rebuilt) once per session."""
    require_system(find_compiler() is not None, "a C compiler (cc, gcc or clang)")
    path = build_library()
    assert path is not None
    library = open_library(path, aot_stamp.library_stamp())
    assert library is not None
    return library


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
    monkeypatch.setattr(aot_library, "library_dirs", lambda: [folder])
    stamp = aot_stamp.library_stamp()
    shutil.copyfile(aot.path, folder / aot_stamp.library_name(stamp))
    aot_library.load.cache_clear()
    try:
        loaded = aot_library.load()
        assert loaded is not None and loaded.path == folder / aot_stamp.library_name(stamp)
        with copies[0].open("a") as edited:
            edited.write("\n")  # a source changed since the build: a new stamp, no library for it
        aot_library.load.cache_clear()
        assert aot_library.load() is None
        renamed = folder / aot_stamp.library_name(aot_stamp.library_stamp())
        shutil.copyfile(aot.path, renamed)  # a library under another stamp's name carries its own stamp
        aot_library.load.cache_clear()
        assert aot_library.load() is None
    finally:
        aot_library.load.cache_clear()


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
    time.sleep(0.1)
    rendered = renderer.stats()["blocks"]
print(json.dumps({"aot": library.load() is not None, "numba_imported_by": watch.module,
                  "kernels": sorted(m for m in sys.modules if m.startswith("tpad_rt.kernel.") and
                                    m not in ("tpad_rt.kernel.layout", "tpad_rt.kernel.table_layout")),
                  "compiling": "tpad_rt.compiling" in sys.modules, "blocks": rendered}))
"""


def test_a_renderer_on_audio_starts_without_numba_when_the_library_is_there(aot: AotLibrary) -> None:
    with server_process(RATE_HZ, 64) as server:
        result = subprocess.run([sys.executable, "-c", RENDERER_START], cwd=REPO_ROOT, capture_output=True,
                                text=True, timeout=120, env={**os.environ, "JACK_DEFAULT_SERVER": server.name})
    assert result.returncode == 0, result.stderr
    seen = json.loads(result.stdout.strip().splitlines()[-1])
    assert seen["aot"] and seen["blocks"] > 0
    assert seen["kernels"] == [] and not seen["compiling"] and seen["numba_imported_by"] is None


def test_the_build_command_says_in_one_line_when_there_is_no_compiler_or_it_fails(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("CC", "no-such-compiler")
    assert build.main() == 1
    assert capsys.readouterr().err.strip().splitlines() == [
        "aot: no C compiler (set CC, or install cc, gcc or clang): the kernels stay on numba's JIT"]
    false = shutil.which("false")
    require_system(false is not None, "program 'false'")
    monkeypatch.setenv("CC", str(false))
    assert build.main() == 1
    assert capsys.readouterr().err.strip().splitlines()[-1] == f"aot: linking with {false} failed (exit 1): no message"
