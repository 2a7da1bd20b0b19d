"""The compile plan: every numba kernel every path of tpad-rt runs, compiled by the runtime's own warm-ups.

API map
-------
STEPS
    the plan, in the order a worker prefers them: each :class:`Step` names what it compiles, the steps that
    must have finished first (``after``) and the warm-up it runs. Together they compile what ``play`` on
    every output (``sim://``, ``audio://``, ``wav://``, ``null://``, ``serial://``: the serial streamer),
    ``render``, ``serve`` and the Pipeline and Renderer APIs call (tests/test_compiling_plan.py proves it)
``python -m tpad_rt.compile_plan``
    a compile worker (:mod:`tpad_rt.compile_runner` starts them): prints the plan as its first line, then
    runs each step named on its standard input, one JSON object a line on its standard output

Why ``after``: numba keeps one cache index per function, and two processes writing different signatures
of one function at once can leave an index that names the other's data (docs/kernel.md "Compilation").
A step that compiles a function another step also compiles (a callee both call, with any signature) runs
after it, so the runner never runs them at once; the plan test checks that steps running together compile
disjoint functions.

The steps run the warm-ups the runtime itself runs before a clock starts (``Pipeline.warm_up``,
``Output.warm``, ``serial_amp.warm_up``, ``CallbackTable.call``), on a real pipeline over the shipped
grating: the same functions with the same argument types as every run, whatever the texture (the texture
program's evaluator compiles every node kind).
"""

from __future__ import annotations

import functools
import json
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import IO, Any

import numpy as np

#: The sample rate (Hz) of the plan's pipeline: any rate compiles the same kernels.
PLAN_FS_HZ = 192000
#: Frames of the audio callback's warm-up call.
CALL_FRAMES = 64


@dataclass(frozen=True)
class Step:
    """One unit of the plan: ``name`` (what it compiles, for progress), the steps it runs ``after``, and
    ``run`` (the warm-up, no arguments)."""

    name: str
    after: tuple[str, ...]
    run: Callable[[], None]


@functools.cache
def _pipeline() -> Any:
    """A pipeline for the default device and the shipped grating (each worker builds its own once)."""
    from tpad_rt.device import Device
    from tpad_rt.pipeline import Pipeline
    from tpad_rt.shipped import TEXTURES_DIR
    from tpad_rt.texture import load_compiled

    return Pipeline(Device.default(), load_compiled(TEXTURES_DIR / "grating.yaml"), fs_hz=PLAN_FS_HZ)


def _table() -> Any:
    """A callback table over copies of the pipeline's arrays."""
    from tpad_rt.pipeline import KernelArrays
    from tpad_rt.realtime import CallbackTable

    pipeline = _pipeline()
    return CallbackTable(KernelArrays(*(array.copy() for array in pipeline.arrays)), pipeline.texture)


def _texture_evaluation() -> None:
    _pipeline().texture.evaluate(np.zeros(1), np.zeros(1))


def _render_kernel() -> None:
    _pipeline().warm_up()


def _offline_render() -> None:
    _pipeline().warm_up(batch=True)


def _sim_output(batch: bool) -> None:
    from tpad_rt.outputs.sim import SimOutput

    SimOutput(_pipeline().device, PLAN_FS_HZ).warm(batch=batch)


def _callback_table() -> None:
    """A texture change's release store (``set_texture``; ``Pipeline.push_finger`` makes the same)."""
    _table().set_texture(_pipeline().texture, 0.0, False)


def _audio_callback() -> None:
    _table().call(np.zeros(CALL_FRAMES, dtype=np.float32))


def _physics_ufuncs() -> None:
    """Every physics model's ufunc on floats (``serve`` computes the friction a page asks about with them)."""
    from tpad_rt.physics import friction, plate

    for module in (friction, plate):
        for name, function in vars(module).items():
            if name.endswith("_ufunc") and hasattr(function, "nin"):
                function(*[1.0] * function.nin)


def _serial_checks() -> None:
    from tpad_rt.outputs import serial_amp

    serial_amp.warm_checks()


def _serial_streamer() -> None:
    from tpad_rt.outputs import serial_amp

    serial_amp.warm_up(_table())


#: The plan (module docstring). The render kernel inlines the texture evaluator's functions and shares the
#: device lookups with the streamer; the offline batch and the audio callback call the render kernel; the
#: streamer calls the codec the checks compile and needs a callback table; the physics models' ufuncs call
#: the friction cores the render kernel and the simulated plate compile.
STEPS: tuple[Step, ...] = (
    Step("texture evaluation", (), _texture_evaluation),
    Step("render kernel", ("texture evaluation",), _render_kernel),
    Step("serial amplifier checks", (), _serial_checks),
    Step("callback table", (), _callback_table),
    Step("serial streamer", ("serial amplifier checks", "callback table", "render kernel"), _serial_streamer),
    Step("simulated plate", (), lambda: _sim_output(batch=False)),
    Step("simulated plate, offline", ("simulated plate",), lambda: _sim_output(batch=True)),
    Step("offline render", ("render kernel",), _offline_render),
    Step("audio callback", ("render kernel", "callback table"), _audio_callback),
    Step("physics models", ("render kernel", "simulated plate"), _physics_ufuncs),
)


def _send(protocol: IO[str], **message: Any) -> None:
    protocol.write(json.dumps(message) + "\n")
    protocol.flush()


def serve_steps(steps: tuple[Step, ...], requests: IO[str], protocol: IO[str]) -> None:
    """The worker's loop: send the plan (``{"plan": [[name, [after...]], ...]}``), then for each step name
    read from ``requests`` run it, sending ``{"compiling": "module.qualname"}`` as numba starts compiling a
    function of tpad-rt and ``{"done": name}`` at its end (``{"failed": name, "error": text}`` and return
    when it raises)."""
    from numba.core import event

    by_name = {step.name: step for step in steps}

    class _Listener(event.Listener):
        def on_start(self, compile_event: event.Event) -> None:
            function = getattr(compile_event.data.get("dispatcher"), "py_func", None)
            module = str(getattr(function, "__module__", ""))
            if module.startswith("tpad_rt."):
                _send(protocol, compiling=f"{module}.{function.__qualname__}")  # type: ignore[union-attr]

        def on_end(self, compile_event: event.Event) -> None:
            pass

    _send(protocol, plan=[[step.name, list(step.after)] for step in steps])
    with event.install_listener("numba:compile", _Listener()):
        for line in requests:
            name = line.strip()
            try:
                by_name[name].run()
            except Exception as error:  # noqa: BLE001 - the runner reports it and stops the plan
                _send(protocol, failed=name, error=f"{type(error).__name__}: {error}")
                return
            _send(protocol, done=name)


def main() -> None:
    """``python -m tpad_rt.compile_plan``: :func:`serve_steps` on stdin and stdout; anything else printed goes
    to stderr."""
    protocol = os.fdopen(os.dup(sys.stdout.fileno()), "w")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    serve_steps(STEPS, sys.stdin, protocol)


if __name__ == "__main__":
    main()
