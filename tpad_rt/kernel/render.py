"""The render kernel: finger samples and a compiled texture in, drive samples out (carrier or envelope).

API map
-------
render_block(out, start_index, cfg, dev, state, power_ring, finger, finger_count,
             prog, params, img, stack, telem, telem_count) -> None
    fill ``out`` (float32, 1 = ``volts_per_full_scale``) with samples ``start_index ..
    start_index + len(out) - 1`` of the stream: DAC samples of the carrier, or with
    ``cfg[CFG_OUTPUT_ENVELOPE]`` set, the envelope itself (for an amplifier that makes the
    carrier); write one telemetry row
carrier_phase_units(n, step_units) -> int
    the carrier phase of sample ``n`` in units of 2**-60 cycles (exact integer arithmetic)
carrier_step_units(carrier_hz, fs_hz) -> int
    the carrier's phase advance per sample in those units

docs/kernel.md is the design; ``tpad_rt.kernel.layout`` names every array slot.
Arguments are arrays and scalars only, so that a numba ``@cfunc`` (the real-time audio
callback) and the serial streamer can call :func:`render_block` with arrays rebuilt
from raw pointers; it is compiled once and called, not inlined into them.

How the doc's per-sample recurrences are evaluated: within a control step the command
``v``, the cap, the pre-emphasis gain ``g`` and the gate are constant, so the
recurrences have closed forms in ``j``, the sample's offset from the step's first
sample. With ``a0`` the smoothed volts before the step and ``d`` the one-pole decay,
``a_j = v + (a0 - v) d^(j+1)`` and the pre-emphasised drive is
``u_j = a_j + g (v - a_j) = v + (1 - g)(a0 - v) d^(j+1)``; the gain ramp position is
``r_j = clip(r0 +- (j + 1), 0, N)`` samples; the carrier is
``sin(theta0 + j w) = sin(theta0) cos(j w) + cos(theta0) sin(j w)`` with ``theta0``
computed exactly from the absolute index at each control step. ``d^(j+1)``,
``cos(j w)`` and ``sin(j w)`` are tables in ``state``, rebuilt only when the sample
rate, carrier or smoothing change. So no transcendental function runs per sample,
and no sample depends on the one before it: the loop vectorises. Each sample's
envelope ``e_j`` is kept in ``state`` until the step closes; the step's power is
then summed from them in a fixed order, whatever blocks the step was rendered in.
"""

from __future__ import annotations

import math

import numpy as np

from tpad_rt.kernel.jit import njit
from tpad_rt.kernel import device_lookup, layout, texture_eval
from tpad_rt.kernel.cache_stamp import stamp_cache
from tpad_rt.kernel.layout import (
    ABSURD_FORCE_N,
    ABSURD_POSITION_MM,
    CFG_BRAKING,
    CFG_CARRIER_HZ,
    CFG_CONTROL_INTERVAL,
    CFG_DEFAULT_FORCE_N,
    CFG_FS_HZ,
    CFG_GAIN_SPAN,
    CFG_HORIZON_S,
    CFG_MAX_VOLTAGE_V,
    CFG_MODE_STEP_MM,
    CFG_MU0,
    CFG_MU_FLOOR,
    CFG_OUTPUT_ENVELOPE,
    CFG_OUTPUT_LEAD_S,
    CFG_POISSON,
    CFG_POWER_AVG_W,
    CFG_POWER_CAP_W,
    CFG_PREEMPHASIS,
    CFG_PSI_STAR,
    CFG_RAMP_S,
    CFG_RUN,
    CFG_SMOOTHING_S,
    CFG_SPEED_FLOOR_M_S,
    CFG_TEXTURE_T0_S,
    CFG_TRACK,
    CFG_VELOCITY_WINDOW_S,
    CFG_VOLTS_PER_FS,
    CFG_WATCHDOG_S,
    DEV_AMP_M_PER_V,
    DEV_CARRIER_HZ,
    DEV_MODE_GAIN,
    DEV_POWER_W_PER_V2,
    DEV_TAU_S,
    FINGER_DOWN,
    FINGER_FORCE_N,
    FINGER_T_S,
    FINGER_X_MM,
    FINGER_Y_MM,
    FAULT_DEVICE,
    FAULT_FINGER,
    FAULT_OUTPUT,
    FAULT_POWER,
    FAULT_STATE,
    FAULT_TEXTURE,
    FLAG_FAULT,
    FLAG_POWER,
    FLAG_SHAPER_LIMIT,
    FLAG_SPEED_FLOOR,
    FLAG_VOLTAGE,
    FLAG_WATCHDOG,
    MAX_CARRIER_FRACTION,
    MAX_CONTROL_INTERVAL,
    MAX_GAIN_SPAN,
    MAX_OUTPUT_LEAD_S,
    MAX_SPEED_MM_S,
    MODEL_GUARD_FRACTION,
    TRACKED_CARRIER_FACTOR,
    STATE_AMPLITUDE_M,
    STATE_CAP_V,
    STATE_CARRIER_COS,
    STATE_CARRIER_SIN,
    STATE_COMMAND_V,
    STATE_COS_TABLE,
    STATE_DECAY_TABLE,
    STATE_DRIVE_LOW_V,
    STATE_ENVELOPE,
    STATE_FAULT_CAUSES,
    STATE_FAULT_EVENTS,
    STATE_FAULT_PREVIOUS,
    STATE_FAULT_SAMPLES,
    STATE_FAULT_STEPS,
    STATE_FINGER_SAMPLE,
    STATE_FIRST_SEGMENT_SAMPLES,
    STATE_FIRST_SEGMENT_V2,
    STATE_FORCE_N,
    STATE_GATE,
    STATE_MODEL_GAIN_M_PER_V,
    STATE_MODEL_ON_REF,
    STATE_MODEL_SLIP_V,
    STATE_MODEL_STEP,
    STATE_MODEL_V,
    STATE_NEXT_INDEX,
    STATE_NEXT_PHASE,
    STATE_OVER_CAP_BLOCKS,
    STATE_PHASE_HI,
    STATE_PHASE_INDEX,
    STATE_PHASE_LO,
    STATE_PLATE_W,
    STATE_PRESS_BRAKING,
    STATE_POWER_PER_V2,
    STATE_FOLLOW_GAIN,
    STATE_RING_SLOT,
    STATE_RAMP_SAMPLES,
    STATE_RAMP_START,
    STATE_SIN_TABLE,
    STATE_SMOOTH_START_V,
    STATE_SPEED_MM_S,
    STATE_STEP_CARRIER_HZ,
    STATE_STEP_FLAGS,
    STATE_STEP_OPEN,
    STATE_STEP_SAMPLES,
    STATE_TABLE_CARRIER_HZ,
    STATE_TABLE_FS_HZ,
    STATE_TABLE_SMOOTHING_S,
    STATE_TARGET_MU,
    STATE_VELOCITY_SAMPLE,
    STATE_VX_MM_S,
    STATE_VY_MM_S,
    STATE_WINDOW_SUM_W,
    STATE_X_MM,
    STATE_Y_MM,
    TEL_AMPLITUDE_UM,
    TEL_FLAGS,
    TEL_FORCE_N,
    TEL_PLATE_W,
    TEL_POWER_W,
    TEL_SPEED_MM_S,
    TEL_T_S,
    TEL_TARGET_MU,
    TEL_VOLTAGE_V,
    TEL_X_MM,
    TEL_Y_MM,
)
from tpad_rt.kernel.device_lookup import device_value, force_cell, grid_cell
from tpad_rt.kernel.texture_eval import eval_texture
from tpad_rt.physics import friction
from tpad_rt.physics.friction import amplitude_for_core

