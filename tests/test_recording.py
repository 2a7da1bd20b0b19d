"""Recordings (.npz): round trip, loadable without pickle, and every way a file can be wrong."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tpad_rt.errors import BackendError, ConfigError
from tpad_rt.kernel.layout import TEL_NAMES
from tpad_rt.recording import REQUIRED_METADATA, SIM_NAMES, Recording, read_recording, write_recording


def _recording(blocks: int = 5, sim: bool = True) -> Recording:
    rng = np.random.default_rng(7)
    names = (*TEL_NAMES, *SIM_NAMES) if sim else TEL_NAMES
    per_block = {name: rng.uniform(0, 1, blocks) for name in names}
    per_block["saturated"] = rng.uniform(0, 1, blocks) > 0.5
    metadata = {key: 1.5 for key in REQUIRED_METADATA} | {"texture_path": "textures/grating.yaml", "extra": [1, 2]}
    return Recording(192000, rng.uniform(-1, 1, 64 * blocks).astype(np.float32), per_block, metadata)


@pytest.mark.parametrize("sim", [True, False])
def test_round_trip(tmp_path: Path, sim: bool) -> None:
    original = _recording(sim=sim)
    write_recording(tmp_path / "r.npz", original)
    back = read_recording(tmp_path / "r.npz")
    assert back.fs_hz == 192000 and back.has_sim == sim
    assert back.drive.dtype == np.float32 and np.array_equal(back.drive, original.drive)
    assert back.blocks.keys() == original.blocks.keys()
    for name, values in original.blocks.items():
        assert np.array_equal(back.blocks[name], values) and back.blocks[name].dtype == values.dtype
    assert back.metadata == original.metadata


def test_plain_numpy_reads_it_without_pickle(tmp_path: Path) -> None:
    write_recording(tmp_path / "r.npz", _recording())
    with np.load(tmp_path / "r.npz", allow_pickle=False) as archive:
        entries = {name: archive[name] for name in archive.files}
    assert str(entries["format"]) == "tpad-rt recording" and int(entries["fs"]) == 192000
    assert json.loads(str(entries["metadata_json"]))["texture_path"] == "textures/grating.yaml"


def _broken(tmp_path: Path, **changes: np.ndarray | None) -> Path:
    """A recording file with entries replaced (or removed, for None)."""
    write_recording(tmp_path / "good.npz", _recording())
    with np.load(tmp_path / "good.npz") as archive:
        entries = {name: archive[name] for name in archive.files}
    for name, value in changes.items():
        if value is None:
            del entries[name]
        else:
            entries[name] = value
    np.savez(tmp_path / "bad.npz", **entries)
    return tmp_path / "bad.npz"


@pytest.mark.parametrize(
    ("changes", "expected"),
    [
        ({"format": None}, "not a tpad-rt recording (no 'format' entry saying 'tpad-rt recording')"),
        ({"format_version": np.array(2)}, "format_version: must be 1, got int64 array of shape ()"),
        ({"fs": np.array(0)}, "fs: must be a whole number > 0, got int64 array of shape ()"),
        ({"drive": np.zeros(4)}, "drive: must be a 1-D float32 array, got float64 array of shape (4,)"),
        ({"drive": np.array([0.5, 1.5], dtype=np.float32)}, "drive: samples must be finite and in [-1, 1]"),
        ({"power_w": None}, "power_w: missing"),
        ({"achieved_mu": None}, "achieved_mu and plate_amplitude_um: must both be present or both absent"),
        ({"t": np.zeros(3)}, "per-block arrays: must all have the same length, got t 3, x_mm 5"),
        ({"x_mm": np.array(["a"] * 5)}, "x_mm: must be a 1-D numeric array, got <U1 array of shape (5,)"),
        ({"metadata_json": np.array("{")}, "metadata_json: not valid JSON"),
        ({"metadata_json": np.array("[]")}, "metadata_json: must be a JSON object"),
        ({"metadata_json": np.array('{"carrier_hz": NaN}')}, "metadata_json: texture_path: missing"),
    ],
)
def test_invalid_recordings_name_the_problem(tmp_path: Path, changes: dict, expected: str) -> None:
    path = _broken(tmp_path, **changes)
    with pytest.raises(ConfigError) as caught:
        read_recording(path)
    assert f"{path}: {expected}" in str(caught.value)


def test_a_recording_made_before_plate_w_was_added_still_reads(tmp_path: Path) -> None:
    recording = read_recording(_broken(tmp_path, plate_w=None))
    assert "plate_w" not in recording.blocks and len(recording.blocks["power_w"]) == len(recording.blocks["t"])


def test_nan_metadata_is_refused(tmp_path: Path) -> None:
    path = _broken(tmp_path, metadata_json=np.array(json.dumps({key: float("nan") for key in REQUIRED_METADATA})))
    with pytest.raises(ConfigError, match="metadata_json: carrier_hz: must be finite, got nan"):
        read_recording(path)


def test_files_that_are_not_recordings(tmp_path: Path) -> None:
    (tmp_path / "text.npz").write_text("hello")
    np.save(tmp_path / "array.npy", np.zeros(3))
    np.savez(tmp_path / "objects.npz", a=np.array([{"x": 1}], dtype=object))
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    cases = {
        "missing.npz": "no such file",
        "text.npz": "not a tpad-rt recording (not an .npz archive)",
        "array.npy": "not a tpad-rt recording (a single .npy array, not an .npz archive)",
        "objects.npz": "not a tpad-rt recording (holds pickled objects)",
        "other.npz": "not a tpad-rt recording (no 'format' entry",
    }
    for name, expected in cases.items():
        with pytest.raises(ConfigError) as caught:
            read_recording(tmp_path / name)
        assert str(caught.value).startswith(f"{tmp_path / name}: {expected}")


def test_write_refuses_a_broken_recording_and_reports_unwritable_paths(tmp_path: Path) -> None:
    broken = _recording()
    broken.blocks["t"] = np.zeros(2)
    with pytest.raises(ConfigError, match="per-block arrays: must all have the same length"):
        write_recording(tmp_path / "r.npz", broken)
    with pytest.raises(ConfigError, match=r"r\.npz: cannot write recordings there: no folder .*/no$"):
        write_recording(tmp_path / "no" / "r.npz", _recording())
    assert sorted(path.name for path in tmp_path.iterdir()) == []


@pytest.mark.parametrize(("bad", "problem"), [(np.nan, "not finite"), (np.inf, "not finite"),
                                              (-1.0001, r"beyond full scale \(\|sample\| > 1\)")])
def test_write_refuses_a_bad_drive_sample_and_writes_nothing(tmp_path: Path, bad: float, problem: str) -> None:
    recording = _recording()
    recording.drive[200] = bad
    path = tmp_path / "r.npz"
    expected = (rf"r\.npz: recording not written: drive sample 200 is {float(np.float32(bad))!r}, {problem}: "
                r"the drive held a value no output may carry; this is a bug in tpad-rt, please report it")
    with pytest.raises(BackendError, match=expected):
        write_recording(path, recording)
    assert not path.exists()
