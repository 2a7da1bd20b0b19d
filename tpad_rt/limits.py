"""The documented limits every boundary of tpad-rt checks (README "Safety", docs/realtime.md "Safety").

Values are refused where they enter (an API call, a URL, a flag, a file), before
anything is allocated or rendered, with a message naming the limit. The render kernel
defends itself again with its own (looser) bounds in :mod:`tpad_rt.kernel.layout`.

API map
-------
MAX_RATE_HZ, MAX_BLOCK_FRAMES, MAX_RENDER_S, MAX_INPUT_S, MAX_RECORDING_SAMPLES,
MAX_RENDER_BLOCKS, MAX_STALL_TIMEOUT_S, MAX_FORCE_N, FINGER_TIME_WINDOW_S, MAX_TRAJECTORY_BYTES, MAX_TRAJECTORY_ROWS,
MAX_MEASUREMENT_BYTES, MAX_MEASUREMENT_ROWS
    the limits (units in the names)
DEFAULT_PLATE_MM
    the plate (length, width) assumed without a device file
DEFAULT_FORCE_N
    the contact force assumed where a finger sample carries none
position_range_mm(plate_length_mm, plate_width_mm) -> ((x_low, x_high), (y_low, y_high))
    the finger positions accepted for a plate: one plate length (width) beyond each edge
"""

from __future__ import annotations

#: Highest sample rate (Hz) a render, a play or a Renderer runs at (the fastest audio DACs run 768 kHz).
MAX_RATE_HZ = 768_000
#: Most frames per block (a callback's or a render step's); the kernel renders longer blocks in pieces.
MAX_BLOCK_FRAMES = 65_536
#: Longest offline render (s of input, ``tpad-rt render``): an hour.
MAX_RENDER_S = 3600.0
#: Longest input (s): a scripted pattern's or a trajectory's natural end, and ``play --duration``: a day.
MAX_INPUT_S = 86_400.0
#: Most drive samples a recording keeps in memory (float32: 256 MiB; 349 s at 192 kHz).
MAX_RECORDING_SAMPLES = 2**26
#: Most blocks an offline render keeps a telemetry row for: a render peaks at about 440 bytes per block
#: (measured: 60 s against 5 s in blocks of 16 to .wav), so about 1.8 GB; 1398 s at 192 kHz in blocks of 64.
MAX_RENDER_BLOCKS = 2**22
#: The longest ``Renderer(stall_timeout_s=...)`` / ``play --stall-timeout`` accepted (s).
MAX_STALL_TIMEOUT_S = 60.0
#: Largest contact force (N) a finger sample may carry (a pressing finger stays under 10 N).
MAX_FORCE_N = 50.0
#: A finger sample's time may differ from the stream clock by at most this much (s), either way.
FINGER_TIME_WINDOW_S = 10.0
#: Largest trajectory CSV (bytes) and most samples in one (an hour at 500 Hz).
MAX_TRAJECTORY_BYTES = 64 * 2**20
MAX_TRAJECTORY_ROWS = 2_000_000
#: Plate size (mm, length x width) of the default device, used where no device is given.
DEFAULT_PLATE_MM = (130.0, 60.0)
#: Contact force (N) of a finger sample that carries none (the default of ``RenderOptions.default_force_n``).
DEFAULT_FORCE_N = 0.5


def position_range_mm(plate_length_mm: float, plate_width_mm: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """``((x_low, x_high), (y_low, y_high))`` (mm): finger positions accepted on a plate of that size.

    The plate spans ``[0, length] x [0, width]``; a finger may be reported up to one
    plate length (width) beyond each edge (a pointer sliding off the plate), no further.
    """
    return (-plate_length_mm, 2.0 * plate_length_mm), (-plate_width_mm, 2.0 * plate_width_mm)
#: Largest calibration measurement CSV (bytes) and most rows in one (an analyser sweeps at most tens of
#: thousands of points; this is many sweeps of them).
MAX_MEASUREMENT_BYTES = 32 * 2**20
MAX_MEASUREMENT_ROWS = 500_000
