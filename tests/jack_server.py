"""A real JACK server (dummy backend) for the audio tests, started and stopped by PID.

``jack_server(rate_hz, period_frames)`` is a context manager around
:func:`tpad_rt.jackd.dummy_server` (which starts ``jackd -n NAME -p 16 -d dummy -r RATE
-p PERIOD`` with a NAME no running server has and stops it by PID): it skips the test
without jackd or PortAudio (fails it under TPAD_RT_REQUIRE_SYSTEM=1), points clients
at the server (``JACK_DEFAULT_SERVER``), re-initialises PortAudio so the JACK host API
appears; on exit it terminates PortAudio (closing any stream left: PortAudio's JACK
host API asserts if the server is gone first) before the server stops, and
initialises PortAudio again afterwards.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

from conftest import require_program, require_system
from tpad_rt.jackd import dummy_server
from tpad_rt.outputs import audio

@contextlib.contextmanager
def jack_server(rate_hz: int = 192000, period_frames: int = 64) -> Iterator[str]:
    """Run a dummy JACK server; yields its name (also in ``JACK_DEFAULT_SERVER``)."""
    try:
        import sounddevice
    except OSError:
        require_system(False, "PortAudio (libportaudio2)")
    require_program("jackd")
    require_program("jack_wait")
    previous = os.environ.get("JACK_DEFAULT_SERVER")
    try:
        with dummy_server(rate_hz, period_frames) as name:
            os.environ["JACK_DEFAULT_SERVER"] = name
            try:
                audio.rescan_devices()
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
