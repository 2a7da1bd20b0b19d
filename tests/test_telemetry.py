"""The telemetry log: an output's per-block measurements joined to the rows by block time (whichever comes
first), bounded; push-to-DAC latency from the block records. Real pipeline, real callback, no clock."""

from __future__ import annotations

import gc
import math
import weakref
from pathlib import Path

import numpy as np
import pytest

import tpad_rt.telemetry
from tpad_rt.device import Device
from tpad_rt.felt import DEPARTURE_TOLERANCE_MU, judge_blocks
from tpad_rt.kernel import table as tab
from tpad_rt.kernel.layout import FLAG_SHAPER_LIMIT, STATE_NEXT_INDEX, TEL_NAMES
from tpad_rt.pipeline import Pipeline
from tpad_rt.realtime import CallbackTable, monotonic_ns
from tpad_rt.recording import read_recording, run_metadata
from tpad_rt.telemetry import TelemetryLog
from tpad_rt.texture import load_compiled

GRATING = Path(__file__).resolve().parents[1] / "textures" / "grating.yaml"
RATE_HZ, BLOCK = 96000, 96
NAMES = ("plate_amplitude_um", "achieved_mu")


def _setup() -> tuple[Pipeline, CallbackTable, TelemetryLog]:
    pipeline = Pipeline(Device.default(), load_compiled(GRATING), fs_hz=RATE_HZ)
    return pipeline, CallbackTable(pipeline.arrays, load_compiled(GRATING)), TelemetryLog(pipeline, RATE_HZ)


def _render(table: CallbackTable, blocks: int) -> np.ndarray:
    """Render ``blocks`` blocks; their start times (s)."""
    t_s = []
    for _ in range(blocks):
        t_s.append(table.next_sample / RATE_HZ)
        table.call(np.zeros(BLOCK, dtype=np.float32))
    return np.array(t_s)


def _measured(t_s: np.ndarray) -> dict[str, np.ndarray]:
    """Measurements that say which block they are of: 1000 x its time, and its index + 0.5."""
    return {"plate_amplitude_um": 1000 * t_s, "achieved_mu": t_s * RATE_HZ / BLOCK + 0.5}


def test_nothing_keeps_a_log_or_its_pipeline_alive() -> None:
    pipeline, table, log = _setup()
    gone = weakref.ref(pipeline), weakref.ref(log)
    del pipeline, table, log
    gc.collect()
    assert gone[0]() is None and gone[1]() is None  # a Renderer's arrays go with it (60 runs once leaked 64 MB)


def test_rows_wait_for_their_measurements_and_every_row_is_read_once() -> None:
    """Rows drained before their blocks' measurements come wait; measurements that come first wait for their
    rows; each row is read once, with its own block's values."""
    _, table, log = _setup()
    log.begin_measurements(NAMES)
    first = _render(table, 5)
    log.add_measurements(first[:2], _measured(first[:2]))  # blocks 0-1 measured before their rows are drained
    log.drain(table)
    taken = log.take()
    assert np.array_equal(taken["t"], first[:2])  # 2-4 wait: not measured yet
    log.add_measurements(first[2:], _measured(first[2:]))
    second = _render(table, 3)
    log.add_measurements(second, _measured(second))
    log.drain(table)
    rest = log.take()
    assert np.array_equal(rest["t"], np.r_[first[2:], second])
    everything = {name: np.r_[taken[name], rest[name]] for name in taken}
    assert set(everything) == {*TEL_NAMES, *NAMES}
    assert np.array_equal(everything["plate_amplitude_um"], 1000 * everything["t"])
    assert np.allclose(everything["achieved_mu"], np.arange(8) + 0.5, rtol=0, atol=1e-9)
    assert len(log.take()["t"]) == 0 and set(log.take()) == {*TEL_NAMES, *NAMES}


def test_once_the_measuring_ends_rows_without_one_come_with_nan() -> None:
    """A block the output never measured (it failed on it) does not hold the rows back once the run ended."""
    _, table, log = _setup()
    log.begin_measurements(NAMES)
    t_s = _render(table, 4)
    log.add_measurements(t_s[:3], _measured(t_s[:3]))
    log.drain(table)
    assert len(log.take()["t"]) == 3
    log.end_measurements()
    last = log.take()
    assert np.array_equal(last["t"], t_s[3:]) and np.isnan(last["achieved_mu"]).all()
    _render(table, 2)  # rendered with no one measuring: read at once
    log.drain(table)
    assert np.isnan(log.take()["plate_amplitude_um"]).all()


