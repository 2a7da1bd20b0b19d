"""What every output declares (:class:`OutputKind`), and what a paced backend implements (:class:`Output`).

Every scheme's module states what it consumes, which driver runs it and what else it
can do (``KIND``, an :class:`OutputKind`): :mod:`tpad_rt.drivers` opens that driver, and
the Pipeline renders DAC samples or the envelope accordingly (docs/kernel.md "Two
stages"; docs/architecture.md "Adding an output kind").

The rest of this module is the paced backends' interface: take the drive, one block at a time.

A block is float32 DAC samples in ``[-1, 1]`` (sample ``1.0`` is the device's
``volts_per_full_scale``) at the output's sample rate, with the pipeline's telemetry
row for it (TEL_NAMES -> value: finger speed, contact force, target friction, ...).
Outputs that play to hardware ignore the row; the simulated plate needs the finger
speed and force to say what friction the finger would feel.
"""

from __future__ import annotations

import re
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Flag, auto
from types import TracebackType
from typing import Any

import numpy as np
import numpy.typing as npt

from tpad_rt.drive import Consumes
from tpad_rt.errors import ConfigError


class Capability(Flag):
    """What an output can do besides playing in real time; a scheme's ``KIND`` lists its flags."""

    NONE = 0
    #: it opens offline too (:func:`tpad_rt.outputs.open_output`, ``tpad-rt render``): a simulator or a file
    OFFLINE = auto()
    #: it writes the file its URL names
    WRITES_FILE = auto()


@dataclass(frozen=True)
class OutputKind:
    """What a scheme's output consumes, the driver that runs it in real time (``"module:Class"``, a
    :class:`tpad_rt.drivers.Driver`: named, not imported, since drivers sit a layer above outputs), and its
    :class:`Capability` flags."""

    consumes: Consumes
    driver: str
    capabilities: Capability = Capability.NONE

    def __post_init__(self) -> None:
        if not isinstance(self.consumes, Consumes):
            raise ConfigError(f"OutputKind: consumes: must be Consumes.DAC or Consumes.ENVELOPE, got {self.consumes!r}")
        if not (isinstance(self.driver, str) and re.fullmatch(r"[A-Za-z_][\w.]*:[A-Za-z_]\w*", self.driver)):
            raise ConfigError(f"OutputKind: driver: must name a driver class as 'module:Class' (text, not the class), "
                              f"got {self.driver!r}")
        if not isinstance(self.capabilities, Capability):
            raise ConfigError(f"OutputKind: capabilities: must be Capability flags, got {self.capabilities!r}")

    def can(self, capability: Capability) -> bool:
        """Whether the output has every flag of ``capability``."""
        return capability in self.capabilities


class Output(ABC):
    """Base class of output backends (pyserial model: state what a backend must implement).

    A backend implements :meth:`write`; one that measures something per block returns it
    from :meth:`measurements` (all so far: the offline render) and :meth:`take_measurements`
    (since the last take, then forgotten: the real-time driver, after every step); one that holds a resource (a file, a stream) overrides
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

    def write_blocks(self, samples: npt.NDArray[np.float32], block_frames: int,
                     blocks: Mapping[str, npt.NDArray[Any]]) -> None:
        """:meth:`write` each of the consecutive blocks of ``block_frames`` samples in ``samples``, block ``k``
        with the telemetry row ``{name: blocks[name][k]}``; an output that can take them at once overrides it
        (the offline render calls it once for many blocks). Raises as :meth:`write`."""
        for k in range(len(samples) // block_frames):
            row = {name: float(column[k]) for name, column in blocks.items()}
            self.write(samples[k * block_frames:(k + 1) * block_frames], row)

    def measurements(self) -> dict[str, npt.NDArray[np.float64]]:
        """Per-block arrays the output measured so far, by name (none by default)."""
        return {}

    def take_measurements(self) -> dict[str, npt.NDArray[np.float64]]:
        """The per-block arrays measured since the last take, by name, then forgotten (none by default): a
        real-time driver takes them after every step into the run's telemetry log, so the output keeps none."""
        return {}

    def latest(self) -> dict[str, float]:
        """The last block's measurements, by name (none by default); cheap, for status lines."""
        return {}

    def warm(self, batch: bool = False) -> None:
        """Compile (or load from numba's cache) what :meth:`write` runs (with ``batch``, what
        :meth:`write_blocks` runs), changing nothing; nothing by default.

        A real-time driver calls it before the clock starts, so a first run does not spend its
        first second compiling while blocks fall due.
        """

    def close(self) -> None:
        """Finish and release what the output holds (nothing by default)."""

    def __enter__(self) -> Output:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        self.close()