#: Relative margin every limit keeps against rounding: the cap is ``max_voltage_v``
#: and the budgets times ``1 - SAFETY_MARGIN``, so float32 output rounding (2**-24
#: relative) and sums of rounded powers stay under the true limits.
SAFETY_MARGIN = 1e-6
#: Volts of a carried difference (the smoothing's distance from the command, the plate model, its slip) below
#: which it is 0 (far below any DAC's step): a decay that ends on the command otherwise leaves it a subnormal
#: float for good (the smallest one times a decay over 1/2 rounds back to itself), and every operation on
#: subnormals costs up to a hundred times more (the layers texture rendered 3x slower).
NEGLIGIBLE_V = 1e-24
#: Carrier phase resolution: phases are integers in units of 2**-PHASE_BITS cycles.
PHASE_BITS = 60
_HALF_BITS = PHASE_BITS // 2
_HALF_MASK = (1 << _HALF_BITS) - 1
_HALF_SPAN = float(1 << _HALF_BITS)
_PHASE_MASK = (1 << PHASE_BITS) - 1
_TWO_PI = 2.0 * math.pi
_SMALLEST_FACTOR = 1e-200
# The carrier phasor of a phase: a table at the top 8 bits, a polynomial for the rest.
_COARSE_BITS = 8
_FINE_BITS = PHASE_BITS - _COARSE_BITS
_FINE_MASK = (1 << _FINE_BITS) - 1
_RADIANS_PER_UNIT = _TWO_PI * 2.0**-PHASE_BITS
_COARSE_COS = np.cos(_TWO_PI * np.arange(1 << _COARSE_BITS) / (1 << _COARSE_BITS))
_COARSE_SIN = np.sin(_TWO_PI * np.arange(1 << _COARSE_BITS) / (1 << _COARSE_BITS))

# render_block has the texture evaluation, the layout constants, the device lookups and the
# friction model compiled into it: its disk cache is stamped with all of those files.
COMPILED_SOURCES = stamp_cache(__file__, layout.__file__, texture_eval.__file__, friction.__file__,
                               device_lookup.__file__)

# error_model="numpy": a division by zero gives inf/nan instead of raising, so no
# exception checks are compiled in (nothing here may raise inside an audio callback).
# _nrt=False (numba's one option, private, that turns its runtime off for a function; these two
# decorators, texture_eval's and device_lookup's are the only places it is used): without numba's
# reference-counted runtime (nothing here allocates), a call
# passing arrays costs no reference-count calls, so the helpers are ordinary functions,
# forceinline=True: marked for LLVM to inline always (LLVM's own heuristics left the
# control step's calls in place, about 2 ns per sample at the default control interval).
# Inlining them at numba IR level instead (inline="always") made the
# first compile 24 s for render_block and 60 s more for the audio @cfunc it was inlined
# into (numba deep-copies the callee's IR at every call site); now render_block compiles
# once, in about 10 s, and the @cfunc, the serial streamer and the offline batch call it
# (_entry: not forced inline into them; docs/kernel.md "Compilation"). The per-segment
# helpers stay inlined at IR level: cheap to copy.
_kernel = njit(cache=True, nogil=True, error_model="numpy", _nrt=False, forceinline=True)
_inline = njit(cache=True, nogil=True, error_model="numpy", _nrt=False, inline="always")
_entry = njit(cache=True, nogil=True, error_model="numpy", _nrt=False)


@_kernel
def carrier_step_units(carrier_hz: float, fs_hz: float) -> int:
    """The carrier's phase advance per sample, ``round(carrier_hz / fs_hz * 2**60)`` (2**-60 cycles).

    Exact for any ratio above 2**-8 (the ratio is a float64, so scaling it by 2**60
    is an integer); the carrier then runs at ``step * fs_hz / 2**60`` Hz, within
    2**-61 fs of ``carrier_hz``. Needs ``0 <= carrier_hz < fs_hz``.
    """
    return round(carrier_hz / fs_hz * 2.0**PHASE_BITS)


@_kernel
def carrier_phase_units(n: int, step_units: int) -> int:
    """``(n * step_units) mod 2**60``: the carrier phase of sample ``n`` in 2**-60 cycles.

    Exact for any ``n >= 0`` and ``0 <= step_units < 2**60``: the product is built
    from 30-bit halves so that no intermediate exceeds 2**61 (no int64 overflow).
    """
    n_lo = n & _HALF_MASK
    n_hi = (n >> _HALF_BITS) & _HALF_MASK
    s_lo = step_units & _HALF_MASK
    s_hi = step_units >> _HALF_BITS
    cross = (n_hi * s_lo + n_lo * s_hi) & _HALF_MASK
    return (n_lo * s_lo + (cross << _HALF_BITS)) & _PHASE_MASK


@_kernel
def _unit_phasor(phase_units: int) -> tuple[float, float]:
    """``(cos, sin)`` of the phase ``phase_units`` (2**-60 cycles), within ~3e-16, without libm.

    ``cos`` and ``sin`` of the top 8 bits come from a table, those of the rest
    (``d < 2 pi / 256``) from their Taylor series to ``d**8`` (next term < 1e-20),
    then the angle-sum formulas combine them (cheaper than libm's ``sin`` and ``cos``).
    """
    coarse = phase_units >> _FINE_BITS
    d = (phase_units & _FINE_MASK) * _RADIANS_PER_UNIT
    d2 = d * d
    sin_d = d * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0)))
    cos_d = 1.0 - d2 / 2.0 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0 * (1.0 - d2 / 56.0)))
    cos_c = _COARSE_COS[coarse]
    sin_c = _COARSE_SIN[coarse]
    return cos_c * cos_d - sin_c * sin_d, sin_c * cos_d + cos_c * sin_d


@_kernel
def _mode_gain(cfg: np.ndarray, dev: np.ndarray, x_mm: float) -> float:
    """``dev[DEV_MODE_GAIN]`` at ``x_mm`` (mm, clamped to its grid): the amplitude the finger's contact patch
    feels over the antinode amplitude; 1 when CFG_MODE_STEP_MM is not > 0 (no mode shape to compensate)."""
    step_mm = cfg[CFG_MODE_STEP_MM]
    if not step_mm > 0.0:
        return 1.0
    return device_value(dev, DEV_MODE_GAIN, grid_cell(dev, x_mm / step_mm))


@_kernel
def _refresh_tables(cfg: np.ndarray, state: np.ndarray, carrier_hz: float) -> None:
    """Rebuild the per-sample tables (carrier rotation, smoothing decay) if the rate, the step's carrier
    ``carrier_hz`` (Hz) or the smoothing changed.

    ``cos(j w)``, ``sin(j w)`` of the exact integer phase of sample ``j``, for every
    ``j < MAX_CONTROL_INTERVAL``, and ``d^j = exp(-j / (smoothing_s fs))`` for every ``j <=
    MAX_CONTROL_INTERVAL``.
    """
    fs_hz = cfg[CFG_FS_HZ]
    smoothing_s = cfg[CFG_SMOOTHING_S]
    if (
        state[STATE_TABLE_FS_HZ] == fs_hz
        and state[STATE_TABLE_CARRIER_HZ] == carrier_hz
        and state[STATE_TABLE_SMOOTHING_S] == smoothing_s
    ):
        return
    step_units = carrier_step_units(carrier_hz, fs_hz)
    smoothing_samples = smoothing_s * fs_hz
    for j in range(MAX_CONTROL_INTERVAL):
        state[STATE_COS_TABLE + j], state[STATE_SIN_TABLE + j] = _unit_phasor(carrier_phase_units(j, step_units))
    for j in range(MAX_CONTROL_INTERVAL + 1):  # (0 past the normal floats: a subnormal factor is slow)
        decay = math.exp(-j / smoothing_samples)
        state[STATE_DECAY_TABLE + j] = decay if decay >= _SMALLEST_FACTOR else 0.0
    state[STATE_TABLE_FS_HZ] = fs_hz
    state[STATE_TABLE_CARRIER_HZ] = carrier_hz
    state[STATE_TABLE_SMOOTHING_S] = smoothing_s


@_kernel
def _ring_sum(power_ring: np.ndarray) -> float:
    """Sum of the power ring in slot order (W)."""
    total = 0.0
    for slot in range(power_ring.shape[0]):
        total += power_ring[slot]
    return total


@_kernel
def _repaired_ring_sum(power_ring: np.ndarray, cap_w: float) -> float:
    """Sum of the power ring (W) after entering every slot outside ``[0, cap_w]`` (NaN too) as ``cap_w``."""
    for slot in range(power_ring.shape[0]):
        if not 0.0 <= power_ring[slot] <= cap_w:
            power_ring[slot] = cap_w
    return _ring_sum(power_ring)


