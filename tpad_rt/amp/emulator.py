"""A software serial amplifier that follows docs/amp-protocol.md (version 2); ``tpad-rt amp emulate`` runs it.

The :class:`Amplifier` is the protocol's amplifier side as a discrete-event machine on
times (s) it is given: host frames arrive at given times, envelope samples play at their
due times (``t_run + (k - start_index) / envelope_hz`` while RUNNING), STATUS goes out
every ``status_period_ms`` on a microsecond schedule. It
enforces the document's rules where the code says A1..A8. Each applied sample drives
the device's simulated plate (the carrier it modulates, made at SIM_RATE_HZ, through the
resonator of :mod:`tpad_rt.kernel.sim`) and the device's circuit gives the measured
current and phase. The :class:`Emulator` runs it on a :class:`Line` and a
:class:`tpad_rt.clock.Clock`, applies the :class:`FaultPlan`, and stops on request with
the output ramped to 0: in real time on a :class:`Port` (a new pty, or an existing serial
device) with the monotonic clock, or on a :class:`MemoryLine` with a virtual clock, where a
test is the host and every time is exact.

Choices the document leaves open (each said again where it is made):

- valid frames (steps 1-2 of section 2.3 passed), rejected or not, reset the watchdog,
  count sequence gaps and set ``last_seq``; a HELLO (type byte 0x01) sets the count's
  start and is counted in ``frames_ok`` after HELLO's reset (frames_ok is 1 after it);
- every rejected frame is answered with an ACK (value 0; BAD_VERSION's value is VERSION)
  except an ENVELOPE of this version, which is only counted (codes NOT_STARTED and
  OUT_OF_WINDOW are therefore never sent); START is checked in the order FAULT,
  BAD_RATE, NO_CARRIER, OUT_OF_RANGE; STOP outside a stream is acknowledged OK;
- the watchdog (A4) is armed while PRIMING or RUNNING only, and trips READ_LATENCY_S
  early: a frame is stamped when the emulator reads it, up to a tick (and a busy
  machine's scheduling) after it reached the line;
- STATUS goes out from the first HELLO on (3.2), on a schedule of whole microseconds
  restarted by each HELLO; before any HELLO the emulator sends only ACKs;
- every ramp (STOP's, A4's, A6's, HELLO's) passes A1 and A2 like any sample; the slew
  limit is at least ``max_mv`` per ms, so A6's 1 ms ramp from ``max_mv`` fits it;
- the output is held during PRIMING (0 after IDLE; the present value after a restart), and goes to 0
  through A2 at rest (IDLE, FAULT: after a STOP ramp shorter than the slew allows, too);
  during a ramp after HELLO the old carrier is still made and reported;
- the carriers made are multiples of CARRIER_STEP_MHZ, and so are the limits (ties
  round up); a carrier refused OUT_OF_RANGE is answered with value 0;
- measured: ``voltage = |envelope| / sqrt(2)``, ``current = voltage / |Z|`` with ``Z`` the
  device's shunt in series with C0 parallel to the motional branch, at the carrier made.

API map
-------
amplifier_info(device, circuit) -> Info         what this amplifier says in INFO
Circuit(device, force_n), Plate(device, force_n, sim_rate_hz)   the load
carrier_phase_cycles(carrier_hz, per_sample, sim_rate_hz, phase_cycles) -> (phase, phase_after)   Plate's carrier
Amplifier(info, circuit, plate, origin_s, recorder=None, on_hello=None)   the protocol machine
Recorder(limit), write_recording(path, recorder, scalars), check_record_path(path)
counters(amplifier), recording_scalars(amplifier, recorder)   the summary's and the recording's numbers
Line                                           the protocol the Emulator serves: read, write, wait, ...
Port.open_pty(), Port.open_device(path)        a real line (CLOCK_MONOTONIC)
MemoryLine(virtual_clock, name, output_room)   a line in memory: feed(bytes), take() -> [(t_ns, bytes)]
FaultPlan(...)                                 faults on demand (``--fault``)
Emulator(amplifier, line, plan, clock, duration_s).run(stop_requested) -> reason
"""

from __future__ import annotations

import math
import os
import select
import sys
import termios
import time
import tty
import zipfile
from collections import deque
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Protocol

import numpy as np
import numpy.typing as npt

from tpad_rt.amp import wire
from tpad_rt.amp.wire import Code, Fault, State, Type
from tpad_rt.clock import Clock, VirtualClock
from tpad_rt.device import Device
from tpad_rt.errors import BackendError, ConfigError, printable
from tpad_rt.files import NewFile, check_writable_target
from tpad_rt.kernel.sim import COEF_SIZE, SIM_STATE_SIZE, resonate
from tpad_rt.outputs.sim import plate_resonator
from tpad_rt.physics import electromech

FIRMWARE = "tpad-emu 1.0"
#: INFO's envelope_rates_hz: the rates START accepts (0: unused entry).
ENVELOPE_RATES_HZ = (8000, 16000, 0, 0)
#: Carrier range (Hz) made whatever the device; widened to take in the device's resonance.
CARRIER_RANGE_HZ = (10_000, 80_000)
#: Carrier resolution (mHz): the carriers made are multiples of it (a DDS-like step).
CARRIER_STEP_MHZ = 10
BUFFER_SAMPLES = 1024
#: A4: time (ms) from the last valid frame to zero output, and R, the amplifier's own ramp (ms).
WATCHDOG_MS = 50
RAMP_MS = 10
#: A6: a fault ramps the output to 0 within this (ms).
FAULT_RAMP_MS = 1
#: STOP's longest ramp (ms).
MAX_STOP_RAMP_MS = 50
STATUS_PERIOD_MS = 5
#: INFO's measures: 1 current, 2 voltage, 4 phase.
MEASURES = 7
#: Lowest slew limit (mV per ms); never below max_mv per ms (see the module docstring).
MIN_SLEW_MV_PER_MS = 100_000
#: The overcurrent trip: this times the current at max_mv at the device's resonance.
OVERCURRENT_MARGIN = 1.5
#: How late the emulator may read a frame after it reached the line (s: its tick, and a busy machine's
#: scheduling); the watchdog trips this much early, so the output is 0 within watchdog_ms of the arrival.
READ_LATENCY_S = 0.002
#: Carrier samples per second of the plate simulation for carriers up to 80 kHz (a multiple of every rate).
SIM_RATE_HZ = 192_000
#: The real-time loop's tick (s) while samples play: the longest wait for bytes before samples are played.
TICK_S = 0.001
#: The longest wait (s) when nothing plays and nothing else is due (a signal is seen within this).
IDLE_WAIT_S = 0.05
#: A tick this late (s) while samples play is said on stderr (at most once a second): the emulator's timing
#: was not an amplifier's.
LATE_TICK_S = 0.02
#: Most samples a recording keeps: 10 minutes at 16 kHz (then a note on stderr, and no more).
MAX_RECORDED_SAMPLES = 10 * 60 * 16_000
#: Below this plate amplitude (um), with zero output at rest, the sample clock stops.
PLATE_QUIET_UM = 1e-4
#: Most envelope samples simulated at once (bounds the carrier arrays after a late tick).
MAX_BATCH = 4096
#: A periodic STATUS overdue by more than this (s; the emulator was stopped) is skipped, not sent late.
MAX_STATUS_LAG_S = 0.1
#: Most received bytes a tick reads, and most held back by a delay fault (then dropped, as by a full UART).
READ_LIMIT_BYTES = 1 << 16
MAX_DELAYED_BYTES = 1 << 20
#: How long (s) the emulator stops reading after it saw the host gone (end of file, an error): it does not spin.
HOST_GONE_WAIT_S = 0.1
#: Most unsent bytes kept for a host that does not read; past it they are dropped (a 0x00 ends a cut frame).
MAX_UNSENT_BYTES = 1 << 16

