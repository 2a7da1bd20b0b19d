"""Recordings: a render's drive, per-block telemetry and metadata in one ``.npz`` file.

Entries (NumPy arrays; no pickled objects, so ``np.load(path, allow_pickle=False)``
reads every one):

- ``format`` (0-d str, ``"tpad-rt recording"``) and ``format_version`` (0-d int);
- ``fs`` (0-d int): sample rate (Hz) of ``drive``;
- ``drive`` (float32 ``[samples]``): the DAC samples, in ``[-1, 1]`` (1.0 is the
  metadata's ``volts_per_full_scale``); from a Renderer on an envelope output (a serial
  amplifier: metadata ``output_consumes`` is ``"envelope"``) the envelope at the
  envelope rate, in the amplifier's full scale;
- one 1-D array per block, all the same length: the telemetry columns ``t, x_mm, y_mm,
  speed_mm_s, force_n, target_mu, amplitude_um, voltage_v, power_w, saturated, plate_w``
  (``tpad_rt.kernel.layout.TEL_NAMES``; ``plate_w`` may be absent from a recording made before
  it was added), plus ``achieved_mu`` and
  ``plate_amplitude_um`` when the output was the simulated plate (NaN for a block it did
  not measure), and ``departed`` (1 where the achieved friction was further than the
  metadata's ``departure_tolerance_mu`` from the texture under the finger:
  :func:`tpad_rt.felt.judge_blocks`) from ``tpad-rt render``, and from a Renderer's
  recording (``play --record``) that rendered one texture all along;
- ``metadata_json`` (0-d str): a JSON object with at least the keys in
  :data:`REQUIRED_METADATA` (texture path and description, device label, carrier,
  volts per full scale, max voltage, power budgets, block size, tpad-rt version); a run's
  is made by :func:`run_metadata`, for ``tpad-rt render`` and the Renderer alike, and also
  holds ``input_url``, ``output_url``, ``render_options``, and the drive's
  ``output_consumes`` (``"DAC samples"`` or ``"envelope"``), ``drive_rate_hz`` and
  ``drive_source`` (``"device file"``, or the amplifier that reported the carrier, full
  scale and clamp: :class:`tpad_rt.drive.DriveSpec`).
"""

from __future__ import annotations

import json
import math
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from tpad_rt.drive_guard import bad_sample_message, first_bad_sample
from tpad_rt.errors import BackendError, ConfigError
from tpad_rt.files import NewFile
from tpad_rt.kernel.layout import CFG_POWER_AVG_W, CFG_POWER_CAP_W, TEL_NAMES
from tpad_rt.limits import MAX_RECORDING_SAMPLES, MAX_RENDER_BLOCKS
from tpad_rt.version import __version__

if TYPE_CHECKING:  # only for run_metadata's hints: reading a recording loads neither numba nor the pipeline
    from tpad_rt.pipeline import Pipeline
    from tpad_rt.texture import CompiledTexture

FORMAT = "tpad-rt recording"
FORMAT_VERSION = 1
#: Telemetry columns added to format 1 since its first recordings: read when present.
ADDED_NAMES = ("plate_w",)
#: Per-block arrays the simulated plate adds (both or neither).
SIM_NAMES = ("achieved_mu", "plate_amplitude_um")
#: Per-block arrays a render on the simulated plate adds (optional): 1 where the achieved friction
#: departed from the texture under the finger by more than the metadata's ``departure_tolerance_mu``.
JUDGED_NAMES = ("departed",)
#: Metadata keys every recording has (values: JSON numbers, text or null).
REQUIRED_METADATA = (
    "texture_path", "texture_description", "device_label", "carrier_hz", "volts_per_full_scale",
    "max_voltage_v", "power_budget_w", "power_avg_w", "power_window_s", "block_frames", "tpad_rt_version",
)
#: Metadata keys whose values are numbers (finite, >= 0; ``block_frames`` > 0).
_NUMERIC_METADATA = (
    "carrier_hz", "volts_per_full_scale", "max_voltage_v", "power_budget_w", "power_avg_w", "power_window_s",
    "block_frames",
)
#: Largest entry (bytes, uncompressed) a recording may hold: the drive at MAX_RECORDING_SAMPLES, plus headers.
MAX_ENTRY_BYTES = 4 * MAX_RECORDING_SAMPLES + 2**16
#: Largest recording (bytes, uncompressed): the drive and every per-block column at MAX_RENDER_BLOCKS.
MAX_RECORDING_BYTES = MAX_ENTRY_BYTES + (len(TEL_NAMES) + len(SIM_NAMES) + len(JUDGED_NAMES) + 8) * (
    8 * MAX_RENDER_BLOCKS + 2**16)


