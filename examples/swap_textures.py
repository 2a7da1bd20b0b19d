"""Swap textures on a key press while a finger sweeps: press Enter for the next texture, q Enter to quit.

    python examples/swap_textures.py [OUTPUT_URL]

A thread pushes a back-and-forth sweep (the one finger-sample producer); the main
thread reads the keyboard and calls ``Renderer.set_texture``, which swaps atomically
and keeps the carrier phase-continuous. Output as in examples/minimal_app.py.
"""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

from minimal_app import open_renderer, print_stats

TEXTURES = [Path(__file__).resolve().parents[1] / "textures" / name
            for name in ("grating.yaml", "square_grating.yaml", "bumps_grid.yaml", "edges_buttons.yaml")]


def sweep(renderer: object, done: threading.Event) -> None:
    """Push a 50 mm/s back-and-forth sweep over x = 10..50 mm until ``done``."""
    started = time.monotonic()
    while not done.is_set():
        travelled_mm = (50.0 * (time.monotonic() - started)) % 80.0
        renderer.push_finger(10.0 + min(travelled_mm, 80.0 - travelled_mm), 20.0)  # type: ignore[attr-defined]
        time.sleep(0.002)


def main(url: str = "audio://") -> None:
    renderer = open_renderer(url)
    done = threading.Event()
    finger = threading.Thread(target=sweep, args=(renderer, done), daemon=True)
    with renderer:
        renderer.set_texture(TEXTURES[0])
        finger.start()
        index = 0
        print(f"rendering {TEXTURES[index].name}; Enter: next texture, q Enter: quit")
        for line in sys.stdin:
            if line.strip() == "q":
                break
            index = (index + 1) % len(TEXTURES)
            renderer.set_texture(TEXTURES[index])
            stats = renderer.stats()
            print(f"rendering {TEXTURES[index].name} ({stats['callbacks']} callbacks, "
                  f"{stats['underflows']} underflows)")
        done.set()
        finger.join()
    print_stats(renderer.stats())


if __name__ == "__main__":
    main(*sys.argv[1:])