_U32 = 0xFFFFFFFF
_U16 = 0xFFFF


# --- the load ------------------------------------------------------------------------------------------------

class Circuit:
    """The device's electrical load at contact force ``force_n`` (N): shunt R0 in series with C0 || (R, L, C)."""

    def __init__(self, device: Device, force_n: float):
        self._device = device
        self._motional = tuple(float(value) for value in device.motional(force_n))
        self._carrier_mhz = -1
        self._abs_z = math.inf
        self._phase_cdeg = 0

    def impedance(self, carrier_hz: float) -> complex:
        """Complex impedance (ohm) at ``carrier_hz`` (> 0)."""
        l_h, c_f, r_ohm = self._motional
        return self._device.shunt_ohm + complex(electromech.impedance(carrier_hz, self._device.c0_f, l_h, c_f, r_ohm))

    def _at(self, carrier_mhz: int) -> None:
        if carrier_mhz != self._carrier_mhz:
            z = self.impedance(carrier_mhz / 1000) if carrier_mhz else complex(math.inf)
            self._carrier_mhz, self._abs_z = carrier_mhz, abs(z)
            self._phase_cdeg = round(-math.degrees(math.atan2(z.imag, z.real)) * 100) if carrier_mhz else 0

    def current_ma(self, envelope_mv: float, carrier_mhz: int) -> float:
        """RMS current (mA) for an envelope of ``envelope_mv`` (mV peak) at ``carrier_mhz`` (0: none made)."""
        self._at(carrier_mhz)
        return abs(envelope_mv) / math.sqrt(2) / self._abs_z

    def measure(self, envelope_mv: float, carrier_mhz: int) -> tuple[int, int, int]:
        """STATUS's ``(voltage_mv_rms, current_ua_rms, phase_cdeg)``: phase of current against voltage."""
        current_ua = self.current_ma(envelope_mv, carrier_mhz) * 1000
        return round(abs(envelope_mv) / math.sqrt(2)), round(current_ua), self._phase_cdeg


class Plate:
    """The device's plate driven by the carrier the envelope modulates, at ``sim_rate_hz``.

    The resonator is ``sim://``'s (:func:`tpad_rt.outputs.sim.plate_resonator`) at contact
    force ``force_n`` (N): the loaded motional resonance and quality factor, the device's
    gain at its carrier. The carrier's phase runs on
    across batches and carrier changes (A2: it never jumps).
    """

    def __init__(self, device: Device, force_n: float, sim_rate_hz: int):
        self.sim_rate_hz = sim_rate_hz
        self._volts_per_full_scale = device.volts_per_full_scale
        self._coef = np.zeros(COEF_SIZE)
        self._state = np.zeros(SIM_STATE_SIZE)
        plate_resonator(device, force_n, sim_rate_hz, self._coef)
        self._phase_cycles = 0.0
        resonate(np.zeros(0, np.float32), 1.0, self._coef, self._state, np.zeros(0))  # compile or load it now

    def drive(self, envelope_v: npt.NDArray[np.float64], carrier_hz: npt.NDArray[np.float64],
              rate_hz: int) -> npt.NDArray[np.float64]:
        """Mean plate amplitude (um) over each envelope sample's period (``1 / rate_hz``, held envelope)."""
        per_sample = self.sim_rate_hz // rate_hz
        phase, self._phase_cycles = carrier_phase_cycles(carrier_hz, per_sample, self.sim_rate_hz, self._phase_cycles)
        drive = (np.repeat(envelope_v / self._volts_per_full_scale, per_sample)
                 * np.sin(2 * math.pi * phase)).astype(np.float32)
        amplitude_m = np.empty(len(drive))
        resonate(drive, self._volts_per_full_scale, self._coef, self._state, amplitude_m)
        return amplitude_m.reshape(-1, per_sample).mean(axis=1) * 1e6


def carrier_phase_cycles(carrier_hz: npt.NDArray[np.float64], per_sample: int, sim_rate_hz: int,
                         phase_cycles: float) -> tuple[npt.NDArray[np.float64], float]:
    """The carrier's phase (cycles) at each of its samples, and the phase after the last one (mod 1).

    ``carrier_hz`` is the carrier (Hz) for each envelope sample, made for ``per_sample`` samples at
    ``sim_rate_hz``; the phase starts at ``phase_cycles`` and accumulates ``carrier_hz / sim_rate_hz`` per
    sample (a phase accumulator: the carrier never jumps in phase, A2). The carrier sample is the envelope
    times ``sin(2 pi phase)``: :meth:`Plate.drive`, and the conformance suite's equivalence test.
    """
    step = np.repeat(carrier_hz / sim_rate_hz, per_sample)
    phase = phase_cycles + np.cumsum(step) - step
    return phase, float((phase_cycles + step.sum()) % 1.0)


def sim_rate_hz(carrier_max_mhz: int) -> int:
    """Plate simulation rate (Hz): SIM_RATE_HZ per 80 kHz of the highest carrier, so it stays above 2.4 x."""
    return SIM_RATE_HZ * max(1, math.ceil(carrier_max_mhz / (CARRIER_RANGE_HZ[1] * 1000)))


