"""The control of the serial GIL-load test and bench: a plain-Python envelope writer.

    python tests/python_serial_writer.py SERIAL_URL SECONDS [--gil-threads N]

Does what tpad-rt's streamer does, the way an ordinary Python program would: the same
handshake (:class:`tpad_rt.outputs.serial_amp.AmpLink`), then a Python loop that every
frame period renders a frame of the grating's envelope with ``Pipeline.render``, encodes
it and writes it, pacing itself with ``time.sleep`` on the monotonic clock, while N other
Python threads spin a pure-Python loop (GIL load). It keeps the amplifier's buffer at
the URL's target fill from the start of the run, without reading STATUS (a simple writer
trusts its clock). Prints ``FRAMES EXPECTED MISSED`` last: frames written, frames the
clock asked for, and the samples the amplifier did not play from them (its underruns,
and the samples of frames it refused: late, or after its watchdog tripped), as its
STATUS after the STOP that ends the run says.
"""

from __future__ import annotations

import argparse
import threading
import time
from pathlib import Path

import numpy as np

from tpad_rt.device import Device
from tpad_rt.kernel import amp_codec as codec
from tpad_rt.kernel import amp_stream
from tpad_rt.outputs.serial_amp import AmpLink, parse_serial_url
from tpad_rt.pipeline import Pipeline
from tpad_rt.texture import load_compiled

GRATING = Path(__file__).resolve().parents[1] / "textures" / "grating.yaml"


def hog(stop: threading.Event) -> None:
    """Hold the GIL but for the switch interval, until ``stop``."""
    count = 0
    while not stop.is_set():
        count += 1


def main(url: str, seconds: float, gil_threads: int) -> None:
    device = Device.default()
    target = parse_serial_url(url)
    link = AmpLink.open(target, carrier_hz=device.carrier_hz, max_voltage_v=device.max_voltage_v)
    scale = link.scale  # the streamer's scale (H3), decided by the link
    assert scale is not None
    pipeline = Pipeline(device, load_compiled(GRATING), target.envelope_hz, envelope_output=True)
    pipeline.set_drive(pipeline.device_drive.from_hardware(volts_per_full_scale=scale.full_scale_v, max_voltage_v=scale.max_v,
                                                    carrier_hz=link.carrier_hz, source="the Python writer's amplifier"))
    pipeline.start()
    frame = np.zeros(link.frame_samples, dtype=np.float32)
    pipeline.render(frame)  # compiled before the clock starts
    body = np.zeros(codec.MAX_BODY, dtype=np.uint8)
    out = np.zeros(codec.MAX_ENCODED, dtype=np.uint8)
    payload = (target.envelope_hz.to_bytes(4, "little") + (0).to_bytes(4, "little")
               + link.target_fill.to_bytes(2, "little"))
    link._command(payload, codec.MSG_START, "START")  # the same START as the streamer's
    hogs_stop = threading.Event()
    for _ in range(gil_threads):
        threading.Thread(target=hog, args=(hogs_stop,), daemon=True).start()
    frame_s = link.frame_samples / target.envelope_hz
    written = 0
    started = time.monotonic()
    end = started + seconds
    while (now := time.monotonic()) < end:
        due = link.target_fill + int((now - started) / frame_s) * link.frame_samples
        while written < due:
            pipeline.push_finger(now - started, 20.0 + 10.0 * (now - started), 20.0)
            pipeline.render(frame)
            body[codec.PAYLOAD:codec.PAYLOAD + 4] = np.frombuffer(written.to_bytes(4, "little"), np.uint8)
            levels = np.round(frame * 32767).astype("<i2")
            body[codec.PAYLOAD + 4:codec.PAYLOAD + 4 + 2 * len(levels)] = np.frombuffer(levels.tobytes(), np.uint8)
            size = codec.seal(body, 4 + 2 * len(levels), codec.MSG_ENVELOPE, int(link.link[amp_stream.LINK_SEQ]), out)
            link.link[amp_stream.LINK_SEQ] = (link.link[amp_stream.LINK_SEQ] + 1) & 0xFFFF
            link._write(bytes(out[:size]))
            written += link.frame_samples
        time.sleep(frame_s / 2)
    hogs_stop.set()
    expected = (link.target_fill + seconds * target.envelope_hz) / link.frame_samples
    missed = _missed_samples(link)
    print(written // link.frame_samples, round(expected), missed, flush=True)
    link.close()


def _missed_samples(link: AmpLink) -> int:
    """STOP the stream, then from the first STATUS after its ACK the samples the amplifier did not play from the
    writer's frames: its underruns, and the samples of the frames it refused (late ones, or any after its
    watchdog tripped); -1 if no STATUS came."""
    link._command((5).to_bytes(2, "little"), codec.MSG_STOP, "STOP")
    body = link._receive(codec.MSG_STATUS, link.clock.now_ns() + 1_000_000_000)
    if body is None:
        return -1
    rejected = int(codec.get_u32(body, codec.PAYLOAD + codec.STATUS_FRAMES_REJECTED))
    return int(codec.get_u32(body, codec.PAYLOAD + codec.STATUS_UNDERRUNS)) + rejected * link.frame_samples


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("url", help="serial://PORT?buffer_ms=...")
    parser.add_argument("seconds", type=float)
    parser.add_argument("--gil-threads", type=int, default=0)
    arguments = parser.parse_args()
    main(arguments.url, arguments.seconds, arguments.gil_threads)
