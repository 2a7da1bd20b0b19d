"""Pure physical models of a TPaD, in SI units (paper: Xu, Peshkin, Colgate).

API map
-------
``friction`` (Eqs. 2-3)
    relative_friction, amplitude_for; defaults MU0, POISSON, PSI_STAR
``electromech`` (Butterworth-Van Dyke circuit, Eqs. 2-6)
    impedance, real_power_eq6, real_power_exact, resonance_hz, quality_factor
``plate`` (Eqs. 16-21)
    bending_wavenumber, mode_resonance_hz, sandwich_stiffness_per_width,
    amplification_number, power_ratio; Layer, TABLE1_GLASSES, ACTUATOR, table1_glass

Every public function validates its inputs (ValueError naming the argument, the
expected range and the value got) and broadcasts like a NumPy ufunc. The friction
model, which the real-time kernels evaluate, has a numba-compiled scalar twin
``<name>_core`` of each function (``njit(cache=True, nogil=True)``, no checks);
``electromech`` and ``plate`` are plain NumPy. The package imports each module on
first use, so that what needs no friction model starts without numba.
"""

import importlib
from types import ModuleType

__all__ = ["electromech", "friction", "plate"]


def __getattr__(name: str) -> ModuleType:
    """The submodule ``name`` of __all__, imported on first use: friction imports numba, which a
    renderer on the ahead-of-time kernels never needs (docs/kernel.md "Ahead-of-time kernels")."""
    if name in __all__:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
