"""Index constants of the kernel's shared arrays (docs/kernel.md "State layout").

Module-level ints: numba freezes them into the compiled kernels as constants.
The kernel owns ``STATE_*``; ``CFG_*``, ``DEV_*``, ``FINGER_*``, ``TEL_*`` and the
flags are the contract with the Python side that fills and reads the arrays.
"""

# --- cfg: float64[CFG_SIZE], written by Python -------------------------------
CFG_FS_HZ = 0                 # output sample rate
CFG_CARRIER_HZ = 1            # the carrier (drive frequency), the device's carrier_hz
CFG_VOLTS_PER_FS = 2          # drive volts at DAC sample 1.0
CFG_MAX_VOLTAGE_V = 3         # peak drive never exceeded
CFG_POWER_CAP_W = 4           # instantaneous power cap
CFG_POWER_AVG_W = 5           # average power budget over the window
CFG_WINDOW_STEPS = 6          # M: control steps in the averaging window (== len(power_ring))
CFG_SPEED_FLOOR_M_S = 7       # speed used in the inversion when slower
CFG_MU0 = 8                   # friction model (paper Eqs. 2-3)
CFG_POISSON = 9
CFG_PSI_STAR = 10
CFG_MU_FLOOR = 11             # lowest relative friction the kernel asks for
CFG_CONTROL_INTERVAL = 12     # samples between control steps
CFG_SMOOTHING_S = 13          # envelope one-pole time constant
CFG_PREEMPHASIS = 14          # 1.0: shape the drive so a model of the plate envelope follows the smoothing
CFG_HORIZON_S = 15            # extra extrapolation lead (latency compensation)
CFG_VELOCITY_WINDOW_S = 16    # finger velocity estimated over this span
CFG_WATCHDOG_S = 17           # no finger sample for longer: gate closes
CFG_RAMP_S = 18               # gain ramp time (start, stop, watchdog, lift)
CFG_DEFAULT_FORCE_N = 19      # contact force when a sample carries none (NaN)
CFG_FORCE_GRID_START_N = 20   # dev tables: force of column 0
CFG_FORCE_GRID_STEP_N = 21    # dev tables: force step between columns
CFG_RUN = 22                  # 1.0 while running, 0.0 to ramp down and stay silent
CFG_TEXTURE_T0_S = 23         # stream time the current texture was set (temporal kinds)
CFG_OUTPUT_ENVELOPE = 24      # 1.0: samples are the envelope (for an amplifier that makes the carrier); 0.0: carrier
CFG_BRAKING = 25              # 1.0: the shaper may drive in anti-phase (negative envelope) to brake the plate
CFG_TRACK = 26                # 1.0: each control step drives at dev[DEV_CARRIER_HZ] at its force, phase continuous
CFG_MODE_STEP_MM = 27         # > 0: x step (mm) of dev[DEV_MODE_GAIN]'s grid from x = 0, and the command compensates it
CFG_C0_F = 28                 # the device's static capacitance (a serial amplifier's lock)
CFG_SHUNT_OHM = 29            # the device's series shunt
CFG_GAIN_SPAN = 30            # largest / smallest dev[DEV_AMP_M_PER_V], in [1, MAX_GAIN_SPAN]: bounds the model after a press
CFG_OUTPUT_LEAD_S = 31        # how far (s) ahead of the output the block's first sample is rendered (0: offline)
CFG_SIZE = 32

# --- dev: float64[DEV_ROWS, G], written by Python (uniform force grid) -------
DEV_AMP_M_PER_V = 0           # plate amplitude (m) per peak drive volt
DEV_POWER_W_PER_V2 = 1        # the most real power (W) a 1 V peak drive at the carrier draws (detuning bound)
DEV_TAU_S = 2                 # plate envelope time constant, the loaded branch's 2 L / (R + Re Z_th)
DEV_CARRIER_HZ = 3            # the carrier to drive at (the loaded resonance when tracking, else carrier_hz)
DEV_MODE_GAIN = 4             # on a grid in x, not force: amplitude under the finger / antinode amplitude (floored)
DEV_REACTANCE_OHM = 5         # the motional branch's reactance at DEV_CARRIER_HZ (a serial amplifier's lock)
DEV_REACTANCE_SLOPE_OHM_PER_HZ = 6  # its derivative in frequency there
DEV_ROWS = 7