def test_without_measurements_the_rows_are_the_telemetry_s() -> None:
    _, table, log = _setup()
    _render(table, 3)
    log.drain(table)
    rows = log.take()
    assert set(rows) == set(TEL_NAMES) and len(rows["t"]) == 3 and log.measured_names == ()


def test_what_waits_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    """Rows whose measurements do not come, measurements whose rows are not drained and rows no one takes are
    each kept at most MAX_PENDING_ROWS (the oldest go first)."""
    monkeypatch.setattr(tpad_rt.telemetry, "MAX_PENDING_ROWS", 10)
    _, table, log = _setup()
    log.begin_measurements(NAMES)
    _render(table, 25)
    log.drain(table)  # no measurement: 15 rows go on unmeasured, the newest 10 wait
    rows = log.take()
    assert np.array_equal(np.rint(rows["t"] * RATE_HZ / BLOCK), np.arange(5, 15))  # the newest 10 of the 15
    assert np.isnan(rows["achieved_mu"]).all()
    ahead = (np.arange(100) + 1000) * BLOCK / RATE_HZ  # measurements of blocks 1000-1099, not rendered yet
    for k in range(0, 100, 5):
        log.add_measurements(ahead[k:k + 5], _measured(ahead[k:k + 5]))  # the first releases the 10 waiting
    rows = log.take()
    assert np.array_equal(np.rint(rows["t"] * RATE_HZ / BLOCK), np.arange(15, 25))
    assert np.isnan(rows["achieved_mu"]).all()
    _render(table, 1095 - 25)
    log.drain(table)
    rows = log.take()  # blocks 1085-1094; of the measurements only those of 1090-1099 were kept
    assert np.array_equal(np.rint(rows["t"] * RATE_HZ / BLOCK), np.arange(1085, 1095))
    assert np.isnan(rows["achieved_mu"][:5]).all()
    assert np.allclose(rows["achieved_mu"][5:], np.arange(1090, 1095) + 0.5, rtol=0, atol=1e-9)


@pytest.mark.parametrize(("names", "problem"), [
    ((), "need distinct names"), (("t",), "need distinct names"), (("a", "a"), "need distinct names"),
])
def test_bad_measured_names_are_refused(names: tuple[str, ...], problem: str) -> None:
    _, _, log = _setup()
    with pytest.raises(ValueError, match=problem):
        log.begin_measurements(names)


def test_measurements_must_match_the_names_and_blocks() -> None:
    _, _, log = _setup()
    with pytest.raises(ValueError, match="begin_measurements"):
        log.add_measurements(np.zeros(1), {"a": np.zeros(1)})
    log.begin_measurements(NAMES)
    with pytest.raises(ValueError, match="for 2 blocks"):
        log.add_measurements(np.zeros(2), {"plate_amplitude_um": np.zeros(2), "achieved_mu": np.zeros(1)})
    with pytest.raises(ValueError, match="but the log's readers have"):
        log.begin_measurements(("other",))


def _push_and_render(pipeline: Pipeline, table: CallbackTable, log: TelemetryLog, blocks: int) -> list[float]:
    """Render ``blocks`` blocks with 0, 1 or 2 samples pushed before each (push times made up), draining after each; each sample's expected latency (ms): the DAC time of the next block minus its
    push time."""
    pushed_ns: dict[int, int] = {}
    expected_ms: list[float] = []
    for k in range(blocks):
        for j in range(k % 3):
            index = int(pipeline.arrays.finger_count[0])
            pipeline.push_finger(table.next_sample / RATE_HZ, 30.0, 20.0)
            pushed_ns[index] = monotonic_ns() - 1_000 * (10 * k + j)  # any time before the block: the log takes it
            log.note_push(index, pushed_ns[index])
        table.call(np.zeros(BLOCK, dtype=np.float32))
        log.drain(table)
        record = table.recent_blocks()[-1]
        out_ns = int(record[tab.BLOCK_ENTRY_NS] + record[tab.BLOCK_DAC_DELAY_NS])
        expected_ms += [(out_ns - pushed_ns[index]) * 1e-6 for index in sorted(pushed_ns)[len(expected_ms):]]
    return expected_ms


def _nearest_rank(values: list[float], q: float) -> float:
    return sorted(values)[max(math.ceil(q / 100 * len(values)), 1) - 1]


