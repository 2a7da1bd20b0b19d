"""Bounds of device-file numbers, as plain numbers (docs/formats.md "Ranges, and why").

The device schema (:mod:`tpad_rt.config.device_schema`) builds its types from them; the
command line checks its flags against the same bounds (``design --plate``, calibrate's
carriers and volts, the calibration's force steps) without loading pydantic. Each pair is ``(low, high)``, both allowed.
"""

from __future__ import annotations

#: Carriers (Hz) a device file may drive at, and the highest peak volts it may name.
MIN_CARRIER_HZ = 1000.0
MAX_CARRIER_HZ = 200_000.0
MAX_VOLTS = 10_000.0
#: A plate's or an actuator's thickness (mm), density (g/cm^3) and Young's modulus (GPa).
THICKNESS_MM = (0.01, 100)
DENSITY_G_CM3 = (0.1, 50)
YOUNGS_MODULUS_GPA = (0.01, 2000)
#: A plate's length and width (mm).
PLATE_SIDE_MM = (1, 1000)
#: m of the plate's m x n mode (nodal lines along its length).
MODE_M = (1, 1000)
#: Forces closer than this (N) are not told apart: far finer than a finger-force calibration resolves,
#: and it keeps the kernel's force grid from collapsing to a zero step.
MIN_FORCE_STEP_N = 0.001
#: Slack (N) for decimal forces' rounding: 1.001 - 1.0 is 0.000999999999999889 in binary.
FORCE_SLACK_N = 1e-9
