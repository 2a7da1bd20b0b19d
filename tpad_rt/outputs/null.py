"""``null://``: discards the drive, counting the samples (a sink for benchmarks and tests)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from tpad_rt.device import Device
from tpad_rt.outputs.base import Capability, Consumes, Output, OutputKind
from tpad_rt.urls import Url, UrlForm

#: The accepted URL.
FORMS = (UrlForm("null"),)
#: What it consumes and what runs it.
KIND = OutputKind(Consumes.DAC, "tpad_rt.drivers.paced:PacedDriver", Capability.OFFLINE)


class NullOutput(Output):
    """Counts the samples written (``samples_written``) and keeps none."""

    def __init__(self, fs_hz: int):
        super().__init__(fs_hz)
        self.samples_written = 0

    def write(self, samples: npt.NDArray[np.float32], block: Mapping[str, float]) -> None:
        """Count ``samples``."""
        self.samples_written += len(samples)

    def write_blocks(self, samples: npt.NDArray[np.float32], block_frames: int,
                     blocks: Mapping[str, npt.NDArray[Any]]) -> None:
        """Count every block's samples."""
        self.samples_written += len(samples)


def open_url(url: Url, *, device: Device, fs_hz: int) -> NullOutput:
    """A NullOutput; ConfigError for any option or target."""
    FORMS[0].read(url)
    if url.target:
        raise url.fail(f"unexpected '{url.target}' after null://", FORMS)
    return NullOutput(fs_hz)
