"""A minimal app: render the grating while pushing its own finger samples, then print the stats.

    python examples/minimal_app.py [OUTPUT_URL]

OUTPUT_URL defaults to ``audio://`` (a sound card, or a JACK server that runs at
192 kHz), falling back to the simulated plate ``sim://`` when no audio device can run
the stream. The finger sweeps back and forth across the plate at 50 mm/s for 3 s.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path
from typing import Any

from tpad_rt.engine import Renderer
from tpad_rt.errors import BackendError

GRATING = Path(__file__).resolve().parents[1] / "textures" / "grating.yaml"
SPEED_MM_S = 50.0
SPAN_MM = 40.0


def open_renderer(url: str) -> Renderer:
    """A started Renderer on ``url``, or on ``sim://`` if the audio device cannot run it."""
    renderer = Renderer(output=url, texture=GRATING)
    try:
        renderer.start()
    except BackendError as error:
        print(f"{error}; using sim:// instead")
        renderer = Renderer(output="sim://", texture=GRATING)
        renderer.start()
    return renderer


def main(url: str = "audio://") -> None:
    renderer = open_renderer(url)
    with renderer:  # already started: leaving the block ramps down and closes the output
        started = time.monotonic()
        while (elapsed_s := time.monotonic() - started) < 3.0:
            travelled_mm = (SPEED_MM_S * elapsed_s) % (2 * SPAN_MM)
            x_mm = 10.0 + (travelled_mm if travelled_mm < SPAN_MM else 2 * SPAN_MM - travelled_mm)
            renderer.push_finger(x_mm, 20.0, force_n=0.5)
            time.sleep(0.002)
        renderer.lift()
    print_stats(renderer.stats())


def print_stats(stats: dict[str, Any]) -> None:
    """One line per statistic (its unit in its name): numbers to 4 significant digits, "n/a" where nothing
    was measured (NaN)."""
    for name, value in stats.items():
        if isinstance(value, float):
            value = "n/a" if math.isnan(value) else f"{value:.4g}"
        print(f"{name:>28}: {value}")


if __name__ == "__main__":
    main(*sys.argv[1:])