@_inline
def _envelope_sums(state: np.ndarray, first: int, stop: int) -> tuple[float, float]:
    """Peak magnitude (V) and sum of squares (V^2) of the open step's envelope ``e_j``, ``first <= j < stop``.

    Summed in four interleaved partial sums (independent chains, so fast) combined
    as ``(s0 + s1) + (s2 + s3)``: a fixed order for given ``first, stop``.
    """
    peak_v = 0.0
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    j = STATE_ENVELOPE + first
    end = STATE_ENVELOPE + stop
    while j + 4 <= end:
        e0 = state[j]
        e1 = state[j + 1]
        e2 = state[j + 2]
        e3 = state[j + 3]
        s0 += e0 * e0
        s1 += e1 * e1
        s2 += e2 * e2
        s3 += e3 * e3
        peak_v = max(peak_v, max(max(abs(e0), abs(e1)), max(abs(e2), abs(e3))))
        j += 4
    while j < end:
        e0 = state[j]
        s0 += e0 * e0
        peak_v = max(peak_v, abs(e0))
        j += 1
    return peak_v, (s0 + s1) + (s2 + s3)


@_inline
def _drive_power_w(state: np.ndarray, energy_v2: float, samples: int) -> float:
    """The open step's drive power (W) over ``samples`` samples whose squared envelopes sum to ``energy_v2`` (V^2):
    ``p1 * mean(e^2)``, at most what a drive at the step's cap costs (a pressed plate braked at the full volts
    spends what braking at the cap would: the budgets hold; the plate's power is reported apart, TEL_PLATE_W)."""
    p1_w = state[STATE_POWER_PER_V2]
    return min(p1_w * energy_v2 / samples, p1_w * state[STATE_CAP_V] * state[STATE_CAP_V])


@_kernel
def _noticeable_v(value_v: float) -> float:
    """``value_v`` (V), or 0 when its magnitude is below NEGLIGIBLE_V (NaN is kept: the guards see it)."""
    return 0.0 if abs(value_v) < NEGLIGIBLE_V else value_v


@_kernel
def _close_step(cfg: np.ndarray, state: np.ndarray, power_ring: np.ndarray) -> None:
    """Account for the open control step: its power into the ring, its smoothing and ramp advanced.

    The step's power is ``p1(force) * mean(e^2)`` over its rendered samples, the sum of
    ``e^2`` taken in one fixed order (the first segment's sum when it covered the whole
    step, else the same sum recomputed), whatever the blocks were. The ring's
    running sum is recomputed from scratch each time the last slot is written, so its
    rounding error never accumulates beyond one window. A step whose power is not a
    number in ``[0, power_cap_w]`` (the limits keep every step's power in it; only a
    corrupt ``p1`` or envelope gets out) is entered as ``power_cap_w``.
    """
    if state[STATE_STEP_OPEN] == 0.0 or not 0.0 < state[STATE_STEP_SAMPLES] <= MAX_CONTROL_INTERVAL:
        return
    if not 0.0 <= state[STATE_RING_SLOT] < power_ring.shape[0]:
        return  # a corrupt slot: _control_step resets it and counts a state fault
    samples = int(state[STATE_STEP_SAMPLES])
    energy_v2 = state[STATE_FIRST_SEGMENT_V2]
    if state[STATE_FIRST_SEGMENT_SAMPLES] != samples:  # rendered in pieces: sum them in the same order
        energy_v2 = _envelope_sums(state, 0, samples)[1]
    power_w = _drive_power_w(state, energy_v2, samples)
    if not 0.0 <= power_w <= cfg[CFG_POWER_CAP_W]:  # only a bad p1 or envelope: counted as the whole cap
        power_w = cfg[CFG_POWER_CAP_W]
    slot = int(state[STATE_RING_SLOT])
    state[STATE_WINDOW_SUM_W] += power_w - power_ring[slot]
    power_ring[slot] = power_w
    if slot == power_ring.shape[0] - 1:
        state[STATE_WINDOW_SUM_W] = _ring_sum(power_ring)
    # The plate and the model follow the same drive with the same step: what one holds beyond the other decays
    # (all of it when the step is corrupt).
    keep = 1.0 - state[STATE_MODEL_STEP]
    state[STATE_MODEL_SLIP_V] = _noticeable_v(state[STATE_MODEL_SLIP_V] * (keep ** samples if 0.0 <= keep < 1.0
                                                                           else 0.0))
    state[STATE_MODEL_V] = _noticeable_v(state[STATE_MODEL_V])
    command_v = state[STATE_COMMAND_V]
    decay = state[STATE_DECAY_TABLE + samples]
    state[STATE_SMOOTH_START_V] = command_v + _noticeable_v((state[STATE_SMOOTH_START_V] - command_v) * decay)
    direction = 1.0 if state[STATE_GATE] != 0.0 else -1.0
    ramp = state[STATE_RAMP_START] + direction * samples
    state[STATE_RAMP_START] = min(max(ramp, 0.0), state[STATE_RAMP_SAMPLES])


@_kernel
def _next_slot(slot: int, slots: int) -> int:
    """The ring slot after ``slot`` (no division)."""
    return slot + 1 if slot + 1 < slots else 0


@_kernel
def _previous_slot(slot: int, slots: int) -> int:
    """The ring slot before ``slot`` (no division)."""
    return slot - 1 if slot > 0 else slots - 1


@_kernel
def _newest_sample(finger: np.ndarray, count: int, t_s: float, hint: int) -> tuple[int, int]:
    """``(index, row)`` of the newest finger sample with ``t <= t_s``, or ``(-1, -1)``.

    ``index`` counts the samples written before it; ``row = index % R``. Only rows the
    producer cannot be overwriting are read: the newest ``R - 1`` (row ``count % R``
    may be half-written). Finger times are non-decreasing, so the search runs forward
    from ``hint`` (the previous step's answer) when that is still readable and not
    later than ``t_s``: O(1) per step however far ahead the producer writes;
    otherwise backwards from the newest.
    """
    rows = finger.shape[0]
    oldest = max(0, count - rows + 1)
    if oldest <= hint < count:
        row = hint % rows
        if finger[row, FINGER_T_S] <= t_s:
            i = hint
            while i + 1 < count and finger[_next_slot(row, rows), FINGER_T_S] <= t_s:
                i += 1
                row = _next_slot(row, rows)
            return i, row
    i = count - 1
    row = i % rows
    while i >= oldest and finger[row, FINGER_T_S] > t_s:
        i -= 1
        row = _previous_slot(row, rows)
    return (i, row) if i >= oldest else (-1, -1)


@_kernel
def _velocity_mm_s(finger: np.ndarray, count: int, newest: int, row: int, window_s: float) -> tuple[float, float]:
    """Finger velocity (mm/s) from sample ``newest`` (at ``row``) and the oldest of its stroke within ``window_s``.

    The stroke runs back while samples are down, their positions are finite and within
    ABSURD_POSITION_MM (a bad sample ends it, as a lift does), and the finger moved the
    same way: a step whose direction is opposed (negative dot product) to the newest
    step that moved ends it, so a reversal inside the window does not average the two
    directions into a slow speed. ``(0, 0)`` without an older sample or when the two
    samples share a time.
    """
    rows = finger.shape[0]
    oldest = max(0, count - rows + 1)
    t_newest = finger[row, FINGER_T_S]
    first = row
    k = newest - 1
    earlier = _previous_slot(row, rows)
    heading_x = 0.0
    heading_y = 0.0
    while (k >= oldest and finger[earlier, FINGER_DOWN] != 0.0 and t_newest - finger[earlier, FINGER_T_S] <= window_s
           and abs(finger[earlier, FINGER_X_MM]) <= ABSURD_POSITION_MM
           and abs(finger[earlier, FINGER_Y_MM]) <= ABSURD_POSITION_MM):
        step_x = finger[first, FINGER_X_MM] - finger[earlier, FINGER_X_MM]
        step_y = finger[first, FINGER_Y_MM] - finger[earlier, FINGER_Y_MM]
        if step_x * heading_x + step_y * heading_y < 0.0:
            break
        if heading_x == 0.0 and heading_y == 0.0:
            heading_x = step_x
            heading_y = step_y
        first = earlier
        k -= 1
        earlier = _previous_slot(earlier, rows)
    dt_s = t_newest - finger[first, FINGER_T_S]
    if not dt_s > 0.0:
        return 0.0, 0.0
    return (finger[row, FINGER_X_MM] - finger[first, FINGER_X_MM]) / dt_s, (
        finger[row, FINGER_Y_MM] - finger[first, FINGER_Y_MM]
    ) / dt_s