def test_latency_is_from_each_push_to_the_dac_time_of_the_first_block_that_read_it() -> None:
    """Samples pushed between blocks: each one's latency is the next block's DAC time minus its push time (the
    Renderer notes pushes; the block records are the callback's own)."""
    pipeline, table, log = _setup()
    table.call(np.zeros(BLOCK, dtype=np.float32))  # the run's first block: what it reads was pushed before the run
    expected_ms = _push_and_render(pipeline, table, log, 6)
    assert len(expected_ms) == 6
    latency = log.latency_ms()
    assert latency == {f"latency_ms_p{q}": pytest.approx(_nearest_rank(expected_ms, q), rel=0.012) for q in (50, 99)}


def test_latency_covers_the_whole_run_not_the_blocks_the_ring_still_holds() -> None:
    """Pushes in a run's first blocks, then many more blocks than the block ring holds without any (a finger
    that rested: a live input's run): the latency is still that of the pushes."""
    pipeline = Pipeline(Device.default(), load_compiled(GRATING), fs_hz=RATE_HZ)
    table = CallbackTable(pipeline.arrays, load_compiled(GRATING), block_rows=8)
    log = TelemetryLog(pipeline, RATE_HZ)
    table.call(np.zeros(BLOCK, dtype=np.float32))
    expected_ms = _push_and_render(pipeline, table, log, 9)
    for _ in range(5):
        _render(table, 6)
        log.drain(table)
    assert len(table.recent_blocks()) < 30 and not np.diff(table.recent_blocks()[:, tab.BLOCK_FINGER_COUNT]).any()
    assert log.latency_ms()["latency_ms_p50"] == pytest.approx(_nearest_rank(expected_ms, 50), rel=0.012)


def test_blocks_the_ring_lost_before_a_drain_are_not_folded_in_as_if_next_to_the_ones_kept() -> None:
    """More blocks than the ring holds between two drains: the samples read by the lost blocks are not counted
    (their block is not known), and the kept blocks' are."""
    pipeline = Pipeline(Device.default(), load_compiled(GRATING), fs_hz=RATE_HZ)
    table = CallbackTable(pipeline.arrays, load_compiled(GRATING), block_rows=4)
    log = TelemetryLog(pipeline, RATE_HZ)
    table.call(np.zeros(BLOCK, dtype=np.float32))
    log.drain(table)
    index = int(pipeline.arrays.finger_count[0])
    pipeline.push_finger(table.next_sample / RATE_HZ, 30.0, 20.0)
    log.note_push(index, 0)  # read by a block the ring loses: its latency would be that block's DAC time
    _render(table, 10)
    index = int(pipeline.arrays.finger_count[0])
    pipeline.push_finger(table.next_sample / RATE_HZ, 30.0, 20.0)
    pushed_ns = int(table.recent_blocks()[-1][tab.BLOCK_ENTRY_NS])
    log.note_push(index, pushed_ns)
    _render(table, 1)
    log.drain(table)
    record = table.recent_blocks()[-1]
    expected_ms = (int(record[tab.BLOCK_ENTRY_NS] + record[tab.BLOCK_DAC_DELAY_NS]) - pushed_ns) * 1e-6
    assert log.latency_ms() == {f"latency_ms_p{q}": pytest.approx(expected_ms, rel=0.012) for q in (50, 99)}


def test_totals_keep_the_drive_peak_and_tell_the_shaper_s_kicks_apart() -> None:
    """A finger touching down: the shaper kicks the drive to its limit (flag SHAPER_LIMIT) for a few blocks; the
    totals keep the peak, those blocks and the peak of the others, over every row drained."""
    pipeline, table, log = _setup()
    pipeline.start()
    rows = []
    for k in range(60):
        pipeline.push_finger(table.next_sample / RATE_HZ, 30.0 + 0.1 * k, 20.0)
        table.call(np.zeros(BLOCK, dtype=np.float32))
        if k % 7 == 0:
            log.drain(table)
            rows.append(log.take())
    log.drain(table)
    rows.append(log.take())
    flags = np.concatenate([chunk["saturated"] for chunk in rows])
    volts = np.concatenate([chunk["voltage_v"] for chunk in rows])
    kicks = (flags & FLAG_SHAPER_LIMIT) != 0
    assert kicks.any() and not kicks.all()
    totals = log.totals()
    assert totals["kick_blocks"] == np.count_nonzero(kicks)
    assert totals["peak_v"] == volts.max() and totals["peak_outside_kicks_v"] == volts[~kicks].max()


def test_latency_without_pushes_is_nan() -> None:
    _, table, log = _setup()
    _render(table, 3)
    log.drain(table)
    latency = log.latency_ms()
    assert np.isnan(latency["latency_ms_p50"]) and np.isnan(latency["latency_ms_p99"])


