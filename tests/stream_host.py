"""A host that streams a constant envelope to a protocol amplifier on a pty until it is killed (the host a test
freezes with SIGSTOP).

    python tests/stream_host.py PORT VOLTS

HELLO, SET_CARRIER (the default device's carrier), START at 16 kHz, then ENVELOPE frames of
1 ms paced on the monotonic clock LEAD_SAMPLES ahead of the amplifier's play position (more
than its watchdog's 50 ms: a host frozen now leaves the amplifier samples to play past its
watchdog's time); prints ``streaming`` once a STATUS says RUNNING. Bytes from the amplifier
are read and dropped.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

from pty_host import PtyHost
from tpad_rt.amp import wire
from tpad_rt.amp.wire import State, Type
from tpad_rt.device import Device

ENVELOPE_HZ = 16_000
FRAME_SAMPLES = 16
LEAD_SAMPLES = 1008  # 63 ms at 16 kHz, within the 1024-sample buffer


def main(port: str, volts: float) -> None:
    host = PtyHost(port)
    info = host.hello(0x57AE0001)
    carrier = host.send(Type.SET_CARRIER, wire.SetCarrier(round(Device.default().carrier_hz * 1000)).pack())
    host.ack(carrier)
    frame = np.full(FRAME_SAMPLES, round(volts * 1000 / info.full_scale_mv * 32767), np.int16)
    start = host.send(Type.START, wire.Start(ENVELOPE_HZ, 0, LEAD_SAMPLES).pack())
    host.ack(start)
    os.set_blocking(host.fd, False)
    started_s, written, running = time.monotonic(), 0, False
    while True:
        due = LEAD_SAMPLES + (time.monotonic() - started_s) * ENVELOPE_HZ
        while written < due:
            host.send(Type.ENVELOPE, wire.Envelope(written, frame).pack())
            written += FRAME_SAMPLES
        try:
            data = os.read(host.fd, 65536)
        except BlockingIOError:
            data = b""
        if not running:
            for encoded in host.splitter.feed(data):
                decoded = None if encoded is None else wire.decode(encoded)
                if decoded is not None and decoded.type == Type.STATUS and \
                        wire.Status.unpack(decoded.payload).state == State.RUNNING:
                    running = True
                    print("streaming", flush=True)
        time.sleep(0.001)


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]))