@_kernel
def _read_finger(t_s: float, cfg: np.ndarray, state: np.ndarray, finger: np.ndarray, count: int) -> int:
    """Update the step's finger in ``state`` (position extrapolated, speed, force): 1 if it is active,
    0 if not, -1 for a fault (the sample or the velocity from it is not finite, or is absurd).

    Active: a sample at or before ``t_s``, down, at most ``watchdog_s`` old when the block is rendered: finger
    times are the stream time of the sample at the output when they were pushed (Renderer.now_s), and an output
    that plays a block ``CFG_OUTPUT_LEAD_S`` after rendering it (a serial amplifier's buffer, an audio device's
    latency) renders ``t_s`` that much ahead, so the age is judged at ``t_s - lead``: a finger that stops reporting
    closes the gate ``watchdog_s`` after its last sample on the host's clock, whatever the lead. The position is
    extrapolated to ``t_s`` itself (at most ``watchdog_s + lead`` ahead). When not active, or at a fault, the
    previous step's finger is kept. A speed above
    MAX_SPEED_MM_S is clamped to it (direction kept); a position beyond
    ABSURD_POSITION_MM, extrapolated or not, or a force outside ``[0, ABSURD_FORCE_N]``
    (NaN: unknown, the default applies) is a fault.
    """
    hint = state[STATE_FINGER_SAMPLE]
    newest, row = _newest_sample(finger, count, t_s, int(hint) - 1 if 0.0 <= hint <= count else -1)
    state[STATE_FINGER_SAMPLE] = newest + 1.0
    if newest < 0:
        return 0
    age_s = t_s - finger[row, FINGER_T_S]
    watchdog_s = cfg[CFG_WATCHDOG_S]
    output_lead_s = cfg[CFG_OUTPUT_LEAD_S]
    if not 0.0 <= output_lead_s <= MAX_OUTPUT_LEAD_S:  # NaN too: the table's writer clamps it; this is the guard
        output_lead_s = 0.0
    if finger[row, FINGER_DOWN] == 0.0 or age_s - output_lead_s > watchdog_s:
        return 0
    x_mm = finger[row, FINGER_X_MM]
    y_mm = finger[row, FINGER_Y_MM]
    force_n = finger[row, FINGER_FORCE_N]
    if not (abs(x_mm) <= ABSURD_POSITION_MM and abs(y_mm) <= ABSURD_POSITION_MM
            and (math.isnan(force_n) or 0.0 <= force_n <= ABSURD_FORCE_N)):
        return -1
    if state[STATE_VELOCITY_SAMPLE] != newest + 1.0:
        vx, vy = _velocity_mm_s(finger, count, newest, row, cfg[CFG_VELOCITY_WINDOW_S])
        fastest = max(abs(vx), abs(vy))
        if not fastest < math.inf:
            return -1
        if fastest > MAX_SPEED_MM_S:
            vx *= MAX_SPEED_MM_S / fastest
            vy *= MAX_SPEED_MM_S / fastest
        state[STATE_VX_MM_S] = vx
        state[STATE_VY_MM_S] = vy
        state[STATE_VELOCITY_SAMPLE] = newest + 1.0
    vx = state[STATE_VX_MM_S]
    vy = state[STATE_VY_MM_S]
    lead_s = min(age_s + cfg[CFG_HORIZON_S], watchdog_s + output_lead_s)
    x_mm += vx * lead_s
    y_mm += vy * lead_s
    if not (abs(x_mm) <= ABSURD_POSITION_MM and abs(y_mm) <= ABSURD_POSITION_MM):
        return -1
    state[STATE_X_MM] = x_mm
    state[STATE_Y_MM] = y_mm
    state[STATE_SPEED_MM_S] = math.sqrt(vx * vx + vy * vy)
    state[STATE_FORCE_N] = cfg[CFG_DEFAULT_FORCE_N] if math.isnan(force_n) else force_n
    return 1


@_kernel
def _command_volts(
    t_s: float, cfg: np.ndarray, state: np.ndarray, amplitude_m_per_v: float, carrier_hz: float,
    prog: np.ndarray, params: np.ndarray, img: np.ndarray, stack: np.ndarray,
) -> tuple[float, int, int]:
    """Envelope volts (peak) the texture asks for at the step's finger, and FLAG_SPEED_FLOOR if floored; the
    friction model's vibration frequency is the step's carrier ``carrier_hz`` (Hz), ``amplitude_m_per_v``
    the plate amplitude under the finger per peak volt (m/V).

    Returns ``(volts, FLAG_* bits, FAULT_* bits)``; writes the clamped target friction to
    ``state``. A texture value that is not finite is a FAULT_TEXTURE, a command that is
    not a finite number >= 0 (the device's constants) a FAULT_DEVICE: the volts are 0 then.
    """
    speed_mm_s = state[STATE_SPEED_MM_S]
    per_speed = 1.0 / speed_mm_s if speed_mm_s > 0.0 else 0.0
    ux = state[STATE_VX_MM_S] * per_speed
    uy = state[STATE_VY_MM_S] * per_speed
    mu = eval_texture(
        prog, params, img, stack, state[STATE_X_MM], state[STATE_Y_MM], ux, uy, t_s - cfg[CFG_TEXTURE_T0_S]
    )
    if not abs(mu) < math.inf:
        return 0.0, 0, FAULT_TEXTURE
    mu = min(max(mu, cfg[CFG_MU_FLOOR]), 1.0)
    state[STATE_TARGET_MU] = mu
    speed_m_s = speed_mm_s * 1e-3
    flags = 0
    if speed_m_s < cfg[CFG_SPEED_FLOOR_M_S]:
        speed_m_s = cfg[CFG_SPEED_FLOOR_M_S]
        flags = FLAG_SPEED_FLOOR
    amplitude_m = amplitude_for_core(
        mu, carrier_hz, speed_m_s, cfg[CFG_MU0], cfg[CFG_POISSON], cfg[CFG_PSI_STAR]
    )
    command_v = amplitude_m / amplitude_m_per_v
    if not 0.0 <= command_v < math.inf:
        return 0.0, 0, FAULT_DEVICE
    return command_v, flags, 0


@_kernel
def _cap_volts(
    cfg: np.ndarray, state: np.ndarray, power_ring: np.ndarray, p1_w: float, slot: int
) -> tuple[float, int, int]:
    """The step's envelope cap (volts peak), the FLAG_* of the bound that sets it, and FAULT_* bits.

    ``min(max_voltage_v, sqrt(power_cap_w / p1), sqrt(allowance / p1))``, each limit
    times ``1 - SAFETY_MARGIN``; ``allowance = M * power_avg_w`` less the previous
    ``M - 1`` steps' powers (the ring without ``slot``, which this step will overwrite).
    A running sum outside ``[0, M * power_cap_w]`` (to rounding) or a ring slot outside
    ``[0, power_cap_w]`` has the ring repaired and summed again (FAULT_STATE); a power
    bound that is not a finite number >= 0 gives a cap of 0 (FAULT_POWER).
    """
    keep = 1.0 - SAFETY_MARGIN
    fault = 0
    most_w = power_ring.shape[0] * cfg[CFG_POWER_CAP_W] * (1.0 + SAFETY_MARGIN)  # every slot <= the cap
    if not (-most_w * SAFETY_MARGIN <= state[STATE_WINDOW_SUM_W] <= most_w
            and 0.0 <= power_ring[slot] <= cfg[CFG_POWER_CAP_W]):
        state[STATE_WINDOW_SUM_W] = _repaired_ring_sum(power_ring, cfg[CFG_POWER_CAP_W])
        fault = FAULT_STATE
    previous_w = state[STATE_WINDOW_SUM_W] - power_ring[slot]
    allowance_w = max(power_ring.shape[0] * cfg[CFG_POWER_AVG_W] * keep - previous_w, 0.0)
    power_v = math.sqrt(min(cfg[CFG_POWER_CAP_W] * keep, allowance_w) / p1_w)
    voltage_v = cfg[CFG_MAX_VOLTAGE_V] * keep
    if voltage_v <= power_v:
        return voltage_v, FLAG_VOLTAGE, fault
    if power_v >= 0.0:
        return power_v, FLAG_POWER, fault
    return 0.0, FLAG_POWER, fault | FAULT_POWER