def test_a_recording_takes_the_drive_up_to_the_last_finished_block_not_the_published_index(tmp_path: Path) -> None:
    """A block's index is published while it renders and its samples reach the drive ring after: a drain in
    between (the watcher, on another core) must not copy the ring's stale samples from its previous lap. Here the
    kernel's published index is put ahead of the finished blocks, as a drain would find it mid-block."""
    pipeline, table, log = _setup()
    assert table.drive_end() is None  # no block finished yet
    log.record(tmp_path / "run.npz")
    pipeline.start()
    pipeline.push_finger(0.0, 30.0, 20.0)
    _render(table, 4)
    assert table.drive_end() == 4 * BLOCK == table.next_sample
    table.drive[4 * BLOCK:5 * BLOCK] = 0.75  # the ring's stale lap, where block 4 will go
    table.arrays.state[STATE_NEXT_INDEX] = 5 * BLOCK  # block 4 published, its samples not yet in the ring
    log.drain(table)
    table.arrays.state[STATE_NEXT_INDEX] = 4 * BLOCK
    _render(table, 2)
    log.drain(table)
    log.write_recording(run_metadata(pipeline, load_compiled(GRATING), texture_path=None, block_frames=BLOCK,
                                     input_url="api", output_url="null://"))
    drive = read_recording(tmp_path / "run.npz").drive
    assert len(drive) == 6 * BLOCK and not np.any(drive == 0.75)
    assert np.array_equal(drive, table.drive[:6 * BLOCK])


def test_a_recording_on_a_measured_plate_has_its_columns_and_departures_as_render_judges_them(tmp_path: Path) -> None:
    """An output that measures the plate (sim://): the recording has the measured columns of each block (NaN for
    one not measured), and ``departed`` judged against the texture under the recorded finger, by the function
    ``render`` judges with."""
    pipeline, table, log = _setup()
    texture = load_compiled(GRATING)
    log.begin_measurements(NAMES)
    log.record(tmp_path / "run.npz")
    pipeline.start()
    for k in range(40):  # a swipe, drained as the watcher would, every few blocks
        pipeline.push_finger(table.next_sample / RATE_HZ, 30.0 + 0.1 * k, 20.0)
        t_s = _render(table, 1)
        if k != 17:  # one block the output did not measure
            measured = _measured(t_s)
            if k % 3 == 0:
                measured["achieved_mu"] = np.zeros(1)  # far from any texture: a departure where judged
            log.add_measurements(t_s, measured)
        if k % 5 == 4:
            log.drain(table)
    log.end_measurements()
    log.drain(table)
    fingers = pipeline.recent_fingers()
    log.write_recording(run_metadata(pipeline, texture, texture_path=None, block_frames=BLOCK, input_url="api",
                                     output_url="sim://"), texture)
    recording = read_recording(tmp_path / "run.npz")
    blocks = recording.blocks
    assert recording.has_sim and len(blocks["t"]) == 40
    index = np.round(blocks["t"] * RATE_HZ / BLOCK).astype(int)
    measured_now = ~np.isin(index, [17])
    assert np.isnan(blocks["achieved_mu"][~measured_now]).all()
    expected = _measured(blocks["t"])
    assert np.array_equal(blocks["plate_amplitude_um"][measured_now], expected["plate_amplitude_um"][measured_now])
    judged = judge_blocks(blocks, fingers, texture, block_s=BLOCK / RATE_HZ, mu_floor=pipeline.options.mu_floor)
    assert judged.departed.any() and not judged.departed.all()
    assert np.array_equal(blocks["departed"], judged.departed.astype(np.int8))
    assert not blocks["departed"][~measured_now].any()
    assert recording.metadata["departure_tolerance_mu"] == DEPARTURE_TOLERANCE_MU


def test_a_recording_without_a_texture_to_judge_against_has_no_departures(tmp_path: Path) -> None:
    """No texture given (the Renderer's was swapped while recording): the plate's columns, no ``departed``."""
    pipeline, table, log = _setup()
    log.begin_measurements(NAMES)
    log.record(tmp_path / "run.npz")
    pipeline.start()
    pipeline.push_finger(0.0, 30.0, 20.0)
    t_s = _render(table, 3)
    log.add_measurements(t_s, _measured(t_s))
    log.drain(table)
    log.write_recording(run_metadata(pipeline, load_compiled(GRATING), texture_path=None, block_frames=BLOCK,
                                     input_url="api", output_url="sim://"))
    recording = read_recording(tmp_path / "run.npz")
    assert recording.has_sim and "departed" not in recording.blocks