def run_metadata(pipeline: Pipeline, texture: CompiledTexture, *, texture_path: str | None, block_frames: int,
                 input_url: str, output_url: str) -> dict[str, Any]:
    """The metadata of a run of ``pipeline`` rendering ``texture`` (from ``texture_path``, None for one made in
    memory) in blocks of ``block_frames``: what ran, on what, with which settings; the drive is the run's
    (:attr:`tpad_rt.pipeline.Pipeline.drive`: on ``serial://`` the amplifier's, as its handshake set it) and
    the power limits the kernel applied, defaults resolved."""
    cfg = pipeline.arrays.cfg
    return {
        "texture_path": texture_path, "texture_description": texture.description,
        "device_label": pipeline.device.label, **pipeline.drive.metadata(),
        "power_budget_w": float(cfg[CFG_POWER_CAP_W]), "power_avg_w": float(cfg[CFG_POWER_AVG_W]),
        "power_window_s": pipeline.options.power_window_s, "block_frames": block_frames,
        "input_url": input_url, "output_url": output_url, "render_options": asdict(pipeline.options),
        "tpad_rt_version": __version__,
    }


@dataclass(frozen=True)
class Recording:
    """A render: ``fs_hz`` (Hz), ``drive`` (float32 DAC samples), ``blocks`` (name -> per-block array)
    and ``metadata`` (a JSON-compatible dict)."""

    fs_hz: int
    drive: npt.NDArray[np.float32]
    blocks: dict[str, np.ndarray]
    metadata: dict[str, Any]

    @property
    def has_sim(self) -> bool:
        """True when the plate was simulated (``achieved_mu`` and ``plate_amplitude_um`` present)."""
        return all(name in self.blocks for name in SIM_NAMES)


def write_recording(path: str | Path, recording: Recording) -> None:
    """Write ``recording`` to ``path`` (exactly that name), complete or not at all (:class:`tpad_rt.files.NewFile`).

    Raises BackendError, writing nothing, when a drive sample is not finite or beyond full
    scale (a bug in tpad-rt: the message names the first such sample), and ConfigError when
    ``recording`` otherwise breaks the format (see :func:`read_recording`). ``path`` that
    is no place to write (no folder, a directory, a FIFO) is a ConfigError, a write that
    fails (a full disk) a BackendError, as NewFile has them.
    """
    path = Path(path)
    drive = np.asarray(recording.drive)
    bad = first_bad_sample(drive) if drive.ndim == 1 and drive.dtype.kind == "f" else None
    if bad is not None:
        raise BackendError(f"{path}: recording not written: {bad_sample_message(bad, float(drive[bad]))}")
    entries = {
        "format": np.array(FORMAT),
        "format_version": np.array(FORMAT_VERSION),
        "fs": np.array(recording.fs_hz, dtype=np.int64),
        "drive": drive,
        "metadata_json": np.array(json.dumps(recording.metadata, allow_nan=False)),
        **recording.blocks,
    }
    _check(str(path), entries)
    with NewFile(path, "recordings") as new:
        np.savez(new.file, allow_pickle=False, **entries)


def read_recording(path: str | Path) -> Recording:
    """The recording in the ``.npz`` file at ``path``.

    Raises ConfigError naming the file when it is missing or unreadable, not an ``.npz``
    archive, holds pickled objects, or is not a valid recording of this format version
    (each problem found is one line).
    """
    _check_sizes(path)
    try:
        loaded = np.load(path, allow_pickle=False)
        if isinstance(loaded, np.ndarray):
            raise ConfigError(f"{path}: not a tpad-rt recording (a single .npy array, not an .npz archive)")
        with loaded as archive:
            entries = {name: archive[name] for name in archive.files}
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except (zipfile.BadZipFile, EOFError, OSError, ValueError) as error:
        reason = "holds pickled objects" if "Object arrays" in str(error) else "not an .npz archive"
        raise ConfigError(f"{path}: not a tpad-rt recording ({reason})") from None
    except MemoryError:  # an entry's header claiming more elements than the machine can address
        raise ConfigError(f"{path}: not a tpad-rt recording (an entry's header claims an array too large to "
                          "allocate)") from None
    _check(str(path), entries)
    blocks = {name: entries[name] for name in (*TEL_NAMES, *SIM_NAMES, *JUDGED_NAMES) if name in entries}
    return Recording(
        fs_hz=int(entries["fs"]),
        drive=entries["drive"],
        blocks=blocks,
        metadata=json.loads(str(entries["metadata_json"])),
    )