def amplifier_info(device: Device, circuit: Circuit) -> wire.Info:
    """INFO for ``device``: clamp at its max_voltage_v, full scale 1.25 x that, carriers around its resonance."""
    max_mv = round(device.max_voltage_v * 1000)
    step = CARRIER_STEP_MHZ
    low_mhz = min(CARRIER_RANGE_HZ[0] * 1000, math.floor(device.carrier_hz * 1000 / step) * step)
    high_mhz = max(CARRIER_RANGE_HZ[1] * 1000, math.ceil(device.carrier_hz * 1000 / step) * step)
    resonance_ma = circuit.current_ma(max_mv, round(device.carrier_hz * 1000))
    return wire.Info(
        firmware=FIRMWARE, serial=f"EMU-{os.getpid()}", envelope_rates_hz=ENVELOPE_RATES_HZ,
        carrier_min_mhz=low_mhz, carrier_max_mhz=high_mhz, carrier_step_mhz=step,
        full_scale_mv=round(device.max_voltage_v * 1250), max_mv=max_mv,
        slew_mv_per_ms=max(MIN_SLEW_MV_PER_MS, max_mv), buffer_samples=BUFFER_SAMPLES,
        max_frame_samples=wire.MAX_FRAME_SAMPLES, watchdog_ms=WATCHDOG_MS, status_period_ms=STATUS_PERIOD_MS,
        measures=MEASURES, max_current_ma=math.ceil(OVERCURRENT_MARGIN * resonance_ma),
    )


# --- the amplifier -------------------------------------------------------------------------------------------

@dataclass
class Counters:
    """STATUS's counters (section 3.2), set to 0 by HELLO."""

    frames_ok: int = 0
    frames_bad: int = 0
    frames_rejected: int = 0
    sequence_gaps: int = 0
    underruns: int = 0
    watchdog_trips: int = 0


class SampleBuffer:
    """Envelope samples by stream index: slot ``index % size`` (``size`` divides 2**32)."""

    def __init__(self, size: int):
        self.size = size
        self._values = np.zeros(size, dtype=np.int16)
        self._present = np.zeros(size, dtype=bool)

    def clear(self) -> None:
        self._present[:] = False

    def fits(self, first: int, count: int, play_index: int) -> bool:
        """True when indices ``first .. first + count - 1`` all lie in ``[play_index, play_index + size)`` mod 2**32."""
        return ((first - play_index) & _U32) + count <= self.size

    def put(self, first: int, samples: npt.NDArray[np.int16]) -> None:
        """Store ``samples`` from index ``first`` on (replacing any already there)."""
        slots = (first + np.arange(len(samples))) % self.size
        self._values[slots] = samples
        self._present[slots] = True

    def take(self, index: int) -> int | None:
        """The sample at ``index``, removed; None when missing."""
        slot = index % self.size
        if not self._present[slot]:
            return None
        self._present[slot] = False
        return int(self._values[slot])

    def fill(self, play_index: int) -> int:
        """Samples present from ``play_index`` on, up to the first missing one."""
        present = np.roll(self._present, -(play_index % self.size))
        return self.size if present.all() else int(np.argmin(present))


class Ramp:
    """A linear ramp from ``start_mv`` to 0 over ``samples`` samples (the last one 0), then state ``then``."""

    def __init__(self, start_mv: float, samples: int, then: State):
        self.start_mv, self.samples, self.then = start_mv, samples, then
        self.done = 0

    def next_mv(self) -> float:
        self.done += 1
        return self.start_mv * (1.0 - self.done / self.samples)


class SampleClock:
    """Due times of the output samples: ``anchor_s + n / rate_hz``."""

    def __init__(self, anchor_s: float, rate_hz: int):
        self.anchor_s, self.rate_hz, self.n = anchor_s, rate_hz, 0

    def due_s(self) -> float:
        return self.anchor_s + self.n / self.rate_hz