@_kernel
def _repaired_state(cfg: np.ndarray, state: np.ndarray) -> int:
    """Reset the carried values that are out of their ranges; FAULT_STATE if one was.

    The smoothed volts must lie in ``[0, max_voltage_v]``, the plate model's within ``max_voltage_v`` times
    the device's gain span (:func:`_model_bound_v`), its slip within twice that, the press-braking mark 0 or 1
    and the model's gain (m/V) a finite number >= 0, the gain ramp position in
    ``[0, ramp samples]`` (both 0 for a fresh stream); a reset one restarts from 0 (no
    ramp can start from a value that is not finite). The per-sample tables are then
    rebuilt, in case they were overwritten too.
    """
    fault = 0
    if not 0.0 <= state[STATE_SMOOTH_START_V] <= cfg[CFG_MAX_VOLTAGE_V]:
        state[STATE_SMOOTH_START_V] = 0.0
        fault = FAULT_STATE
    if not abs(state[STATE_MODEL_V]) <= _model_bound_v(cfg):
        state[STATE_MODEL_V] = 0.0
        fault = FAULT_STATE
    if not abs(state[STATE_MODEL_SLIP_V]) <= 2.0 * _model_bound_v(cfg):
        state[STATE_MODEL_SLIP_V] = 0.0
        fault = FAULT_STATE
    if not (state[STATE_PRESS_BRAKING] == 0.0 or state[STATE_PRESS_BRAKING] == 1.0):
        state[STATE_PRESS_BRAKING] = 0.0
        fault = FAULT_STATE
    if not (state[STATE_MODEL_ON_REF] == 0.0 or state[STATE_MODEL_ON_REF] == 1.0):
        state[STATE_MODEL_ON_REF] = 0.0
        fault = FAULT_STATE
    if not 0.0 <= state[STATE_MODEL_GAIN_M_PER_V] < math.inf:
        state[STATE_MODEL_GAIN_M_PER_V] = 0.0
        fault = FAULT_STATE
    if not 0.0 <= state[STATE_RAMP_START] <= max(state[STATE_RAMP_SAMPLES], 0.0):
        state[STATE_RAMP_START] = 0.0
        fault = FAULT_STATE
    if fault:
        state[STATE_TABLE_FS_HZ] = math.nan  # never equal: _refresh_tables rebuilds them
    return fault


@_inline
def _gain_span(cfg: np.ndarray) -> float:
    """The device's largest over its smallest plate amplitude per volt (CFG_GAIN_SPAN; one that is not a number in
    ``[1, MAX_GAIN_SPAN]`` counts as MAX_GAIN_SPAN)."""
    span = cfg[CFG_GAIN_SPAN]
    return span if 1.0 <= span <= MAX_GAIN_SPAN else MAX_GAIN_SPAN


@_inline
def _model_bound_v(cfg: np.ndarray) -> float:
    """The most volts of drive the plate model may hold: ``max_voltage_v`` times the device's gain span (0 if that
    is not a finite number).

    A drive within ``max_voltage_v`` brings the plate to at most ``max_voltage_v`` times the largest gain; a press
    then makes that amplitude worth up to the span times as many volts at the smallest gain.
    """
    bound_v = cfg[CFG_MAX_VOLTAGE_V] * _gain_span(cfg)
    return bound_v if 0.0 < bound_v < math.inf else 0.0


@_inline
def _model_volts(state: np.ndarray) -> float:
    """The shaper's model of the plate (volts of drive): the smoothed volts while it sits on them."""
    return state[STATE_SMOOTH_START_V] if state[STATE_MODEL_ON_REF] != 0.0 else state[STATE_MODEL_V]


@_inline
def _guard_model(cfg: np.ndarray, state: np.ndarray, gain_m_per_v: float, p1_w: float) -> int:
    """Brake a plate that holds more than the power cap allows at the step's gain ``gain_m_per_v`` (m/V) and
    power bound ``p1_w`` (W/V^2); FAULT_STATE if the last step's gain cannot be one of the device's.

    The shaper's model is the plate's envelope in volts of drive (docs/kernel.md "Per
    sample"). A finger that presses harder lowers the gain and raises the damping: the
    amplitude the plate already holds is worth ``old gain / new gain`` times the volts it
    was, and dissipates more. Where that is over the power cap by more than
    MODEL_GUARD_FRACTION, the model is set to it (unclamped: it may exceed ``max_voltage_v``,
    up to :func:`_model_bound_v`) and leaves the command, so the shaper brakes the plate down to
    the command, at up to the full volts while it holds more than the cap (_control_step),
    instead of driving on as if it held what the cap allows. Smaller changes (a lighter touch too) leave the
    model as it is (the shaper does not answer every wobble of a finger's force with a full-volt correction)
    and are kept as its slip (STATE_MODEL_SLIP_V): the volts the plate holds beyond the model, which the next
    changes add to and which decays as the plate settles (_close_step), so a press made of many small
    changes is braked once they add up to the guard's fraction. A gain that is not a finite number > 0 (a
    device fault) leaves the model, its slip and the last valid gain as they are: the next valid step compares
    with that one. Two gains further apart than the device's gain span (a corrupt record of the last one) make
    the step a state fault, its slip reset.
    """
    previous = state[STATE_MODEL_GAIN_M_PER_V]
    if not 0.0 < gain_m_per_v < math.inf:
        return 0
    state[STATE_MODEL_GAIN_M_PER_V] = gain_m_per_v
    if not (previous > 0.0 and p1_w > 0.0):
        return 0
    ratio = previous / gain_m_per_v
    span = _gain_span(cfg) * (1.0 + SAFETY_MARGIN)
    if not (1.0 <= ratio * span and ratio <= span):
        state[STATE_MODEL_SLIP_V] = 0.0
        return FAULT_STATE
    model_v = _model_volts(state)
    bound_v = _model_bound_v(cfg)
    held_v = min(max((model_v + state[STATE_MODEL_SLIP_V]) * ratio, -bound_v), bound_v)
    if held_v > 0.0 and held_v * held_v * p1_w > cfg[CFG_POWER_CAP_W] * (1.0 + MODEL_GUARD_FRACTION):
        state[STATE_MODEL_V] = held_v
        state[STATE_MODEL_ON_REF] = 0.0
        state[STATE_MODEL_SLIP_V] = 0.0
    else:
        state[STATE_MODEL_SLIP_V] = held_v - model_v
    return 0


@_kernel
def _note_fault(state: np.ndarray, causes: int, new_step: bool) -> None:
    """Record the faults ``causes`` (FAULT_* bits); a ``new_step`` is counted as a fault step, and as a
    new fault if the last step had none."""
    if new_step:
        if state[STATE_FAULT_PREVIOUS] == 0.0:
            state[STATE_FAULT_EVENTS] += 1.0
        state[STATE_FAULT_PREVIOUS] = 1.0
        state[STATE_FAULT_STEPS] += 1.0
    known = state[STATE_FAULT_CAUSES]
    state[STATE_FAULT_CAUSES] = float((int(known) if 0.0 <= known < 2**31 else 0) | causes)


@_kernel
def _step_phase(n: int, cfg: np.ndarray, state: np.ndarray, carrier_hz: float) -> tuple[int, int]:
    """``(phase, FAULT_* bits)``: the carrier's phase at sample ``n`` (2**-60 cycles), the first of a step at
    ``carrier_hz`` (Hz), recorded in ``state`` for the next step.

    A fixed carrier's phase is ``n * S mod 2**60`` (exact, from the index alone). A tracked one
    (CFG_TRACK, carrier samples) runs on from the last step's phase, at the last step's carrier, over
    the samples between: the phase never jumps when the carrier moves. Recorded phase halves that are not
    whole numbers in ``[0, 2**30)``, or an index that is not a whole number in ``[0, n]``, are
    corrupt: the phase restarts from ``n * S`` (FAULT_STATE).
    """
    fs_hz = cfg[CFG_FS_HZ]
    step_units = carrier_step_units(carrier_hz, fs_hz)
    fault = 0
    if cfg[CFG_TRACK] == 0.0 or cfg[CFG_OUTPUT_ENVELOPE] != 0.0 or state[STATE_STEP_OPEN] == 0.0:
        phase_units = carrier_phase_units(n, step_units)  # (envelope output: the amplifier keeps the phase)
    else:
        hi, lo, index, last_hz = (state[STATE_PHASE_HI], state[STATE_PHASE_LO], state[STATE_PHASE_INDEX],
                                  state[STATE_STEP_CARRIER_HZ])
        if (0.0 <= hi < _HALF_SPAN and hi == math.floor(hi) and 0.0 <= lo < _HALF_SPAN and lo == math.floor(lo)
                and 0.0 <= index <= n and index == math.floor(index) and 0.0 < last_hz < fs_hz):
            start = (int(hi) << _HALF_BITS) | int(lo)
            phase_units = (start + carrier_phase_units(n - int(index), carrier_step_units(last_hz, fs_hz))) \
                & _PHASE_MASK
        else:
            phase_units = carrier_phase_units(n, step_units)
            fault = FAULT_STATE
    state[STATE_PHASE_HI] = float(phase_units >> _HALF_BITS)
    state[STATE_PHASE_LO] = float(phase_units & _HALF_MASK)
    state[STATE_PHASE_INDEX] = float(n)
    state[STATE_STEP_CARRIER_HZ] = carrier_hz
    return phase_units, fault