# --- finger: float64[R, FINGER_COLS], one writer at a time (Python, under a lock) ---
FINGER_T_S = 0
FINGER_X_MM = 1
FINGER_Y_MM = 2
FINGER_FORCE_N = 3            # NaN: unknown, use CFG_DEFAULT_FORCE_N
FINGER_DOWN = 4               # 1.0 touching, 0.0 lifted
FINGER_COLS = 5

# --- telem: float64[T, TEL_COLS], one row per rendered block -----------------
TEL_T_S = 0
TEL_X_MM = 1
TEL_Y_MM = 2
TEL_SPEED_MM_S = 3
TEL_FORCE_N = 4
TEL_TARGET_MU = 5
TEL_AMPLITUDE_UM = 6          # commanded plate amplitude after the limits
TEL_VOLTAGE_V = 7             # peak drive envelope in the block
TEL_POWER_W = 8               # mean estimated power of the drive in the block (braking at the full volts: at the step's cap)
TEL_FLAGS = 9                 # OR of the FLAG_* bits over the block
TEL_PLATE_W = 10              # the most power the plate held in the block as the model has it (a press: over the cap)
TEL_COLS = 11
TEL_NAMES = ("t", "x_mm", "y_mm", "speed_mm_s", "force_n", "target_mu",
             "amplitude_um", "voltage_v", "power_w", "saturated", "plate_w")

#: The most output lead (s) the finger watchdog takes off a finger sample's age, whatever the output (CFG_OUTPUT_LEAD_S
#: is clamped to [0, this]). Each driver's own bound is tighter (kernel.table's TAB_LEAD_BOUND_NS: the serial
#: streamer's target fill plus a frame, PortAudio's reported output latency plus a block): a reported delay above
#: that is taken as the bound and counted.
MAX_OUTPUT_LEAD_S = 1.0
#: The most the plate's amplitude per volt may vary over a device's forces that the press guard follows (CFG_GAIN_SPAN).
MAX_GAIN_SPAN = 1e6
#: A plate whose power, as the model has it, is over the power cap times 1 + this (a press) is braked at up to the full
#: volts, and the block is reported over the cap (STATE_OVER_CAP_BLOCKS); smaller excursions are a finger's wobble.
MODEL_GUARD_FRACTION = 0.02

# --- flags -------------------------------------------------------------------
FLAG_VOLTAGE = 1              # drive limited by max_voltage_v
FLAG_POWER = 2                # drive limited by the power cap or average budget
FLAG_SPEED_FLOOR = 4          # finger slower than the speed floor
FLAG_WATCHDOG = 8             # no fresh finger sample, or finger lifted: gate closed
FLAG_FAULT = 16               # a non-finite or absurd value met: the drive ramps to 0 (FAULT_* say where)
FLAG_SHAPER_LIMIT = 32        # the shaper's drive was held at the cap (or -cap, braking): a step as fast as the limits allow

# --- fault causes: bits of STATE_FAULT_CAUSES ----------------------------------
FAULT_FINGER = 1              # the finger sample or the velocity from it is non-finite or absurd
FAULT_TEXTURE = 2             # the texture's value (or the command from it) is not finite
FAULT_DEVICE = 4              # a device table value (amplitude, power per V^2, tau) is not finite and > 0
FAULT_POWER = 8               # the power estimate or the cap from it is not finite
FAULT_STATE = 16              # the kernel's own state held a value out of its range (reset)
FAULT_OUTPUT = 32             # a sample past the voltage limit or not finite reached the output guard (zeroed)
FAULT_NAMES = ("finger", "texture", "device", "power", "state", "output")
# The kernel's own bounds (looser than the boundary's, tpad_rt/limits.py): a finger beyond
# them is a fault; a speed above MAX_SPEED_MM_S is clamped to it.
ABSURD_POSITION_MM = 1e6
ABSURD_FORCE_N = 1e4
MAX_SPEED_MM_S = 1e5

