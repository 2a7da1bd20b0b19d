"""The arrays a real-time callback reaches through ``userData``, and the clocks read from them.

API map
-------
CallbackTable(arrays, texture, *, channels=1, channel=0, scratch_frames=4096, drive_frames=2**20,
              block_rows=4096)
    owns the pointer table (``.table``, int64, layout in :mod:`tpad_rt.kernel.table_layout`) and
    every array it points to: the render kernel's arrays (:class:`tpad_rt.pipeline.KernelArrays`,
    shared, not copied), two texture slots, the output scratch, the drive ring, the
    statistics (``.stats``) and the per-block records (``.blocks``)
    ``.user_data``: the address to pass as ``userData``; ``.set_texture(texture, t0_s, running)``;
    ``.recent_blocks()``, ``.blocks_since(first)``; ``.dac_sample(now_ns)``; ``.next_sample``; ``.drive_end()``; ``.copy()``;
    ``.set_lead_bound_s(seconds)`` / ``.lead_bound_s`` (the most output lead the driver's output can have);
    ``.call(out, callback=None, dac_delay_s=0.0)``
monotonic_ns() -> int
    the clock the callback stamps blocks with (CLOCK_MONOTONIC, ns)

docs/realtime.md is the design. One Python thread (the owner of the texture slots) may
call :meth:`CallbackTable.set_texture`; any thread may read.
"""

from __future__ import annotations

import ctypes
import math
import time
from typing import Any

import numpy as np

from tpad_rt.aot import library as native
from tpad_rt.kernel import table_layout as tab
from tpad_rt.kernel.layout import CFG_FS_HZ, CFG_TEXTURE_T0_S, MAX_OUTPUT_LEAD_S, STATE_NEXT_INDEX
from tpad_rt.pipeline import KernelArrays
from tpad_rt.texture import CompiledTexture

#: The callback's clock (Python's ``time.monotonic_ns`` is CLOCK_MONOTONIC on Linux).
monotonic_ns = time.monotonic_ns
#: Longest wait (s) for the callback to let go of a texture slot before it is rewritten.
SLOT_RELEASE_TIMEOUT_S = 1.0

_TIME_INFO = ctypes.c_double * 3


def _prefault(array: np.ndarray) -> None:
    """Write every page of ``array`` once, values unchanged.

    NumPy's zeros are mapped lazily: without this the audio callback takes a
    first-touch page fault every few kB of a ring (bench/latency/README.md: p99
    compute time 7-10 us instead of 2-3 us until the 4 MiB drive ring has wrapped).
    """
    np.add(array, 0, out=array)


