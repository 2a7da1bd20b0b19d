"""The client examples (examples/clients/) against a real tpad-rt serve: Python (websockets), Node (the standard
WebSocket), C# (System.Net.WebSockets, compiled with Mono's mcs and run with mono) and the browser example in a
headless Chromium, each setting a texture, swiping a finger and reading the telemetry back."""

from __future__ import annotations

import functools
import re
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from cdp import Browser
from cli_run import REPO
from conftest import require_program
from serve_process import Client, Serve, stopped_by_signal_cleanly
from test_serve_page import wait_for
from tpad_rt.kernel.layout import FLAG_WATCHDOG
from tpad_rt.recording import read_recording

CLIENTS = REPO / "examples" / "clients"
SQUARE = "4 mm square grating at 45 degrees, 30 % duty (sticky bars on a slippery ground)"
TELEMETRY_LINE = re.compile(r"^  x +[\d.]+ mm  target (0\.\d+|1\.000)  achieved [\d.]+  drive +[\d.]+ V", re.M)


@pytest.fixture(scope="module")
def server() -> Iterator[Serve]:
    with Serve("--output", "sim://", "--no-osc", port_args=("--port", "0")) as serve:
        yield serve
        stopped_by_signal_cleanly(serve)


def node_command() -> list[str]:
    """node, with --experimental-websocket before Node 22 (which has WebSocket without it)."""
    node = require_program("node")
    major = int(subprocess.run([node, "--version"], capture_output=True, text=True).stdout.strip().lstrip("v")
                .split(".")[0])
    return [node, "--experimental-websocket"] if major < 22 else [node]


@functools.cache
def csharp_command() -> list[str]:
    """The C# example compiled with mcs (once): mono and the program."""
    mcs, mono = require_program("mcs"), require_program("mono")
    program = Path(tempfile.mkdtemp(prefix="tpad-rt-csharp-")) / "tpad_client.exe"
    built = subprocess.run([mcs, f"-out:{program}", "Program.cs", "TpadClient.cs"], cwd=CLIENTS / "csharp",
                           capture_output=True, text=True, timeout=120)
    assert built.returncode == 0 and "warning" not in built.stdout, built.stdout + built.stderr
    return [mono, str(program)]


def run_client(kind: str, url: str, texture: str) -> subprocess.CompletedProcess[str]:
    if kind == "python":
        command = [sys.executable, str(CLIENTS / "python_client.py"), "--url", url, "--texture", texture]
    elif kind == "node":
        command = [*node_command(), str(CLIENTS / "node_client.mjs"), url, texture]
    else:
        command = [*csharp_command(), url, texture]
    return subprocess.run(command, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("kind", ["python", "node", "csharp"])
def test_each_client_sets_a_texture_swipes_and_reads_the_renderer_back(kind: str, tmp_path: Path) -> None:
    """The client prints the telemetry it reads (how many lines at 20 Hz depends on the host's speed: a loaded
    machine printed 5 in a run); what the renderer did with its swipe is read from the server's recording,
    every block of it: the finger from 20 mm to 110 mm over both levels of the texture the client set."""
    record = tmp_path / "client.npz"
    with Serve("--output", "sim://", "--no-osc", "--record", str(record), port_args=("--port", "0")) as serve:
        done = run_client(kind, serve.ws_url, "square_grating")
        stopped_by_signal_cleanly(serve)
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"texture set: {SQUARE}" in done.stdout
    assert TELEMETRY_LINE.search(done.stdout), done.stdout
    # the renderer's figures rounded, with units (the whole run's latency: a number, not n/a)
    assert re.search(r"\npush-to-output latency p50 \d+\.\d\d ms, p99 \d+\.\d\d ms; 0 errors$", done.stdout.rstrip()), \
        done.stdout
    blocks = read_recording(record).blocks
    touching = (blocks["saturated"].astype(np.int64) & FLAG_WATCHDOG) == 0
    assert blocks["x_mm"][touching].min() < 25.0 and blocks["x_mm"][touching].max() > 105.0
    assert {0.5, 1.0} <= set(np.round(blocks["target_mu"][touching], 3).tolist())  # both levels of the grating


@pytest.mark.parametrize("kind", ["python", "node", "csharp"])
def test_each_client_reports_a_refusal_and_exits_1(server: Serve, kind: str) -> None:
    done = run_client(kind, server.ws_url, "no_such_texture")
    assert done.returncode == 1
    assert "no shipped texture is called 'no_such_texture'" in done.stdout + done.stderr


@pytest.mark.parametrize("kind", ["python", "node", "csharp"])
def test_each_client_says_when_no_server_answers(kind: str) -> None:
    done = run_client(kind, "ws://127.0.0.1:9/ws", "grating")
    assert done.returncode == 1 and "is tpad-rt serve running?" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.system
def test_the_browser_example_on_a_page_of_another_allowed_origin() -> None:
    static = subprocess.Popen([sys.executable, "-m", "http.server", "0", "--bind", "127.0.0.1", "--directory",
                               str(CLIENTS)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert static.stdout is not None
        port = int(re.search(r"port (\d+)", static.stdout.readline()).group(1))  # type: ignore[union-attr]
        origin = f"http://127.0.0.1:{port}"
        with Serve("--output", "sim://", "--no-osc", "--allow-origin", origin, port_args=("--port", "0")) as serve, \
                Client(serve.ws_url) as watcher:
            watcher.request({"type": "subscribe", "rate_hz": 50}, "subscribed")
            with Browser(f"{origin}/browser_client.html?ws={serve.ws_url}") as browser:
                browser.evaluate(wait_for("window.demo && window.demo.swipe"))
                browser.evaluate("window.demo.swipe()")
                watcher.expect("telemetry", lambda m: m["touching"] and m["x_mm"] > 90.0)
                browser.evaluate(wait_for("window.demo.done === 1 && window.demo.telemetry > 5"))
                assert browser.evaluate("window.demo.errors") == []
            stopped_by_signal_cleanly(serve)
    finally:
        static.terminate()
        static.wait()
