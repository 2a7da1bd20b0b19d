"""A real JACK server (dummy backend) for the audio tests, started and stopped by PID.

``jack_server(rate_hz, period_frames)`` is a context manager: it starts
``jackd -n NAME -p 16 -d dummy -r RATE -p PERIOD`` with a NAME no running server has, waits for it with
``jack_wait``, points clients at it (``JACK_DEFAULT_SERVER``), re-initialises PortAudio
so the JACK host API appears; on exit it terminates PortAudio (closing any stream left:
PortAudio's JACK host API asserts if the server is gone first), stops the server with
SIGTERM, waits for it to exit and initialises PortAudio again.
ARCHITECTURE.md section 5 says why each flag.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import tempfile
from collections.abc import Iterator

from conftest import require_program, require_system
from tpad_rt.outputs import audio

#: Seconds to wait for the server to come up, and to exit after SIGTERM.
START_TIMEOUT_S = 10
EXIT_TIMEOUT_S = 10
#: Server names tried (JACK's own table holds few servers).
MAX_SERVERS = 4


def _free_name(jack_wait: str) -> str:
    """The first of ``tpadrt-0`` .. ``tpadrt-{MAX_SERVERS - 1}`` no running server has.

    Names are reused, not random: JACK keeps a small table of servers in shared memory
    and reclaims an entry left by a server that died without cleaning up (a killed test
    run) only when a new server takes the same name.
    """
    for index in range(MAX_SERVERS):
        name = f"tpadrt-{index}"
        probe = subprocess.run([jack_wait, "-s", name, "-c"], capture_output=True, text=True, timeout=10)
        if "not running" in probe.stdout:
            return name
    raise RuntimeError(f"{MAX_SERVERS} JACK servers named tpadrt-N already run")


@contextlib.contextmanager
def jack_server(rate_hz: int = 192000, period_frames: int = 64) -> Iterator[str]:
    """Run a dummy JACK server; yields its name (also in ``JACK_DEFAULT_SERVER``)."""
    try:
        import sounddevice
    except OSError:
        require_system(False, "PortAudio (libportaudio2)")
    jackd = require_program("jackd")
    jack_wait = require_program("jack_wait")
    name = _free_name(jack_wait)
    log = tempfile.TemporaryFile()  # a file, not a pipe: an unread pipe would fill up and block jackd
    process = subprocess.Popen(
        [jackd, "-n", name, "-p", "16", "-d", "dummy", "-r", str(rate_hz), "-p", str(period_frames)],
        stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    previous = os.environ.get("JACK_DEFAULT_SERVER")
    os.environ["JACK_DEFAULT_SERVER"] = name
    try:
        waited = subprocess.run([jack_wait, "-s", name, "-w", "-t", str(START_TIMEOUT_S)],
                                capture_output=True, text=True, timeout=START_TIMEOUT_S + 5)
        if waited.returncode != 0 or process.poll() is not None:
            log.seek(0)
            raise RuntimeError(f"jackd {name} did not start: {log.read().decode(errors='replace')[-2000:]}")
        audio.rescan_devices()
        yield name
    finally:
        # PortAudio's JACK host API must let go of the server while it still runs.
        sounddevice._terminate()
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(EXIT_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        log.close()
        if previous is None:
            os.environ.pop("JACK_DEFAULT_SERVER", None)
        else:
            os.environ["JACK_DEFAULT_SERVER"] = previous
        sounddevice._initialize()