class CallbackTable:
    """The pointer table over ``arrays`` (used in place) and ``texture`` in slot 0.

    ``channels`` interleaved output channels with the drive in ``channel`` (0-based);
    ``scratch_frames`` the most frames rendered per ``render_block`` call;
    ``drive_frames`` samples the drive ring keeps; ``block_rows`` blocks the record
    ring keeps. Raises ValueError when ``channels``, ``scratch_frames``, ``drive_frames`` or
    ``block_rows`` is not a whole number of at least 1 (the callback would loop for ever on an
    empty scratch, and write past an empty ring: its remainders by 0 give 0, not an error), or
    for a channel outside ``[0, channels)``.
    """

    def __init__(self, arrays: KernelArrays, texture: CompiledTexture, *, channels: int = 1, channel: int = 0,
                 scratch_frames: int = 4096, drive_frames: int = 2**20, block_rows: int = 4096):
        for name, count in (("channels", channels), ("scratch_frames", scratch_frames),
                            ("drive_frames", drive_frames), ("block_rows", block_rows)):
            if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
                raise ValueError(f"{name}: must be a whole number of at least 1, got {count!r}")
        if isinstance(channel, bool) or not isinstance(channel, (int, np.integer)) or not 0 <= channel < channels:
            raise ValueError(f"channel: must be a whole number in [0, {channels}), got {channel!r}")
        self.arrays = arrays
        self.scratch = np.zeros(scratch_frames, dtype=np.float32)
        self.drive = np.zeros(drive_frames, dtype=np.float32)
        self.stats = np.zeros(tab.STAT_SIZE, dtype=np.int64)
        self.blocks = np.zeros((block_rows, tab.BLOCK_COLS), dtype=np.int64)
        for written_by_callback in (self.scratch, self.drive, self.blocks, arrays.state, arrays.power_ring,
                                    arrays.telem):
            _prefault(written_by_callback)
        self.slot_t0_s = np.zeros(2)
        self._slots: list[tuple[np.ndarray, ...]] = [(), ()]
        self._flip_callbacks = -2  # the callback count when a slot was last flipped
        table = np.zeros(tab.TAB_SIZE, dtype=np.int64)
        for address_at, array, sizes in (
            (tab.TAB_CFG, arrays.cfg, (tab.TAB_CFG_SIZE,)),
            (tab.TAB_DEV, arrays.dev, (tab.TAB_DEV_ROWS, tab.TAB_DEV_COLS)),
            (tab.TAB_STATE, arrays.state, (tab.TAB_STATE_SIZE,)),
            (tab.TAB_POWER_RING, arrays.power_ring, (tab.TAB_POWER_RING_SIZE,)),
            (tab.TAB_FINGER, arrays.finger, (tab.TAB_FINGER_ROWS,)),
            (tab.TAB_FINGER_COUNT, arrays.finger_count, ()),
            (tab.TAB_TELEM, arrays.telem, (tab.TAB_TELEM_ROWS,)),
            (tab.TAB_TELEM_COUNT, arrays.telem_count, ()),
            (tab.TAB_SLOT_T0, self.slot_t0_s, ()),
            (tab.TAB_SCRATCH, self.scratch, (tab.TAB_SCRATCH_FRAMES,)),
            (tab.TAB_DRIVE, self.drive, (tab.TAB_DRIVE_FRAMES,)),
            (tab.TAB_STATS, self.stats, ()),
            (tab.TAB_BLOCKS, self.blocks, (tab.TAB_BLOCK_ROWS,)),
        ):
            table[address_at] = _address(array)
            table[list(sizes)] = array.shape[:len(sizes)]
        table[tab.TAB_CHANNELS] = channels
        table[tab.TAB_CHANNEL] = channel
        self.table = table
        self._write_slot(0, texture, float(arrays.cfg[CFG_TEXTURE_T0_S]))

    @property
    def user_data(self) -> int:
        """The address of the table (the callback's ``userData``)."""
        return _address(self.table)

    @property
    def active_slot(self) -> int:
        """The texture slot the callback renders (0 or 1)."""
        return int(self.table[tab.TAB_ACTIVE_SLOT])

    def _write_slot(self, slot: int, texture: CompiledTexture, t0_s: float) -> None:
        """Copy ``texture`` into ``slot`` (writable arrays the table points to) with start time ``t0_s`` (s)."""
        arrays = (np.array(texture.prog, dtype=np.int64, order="C"), np.array(texture.params, dtype=np.float64),
                  np.array(texture.img, dtype=np.float64), np.zeros(max(texture.stack_depth, 1)))
        base = tab.TAB_SLOTS + slot * tab.SLOT_SIZE
        for offset, array in zip((tab.SLOT_PROG, tab.SLOT_PARAMS, tab.SLOT_IMG, tab.SLOT_STACK), arrays):
            self.table[base + offset] = _address(array)
            self.table[base + offset + 1] = array.shape[0]
        self.slot_t0_s[slot] = t0_s
        self._slots[slot] = arrays  # keeps them alive while the table points to them

    def set_texture(self, texture: CompiledTexture, t0_s: float, running: bool) -> None:
        """Write ``texture`` (starting at stream time ``t0_s``, s) into the idle slot, then make it active.

        The callback reads the active slot once per call, so it renders either texture
        whole. While ``running``, the idle slot may still be in use by a callback that
        began before the previous flip: wait (at most SLOT_RELEASE_TIMEOUT_S) until a
        callback has begun since.
        """
        if running:
            deadline = time.monotonic() + SLOT_RELEASE_TIMEOUT_S
            while self.stats[tab.STAT_CALLBACKS] < self._flip_callbacks + 2 and time.monotonic() < deadline:
                time.sleep(0.0005)
        idle = 1 - self.active_slot
        self._write_slot(idle, texture, t0_s)
        native.publish(self.table, tab.TAB_ACTIVE_SLOT, idle)  # after the slot: a release store
        self._flip_callbacks = int(self.stats[tab.STAT_CALLBACKS])

    def recent_blocks(self) -> np.ndarray:
        """The block records still in the ring, oldest first (int64 ``[rows, BLOCK_COLS]``, a copy)."""
        return self.blocks_since(0)[0]

    def blocks_since(self, first: int) -> tuple[np.ndarray, int]:
        """The records of block number ``first`` (0: the run's first block) and after that are still in the ring,
        oldest first (int64 ``[rows, BLOCK_COLS]``, a copy), and the number of the first of them (above ``first``
        when the ring lost some)."""
        callbacks = int(self.stats[tab.STAT_CALLBACKS])
        rows = self.blocks.shape[0]
        start = max(first, callbacks - rows + 1, 0)  # the oldest row may be rewritten by the running callback
        return self.blocks[np.arange(start, callbacks) % rows], start

    def dac_sample(self, now_ns: int) -> float:
        """The stream sample (fractional) at the DAC at CLOCK_MONOTONIC ``now_ns``, from the newest block.

        A block's first sample reaches the DAC ``BLOCK_DAC_DELAY_NS`` after the callback
        began; the rate is the stream's (cfg). 0.0 before the first callback.
        """
        callbacks = int(self.stats[tab.STAT_CALLBACKS])
        if callbacks == 0:
            return 0.0
        row = self.blocks[(callbacks - 1) % self.blocks.shape[0]]
        since_s = (now_ns - row[tab.BLOCK_ENTRY_NS] - row[tab.BLOCK_DAC_DELAY_NS]) * 1e-9
        return float(row[tab.BLOCK_SAMPLE_INDEX]) + since_s * float(self.arrays.cfg[CFG_FS_HZ])

    def drive_end(self) -> int | None:
        """The stream index after the last sample of the newest block the callback finished: the drive ring holds
        every sample before it (a block's index is published as it renders, its samples reach the ring after);
        None before the first block."""
        callbacks = int(self.stats[tab.STAT_CALLBACKS])  # released last by finish_block
        if callbacks == 0:
            return None
        row = self.blocks[(callbacks - 1) % len(self.blocks)]
        return int(row[tab.BLOCK_SAMPLE_INDEX] + row[tab.BLOCK_FRAMES])

    def set_lead_bound_s(self, seconds: float) -> None:
        """The most lead (s) the driver's output can have (its buffer, its reported latency plus a block), within
        ``[0, MAX_OUTPUT_LEAD_S]`` (NaN: 0): a block's reported delay above it is taken as this much and counted
        (``stats[STAT_LEAD_OVER]``). Write it before the output starts; 0 (no lead) until then."""
        bounded_s = min(seconds, MAX_OUTPUT_LEAD_S) if seconds > 0.0 else 0.0
        self.table[tab.TAB_LEAD_BOUND_NS] = math.ceil(bounded_s * 1e9)

    @property
    def lead_bound_s(self) -> float:
        """The bound :meth:`set_lead_bound_s` wrote (s)."""
        return int(self.table[tab.TAB_LEAD_BOUND_NS]) * 1e-9

    @property
    def next_sample(self) -> int:
        """The sample index the next callback renders first."""
        return int(self.arrays.state[STATE_NEXT_INDEX])

    def copy(self) -> CallbackTable:
        """A table over copies of every array (the same textures): for warming the callback up."""
        twin = CallbackTable(KernelArrays(*(array.copy() for array in self.arrays)),
                             _texture_of(self._slots[self.active_slot]),
                             channels=int(self.table[tab.TAB_CHANNELS]), channel=int(self.table[tab.TAB_CHANNEL]),
                             scratch_frames=len(self.scratch), drive_frames=len(self.drive),
                             block_rows=len(self.blocks))
        twin.slot_t0_s[:] = self.slot_t0_s
        twin.table[tab.TAB_LEAD_BOUND_NS] = self.table[tab.TAB_LEAD_BOUND_NS]
        return twin

    def call(self, out: np.ndarray, callback: Any = None, dac_delay_s: float = 0.0) -> None:
        """Run ``callback`` (None: the render callback, :func:`tpad_rt.aot.library.render_callback`) once from
        Python on ``out`` (float32, frames x channels), as PortAudio would.

        Its time info says the first sample plays ``dac_delay_s`` (s) from now (DAC time - current time;
        any float, as a driver might report it). The ctypes call releases the GIL while the callback runs.
        """
        callback = native.render_callback() if callback is None else callback
        channels = int(self.table[tab.TAB_CHANNELS])
        if out.dtype != np.float32 or not out.flags.c_contiguous or out.size % channels:
            raise ValueError(f"out: must be C-contiguous float32 holding whole frames of {channels} channels")
        callback.ctypes(None, _address(out), out.size // channels, _TIME_INFO(0.0, 0.0, dac_delay_s), 0,
                         self.user_data)


def _texture_of(slot: tuple[np.ndarray, ...]) -> CompiledTexture:
    """The texture a slot's arrays hold (for :meth:`CallbackTable.copy`)."""
    prog, params, img, stack = slot
    return CompiledTexture(prog, params, img, len(stack), "copy", "copy of a slot")


def _address(array: np.ndarray) -> int:
    """The data address of a C-contiguous ``array``."""
    if not array.flags.c_contiguous:
        raise ValueError("the callback's arrays must be C-contiguous")
    return int(array.ctypes.data)