@_kernel
def _control_step(
    n: int, cfg: np.ndarray, dev: np.ndarray, state: np.ndarray, power_ring: np.ndarray,
    finger: np.ndarray, finger_count: np.ndarray,
    prog: np.ndarray, params: np.ndarray, img: np.ndarray, stack: np.ndarray,
) -> None:
    """Close the open step and open one at sample ``n``: finger, texture, inverse model, limits, carrier.

    Faults (docs/kernel.md "Faults"): a finger, texture, device or power value that is
    not finite or is absurd, or carried state out of its range, makes the step's
    command 0 and closes the gate (the drive ramps to 0), sets FLAG_FAULT and counts it;
    the next step starts afresh from the data it then finds.
    """
    fault = 0
    slot = 0
    if state[STATE_STEP_OPEN] != 0.0:
        if 0.0 <= state[STATE_RING_SLOT] < power_ring.shape[0]:
            slot = _next_slot(int(state[STATE_RING_SLOT]), power_ring.shape[0])
        else:
            fault = FAULT_STATE
    _close_step(cfg, state, power_ring)
    fault |= _repaired_state(cfg, state)
    fs_hz = cfg[CFG_FS_HZ]
    t_s = n / fs_hz
    finger_status = _read_finger(t_s, cfg, state, finger, finger_count[0])
    if finger_status < 0:
        fault |= FAULT_FINGER
    cell = force_cell(cfg, dev, state[STATE_FORCE_N])
    carrier_hz = cfg[CFG_CARRIER_HZ]
    if cfg[CFG_TRACK] != 0.0:
        tracked_hz = device_value(dev, DEV_CARRIER_HZ, cell)
        # Carrier samples must stay below the sample rate's limit; an amplifier that makes the carrier itself
        # (envelope output) is sent the carrier instead, within twice the device's (its derived checks).
        highest_hz = (MAX_CARRIER_FRACTION * fs_hz if cfg[CFG_OUTPUT_ENVELOPE] == 0.0
                      else TRACKED_CARRIER_FACTOR * cfg[CFG_CARRIER_HZ])
        if 0.0 < tracked_hz <= highest_hz:
            carrier_hz = tracked_hz
        else:
            fault |= FAULT_DEVICE
    _refresh_tables(cfg, state, carrier_hz)
    phase_units, phase_fault = _step_phase(n, cfg, state, carrier_hz)
    fault |= phase_fault
    amplitude_m_per_v = device_value(dev, DEV_AMP_M_PER_V, cell)
    p1_w = device_value(dev, DEV_POWER_W_PER_V2, cell)
    tau_s = device_value(dev, DEV_TAU_S, cell)
    if not (0.0 < amplitude_m_per_v < math.inf and 0.0 < p1_w < math.inf and 0.0 <= tau_s < math.inf):
        fault |= FAULT_DEVICE
        # The step's power is then counted as if a drive at max_voltage_v used the whole cap.
        p1_w = cfg[CFG_POWER_CAP_W] / (cfg[CFG_MAX_VOLTAGE_V] * cfg[CFG_MAX_VOLTAGE_V])
        tau_s = 0.0
    command_v = 0.0
    flags = 0
    mode_gain = _mode_gain(cfg, dev, state[STATE_X_MM])
    if not 0.0 < mode_gain < math.inf:
        fault |= FAULT_DEVICE
    if finger_status > 0 and fault == 0:
        command_v, flags, command_fault = _command_volts(
            t_s, cfg, state, amplitude_m_per_v * mode_gain, carrier_hz, prog, params, img, stack)
        fault |= command_fault
    elif finger_status == 0:
        command_v = state[STATE_COMMAND_V]
        flags = FLAG_WATCHDOG
    cap_v, limit_flag, cap_fault = _cap_volts(cfg, state, power_ring, p1_w, slot)
    fault |= cap_fault
    if command_v > cap_v:
        command_v = cap_v
        flags |= limit_flag
    elif not command_v >= 0.0:
        fault |= FAULT_STATE
    # The plate model's step per sample, 1 - exp(-1 / (tau fs)) (1 for tau = 0: the model is the drive).
    model_step = -math.expm1(-1.0 / (tau_s * fs_hz)) if tau_s > 0.0 else 1.0
    follow_gain = 1.0 / model_step if cfg[CFG_PREEMPHASIS] != 0.0 else 0.0
    if not (0.0 < model_step <= 1.0 and 0.0 <= follow_gain < math.inf):
        fault |= FAULT_DEVICE
    # The plate model follows the plate through a fault too (a press then is still seen).
    fault |= _guard_model(cfg, state, amplitude_m_per_v, p1_w)
    held_v = _model_volts(state) + state[STATE_MODEL_SLIP_V]
    plate_w = p1_w * held_v * held_v  # the plate's power as the model has it (a press may take it over the cap)
    if not 0.0 <= plate_w < math.inf:  # only a corrupt model or slip: forgotten
        state[STATE_MODEL_V] = state[STATE_MODEL_SLIP_V] = state[STATE_MODEL_ON_REF] = plate_w = 0.0
        fault |= FAULT_STATE
    state[STATE_PLATE_W] = plate_w
    if fault:
        command_v = 0.0
        follow_gain = 0.0
        if not 0.0 < model_step <= 1.0:
            model_step = 1.0
        flags |= FLAG_FAULT
        _note_fault(state, fault, True)
    else:
        state[STATE_FAULT_PREVIOUS] = 0.0
    state[STATE_COMMAND_V] = command_v
    state[STATE_CAP_V] = cap_v
    state[STATE_AMPLITUDE_M] = command_v * amplitude_m_per_v if fault == 0 else 0.0
    state[STATE_POWER_PER_V2] = p1_w
    # Braking: down to -cap, or to the full volts from a step whose plate holds more than the power cap (a press)
    # until the model is back down on the command; the shaper then brakes it even without pre-emphasis.
    over_cap = state[STATE_PLATE_W] > cfg[CFG_POWER_CAP_W] * (1.0 + MODEL_GUARD_FRACTION)
    landing = state[STATE_PRESS_BRAKING] != 0.0 and held_v > state[STATE_SMOOTH_START_V]
    pressed = (over_cap or landing) and cfg[CFG_BRAKING] != 0.0 and fault == 0
    state[STATE_PRESS_BRAKING] = 1.0 if pressed else 0.0
    if pressed:
        follow_gain = 1.0 / model_step
    state[STATE_FOLLOW_GAIN] = follow_gain
    state[STATE_MODEL_STEP] = model_step
    brake_v = cfg[CFG_MAX_VOLTAGE_V] * (1.0 - SAFETY_MARGIN) if pressed else cap_v
    state[STATE_DRIVE_LOW_V] = -brake_v if cfg[CFG_BRAKING] != 0.0 and follow_gain > 0.0 else 0.0
    state[STATE_GATE] = 1.0 if finger_status > 0 and fault == 0 and cfg[CFG_RUN] != 0.0 else 0.0
    state[STATE_RAMP_SAMPLES] = max(1.0, float(round(cfg[CFG_RAMP_S] * fs_hz)))
    state[STATE_RAMP_START] = min(state[STATE_RAMP_START], state[STATE_RAMP_SAMPLES])
    state[STATE_CARRIER_COS], state[STATE_CARRIER_SIN] = _unit_phasor(phase_units)
    state[STATE_RING_SLOT] = slot
    state[STATE_STEP_SAMPLES] = 0.0
    state[STATE_FIRST_SEGMENT_SAMPLES] = 0.0
    state[STATE_STEP_FLAGS] = flags
    state[STATE_STEP_OPEN] = 1.0


@_inline
def _step_flags(state: np.ndarray) -> int:
    """The open step's FLAG_* bits (0 if the slot holds no such value)."""
    flags = state[STATE_STEP_FLAGS]
    return int(flags) if 0.0 <= flags < 256.0 else 0


