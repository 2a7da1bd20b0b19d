"""What every output backend implements: take the drive, one block at a time.

A block is float32 DAC samples in ``[-1, 1]`` (sample ``1.0`` is the device's
``volts_per_full_scale``) at the output's sample rate, with the pipeline's telemetry
row for it (TEL_NAMES -> value: finger speed, contact force, target friction, ...).
Outputs that play to hardware ignore the row; the simulated plate needs the finger
speed and force to say what friction the finger would feel.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from types import TracebackType

import numpy as np
import numpy.typing as npt


class Output(ABC):
    """Base class of output backends (pyserial model: state what a backend must implement).

    A backend implements :meth:`write`; one that measures something per block returns it
    from :meth:`measurements`; one that holds a resource (a file, a stream) overrides
    :meth:`close`, which must be safe to call twice. Outputs are context managers that
    close on exit. ``fs_hz`` is the sample rate (Hz) the blocks are played at.
    """

    def __init__(self, fs_hz: int):
        self.fs_hz = fs_hz

    @abstractmethod
    def write(self, samples: npt.NDArray[np.float32], block: Mapping[str, float]) -> None:
        """Play or store the DAC ``samples`` of one block; ``block`` is its telemetry row.

        Raises BackendError when the backend fails (a full disk, a lost device).
        """

    def measurements(self) -> dict[str, npt.NDArray[np.float64]]:
        """Per-block arrays the output measured so far, by name (none by default)."""
        return {}

    def latest(self) -> dict[str, float]:
        """The last block's measurements, by name (none by default); cheap, for status lines."""
        return {}

    def close(self) -> None:
        """Finish and release what the output holds (nothing by default)."""

    def __enter__(self) -> Output:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        self.close()
