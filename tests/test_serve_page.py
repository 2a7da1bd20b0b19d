"""The page of ``tpad-rt serve`` in a real headless Chromium (Debian's), driven over DevTools (tests/cdp.py):
it loads, draws the texture's friction map as ``show`` draws it, and mouse and touch input on the plate are
the finger the renderer follows: the telemetry a second client reads, and the drive in the server's recording.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from matplotlib import colormaps

from cdp import Browser
from cli_run import REPO
from serve_process import Client, Serve, stopped_by_signal_cleanly
from test_serve import paced, telemetry_until
from tpad_rt.kernel.layout import FLAG_WATCHDOG
from tpad_rt.recording import read_recording
from tpad_rt.texture import load_compiled

GRATING = REPO / "textures" / "grating.yaml"
PLATE_MM = (130.0, 60.0)
MAP_STEP_MM = 0.25  # the page's map: one pixel per 0.25 mm cell (tpad_rt.serve.core.friction_map_png)

pytestmark = pytest.mark.system


def wait_for(condition: str, seconds: float = 30.0) -> str:
    """A JavaScript promise that resolves once ``condition`` holds (checked every 20 ms in the page), and
    rejects naming it after ``seconds``."""
    return (f"new Promise((resolve, reject) => {{ const end = performance.now() + {seconds * 1000};"
            f" (function poll() {{ if ({condition}) resolve(true); else if (performance.now() > end) "
            f"reject(new Error({json.dumps('not so within ' + str(seconds) + ' s: ' + condition)})); "
            f"else setTimeout(poll, 20); }})(); }})")


def plate_box(browser: Browser) -> dict[str, float]:
    """The plate canvas: its box on the screen (CSS px) and its pixel size."""
    return browser.evaluate("(() => { const c = document.getElementById('plate'); const b = c.getBoundingClientRect();"
                            " return {left: b.left, top: b.top, width: b.width, height: b.height,"
                            " pixels_x: c.width, pixels_y: c.height}; })()")


def screen_point(box: dict[str, float], x_mm: float, y_mm: float) -> tuple[float, float]:
    return box["left"] + x_mm / PLATE_MM[0] * box["width"], box["top"] + y_mm / PLATE_MM[1] * box["height"]


def drag(browser: Browser, box: dict[str, float], y_mm: float, touch: bool) -> None:
    """Press at x = 20 mm, slide to 100 mm (an event per 0.8 mm, every 8 ms or as fast as DevTools delivers
    them), lift; mouse or touch."""
    points = [screen_point(box, 20.0 + 0.8 * step, y_mm) for step in range(101)]
    if touch:
        kinds = ["touchStart"] + ["touchMove"] * (len(points) - 1)
        for step in paced(len(points), 0.008):
            x, y = points[step]
            browser.call("Input.dispatchTouchEvent", type=kinds[step], touchPoints=[{"x": x, "y": y}])
        browser.call("Input.dispatchTouchEvent", type="touchEnd", touchPoints=[])
        return
    for step in paced(len(points), 0.008):
        x, y = points[step]
        kind = "mousePressed" if step == 0 else "mouseMoved"
        browser.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", buttons=1, clickCount=1)
    browser.call("Input.dispatchMouseEvent", type="mouseReleased", x=points[-1][0], y=points[-1][1], button="left",
                 buttons=0, clickCount=1)


def followed(watcher: Client, y_mm: float) -> None:
    """Return once the page took the finger, the telemetry showed it touching at ``y_mm`` and the page let it go.

    Judged on messages each sent once (the server's ``finger`` messages when the page takes and lets go of the
    finger), not on catching a moment of the drag in the telemetry's 50 Hz snapshots, which a loaded machine
    sends late: where the finger went and what the drive did is read from the recording, every block of it.
    """
    watcher.expect("finger", lambda m: m["held"])
    touching = released = False
    while not (touching and released):
        message = watcher.first(lambda m: m["type"] in ("telemetry", "finger"), "telemetry or finger message")
        if message["type"] == "finger":
            released = released or not message["held"]
        else:
            touching = touching or (message["touching"] and abs(message["y_mm"] - y_mm) < 0.5)
    telemetry_until(watcher, lambda m: not m["touching"])


def test_the_page_draws_the_map_and_mouse_and_touch_are_the_finger(tmp_path: Path) -> None:
    record = tmp_path / "page.npz"
    serve = Serve(str(GRATING), "--output", "sim://", "--record", str(record), "--no-osc", port_args=("--port", "0"))
    with serve, Client(serve.ws_url) as watcher, Browser(serve.http_url + "/") as browser:
        watcher.request({"type": "subscribe", "rate_hz": 50}, "subscribed")
        browser.evaluate(wait_for("window.tpadPage && window.tpadPage.connected && window.tpadPage.mapDrawn > 0"))
        assert browser.evaluate("document.getElementById('texture-description').textContent").startswith("2.5 mm sine")

        # The map, as show draws it: viridis of the target friction (a finger moving towards +x, t = 0).
        box = plate_box(browser)
        assert box["pixels_x"] / box["pixels_y"] == pytest.approx(PLATE_MM[0] / PLATE_MM[1], rel=0.01)
        columns = np.linspace(3, box["pixels_x"] - 4, 37).astype(int)
        rows = np.linspace(3, box["pixels_y"] - 4, 5).astype(int)
        drawn = np.array(browser.evaluate(
            "(() => { const g = document.getElementById('plate').getContext('2d'); const out = [];"
            f" for (const y of {json.dumps(rows.tolist())}) for (const x of {json.dumps(columns.tolist())})"
            " out.push(Array.from(g.getImageData(x, y, 1, 1).data)); return out; })()"), dtype=float)
        x_mm = (np.floor((columns + 0.5) / box["pixels_x"] * PLATE_MM[0] / MAP_STEP_MM) + 0.5) * MAP_STEP_MM
        y_mm = (np.floor((rows + 0.5) / box["pixels_y"] * PLATE_MM[1] / MAP_STEP_MM) + 0.5) * MAP_STEP_MM
        friction = load_compiled(GRATING).evaluate(x_mm[None, :], y_mm[:, None], 1.0, 0.0)
        expected = colormaps["viridis"](friction.ravel(), bytes=True)[:, :3].astype(float)
        assert np.abs(drawn[:, :3] - expected).max() <= 3.0
        assert np.all(drawn[:, 3] == 255)
        assert np.ptp(friction) > 0.2  # the points span the grating's levels

        drag(browser, box, 20.0, touch=False)
        followed(watcher, 20.0)
        browser.call("Emulation.setTouchEmulationEnabled", enabled=True, maxTouchPoints=1)
        drag(browser, box, 40.0, touch=True)
        followed(watcher, 40.0)
        sent = browser.evaluate("window.tpadPage.sent")
        assert sent > 150  # the page sent samples (and its still-finger resends) for both drags
        errors = browser.evaluate("window.tpadPage.errors")
        assert errors == []
        # The page's texture menu sets a shipped texture for everyone, and the page draws its map.
        drawn_before = browser.evaluate("window.tpadPage.mapDrawn")
        browser.evaluate("(() => { const menu = document.getElementById('texture-select'); menu.value = 'bumps_grid';"
                         " menu.dispatchEvent(new Event('change')); })()")
        assert watcher.expect("texture")["kind"] == "bumps"
        browser.evaluate(wait_for(f"window.tpadPage.mapDrawn > {drawn_before}"))
        assert browser.evaluate("window.tpadPage.texture.kind") == "bumps"
        stopped_by_signal_cleanly(serve)

    recording = read_recording(record)
    blocks = recording.blocks
    block = recording.metadata["block_frames"]
    peaks = np.abs(recording.drive[:len(blocks["t"]) * block]).reshape(-1, block).max(axis=1)
    touching = (blocks["saturated"].astype(np.int64) & FLAG_WATCHDOG) == 0
    for y_mm in (20.0, 40.0):
        mine = touching & (np.abs(blocks["y_mm"] - y_mm) < 0.5)
        assert blocks["x_mm"][mine].min() < 30.0 and blocks["x_mm"][mine].max() > 90.0
        assert blocks["voltage_v"][mine].max() > 1.0
        assert np.all((blocks["target_mu"][mine] > 0.7) & (blocks["target_mu"][mine] <= 1.0))
        # The drive follows the amplitude the renderer commanded for the finger along the grating (ramps and
        # the plate's ring-up blur it), and rose well above nothing.
        assert peaks[mine].max() > 0.1
        assert np.corrcoef(peaks[mine], blocks["amplitude_um"][mine])[0, 1] > 0.7
    first_touch, last_touch = np.flatnonzero(touching)[[0, -1]]
    # Silent until a finger came: a block is flagged touching when no part of it was under the watchdog, so the
    # drive may begin in the block before the first one flagged (the first sample's time fell inside it).
    assert np.all(peaks[:first_touch - 1] == 0.0)
    assert np.all(peaks[last_touch + int(0.02 * recording.fs_hz / block):] == 0.0)  # and after it left