# --- texture program: int64[N, 4] rows (opcode, params_offset, aux0, aux1) ---
OP_PUSH_ONE = 0
OP_GRATING = 1
OP_BITMAP = 2
OP_GRADIENT = 3
OP_BUMPS = 4
OP_EDGES = 5
OP_TEMPORAL = 6
OP_COMBINE = 7
TEX_PROG_COLS = 4
# Codes in the aux columns and parameter records of the texture program (records:
# tpad_rt/kernel/texture_eval.py docstring; written by tpad_rt/texture.py).
WAVE_SINE = 0                 # OP_GRATING / OP_TEMPORAL aux0
WAVE_SQUARE = 1
WAVE_TRIANGLE = 2
WAVE_SAWTOOTH = 3
COMBINE_REPLACE = 0           # OP_COMBINE aux0
COMBINE_MULTIPLY = 1
COMBINE_MIN = 2
COMBINE_MAX = 3
COMBINE_ADD = 4
SHAPE_EVERYWHERE = 0          # OP_COMBINE aux1 (region); edges shape records
SHAPE_RECT = 1
SHAPE_CIRCLE = 2
SHAPE_LINE = 3
SHAPE_RECORD_SIZE = 6         # floats per edges shape record
WRAP_TILE = 0                 # image maps: outside the image
WRAP_CLAMP = 1
HEIGHT_BUMP = 0               # OP_GRADIENT aux0
HEIGHT_RIDGE = 1
HEIGHT_SINE = 2
HEIGHT_IMAGE = 3
PROFILE_COSINE = 0            # OP_BUMPS / OP_EDGES aux0
PROFILE_GAUSSIAN = 1
PROFILE_DISK = 2
PROFILE_STEP = 3
GAUSSIAN_REACH_SIGMAS = 3.0   # gaussian bumps end at 3 sigma (sigma = radius / 2)
LAYER_FLOOR = 0.01            # every COMBINE result is clamped to [LAYER_FLOOR, 1]
MAX_CARRIER_FRACTION = 0.45   # the carrier stays at or below this fraction of the sample rate (a tracked one too)
TRACKED_CARRIER_FACTOR = 2.0  # an amplifier's tracked carrier stays within this factor of CFG_CARRIER_HZ

