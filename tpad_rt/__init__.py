"""tpad-rt: real-time haptic rendering for ultrasonic friction-modulation displays.

API map
-------
Errors (``tpad_rt.errors``)
    TpadError, ConfigError, BackendError
Files (``tpad_rt.config``)
    load_texture(path) -> TextureFile, load_device(path) -> DeviceFile,
    check_file(path) -> list of breadcrumb errors
Device model (``tpad_rt.device``)
    Device.from_file(path) / Device.default(): calibration, circuit and limits
Textures (``tpad_rt.texture``)
    load_compiled(path) / compile_texture(model) -> CompiledTexture (.evaluate(x, y, ...))
Real time (``tpad_rt.Renderer``, from ``tpad_rt.engine``; imported on first use)
    Renderer(device, output="audio://", texture=...): a context manager; start, stop
    (ramped), set_texture, push_finger, lift, join, check, stats, telemetry, iter_telemetry, record,
    recent_fingers, now_s
Rendering (``tpad_rt.pipeline``)
    RenderOptions, Pipeline(device, texture, fs_hz, options): push_finger, lift,
    set_texture, start, stop, render(block), drain_telemetry
Inputs and outputs, by URL (``tpad_rt.inputs``, ``tpad_rt.outputs``)
    open_input("scripted://swipe?speed_mm_s=100"), open_output("sim://", ...)
Offline rendering and recordings (``tpad_rt.offline``, ``tpad_rt.recording``)
    OfflineRender, read_recording, write_recording
Physics (``tpad_rt.physics``, SI units, NumPy-vectorised; the friction model numba-callable)
    friction.relative_friction, friction.amplitude_for,
    electromech.impedance, electromech.real_power_eq6, electromech.real_power_exact,
    electromech.resonance_hz, electromech.quality_factor,
    plate.bending_wavenumber, plate.mode_resonance_hz, plate.sandwich_stiffness_per_width,
    plate.amplification_number, plate.power_ratio
"""

from typing import Any

from tpad_rt.errors import BackendError, ConfigError, TpadError
from tpad_rt.version import __version__

__all__ = ["BackendError", "ConfigError", "Renderer", "TpadError", "__version__"]


def __getattr__(name: str) -> Any:
    """``tpad_rt.Renderer``, imported on first use (numba and the kernels load then, not at ``import tpad_rt``)."""
    if name == "Renderer":
        from tpad_rt.engine import Renderer

        return Renderer
    raise AttributeError(f"module 'tpad_rt' has no attribute '{name}'")