@_inline
def _shape_at_full_gain(
    envelope: np.ndarray, decay: np.ndarray, first: int, stop: int, command_v: float, start_offset_v: float,
    cap_v: float, low_v: float, follow_gain: float, model_step: float, on_reference: bool, model_v: float,
) -> tuple[bool, float, int]:
    """The shaper over ``envelope[first:stop]``, all at full gain: ``(on_reference, model_v, clipped)`` after them.

    Sample by sample as :func:`_shape_in_sequence` describes, in runs: while the model sits on the command, each
    drive depends on the command alone; while a drive is held at the cap (or at ``low_v``), the next one depends
    on the model alone, which moves by one multiply-add per sample. The run's test is off that chain (a branch
    the processor predicts), so a run costs a few cycles per sample instead of the whole drive-clamp-model chain.
    The same expressions as one sample at a time: the same values to the bit.
    """
    clipped = 0
    model_keep = 1.0 - model_step  # m += k (e - m) as m (1 - k) + k e: a shorter chain from sample to sample
    cap_pull_v = cap_v * model_step
    low_pull_v = low_v * model_step
    j = first
    while j < stop:
        if on_reference:
            while j < stop:  # on the command: no value carried
                reference_before_v = command_v + start_offset_v * decay[j]
                drive_v = reference_before_v + (command_v + start_offset_v * decay[j + 1] - reference_before_v) \
                    * follow_gain
                if not low_v <= drive_v <= cap_v:
                    break
                envelope[j] = drive_v
                j += 1
            if j == stop:
                break
            model_v = command_v + start_offset_v * decay[j]  # the model leaves the command at sample j
            on_reference = False
        while j < stop:  # held at the cap: the model climbs to it
            drive_v = model_v + (command_v + start_offset_v * decay[j + 1] - model_v) * follow_gain
            if not drive_v > cap_v:
                break
            envelope[j] = cap_v
            clipped += 1
            model_v = model_v * model_keep + cap_pull_v
            j += 1
        while j < stop and low_v <= cap_v:  # held at low_v (braking): the model falls to it
            drive_v = model_v + (command_v + start_offset_v * decay[j + 1] - model_v) * follow_gain
            if not drive_v < low_v:
                break
            envelope[j] = low_v
            clipped += 1
            model_v = model_v * model_keep + low_pull_v
            j += 1
        if j == stop:
            break
        drive_v = model_v + (command_v + start_offset_v * decay[j + 1] - model_v) * follow_gain
        e_v = min(max(drive_v, low_v), cap_v)
        envelope[j] = e_v
        on_reference = e_v == drive_v
        clipped += 0 if on_reference else 1
        model_v = model_v * model_keep + e_v * model_step
        j += 1
    return on_reference, model_v, clipped


@_kernel
def _shape_in_sequence(
    state: np.ndarray, envelope: np.ndarray, decay: np.ndarray, command_v: float, start_offset_v: float,
    cap_v: float, low_v: float, follow_gain: float, model_step: float, ramp: float, ramp_direction: float,
    ramp_samples: float,
) -> int:
    """The shaper sample by sample (ramping, or the model off the command): fill ``envelope`` (V), carry the
    model in ``state``; how many drives were held at a limit.

    ``decay[k] = d^j`` for the sample before ``envelope[k]``; ``ramp`` is the gain ramp at the first sample
    before clipping to ``[0, ramp_samples]``. While ramping the drive is the ramped smoothed command and the
    model follows it; at full gain the drive lands the model on the command (docs/kernel.md "Per sample"),
    in runs (:func:`_shape_at_full_gain`).
    """
    on_reference = state[STATE_MODEL_ON_REF] != 0.0
    model_v = state[STATE_MODEL_V]
    clipped = 0
    count = envelope.shape[0]
    k = 0
    while k < count:
        full = k
        if ramp_direction > 0.0 and not min(max(ramp + ramp_direction * k, 0.0), ramp_samples) < ramp_samples:
            full = count  # rising and at full gain: at full gain to the end (no search sample by sample)
        while full < count and not min(max(ramp + ramp_direction * full, 0.0), ramp_samples) < ramp_samples:
            full += 1
        if full > k:
            on_reference, model_v, held = _shape_at_full_gain(
                envelope, decay, k, full, command_v, start_offset_v, cap_v, low_v, follow_gain, model_step,
                on_reference, model_v)
            clipped += held
            k = full
        while k < count:  # ramping: the ramped smoothed command, the model following it
            gain = min(max(ramp + ramp_direction * k, 0.0), ramp_samples)
            if not gain < ramp_samples:
                break
            if on_reference:
                model_v = command_v + start_offset_v * decay[k]
            e_v = gain * (1.0 / ramp_samples) * min(max(command_v + start_offset_v * decay[k + 1], 0.0), cap_v)
            on_reference = False
            model_v = model_v * (1.0 - model_step) + e_v * model_step
            envelope[k] = e_v
            k += 1
    state[STATE_MODEL_ON_REF] = 1.0 if on_reference else 0.0
    state[STATE_MODEL_V] = 0.0 if on_reference else model_v  # on the command: not used, kept canonical
    return clipped


@_inline
def _follow_model(state: np.ndarray, envelope: np.ndarray, reference_before_v: float, model_step: float) -> None:
    """Carry the plate model through the drives ``envelope`` (V) the shaper did not make (no pre-emphasis):
    ``m += k (e - m)``, from ``reference_before_v`` (the smoothed volts before the first) if it sat on the
    command. The guard reads it after a press (_guard_model)."""
    model_v = reference_before_v if state[STATE_MODEL_ON_REF] != 0.0 else state[STATE_MODEL_V]
    model_keep = 1.0 - model_step
    for k in range(envelope.shape[0]):
        model_v = model_v * model_keep + envelope[k] * model_step
    state[STATE_MODEL_V] = model_v
    state[STATE_MODEL_ON_REF] = 0.0


@_inline
def _render_samples(
    out: np.ndarray, first: int, stop: int, state: np.ndarray, out_per_v: float, limit: float, modulate: bool
) -> bool:
    """Render ``out[first:stop]``, all inside the open step, and store their envelope in ``state``.

    The control stage (command, smoothing, shaper, cap, gain ramp) makes each sample's
    envelope ``e_j`` (volts); the modulation stage multiplies it by the carrier when
    ``modulate`` (DAC samples), or passes it on (an amplifier that makes the carrier
    itself), both scaled by ``out_per_v``. Every limit is applied in the control stage,
    so both kinds of output obey the same ones. The shaper carries a first-order model
    of the plate's envelope from sample to sample (docs/kernel.md "Per sample"): the
    one loop with a carried value; the others vectorise. Returns True if every sample's
    magnitude is within ``limit`` (full scale; NaN is not): the output guard's first
    check (render_block then checks the envelope). A shaper drive held at the cap (or
    at ``-cap``, braking) sets FLAG_SHAPER_LIMIT on the step.
    """
    command_v = state[STATE_COMMAND_V]
    cap_v = state[STATE_CAP_V]
    low_v = state[STATE_DRIVE_LOW_V]
    follow_gain = state[STATE_FOLLOW_GAIN]
    model_step = state[STATE_MODEL_STEP]
    start_offset_v = state[STATE_SMOOTH_START_V] - command_v
    ramp_samples = state[STATE_RAMP_SAMPLES]
    per_ramp_sample = 1.0 / ramp_samples
    ramp_direction = 1.0 if state[STATE_GATE] != 0.0 else -1.0
    ramp_start = state[STATE_RAMP_START] + ramp_direction
    j0 = int(state[STATE_STEP_SAMPLES])
    count = stop - first
    decay = state[STATE_DECAY_TABLE + j0 : STATE_DECAY_TABLE + j0 + count + 1]  # d^j for the sample before, on
    envelope = state[STATE_ENVELOPE + j0 : STATE_ENVELOPE + j0 + count]
    samples = out[first:stop]
    # The smoothed command after sample j is a_j = v + (a0 - v) d^(j+1); the shaper lands the model on it.
    ramp_full = ramp_direction > 0.0 and ramp_start + j0 >= ramp_samples  # the whole segment at full gain
    clipped = 0
    if follow_gain == 0.0:  # no shaper: the ramped smoothed command (vectorises)
        for k in range(count):
            ramp = min(max(ramp_start + ramp_direction * (j0 + k), 0.0), ramp_samples)
            envelope[k] = ramp * per_ramp_sample * min(max(command_v + start_offset_v * decay[k + 1], 0.0), cap_v)
        _follow_model(state, envelope, command_v + start_offset_v * decay[0], model_step)
    elif ramp_full and state[STATE_MODEL_ON_REF] != 0.0:
        # The model sits on the command: each drive depends on the command alone (vectorises). If one
        # is clipped the segment is rendered again below, sample by sample, with the same expressions.
        for k in range(count):
            reference_before_v = command_v + start_offset_v * decay[k]
            drive_v = reference_before_v + (command_v + start_offset_v * decay[k + 1] - reference_before_v) * follow_gain
            e_v = min(max(drive_v, low_v), cap_v)
            clipped += 0 if e_v == drive_v else 1
            envelope[k] = e_v
    if follow_gain != 0.0 and (clipped or not (ramp_full and state[STATE_MODEL_ON_REF] != 0.0)):
        clipped = _shape_in_sequence(state, envelope, decay, command_v, start_offset_v, cap_v, low_v,
                                     follow_gain, model_step, ramp_start + ramp_direction * j0, ramp_direction,
                                     ramp_samples)
    if clipped:
        state[STATE_STEP_FLAGS] = float(_step_flags(state) | FLAG_SHAPER_LIMIT)
    if modulate:
        sin0 = state[STATE_CARRIER_SIN] * out_per_v
        cos0 = state[STATE_CARRIER_COS] * out_per_v
        cos_jw = state[STATE_COS_TABLE + j0 : STATE_COS_TABLE + j0 + count]
        sin_jw = state[STATE_SIN_TABLE + j0 : STATE_SIN_TABLE + j0 + count]
        for k in range(count):
            samples[k] = envelope[k] * (sin0 * cos_jw[k] + cos0 * sin_jw[k])
    else:
        for k in range(count):
            samples[k] = envelope[k] * out_per_v
    state[STATE_STEP_SAMPLES] = j0 + count
    within = 0
    for k in range(count):  # a loop of its own, so the ones above vectorise
        within += 1 if abs(samples[k]) <= limit else 0
    return within == count


