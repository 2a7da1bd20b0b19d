"""A real JACK server (dummy backend) for the audio tests, started and stopped by PID.

``jack_server(rate_hz, period_frames, sync=False)`` is a context manager around
:func:`jackd.dummy_server` (which starts ``jackd -n NAME [-S] -p 16 -d dummy -r
RATE -p PERIOD`` with a NAME no running server has and stops it by PID): it skips the test
without jackd or PortAudio (fails it under TPAD_RT_REQUIRE_SYSTEM=1), points clients
at the server (``JACK_DEFAULT_SERVER``), re-initialises PortAudio so the JACK host API
appears; on exit it terminates PortAudio (closing any stream left: PortAudio's JACK
host API asserts if the server is gone first) before the server stops, and
initialises PortAudio again afterwards.

``server_process(rate_hz, period_frames)`` runs the same server for tests that kill
it under a client of their own subprocess: it yields the :class:`RunningServer`
(name and process) and leaves this process's PortAudio alone; ``wait_until_playing``
tells when a client's stream has started on it; ``kill_server_under(command)`` runs a
client on such a server and kills the server under it.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import time
from collections.abc import Iterator
from typing import Any

from conftest import require_program, require_system
from jackd import RunningServer, dummy_server
from tpad_rt.outputs import audio


def _require_jack() -> None:
    """Skip (fail under TPAD_RT_REQUIRE_SYSTEM=1) without PortAudio, jackd or jack_wait."""
    try:
        import sounddevice  # noqa: F401
    except OSError:
        require_system(False, "PortAudio (libportaudio2)")
    require_program("jackd")
    require_program("jack_wait")


@contextlib.contextmanager
def server_process(rate_hz: int = 192000, period_frames: int = 64) -> Iterator[RunningServer]:
    """Run a dummy JACK server without touching this process's PortAudio; yields it (name, process)."""
    _require_jack()
    with dummy_server(rate_hz, period_frames) as server:
        yield server


@contextlib.contextmanager
def jack_server(rate_hz: int = 192000, period_frames: int = 64, *, sync: bool = False) -> Iterator[str]:
    """Run a dummy JACK server (synchronous mode if ``sync``); yields its name (also in ``JACK_DEFAULT_SERVER``)."""
    _require_jack()
    import sounddevice

    previous = os.environ.get("JACK_DEFAULT_SERVER")
    try:
        with dummy_server(rate_hz, period_frames, sync=sync) as server:
            name = server.name
            os.environ["JACK_DEFAULT_SERVER"] = name
            _attach_portaudio(server)
            try:
                yield name
            finally:
                # PortAudio's JACK host API must let go of the server while it still runs.
                sounddevice._terminate()
    finally:
        if previous is None:
            os.environ.pop("JACK_DEFAULT_SERVER", None)
        else:
            os.environ["JACK_DEFAULT_SERVER"] = previous
        sounddevice._initialize()


def _attach_portaudio(server: RunningServer) -> None:
    """Re-initialise PortAudio so that its JACK host API opens on ``server``. Once, on a condition: a JACK client
    opened just as the server's process came up has failed to attach its shared memory while the server ran (a CI
    run: "JackShmReadWritePtr::~JackShmReadWritePtr - Init not done for -1"), so :func:`jackd.dummy_server` has
    already waited until another client of the server listed its ports (:func:`jackd.wait_until_serving`).
    Raises PortAudioError when PortAudio cannot initialise (left uninitialised)."""
    audio.rescan_devices()  # terminates PortAudio, then initialises it


def kill_server_under(command: list[str], **popen: Any) -> subprocess.CompletedProcess[str]:
    """Run ``command`` (a client of a dummy server of its own), SIGKILL the server once the client's stream
    plays, and return how the client ended (its output as text; it may take 120 s to end)."""
    with server_process() as server:
        env = {**popen.pop("env", os.environ), "JACK_DEFAULT_SERVER": server.name}
        client = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                                  **popen)
        try:
            assert wait_until_playing(server.name), "the client's stream never started"
            server.process.kill()
            server.process.wait()
            out, err = client.communicate(timeout=120)
        finally:
            if client.poll() is None:
                client.kill()
    return subprocess.CompletedProcess(command, client.returncode, out, err)


def wait_until_playing(server_name: str, timeout_s: float = 120) -> bool:
    """Poll ``jack_lsp -c`` until a PortAudio output port is connected on ``server_name`` (a started
    stream: PortAudio connects its ports in Pa_StartStream); False if that does not happen in ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        listing = subprocess.run(["jack_lsp", "-s", server_name, "-c"], capture_output=True, text=True).stdout
        lines = listing.splitlines()
        for port, following in zip(lines, lines[1:]):
            if port.startswith("PortAudio:out_") and following.startswith((" ", "\t")):
                return True
        time.sleep(0.05)
    return False
