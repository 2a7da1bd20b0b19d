"""``wav:///path/out.wav``: the drive as a mono 32-bit float WAV file, streamed to disk.

``wav:///abs/path.wav`` or ``wav://relative/path.wav``. The stdlib ``wave`` module
writes only integer PCM, so the header is written here: RIFF/WAVE with a ``fmt ``
chunk of format 3 (IEEE float), a ``fact`` chunk (required for non-PCM formats) and
the ``data`` chunk; the sizes are filled in on :meth:`WavOutput.close`. Samples are
the DAC values as they are (full scale 1.0 = ``volts_per_full_scale``).

The file is written through :class:`tpad_rt.files.NewFile`: a temporary file created
exclusively beside the path, renamed onto it when the output closes with its header
complete. Until then whatever was at the path stays as it was; a write that fails (a
full disk) or a run that ends in an error (the output left by an exception) removes the
temporary file and leaves nothing new at the path.

A block holding a sample that is not finite or beyond full scale (a bug in tpad-rt) is
refused: the file is closed at once, its header counting the samples before that
block, so it is a valid WAV of the drive up to the fault, and the error says so.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt

from tpad_rt.device import Device
from tpad_rt.drive_guard import bad_sample_message, first_bad_sample
from tpad_rt.errors import BackendError
from tpad_rt.files import NewFile
from tpad_rt.outputs.base import Capability, Consumes, Output, OutputKind
from tpad_rt.urls import Url, UrlForm

#: The accepted URL.
FORMS = (UrlForm("wav", "/path/out.wav"),)
#: What it consumes and what runs it.
KIND = OutputKind(Consumes.DAC, "tpad_rt.drivers.paced:PacedDriver", Capability.OFFLINE | Capability.WRITES_FILE)

_FORMAT_IEEE_FLOAT = 3
BYTES_PER_SAMPLE = 4
# Byte offsets of the sizes patched on close (header: RIFF 12 + fmt 26 + fact 12 + data 8).
_RIFF_SIZE_AT = 4
_FACT_FRAMES_AT = 46
_DATA_SIZE_AT = 54
_HEADER_BYTES = 58
#: RIFF sizes are 32-bit.
MAX_DATA_BYTES = 2**32 - 1 - (_HEADER_BYTES - 8)


def _header(fs_hz: int, data_bytes: int) -> bytes:
    frames = data_bytes // BYTES_PER_SAMPLE
    fmt = struct.pack("<HHIIHHH", _FORMAT_IEEE_FLOAT, 1, fs_hz, fs_hz * BYTES_PER_SAMPLE,
                      BYTES_PER_SAMPLE, 8 * BYTES_PER_SAMPLE, 0)
    return b"".join([
        b"RIFF", struct.pack("<I", _HEADER_BYTES - 8 + data_bytes), b"WAVE",
        b"fmt ", struct.pack("<I", len(fmt)), fmt,
        b"fact", struct.pack("<II", 4, frames),
        b"data", struct.pack("<I", data_bytes),
    ])


class WavOutput(Output):
    """Streams blocks into a 32-bit float mono WAV file at ``path``, sample rate ``fs_hz`` (Hz), which appears
    there on :meth:`close` (module docstring).

    Raises ConfigError when ``path`` exists and is not a regular file (a FIFO, a
    device, a directory), lies in no folder or its folder cannot be written,
    BackendError when the header cannot be written.
    """

    def __init__(self, path: str | Path, fs_hz: int):
        super().__init__(fs_hz)
        self.path = Path(path)
        self.data_bytes = 0
        self._new = NewFile(self.path, "WAV files")
        self._file = self._new.file
        try:
            self._file.write(_header(fs_hz, 0))
        except OSError as error:
            raise self._new.failed(error) from None

    def write_blocks(self, samples: npt.NDArray[np.float32], block_frames: int,
                     blocks: Mapping[str, npt.NDArray[Any]]) -> None:
        """Append every block's samples in one :meth:`write` (the telemetry rows are not stored)."""
        self.write(samples, {})

    def write(self, samples: npt.NDArray[np.float32], block: Mapping[str, float]) -> None:
        """Append ``samples``; BackendError when the file would pass the 4 GiB RIFF limit, a write fails,
        the file was closed, or a sample is not finite or beyond full scale (the file is then closed)."""
        if self._file.closed:
            raise BackendError(f"wav: {self.path} is closed; nothing more can be written to it")
        values = np.asarray(samples, dtype="<f4")
        bad = first_bad_sample(values)
        if bad is not None:
            written = self.data_bytes // BYTES_PER_SAMPLE
            self.close()
            raise BackendError(
                f"wav: {self.path}: {bad_sample_message(written + bad, float(values[bad]))}; the file was "
                f"closed holding the {written} samples written before this write"
            )
        data = values.tobytes()
        if self.data_bytes + len(data) > MAX_DATA_BYTES:
            raise BackendError(f"wav: {self.path} would exceed the 4 GiB WAV size limit; render a shorter span")
        try:
            self._file.write(data)
        except OSError as error:
            raise self._new.failed(error) from None
        self.data_bytes += len(data)

    def close(self) -> None:
        """Fill in the header's sizes and move the file to its path (again: nothing); BackendError when that
        fails (a full disk, a file-size limit): nothing is then written at the path."""
        if self._file.closed:
            return
        try:
            header = _header(self.fs_hz, self.data_bytes)
            for offset in (_RIFF_SIZE_AT, _FACT_FRAMES_AT, _DATA_SIZE_AT):
                self._file.seek(offset)
                self._file.write(header[offset:offset + 4])
        except OSError as error:
            raise self._new.failed(error) from None
        self._new.commit()  # flushes what is buffered: a full disk may show only here

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        """Close the file when the block ends normally; discard it when the block raises (no partial WAV)."""
        if error is None:
            self.close()
        else:
            self._new.discard()


def open_url(url: Url, *, device: Device, fs_hz: int) -> WavOutput:
    """A WavOutput writing the file ``url`` names; ConfigError without a path or with an option."""
    FORMS[0].read(url)
    if not url.target:
        raise url.fail("missing the file path", FORMS)
    return WavOutput(url.target, fs_hz)