@_kernel
def _zero_outside(samples: np.ndarray, envelope: np.ndarray, limit: float, max_v: float) -> int:
    """Zero every sample (and its envelope) outside ``limit`` (full scale) or with an envelope whose
    magnitude is over ``max_v`` (volts), NaN included; how many were."""
    rejected = 0
    for k in range(samples.shape[0]):
        if not (abs(samples[k]) <= limit and abs(envelope[k]) <= max_v):
            samples[k] = 0.0
            envelope[k] = 0.0
            rejected += 1
    return rejected


@_kernel
def _output_fault(state: np.ndarray, rejected: int) -> None:
    """The output guard zeroed ``rejected`` samples (>= 1) of the open step: count them, close the gate,
    and restart the smoothing and ramp from 0 with tables rebuilt at the next step (state out of range)."""
    state[STATE_FAULT_SAMPLES] += rejected
    _note_fault(state, FAULT_OUTPUT, _step_flags(state) & FLAG_FAULT == 0)
    state[STATE_STEP_FLAGS] = float(_step_flags(state) | FLAG_FAULT)
    state[STATE_COMMAND_V] = 0.0
    state[STATE_SMOOTH_START_V] = 0.0
    state[STATE_MODEL_V] = 0.0
    state[STATE_MODEL_ON_REF] = 0.0
    state[STATE_MODEL_SLIP_V] = 0.0
    state[STATE_PRESS_BRAKING] = 0.0
    state[STATE_RAMP_START] = 0.0
    state[STATE_GATE] = 0.0
    state[STATE_TABLE_FS_HZ] = math.nan


@_kernel
def _write_telemetry(
    telem: np.ndarray, telem_count: np.ndarray, t_s: float, state: np.ndarray,
    peak_v: float, power_w: float, plate_w: float, flags: int,
) -> None:
    """Append one telemetry row (slot ``telem_count % T``), then bump ``telem_count``."""
    row = telem_count[0] % telem.shape[0]
    telem[row, TEL_T_S] = t_s
    telem[row, TEL_X_MM] = state[STATE_X_MM]
    telem[row, TEL_Y_MM] = state[STATE_Y_MM]
    telem[row, TEL_SPEED_MM_S] = state[STATE_SPEED_MM_S]
    telem[row, TEL_FORCE_N] = state[STATE_FORCE_N]
    telem[row, TEL_TARGET_MU] = state[STATE_TARGET_MU]
    telem[row, TEL_AMPLITUDE_UM] = state[STATE_AMPLITUDE_M] * 1e6
    telem[row, TEL_VOLTAGE_V] = peak_v
    telem[row, TEL_POWER_W] = power_w
    telem[row, TEL_PLATE_W] = plate_w
    telem[row, TEL_FLAGS] = flags
    telem_count[0] += 1


@_entry
def render_block(
    out: np.ndarray,
    start_index: int,
    cfg: np.ndarray,
    dev: np.ndarray,
    state: np.ndarray,
    power_ring: np.ndarray,
    finger: np.ndarray,
    finger_count: np.ndarray,
    prog: np.ndarray,
    params: np.ndarray,
    img: np.ndarray,
    stack: np.ndarray,
    telem: np.ndarray,
    telem_count: np.ndarray,
) -> None:
    """Render stream samples ``start_index ..`` into ``out`` (float32, any length >= 1).

    ``start_index`` (>= 0) continues where the previous call ended
    (``state[STATE_NEXT_INDEX]``); a control step runs at every ``n`` with
    ``n % control_interval == 0``, and also at ``n`` when no step is open or the open
    one has run its full interval (a fresh or discontinuous stream). Array arguments as
    in docs/kernel.md "State layout" (``state`` all zeros for a fresh stream). Writes
    ``out``, ``state``, ``power_ring``, ``stack``, one ``telem`` row and
    ``telem_count``; allocates nothing.
    """
    interval = min(max(int(cfg[CFG_CONTROL_INTERVAL]), 1), MAX_CONTROL_INTERVAL)
    out_per_v = 1.0 / cfg[CFG_VOLTS_PER_FS]
    max_v = cfg[CFG_MAX_VOLTAGE_V]
    limit = max_v * out_per_v  # the output guard's bound, in full scale (<= 1)
    if not limit <= 1.0:
        limit = 1.0 if limit > 1.0 else 0.0
    modulate = cfg[CFG_OUTPUT_ENVELOPE] == 0.0
    total = out.shape[0]
    peak_v = 0.0
    energy_w = 0.0
    plate_w = 0.0
    flags = 0
    next_phase = state[STATE_NEXT_PHASE]
    continues = start_index == state[STATE_NEXT_INDEX] and 0.0 <= next_phase < interval
    phase = int(next_phase) if continues else start_index % interval
    i = 0
    while i < total:
        if (phase == 0 or state[STATE_STEP_OPEN] == 0.0
                or not 0.0 <= state[STATE_STEP_SAMPLES] < interval):
            _control_step(start_index + i, cfg, dev, state, power_ring, finger, finger_count, prog, params, img, stack)
        j0 = int(state[STATE_STEP_SAMPLES])
        stop = min(total, i + interval - phase, i + interval - j0)
        inside = _render_samples(out, i, stop, state, out_per_v, limit, modulate)
        segment_peak_v, segment_v2 = _envelope_sums(state, j0, j0 + stop - i)
        if not (inside and segment_peak_v <= max_v and segment_v2 <= (stop - i) * max_v * max_v):  # NaN fails
            envelope = state[STATE_ENVELOPE + j0 : STATE_ENVELOPE + j0 + stop - i]
            _output_fault(state, _zero_outside(out[i:stop], envelope, limit, max_v))
            segment_peak_v, segment_v2 = _envelope_sums(state, j0, j0 + stop - i)
        if j0 == 0:
            state[STATE_FIRST_SEGMENT_V2] = segment_v2
            state[STATE_FIRST_SEGMENT_SAMPLES] = stop - i
        peak_v = max(peak_v, segment_peak_v)
        energy_w += _drive_power_w(state, segment_v2, stop - i) * (stop - i)
        plate_w = max(plate_w, state[STATE_PLATE_W])
        flags |= _step_flags(state)
        phase += stop - i
        if phase == interval:
            phase = 0
        i = stop
    state[STATE_NEXT_INDEX] = start_index + total
    state[STATE_NEXT_PHASE] = phase
    if plate_w > cfg[CFG_POWER_CAP_W] * (1.0 + MODEL_GUARD_FRACTION):
        state[STATE_OVER_CAP_BLOCKS] += 1.0
    _write_telemetry(telem, telem_count, start_index / cfg[CFG_FS_HZ], state, peak_v, energy_w / max(total, 1),
                     plate_w, flags)