# --- state: float64[STATE_SIZE], written by the render kernel only ------------
# All zeros is a fresh stream (tpad_rt/kernel/render.py says how the values are used).
# The open control step (the one whose samples are being rendered):
STATE_NEXT_INDEX = 0          # sample index after the last rendered block
STATE_STEP_OPEN = 1           # 1.0 once a control step has run
STATE_STEP_SAMPLES = 2        # samples rendered in the open step so far
STATE_RING_SLOT = 3           # its power_ring slot (the next step takes the next slot)
STATE_STEP_FLAGS = 4          # FLAG_* bits of the open step
STATE_GATE = 5                # 1.0: gain ramps up during the open step, 0.0: down
STATE_COMMAND_V = 6           # commanded envelope volts (peak), after the limits
STATE_CAP_V = 7               # the step's cap on the envelope (volts peak)
STATE_SMOOTH_START_V = 8      # smoothed volts before the step's first sample
STATE_RAMP_START = 9          # gain ramp position before it (samples, 0..ramp length)
STATE_RAMP_SAMPLES = 10       # gain ramp length (samples)
STATE_FOLLOW_GAIN = 11        # 1 / (1 - exp(-1 / (tau fs))): drive per volt the plate model lags; 0.0 without pre-emphasis
STATE_POWER_PER_V2 = 12       # p1(force): W per squared peak volt
STATE_CARRIER_COS = 13        # carrier phasor at the step's first sample
STATE_CARRIER_SIN = 14
STATE_WINDOW_SUM_W = 15       # sum of power_ring (W)
STATE_X_MM = 16               # the step's finger (extrapolated) and target, for telemetry
STATE_Y_MM = 17
STATE_SPEED_MM_S = 18
STATE_FORCE_N = 19
STATE_TARGET_MU = 20          # relative friction asked for, clamped to [mu_floor, 1]
STATE_AMPLITUDE_M = 21        # plate amplitude of STATE_COMMAND_V
# Finger samples are numbered by the count written before them; stored as number + 1 (0: none):
STATE_FINGER_SAMPLE = 22      # the newest sample at or before the last control step
STATE_VELOCITY_SAMPLE = 23    # the sample the cached velocity below was computed for
STATE_VX_MM_S = 24
STATE_VY_MM_S = 25
# The cfg values the per-sample tables were built from (rebuilt when one changes):
STATE_TABLE_FS_HZ = 26
STATE_TABLE_CARRIER_HZ = 27
STATE_TABLE_SMOOTHING_S = 28
# Bookkeeping that saves work, not state the output depends on:
STATE_NEXT_PHASE = 29         # STATE_NEXT_INDEX % control_interval
STATE_FIRST_SEGMENT_SAMPLES = 30  # samples of the open step's first rendered piece (0: none yet)
STATE_FIRST_SEGMENT_V2 = 31   # their sum of e^2 (V^2)
# The fault guard's counters (tpad_rt/kernel/render.py "Faults"):
STATE_FAULT_STEPS = 32        # control steps that met a fault
STATE_FAULT_EVENTS = 33       # faults that began (a fault step after a step without)
STATE_FAULT_CAUSES = 34       # OR of the FAULT_* bits met so far
STATE_FAULT_PREVIOUS = 35     # 1.0 if the last control step met a fault
STATE_FAULT_SAMPLES = 36      # samples the output guard zeroed
# The shaper's model of the plate envelope (docs/kernel.md "Per sample"):
STATE_MODEL_V = 37            # model envelope (drive volts it is worth) after the last rendered sample
STATE_MODEL_STEP = 38         # 1 - exp(-1 / (tau(force) fs)): the model's per-sample step towards the drive
STATE_DRIVE_LOW_V = 39        # the open step's lowest drive: -cap with braking, else 0
STATE_MODEL_ON_REF = 40       # 1.0: the model is on the smoothed command (STATE_MODEL_V is then 0, unused), 0.0: off
# The carrier's phase at the open step's first sample (2**-60 cycles, as two 30-bit halves, each exact in a
# float64), that sample's index, and the open step's carrier (Hz): a tracked carrier's phase runs on from them.
STATE_PHASE_HI = 41
STATE_PHASE_LO = 42
STATE_PHASE_INDEX = 43
STATE_STEP_CARRIER_HZ = 44
STATE_MODEL_GAIN_M_PER_V = 45  # plate amplitude per volt (m/V) the model's volts were worth at the last step (0: none)
STATE_PLATE_W = 46            # the plate's power as the model has it at the open step's start, p1 * model^2 (W)
STATE_OVER_CAP_BLOCKS = 47    # rendered blocks whose plate power (TEL_PLATE_W) exceeded the cap (MODEL_GUARD_FRACTION)
STATE_MODEL_SLIP_V = 48       # volts the plate holds beyond the model (force changes the guard let pass), decaying
STATE_PRESS_BRAKING = 49      # 1.0: the open step brakes a pressed plate (at the full volts, with the shaper), 0.0: not
# Per-sample tables, indexed by j, the sample's offset in its control step:
MAX_CONTROL_INTERVAL = 256    # longest control interval (samples)
STATE_COS_TABLE = 50          # cos(j w), w the carrier's phase step (rad)
STATE_SIN_TABLE = STATE_COS_TABLE + MAX_CONTROL_INTERVAL       # sin(j w)
STATE_DECAY_TABLE = STATE_SIN_TABLE + MAX_CONTROL_INTERVAL     # d^j (0 <= j <= MAX_CONTROL_INTERVAL), d the smoothing decay
STATE_ENVELOPE = STATE_DECAY_TABLE + MAX_CONTROL_INTERVAL + 1  # the open step's envelope e_j (V)
STATE_SIZE = STATE_ENVELOPE + MAX_CONTROL_INTERVAL
