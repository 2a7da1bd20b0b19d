"""The serial amplifier's side of docs/amp-protocol.md (version 2), written from that document alone.

:mod:`tpad_rt.amp.wire` is the amplifier's codec (COBS framing, CRC-16/IBM-3740, the
message layouts); :mod:`tpad_rt.amp.emulator` is a software amplifier built on it, run
by ``tpad-rt amp emulate`` (:mod:`tpad_rt.cli.amp`). Nothing here shares code with the
host's side (:mod:`tpad_rt.outputs`), so that the tests of one check the other.
"""