def _check_sizes(path: str | Path) -> None:
    """ConfigError when the archive at ``path`` would unpack to more than a recording can hold.

    Judged from the archive's directory before anything is decompressed (a few MB of
    deflated zeros can stand for gigabytes). Anything that is not a readable zip
    archive is left to ``np.load`` to report.
    """
    try:
        with zipfile.ZipFile(path) as archive:
            infos = archive.infolist()
    except (zipfile.BadZipFile, OSError, ValueError, EOFError):
        return
    for info in infos:
        if info.file_size > MAX_ENTRY_BYTES:
            raise ConfigError(f"{path}: entry '{info.filename}' unpacks to {info.file_size:,} bytes, more than the "
                              f"{MAX_ENTRY_BYTES:,} a recording's entry may (a drive of {MAX_RECORDING_SAMPLES:,} "
                              "samples)")
    total = sum(info.file_size for info in infos)
    if total > MAX_RECORDING_BYTES:
        raise ConfigError(f"{path}: unpacks to {total:,} bytes, more than the {MAX_RECORDING_BYTES:,} a recording "
                          "may")


def _check(where: str, entries: dict[str, np.ndarray]) -> None:
    """ConfigError listing every way ``entries`` break the format."""
    if "format" not in entries or entries["format"].shape != () or str(entries["format"]) != FORMAT:
        raise ConfigError(f"{where}: not a tpad-rt recording (no 'format' entry saying '{FORMAT}')")
    version = entries.get("format_version")
    if version is None or version.shape != () or version.dtype.kind not in "iu" or int(version) != FORMAT_VERSION:
        raise ConfigError(f"{where}: format_version: must be {FORMAT_VERSION}, got {_show(version)}")
    problems = [*_check_header(entries), *_check_blocks(entries), *_check_metadata(entries)]
    if problems:
        raise ConfigError([f"{where}: {problem}" for problem in problems])


def _show(value: np.ndarray | None) -> str:
    return "nothing" if value is None else f"{value.dtype} array of shape {value.shape}"


def _check_header(entries: dict[str, np.ndarray]) -> list[str]:
    problems = []
    fs = entries.get("fs")
    if fs is None or fs.shape != () or fs.dtype.kind not in "iu" or int(fs) <= 0:
        problems.append(f"fs: must be a whole number > 0, got {_show(fs)}")
    drive = entries.get("drive")
    if drive is None or drive.dtype != np.float32 or drive.ndim != 1:
        problems.append(f"drive: must be a 1-D float32 array, got {_show(drive)}")
    elif len(drive) and not (np.all(np.isfinite(drive)) and float(np.max(np.abs(drive))) <= 1.0):
        problems.append("drive: samples must be finite and in [-1, 1]")
    return problems


def _check_blocks(entries: dict[str, np.ndarray]) -> list[str]:
    problems = [f"{name}: missing" for name in TEL_NAMES if name not in entries and name not in ADDED_NAMES]
    present_sim = [name for name in SIM_NAMES if name in entries]
    if present_sim and len(present_sim) != len(SIM_NAMES):
        problems.append(f"{' and '.join(SIM_NAMES)}: must both be present or both absent")
    names = [name for name in (*TEL_NAMES, *SIM_NAMES, *JUDGED_NAMES) if name in entries]
    lengths = set()
    for name in names:
        array = entries[name]
        if array.ndim != 1 or array.dtype.kind not in "biuf":
            problems.append(f"{name}: must be a 1-D numeric array, got {_show(array)}")
        lengths.add(len(array) if array.ndim else -1)
    if len(lengths) > 1:
        problems.append("per-block arrays: must all have the same length, got " +
                        ", ".join(f"{name} {len(entries[name]) if entries[name].ndim else 'scalar'}" for name in names))
    return problems


def _check_metadata(entries: dict[str, np.ndarray]) -> list[str]:
    text = entries.get("metadata_json")
    if text is None or text.shape != () or text.dtype.kind != "U":
        return [f"metadata_json: must be a JSON text, got {_show(text)}"]
    try:
        metadata = json.loads(str(text))
    except json.JSONDecodeError as error:
        return [f"metadata_json: not valid JSON ({error.msg} at character {error.pos})"]
    if not isinstance(metadata, dict):
        return ["metadata_json: must be a JSON object"]
    problems = [f"metadata_json: {key}: missing" for key in REQUIRED_METADATA if key not in metadata]
    for key in REQUIRED_METADATA:
        value = metadata.get(key)
        if isinstance(value, float) and not math.isfinite(value):
            problems.append(f"metadata_json: {key}: must be finite, got {value}")
    for key in _NUMERIC_METADATA:
        value = metadata.get(key)
        if key not in metadata or (isinstance(value, float) and not math.isfinite(value)):
            continue  # said above
        low, rule = (0, "> 0") if key == "block_frames" else (0, ">= 0")
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            fine = value > low if key == "block_frames" else value >= low
        else:
            fine = False
        if not fine:
            problems.append(f"metadata_json: {key}: must be a number {rule}, got {json.dumps(value)[:40]}")
    return problems