class Amplifier:
    """The amplifier of docs/amp-protocol.md as a discrete-event machine on given times (s, any clock's).

    Feed it candidate frames with :meth:`receive`, faults with :meth:`fault`, and the
    passing of time with :meth:`advance`; what it sends accumulates in ``out``. Times
    must not go back (an earlier one is taken as the present). ``on_hello`` is called
    when a HELLO is acted on, before INFO goes into ``out`` (the line drops stale bytes).
    """

    def __init__(self, info: wire.Info, circuit: Circuit, plate: Plate, origin_s: float,
                 recorder: Recorder | None = None, on_hello: Callable[[], None] | None = None):
        self.info = info
        self.circuit = circuit
        self.plate = plate
        self.origin_s = origin_s
        self.recorder = recorder
        self.on_hello = on_hello
        self.out = bytearray()
        self.buffer = SampleBuffer(info.buffer_samples)
        self._rates = {rate for rate in info.envelope_rates_hz if rate}
        self._slew_step_mv = 0.0
        self._trip_s = (info.watchdog_ms - RAMP_MS) / 1000 - READ_LATENCY_S
        self.now_s = origin_s
        # A7: at power-up the output is 0, the state IDLE, and no carrier is set.
        self.state = State.IDLE
        self.faults = 0
        self.counters = Counters()
        #: When (s, the clock of ``t_s``) each of ``counters.watchdog_trips`` came.
        self.watchdog_trip_t_s: list[float] = []
        self.last_seq: int | None = None
        self.tx_seq = 0
        self.carrier_mhz = 0
        self._fading_carrier_mhz = 0
        self.envelope_hz = 0
        self.prefill = 0
        self.play_index = 0
        self.output_mv = 0.0
        self.last_valid_s = -math.inf
        self._ramp: Ramp | None = None
        self._clock: SampleClock | None = None
        self._plate_um = 0.0
        self._next_status_us: int | None = None  # None until the first HELLO (3.2)
        self._batch: list[tuple[float, float, int, int, int]] = []

    # --- the clock ---

    def time_us(self, t_s: float) -> int:
        """The amplifier's microsecond clock at ``t_s`` (unwrapped)."""
        return round((t_s - self.origin_s) * 1e6)

    @property
    def carrier_made_mhz(self) -> int:
        """The carrier being made (mHz): the one set, else during HELLO's ramp the one before; 0 if none."""
        return self.carrier_mhz or (self._fading_carrier_mhz if self._ramp is not None else 0)

    @property
    def playing(self) -> bool:
        """True while the sample clock runs (the output or the plate is not at rest)."""
        return self._clock is not None

    @property
    def next_status_s(self) -> float:
        """When the next periodic STATUS is due (inf before the first HELLO)."""
        return math.inf if self._next_status_us is None else self.origin_s + self._next_status_us / 1e6

    @property
    def at_rest(self) -> bool:
        """True when the output is 0 and nothing is playing or ramping."""
        return self._ramp is None and self.output_mv == 0.0 and self.state in (State.IDLE, State.FAULT)

    def advance(self, t_s: float) -> None:
        """Play every sample and send every periodic STATUS due up to ``t_s``."""
        status_us = self.info.status_period_ms * 1000
        while True:
            sample_s = self._clock.due_s() if self._clock is not None else math.inf
            if self._next_status_us is not None:
                lag_us = self.time_us(t_s - MAX_STATUS_LAG_S) - self._next_status_us
                if lag_us > 0:
                    self._next_status_us += -(-lag_us // status_us) * status_us
            status_s = self.next_status_s
            if min(sample_s, status_s) > t_s:
                break
            if sample_s <= status_s:
                self._play(sample_s)
            else:
                self._send_status(self._next_status_us)  # type: ignore[arg-type]
                self._next_status_us += status_us  # type: ignore[operator]
        self._flush()
        self.now_s = max(self.now_s, t_s)

    # --- the output (A1-A4, A6) ---

    def _play(self, t_s: float) -> None:
        """Make the sample due at ``t_s``."""
        assert self._clock is not None
        if self.state in (State.PRIMING, State.RUNNING) and t_s >= self.last_valid_s + self._trip_s:
            # A4: no valid frame for watchdog_ms - R: count a trip, ramp to 0 over R, empty the buffer, IDLE.
            self.counters.watchdog_trips += 1
            self.watchdog_trip_t_s.append(t_s)
            self.buffer.clear()
            self._begin_ramp(RAMP_MS, State.RAMPING, State.IDLE)
        index = -1
        if self.state == State.RUNNING:
            index = self.play_index
            sample = self.buffer.take(index)
            self.play_index = (index + 1) & _U32
            if sample is None:
                self.counters.underruns += 1  # A3: a missing index plays as 0 (through A2), one underrun
                target_mv = 0.0
                index = -1  # recorded: nothing came from the buffer
            else:
                target_mv = max(sample, -32767) / 32767 * self.info.full_scale_mv
        elif self._ramp is not None:
            target_mv = self._ramp.next_mv()
        else:
            target_mv = self.output_mv if self.state == State.PRIMING else 0.0  # held while PRIMING; to 0 at rest
        carrier_mhz = self.carrier_made_mhz
        if self._ramp is not None and self._ramp.done >= self._ramp.samples:
            self.state, self._ramp = self._ramp.then, None
        self.output_mv = self._limit(target_mv)
        self._clock.n += 1
        self._batch.append((t_s, self.output_mv, carrier_mhz, index, self.state))
        if self.circuit.current_ma(self.output_mv, carrier_mhz) > self.info.max_current_ma:
            self._raise_fault(Fault.OVERCURRENT, t_s)  # A6
        if len(self._batch) >= MAX_BATCH:
            self._flush()

    def _limit(self, target_mv: float) -> float:
        """``target_mv`` clamped to max_mv (A1), then moved from the present output by at most one slew step (A2)."""
        target_mv = min(max(target_mv, -self.info.max_mv), self.info.max_mv)
        change = target_mv - self.output_mv
        if abs(change) <= self._slew_step_mv:
            return target_mv
        return self.output_mv + math.copysign(self._slew_step_mv, change)

    def _begin_ramp(self, ramp_ms: int, during: State, then: State) -> None:
        """Ramp linearly from the present output to 0 over ``ramp_ms`` (at least one sample) in state ``during``."""
        if self._clock is None:  # at rest: nothing to ramp
            self.state = then
            return
        self._ramp = Ramp(self.output_mv, max(1, ramp_ms * self._clock.rate_hz // 1000), then)
        self.state = during

    def _start_clock(self, t_s: float, rate_hz: int) -> None:
        if self._clock is None or self._clock.rate_hz != rate_hz:
            self._clock = SampleClock(t_s, rate_hz)
            self._slew_step_mv = self.info.slew_mv_per_ms * 1000 / rate_hz  # A2, per sample

    def _flush(self) -> None:
        """Drive the plate with the samples made since the last flush, record them; stop the clock at rest."""
        if self._batch and self._clock is not None:
            t_s, envelope_mv, carrier_mhz, index, state = (np.array(column) for column in zip(*self._batch))
            envelope_v, carrier_hz = envelope_mv / 1000, carrier_mhz / 1000
            plate_um = self.plate.drive(envelope_v, carrier_hz, self._clock.rate_hz)
            self._plate_um = float(plate_um[-1])
            if self.recorder is not None:
                self.recorder.add(t_s=t_s, envelope_v=envelope_v, carrier_hz=carrier_hz, index=index,
                                  plate_amplitude_um=plate_um, state=state)
        self._batch.clear()
        if self.at_rest and self._plate_um < PLATE_QUIET_UM:
            self._clock = None

    def fault(self, bit: Fault, t_s: float) -> None:
        """A fault (an overcurrent from outside, a fault plan) at ``t_s``: A6."""
        t_s = max(t_s, self.now_s)
        self.advance(t_s)
        self._raise_fault(bit, t_s)

    def _raise_fault(self, bit: Fault, t_s: float) -> None:
        # A6: ramp to 0 within 1 ms, set the bit, STATUS at once (for a new fault), FAULT until HELLO.
        new = not self.faults & bit
        self.faults |= bit
        if self.state != State.FAULT:
            self.buffer.clear()
            self._begin_ramp(FAULT_RAMP_MS, State.FAULT, State.FAULT)
        if new:
            self._send_status(self.time_us(t_s))

    def stop_output(self, t_s: float) -> None:
        """Ramp to 0 over R (the emulator is ending), as the watchdog would, without counting a trip."""
        self.advance(t_s)
        if self.state in (State.PRIMING, State.RUNNING):
            self.buffer.clear()
            self._begin_ramp(RAMP_MS, State.RAMPING, State.IDLE)

    # --- the line ---

    def _send(self, type_: Type, payload: bytes) -> None:
        self.out += wire.encode(type_, self.tx_seq, payload)
        self.tx_seq = (self.tx_seq + 1) & _U16

    def _send_status(self, time_us: int) -> None:
        voltage_mv, current_ua, phase_cdeg = self.circuit.measure(self.output_mv, self.carrier_made_mhz)
        counters = {name: value & _U32 for name, value in asdict(self.counters).items()}
        status = wire.Status(
            time_us=time_us & _U32, play_index=self.play_index, buffer_fill=self.buffer.fill(self.play_index),
            state=self.state, faults=self.faults, **counters, last_seq=self.last_seq or 0, phase_cdeg=phase_cdeg,
            envelope_mv=round(self.output_mv), voltage_mv_rms=voltage_mv, current_ua_rms=current_ua,
            carrier_mhz=self.carrier_made_mhz)
        self._send(Type.STATUS, status.pack())

    def receive(self, encoded: bytes | None, t_s: float) -> None:
        """Act on the candidate frame ``encoded`` (bytes between two 0x00; None: an over-long run) at ``t_s``."""
        t_s = max(t_s, self.now_s)
        self.advance(t_s)
        frame = None if encoded is None else wire.decode(encoded)
        if frame is None:
            self.counters.frames_bad += 1  # 2.3 steps 1-2: never acted on, no watchdog reset, no ACK (A3)
            return
        self.last_valid_s = t_s  # A4: every valid frame, even one rejected, resets the watchdog
        if frame.type != Type.HELLO and self.last_seq is not None and frame.seq != (self.last_seq + 1) & _U16:
            self.counters.sequence_gaps += 1  # 2.2; HELLO sets the count's start
        self.last_seq = frame.seq
        if frame.version != wire.VERSION:
            self._reject(frame, Code.BAD_VERSION, wire.VERSION)  # 2.3 step 3, A5
        elif (handler := self._HANDLERS.get(frame.type)) is None:
            self._reject(frame, Code.UNKNOWN_TYPE)  # 2.3 step 4
        elif not self._length_ok(frame):
            self._reject(frame, Code.BAD_LENGTH)  # 2.3 step 4
        else:
            handler(self, frame, t_s)  # 2.3 step 5, then acted on

    def _length_ok(self, frame: wire.Frame) -> bool:
        if frame.type == Type.ENVELOPE:
            samples, odd = divmod(len(frame.payload) - wire.ENVELOPE_HEADER_BYTES, 2)
            return not odd and 1 <= samples <= self.info.max_frame_samples
        return len(frame.payload) == wire.PAYLOAD_BYTES[Type(frame.type)]

    def _reject(self, frame: wire.Frame, code: Code, value: int = 0) -> None:
        """Count a refused valid frame; ACK it, unless it is an ENVELOPE of this version (3.1)."""
        self.counters.frames_rejected += 1
        if frame.version != wire.VERSION or frame.type != Type.ENVELOPE:
            self._ack(frame, code, value)

    def _accept(self, frame: wire.Frame, ack_value: int | None = None) -> None:
        """Count a frame acted on; ACK OK with ``ack_value`` for a command that is answered."""
        self.counters.frames_ok += 1
        if ack_value is not None:
            self._ack(frame, Code.OK, ack_value)

    def _ack(self, frame: wire.Frame, code: Code, value: int) -> None:
        self._send(Type.ACK, wire.Ack(frame.seq, frame.type, code, value & _U32).pack())

    # --- the messages (3.1) ---

    def _on_hello(self, frame: wire.Frame, t_s: float) -> None:
        self._fading_carrier_mhz = self.carrier_made_mhz
        self.carrier_mhz = 0
        self.buffer.clear()
        self._begin_ramp(RAMP_MS, State.RAMPING, State.IDLE)  # A4's ramp, then IDLE
        self.faults = 0
        self.counters = Counters()
        self.watchdog_trip_t_s.clear()
        self.tx_seq = 0
        self.out.clear()
        if self.on_hello is not None:
            self.on_hello()
        # INFO echoes the HELLO's nonce, so that the host can tell it from a late answer to an earlier HELLO.
        self._send(Type.INFO, replace(self.info, hello_nonce=wire.Hello.unpack(frame.payload).nonce).pack())
        self._accept(frame)
        self._next_status_us = self.time_us(t_s) + self.info.status_period_ms * 1000

    def _on_set_carrier(self, frame: wire.Frame, t_s: float) -> None:
        asked = wire.SetCarrier.unpack(frame.payload).carrier_mhz
        if not self.info.carrier_min_mhz <= asked <= self.info.carrier_max_mhz:
            self._reject(frame, Code.OUT_OF_RANGE)
            return
        step = self.info.carrier_step_mhz
        self.carrier_mhz = (asked + step // 2) // step * step  # the nearest the amplifier makes
        self._accept(frame, self.carrier_mhz)

    def _on_start(self, frame: wire.Frame, t_s: float) -> None:
        start = wire.Start.unpack(frame.payload)
        if self.state == State.FAULT:
            self._reject(frame, Code.FAULT)  # A6
        elif start.envelope_hz not in self._rates:
            self._reject(frame, Code.BAD_RATE)
        elif not self.carrier_mhz:
            self._reject(frame, Code.NO_CARRIER)
        elif not 1 <= start.prefill <= self.info.buffer_samples:
            self._reject(frame, Code.OUT_OF_RANGE)
        else:
            self.buffer.clear()
            self.play_index, self.prefill, self.envelope_hz = start.start_index, start.prefill, start.envelope_hz
            self._ramp = None
            self._start_clock(t_s, start.envelope_hz)
            self.state = State.PRIMING
            self._accept(frame, start.start_index)

    def _on_envelope(self, frame: wire.Frame, t_s: float) -> None:
        envelope = wire.Envelope.unpack(frame.payload)
        if self.state not in (State.PRIMING, State.RUNNING):
            self._reject(frame, Code.NOT_STARTED)
        elif not self.buffer.fits(envelope.first_index, len(envelope.samples), self.play_index):
            self._reject(frame, Code.OUT_OF_WINDOW)
        else:
            self.buffer.put(envelope.first_index, envelope.samples)
            self._accept(frame)
            if self.state == State.PRIMING and self.buffer.fill(self.play_index) >= self.prefill:
                self.state = State.RUNNING  # its first sample plays at the clock's next due time, t_run

    def _on_stop(self, frame: wire.Frame, t_s: float) -> None:
        self._accept(frame, 0)  # ACK at once, before the ramp ends
        if self.state in (State.PRIMING, State.RUNNING, State.RAMPING):
            self.buffer.clear()
            ramp_ms = min(wire.Stop.unpack(frame.payload).ramp_ms, MAX_STOP_RAMP_MS)
            self._begin_ramp(ramp_ms, State.RAMPING, State.IDLE)

    def _on_keepalive(self, frame: wire.Frame, t_s: float) -> None:
        self._accept(frame)

    _HANDLERS: dict[int, Callable[[Amplifier, wire.Frame, float], None]] = {
        Type.HELLO: _on_hello,
        Type.SET_CARRIER: _on_set_carrier,
        Type.START: _on_start,
        Type.ENVELOPE: _on_envelope,
        Type.STOP: _on_stop,
        Type.KEEPALIVE: _on_keepalive,
    }


# --- the recording -------------------------------------------------------------------------------------------

#: Per-sample columns of a recording and their types.
RECORDED_COLUMNS = {
    "t_s": np.float64, "envelope_v": np.float64, "carrier_hz": np.float64, "index": np.int64,
    "plate_amplitude_um": np.float64, "state": np.uint8,
}


class Recorder:
    """The applied samples, at most ``limit``; past it a note on stderr and no more are kept."""

    CHUNK = 1 << 16

    def __init__(self, limit: int = MAX_RECORDED_SAMPLES):
        self.limit = limit
        self.count = 0
        self.truncated = False
        self._chunks: list[dict[str, np.ndarray]] = []

    def add(self, **columns: np.ndarray) -> None:
        """Append one batch: every RECORDED_COLUMNS name, arrays of one length."""
        total = len(columns["t_s"])
        keep = min(total, self.limit - self.count)
        if keep < total and not self.truncated:
            self.truncated = True
            print(f"tpad-rt amp emulate: the recording is full ({self.limit:,} samples); later samples are not recorded",
                  file=sys.stderr, flush=True)
        done = 0
        while done < keep:
            used = self.count % self.CHUNK
            if used == 0:
                self._chunks.append({name: np.empty(self.CHUNK, dtype) for name, dtype in RECORDED_COLUMNS.items()})
            step = min(keep - done, self.CHUNK - used)
            for name, column in self._chunks[-1].items():
                column[used:used + step] = columns[name][done:done + step]
            done += step
            self.count += step

    def column(self, name: str) -> np.ndarray:
        """The column ``name`` of RECORDED_COLUMNS, ``count`` samples long (a new array)."""
        parts = [chunk[name] for chunk in self._chunks] or [np.empty(0, RECORDED_COLUMNS[name])]
        return np.concatenate(parts)[:self.count]


def check_record_path(path: str) -> None:
    """ConfigError unless a recording can be written at ``path``: a file name (a regular file, or none) in a
    writable folder (:func:`tpad_rt.files.check_writable_target`)."""
    check_writable_target(path, "recordings")
    if not Path(path).name:
        raise ConfigError(f"{printable(path)}: not a file name")


def write_recording(path: str, recorder: Recorder, scalars: dict[str, float | int | list[float]]) -> None:
    """Write the recorded columns and ``scalars`` (numbers, or lists written as float64 arrays) to ``path`` (.npz)
    through :class:`tpad_rt.files.NewFile` (whole or not at all).

    The archive is np.savez's (one ``NAME.npy`` per entry), written a column at a time so
    that a full recording is not copied whole. Raises ConfigError or BackendError (nothing
    written at ``path``) when it cannot be written.
    """
    with NewFile(path, "recordings") as new, zipfile.ZipFile(new.file, "w", allowZip64=True) as archive:
        for name in (*RECORDED_COLUMNS, *scalars):
            array = recorder.column(name) if name in RECORDED_COLUMNS else np.array(
                scalars[name], dtype=np.float64 if isinstance(scalars[name], list) else None)
            with archive.open(f"{name}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, array, allow_pickle=False)


def counters(amplifier: Amplifier) -> dict[str, int]:
    """STATUS's counters since the last HELLO, and ``faults``: what the summary and the recording say."""
    return {**vars(amplifier.counters), "faults": amplifier.faults}


def recording_scalars(amplifier: Amplifier, recorder: Recorder) -> dict[str, float | int | list[float]]:
    """The scalars a recording holds beside its columns (:mod:`tpad_rt.cli.amp` lists them)."""
    info = amplifier.info
    return {**counters(amplifier), "envelope_hz": amplifier.envelope_hz, "full_scale_mv": info.full_scale_mv,
            "max_mv": info.max_mv, "slew_mv_per_ms": info.slew_mv_per_ms, "truncated": recorder.truncated,
            "watchdog_trip_t_s": amplifier.watchdog_trip_t_s}


# --- the line ------------------------------------------------------------------------------------------------

class Line(Protocol):
    """What the :class:`Emulator` serves: the amplifier's end of a serial line (the host holds the other end).

    Times are ns on the clock the Emulator runs on.
    """

    name: str
    closed: bool

    def read(self, limit: int) -> bytes | None:
        """Up to ``limit`` bytes waiting (b"" when none); None when the host is gone."""

    def write(self, data: bytes | bytearray) -> int:
        """How many bytes of ``data`` were taken now (the rest must wait); all of them when the host is gone."""

    def discard_output(self) -> None:
        """Drop the bytes sent but not read by the host yet (a new session starts: they are stale)."""

    def wait(self, until_ns: int) -> None:
        """Return when bytes may be waiting (a Port: when they arrive; a MemoryLine: at its clock's next event, the
        host's), or at ``until_ns`` (ns) at the latest."""

    def close(self) -> None:
        """End the line (the host's reads end)."""


class Port:
    """A real serial line: ``fd`` read and written without blocking; ``name`` is what a host opens. Its times are
    CLOCK_MONOTONIC's (ns): an Emulator on a Port runs on a :class:`tpad_rt.clock.MonotonicClock`."""

    def __init__(self, fd: int, name: str, flush: Callable[[], None], keep_fd: int | None = None):
        self.fd, self.name = fd, name
        self._flush = flush
        self._keep_fd = keep_fd
        self._poller = select.poll()
        self._poller.register(fd, select.POLLIN)
        self.closed = False

    @classmethod
    def open_pty(cls) -> Port:
        """A new pty pair: the emulator keeps the master and its own slave fd (a host closing the slave
        does not end the line); the slave is in raw mode."""
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        # Stale bytes are those queued for the slave's readers (the host), not yet read.
        return cls(master, os.ttyname(slave), lambda: termios.tcflush(slave, termios.TCIFLUSH), keep_fd=slave)

    @classmethod
    def open_device(cls, path: str) -> Port:
        """The existing serial device ``path`` in raw mode at 921600 baud; BackendError when it cannot be."""
        name = printable(path)
        try:
            fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except ValueError:
            raise BackendError(f"{name}: cannot open the port (the path contains a NUL byte)") from None
        except OSError as error:
            raise BackendError(f"{name}: cannot open the port ({error.strerror or error})") from None
        try:
            if not os.isatty(fd):
                raise BackendError(f"{name}: not a serial port (not a terminal device)")
            tty.setraw(fd)
            attributes = termios.tcgetattr(fd)
            attributes[4] = attributes[5] = termios.B921600
            termios.tcsetattr(fd, termios.TCSANOW, attributes)
            termios.tcflush(fd, termios.TCIFLUSH)  # start listening now
        except termios.error as error:
            os.close(fd)
            raise BackendError(f"{name}: cannot set the port up ({error.args[-1]})") from None
        except BaseException:
            os.close(fd)
            raise
        return cls(fd, path, lambda: termios.tcflush(fd, termios.TCOFLUSH))

    def read(self, limit: int) -> bytes | None:
        """Up to ``limit`` bytes waiting; None when the host is gone (end of file, an error)."""
        chunks: list[bytes] = []
        size = 0
        while size < limit:
            try:
                chunk = os.read(self.fd, min(65536, limit - size))
            except BlockingIOError:
                break
            except OSError:  # EIO: the other end closed; ENXIO, ENODEV: a serial device unplugged
                return None
            if not chunk:
                return None
            chunks.append(chunk)
            size += len(chunk)
        return b"".join(chunks)

    def write(self, data: bytes | bytearray) -> int:
        """Bytes of ``data`` written now (the rest must wait); all of them when the host is gone."""
        try:
            return os.write(self.fd, data)
        except BlockingIOError:
            return 0
        except OSError:  # the host is gone (as in read)
            return len(data)

    def discard_output(self) -> None:
        """Drop the bytes sent but not read yet (a new session starts: they are stale)."""
        try:
            self._flush()
        except termios.error:  # a device that went away: nothing to drop
            pass

    def wait(self, until_ns: int) -> None:
        """Return when bytes are waiting, or when CLOCK_MONOTONIC reaches ``until_ns`` (ns) at the latest."""
        self._poller.poll(max(0.0, (until_ns - time.monotonic_ns()) / 1e6))

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            for fd in (self.fd, self._keep_fd):
                if fd is not None:
                    os.close(fd)


class MemoryLine:
    """A line in memory on a :class:`tpad_rt.clock.VirtualClock` (pyserial's ``loop://`` is the model): the seam
    on which an Emulator runs deterministically, as fast as the host computes, with the test as its host.

    The host writes with :meth:`feed` (from an event of the clock: the bytes arrive at its time) and reads what
    the emulator sent with :meth:`take`, each write stamped with the clock's time. ``output_room`` (None: no
    limit) is how many unread bytes the host's side holds: past it a write takes only what fits, as a full pty.
    ``hung_up`` set: the host is gone (reads end, writes are swallowed), until it is cleared.
    ``unread_bytes``: what waits for the host (FIONREAD on its end); ``reads``: the emulator's reads so far.
    """

    def __init__(self, clock: VirtualClock, name: str = "memory", output_room: int | None = None):
        self.name = name
        self.closed = False
        self.hung_up = False
        self.output_room = output_room
        self.reads = 0
        self._clock = clock
        self._incoming: deque[bytes] = deque()
        self._read_from = 0  # bytes of the first incoming chunk already read
        self._outgoing: list[tuple[int, bytes]] = []
        self.unread_bytes = 0

    # --- the host's end ---

    def feed(self, data: bytes) -> None:
        """Bytes the host writes, arriving now (kept as they are, not copied)."""
        if data:
            self._incoming.append(data)

    def take(self) -> list[tuple[int, bytes]]:
        """What the emulator sent since the last take, as (clock time in ns of the write, bytes)."""
        taken, self._outgoing, self.unread_bytes = self._outgoing, [], 0
        return taken

    # --- the emulator's end (Line) ---

    def read(self, limit: int) -> bytes | None:
        """Up to ``limit`` of the bytes fed so far; None while hung up. Each call counts in ``reads``."""
        self.reads += 1
        if self.hung_up:
            return None
        parts: list[bytes] = []
        size = 0
        while self._incoming and size < limit:
            head = self._incoming[0]
            part = head[self._read_from:self._read_from + limit - size]
            self._read_from += len(part)
            if self._read_from == len(head):
                self._incoming.popleft()
                self._read_from = 0
            parts.append(part)
            size += len(part)
        return b"".join(parts)

    def write(self, data: bytes | bytearray) -> int:
        """Take as much of ``data`` as ``output_room`` allows (all of it while hung up, as on a real line)."""
        if self.hung_up:
            return len(data)
        size = len(data) if self.output_room is None else min(len(data), self.output_room - self.unread_bytes)
        if size > 0:
            self._outgoing.append((self._clock.now_ns(), bytes(data[:size])))
            self.unread_bytes += size
        return max(size, 0)

    def discard_output(self) -> None:
        """Drop what the host has not taken."""
        self.take()

    def wait(self, until_ns: int) -> None:
        """Advance the clock to its next event (the host's: a write, a stop request) or to ``until_ns`` (ns),
        whichever comes first; not at all when bytes are waiting."""
        if not self._incoming:
            next_ns = self._clock.next_event_ns()
            self._clock.advance_to(until_ns if next_ns is None else min(next_ns, until_ns))

    def close(self) -> None:
        self.closed = True


# --- faults and the run loop ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class FaultPlan:
    """Faults on demand; times (s) count from the emulator's start, ``seed`` makes the random ones repeatable.

    ``drop_rate``/``corrupt_rate``: each received byte is dropped / has one random bit
    flipped with that probability; ``delay_s``: every received byte is handed on that
    late; ``stalls_s``: (from, for) spans when nothing is read; ``overcurrent_at_s``:
    an overcurrent fault (A6) at each; ``disconnect_at_s``: the port closes and the
    emulator ends.
    """

    drop_rate: float = 0.0
    corrupt_rate: float = 0.0
    delay_s: float = 0.0
    stalls_s: tuple[tuple[float, float], ...] = ()
    overcurrent_at_s: tuple[float, ...] = ()
    disconnect_at_s: float | None = None
    seed: int = 0


def _at_or_after_ns(t_s: float) -> int:
    """The first whole ns that, read back in s (``ns / 1e9``), is not before ``t_s`` (finite, s)."""
    t_ns = math.ceil(t_s * 1e9)
    while t_ns / 1e9 < t_s:
        t_ns += 1
    return t_ns


class Emulator:
    """Runs ``amplifier`` on ``line`` with the faults of ``plan``, on ``clock``, for ``duration_s`` (None: no end).

    In real time on a :class:`Port` with a :class:`tpad_rt.clock.MonotonicClock` (``tpad-rt amp
    emulate``), or on a :class:`MemoryLine` with its :class:`tpad_rt.clock.VirtualClock` (the
    tests: the host's writes are the clock's events). The plan's times count from the
    amplifier's ``origin_s``; times in s are the clock's ns / 1e9.
    """

    def __init__(self, amplifier: Amplifier, line: Line, plan: FaultPlan, clock: Clock,
                 duration_s: float | None = None):
        self.amplifier = amplifier
        self.line = line
        self.plan = plan
        self.clock = clock
        origin_s = amplifier.origin_s
        self.end_s = math.inf if duration_s is None else origin_s + duration_s
        self._rng = np.random.default_rng(plan.seed)
        self._splitter = wire.FrameSplitter()
        self._delayed: deque[tuple[float, bytes]] = deque()
        self._delayed_bytes = 0
        self._overcurrents = sorted(origin_s + at for at in plan.overcurrent_at_s)
        self._stalls = [(origin_s + at, origin_s + at + span) for at, span in plan.stalls_s]
        self._disconnect_s = math.inf if plan.disconnect_at_s is None else origin_s + plan.disconnect_at_s
        self._deaf_until_s = -math.inf  # after the host was seen gone, poll again later
        self.dropped_out_bytes = 0

    def now_s(self) -> float:
        """The clock's time (s)."""
        return self.clock.now_ns() / 1e9

    def run(self, stop_requested: Callable[[], bool]) -> str:
        """Serve the line until ``stop_requested()``, the duration or a disconnect fault; then ramp to 0.

        Returns why it ended: ``"stopped"``, ``"duration"`` or ``"disconnected"``.
        """
        previous_s, noted_s = self.now_s(), -math.inf
        while True:
            now = self.now_s()
            reason = ("stopped" if stop_requested() else "duration" if now >= self.end_s
                      else "disconnected" if now >= self._disconnect_s else "")
            if reason:
                break
            if self.amplifier.playing and now - previous_s > LATE_TICK_S and now - noted_s > 1.0:
                noted_s = now
                print(f"tpad-rt amp emulate: the emulator ran {(now - previous_s) * 1000:.0f} ms late (a busy machine?): "
                      "frames waiting meanwhile were read late, and may have let the watchdog trip", file=sys.stderr,
                      flush=True)
            previous_s = now
            self._tick(now)
            self._wait(now)
        if reason == "disconnected":
            self.line.close()
        self.amplifier.stop_output(now)
        self._send()
        deadline = now + (RAMP_MS + 50) / 1000
        while not self.amplifier.at_rest and now < deadline:
            self.clock.sleep_until_ns(_at_or_after_ns(now + TICK_S))
            now = self.now_s()
            self.amplifier.advance(now)
            self._send()
        return reason

    def _tick(self, now: float) -> None:
        events: list[tuple[float, bytes | None | Fault]] = []
        if self._reading(now):
            data = self.line.read(READ_LIMIT_BYTES)
            if data is None:
                self._deaf_until_s = now + HOST_GONE_WAIT_S  # the host is gone: do not spin on end of file
            elif data:
                self._hold(self._line_faults(data), now)
        while self._delayed and self._delayed[0][0] <= now:
            released_s, data = self._delayed.popleft()
            self._delayed_bytes -= len(data)
            events += [(released_s, frame) for frame in self._splitter.feed(data)]
        while self._overcurrents and self._overcurrents[0] <= now:
            events.append((self._overcurrents.pop(0), Fault.OVERCURRENT))
        for t_s, event in sorted(events, key=lambda item: item[0]):
            if isinstance(event, Fault):
                self.amplifier.fault(event, t_s)
            else:
                self.amplifier.receive(event, t_s)
        self.amplifier.advance(now)
        self._send()

    def _reading(self, now: float) -> bool:
        return (not self.line.closed and now >= self._deaf_until_s
                and not any(start <= now < end for start, end in self._stalls))

    def _line_faults(self, data: bytes) -> bytes:
        """``data`` after the plan's drop and corrupt faults (one pair of random draws per byte, in order)."""
        if not (self.plan.drop_rate or self.plan.corrupt_rate):
            return data
        draws = self._rng.random((len(data), 2))
        received = np.frombuffer(data, dtype=np.uint8).copy()
        flipped = draws[:, 1] < self.plan.corrupt_rate
        bits = (draws[flipped, 1] / self.plan.corrupt_rate * 8).astype(np.uint8)
        received[flipped] ^= np.left_shift(1, bits).astype(np.uint8)
        return received[draws[:, 0] >= self.plan.drop_rate].tobytes()

    def _hold(self, data: bytes, now: float) -> None:
        """Queue received bytes for release after the plan's delay (bounded, as a UART's buffer)."""
        room = MAX_DELAYED_BYTES - self._delayed_bytes
        if room > 0:
            self._delayed.append((now + self.plan.delay_s, data[:room]))
            self._delayed_bytes += min(len(data), room)

    def _send(self) -> None:
        out = self.amplifier.out
        if self.line.closed:
            out.clear()
            return
        if out:
            del out[:self.line.write(out)]
        if len(out) > MAX_UNSENT_BYTES:  # the host does not read: drop, ending any frame cut short
            self.dropped_out_bytes += len(out)
            out[:] = b"\x00"

    def _wait(self, now: float) -> None:
        """Wait until bytes arrive or the next thing is due: a tick while samples play, a STATUS, delayed bytes,
        a planned fault, a stall's edge, the end."""
        wake_s = min(now + (TICK_S if self.amplifier.playing else IDLE_WAIT_S), self.amplifier.next_status_s,
                     self.end_s, self._disconnect_s, *(edge for span in self._stalls for edge in span if edge > now))
        if self._delayed:
            wake_s = min(wake_s, self._delayed[0][0])
        if self._overcurrents:
            wake_s = min(wake_s, self._overcurrents[0])
        wake_ns = _at_or_after_ns(wake_s)
        if self._reading(now):
            self.line.wait(wake_ns)
        else:
            self.clock.sleep_until_ns(wake_ns)
