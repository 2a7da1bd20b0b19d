"""Index constants of the pointer table a real-time driver reaches the render kernel through (no numba).

The layout :mod:`tpad_rt.kernel.table` documents (and re-exports): the table (``TAB_*``), a
texture slot (``SLOT_*``), the statistics (``STAT_*``) and the per-block records
(``BLOCK_*``). Plain ints in a module without numba, so the Python side fills and reads the
arrays without importing it; numba freezes them into the compiled drivers as constants.
"""

# --- pointer table: int64[TAB_SIZE] ----------------------------------------------
TAB_CFG = 0                   # cfg [TAB_CFG_SIZE]
TAB_CFG_SIZE = 1
TAB_DEV = 2                   # dev [DEV_ROWS, TAB_DEV_COLS]
TAB_DEV_ROWS = 3
TAB_DEV_COLS = 4
TAB_STATE = 5
TAB_STATE_SIZE = 6
TAB_POWER_RING = 7
TAB_POWER_RING_SIZE = 8
TAB_FINGER = 9                # finger [TAB_FINGER_ROWS, FINGER_COLS]
TAB_FINGER_ROWS = 10
TAB_FINGER_COUNT = 11
TAB_TELEM = 12                # telem [TAB_TELEM_ROWS, TEL_COLS]
TAB_TELEM_ROWS = 13
TAB_TELEM_COUNT = 14
TAB_ACTIVE_SLOT = 15          # 0 or 1: the texture slot rendered
TAB_SLOT_T0 = 16              # float64[2]: each slot's texture start time (s, stream clock)
TAB_CHANNELS = 17             # interleaved output channels
TAB_CHANNEL = 18              # the channel the drive goes to (0-based)
TAB_SCRATCH = 19              # float32[TAB_SCRATCH_FRAMES]: mono render buffer
TAB_SCRATCH_FRAMES = 20
TAB_DRIVE = 21                # float32[TAB_DRIVE_FRAMES]: ring of the last rendered samples
TAB_DRIVE_FRAMES = 22
TAB_STATS = 23                # int64[STAT_SIZE]
TAB_BLOCKS = 24               # int64[TAB_BLOCK_ROWS, BLOCK_COLS]
TAB_BLOCK_ROWS = 25
TAB_FINGER_SEEN = 26          # finger_count as this callback acquired it (written by the callback)
TAB_LEAD_BOUND_NS = 27        # the most output lead (ns) the driver's output can have: a larger reported delay is taken as this
TAB_SLOTS = 28                # two texture slots of SLOT_SIZE entries each
# --- a texture slot: offsets from TAB_SLOTS + k * SLOT_SIZE -------------------------
SLOT_PROG = 0                 # prog [SLOT_PROG_ROWS, TEX_PROG_COLS] int64
SLOT_PROG_ROWS = 1
SLOT_PARAMS = 2               # float64[SLOT_PARAMS_SIZE]
SLOT_PARAMS_SIZE = 3
SLOT_IMG = 4                  # float64[SLOT_IMG_SIZE]
SLOT_IMG_SIZE = 5
SLOT_STACK = 6                # float64[SLOT_STACK_SIZE]: the texture's evaluation scratch
SLOT_STACK_SIZE = 7
SLOT_SIZE = 8
TAB_SIZE = TAB_SLOTS + 2 * SLOT_SIZE

# --- statistics: int64[STAT_SIZE], written by the driver -------------------------
STAT_CALLBACKS = 0            # blocks so far (callbacks, or frames streamed; written last)
STAT_FRAMES = 1               # frames written so far
STAT_UNDERFLOWS = 2           # blocks that came late (paOutputUnderflow; a frame after a skip ahead)
STAT_PRIMING = 3              # blocks rendered before the output played (paPrimingOutput; prefill)
STAT_LEAD_OVER = 4            # blocks whose reported delay was above TAB_LEAD_BOUND_NS, or not a number
STAT_SIZE = 5

# --- per-block records: int64[rows, BLOCK_COLS], row STAT_CALLBACKS % rows -------
BLOCK_SAMPLE_INDEX = 0        # stream sample index of the block's first sample
BLOCK_ENTRY_NS = 1            # CLOCK_MONOTONIC (ns) when the block began
BLOCK_DAC_DELAY_NS = 2        # ns from then until its first sample plays (at the DAC, or the amplifier)
BLOCK_COMPUTE_NS = 3          # time spent rendering it (ns)
BLOCK_FINGER_COUNT = 4        # finger samples written when the block started
BLOCK_FRAMES = 5              # frames of the block
BLOCK_COLS = 6

#: Every name above (tpad_rt.kernel.table re-exports them).
__all__ = [
    "TAB_CFG", "TAB_CFG_SIZE", "TAB_DEV", "TAB_DEV_ROWS", "TAB_DEV_COLS", "TAB_STATE", "TAB_STATE_SIZE",
    "TAB_POWER_RING", "TAB_POWER_RING_SIZE", "TAB_FINGER", "TAB_FINGER_ROWS", "TAB_FINGER_COUNT", "TAB_TELEM",
    "TAB_TELEM_ROWS", "TAB_TELEM_COUNT", "TAB_ACTIVE_SLOT", "TAB_SLOT_T0", "TAB_CHANNELS", "TAB_CHANNEL",
    "TAB_SCRATCH", "TAB_SCRATCH_FRAMES", "TAB_DRIVE", "TAB_DRIVE_FRAMES", "TAB_STATS", "TAB_BLOCKS",
    "TAB_BLOCK_ROWS", "TAB_FINGER_SEEN", "TAB_LEAD_BOUND_NS", "TAB_SLOTS", "SLOT_PROG", "SLOT_PROG_ROWS",
    "SLOT_PARAMS", "SLOT_PARAMS_SIZE", "SLOT_IMG", "SLOT_IMG_SIZE", "SLOT_STACK", "SLOT_STACK_SIZE",
    "SLOT_SIZE", "TAB_SIZE", "STAT_CALLBACKS", "STAT_FRAMES", "STAT_UNDERFLOWS", "STAT_PRIMING",
    "STAT_LEAD_OVER", "STAT_SIZE", "BLOCK_SAMPLE_INDEX", "BLOCK_ENTRY_NS", "BLOCK_DAC_DELAY_NS",
    "BLOCK_COMPUTE_NS", "BLOCK_FINGER_COUNT", "BLOCK_FRAMES", "BLOCK_COLS",
]
