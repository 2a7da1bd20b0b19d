"""``audio://[device name or index]?rate=192000&block=64&channel=1``: a PortAudio output stream.

The stream's callback is a native function (``tpad_rt.kernel.callback``), handed to
``Pa_OpenStream`` through the PortAudio library that ``sounddevice`` loads; this
module opens, starts, polls and closes the stream and never runs Python in the audio
path. Every ``Pa_*`` call is checked and a failure raised as BackendError naming the
call, the device and PortAudio's message (sounddevice style).

API map
-------
parse_audio_url(url) -> AudioTarget
    the device (None: default output; an index; or part of a name), rate, block, channel
portaudio() -> (ffi, lib)
    sounddevice's cffi handle on PortAudio; BackendError naming the package when missing
rescan_devices()
    re-initialise PortAudio so that host APIs started since (a JACK server) appear;
    closes any open stream
output_devices() -> list[AudioDevice], find_output_device(spec) -> AudioDevice
accepted_rates(device, channels, rates=CANDIDATE_RATES) -> list[int]
AudioStream(device, rate_hz, block_frames, channels, callback_address, user_data_address)
    ``start()``, ``stop()``, ``close()``, ``active()``, ``lost()``, ``abandon()``, ``time_s()``,
    ``output_latency_s``

A lost stream (its device or JACK server went away) cannot be stopped or closed:
PortAudio's JACK host API waits 10 minutes for the dead server's process thread to
acknowledge a stop, and asserts (SIGABRT) when it unregisters the ports of a dead
server, which Pa_CloseStream and Pa_Terminate do. ``abandon()`` leaks such a stream
and keeps sounddevice from terminating PortAudio at exit; audio then stays unusable
in this process (BackendError saying so).
"""

from __future__ import annotations

import atexit
from dataclasses import dataclass
from typing import Any

from tpad_rt.errors import BackendError
from tpad_rt.limits import MAX_BLOCK_FRAMES, MAX_RATE_HZ
from tpad_rt.outputs.base import Consumes, OutputKind
from tpad_rt.urls import Option, Url, UrlForm, count, parse_url

#: The accepted URL.
FORMS = (UrlForm("audio", "[device name or index]", (
    Option("rate", 192000, count(1, MAX_RATE_HZ)), Option("block", 64, count(1, MAX_BLOCK_FRAMES)),
    Option("channel", 1, count(1, 1024)))),)
#: DAC samples, rendered by the native callback PortAudio's audio thread calls (tpad_rt.drivers.audio_callback).
KIND = OutputKind(Consumes.DAC, "tpad_rt.drivers.audio_callback:AudioCallbackDriver")
#: Rates tried when listing what a device accepts (Hz).
CANDIDATE_RATES = (44100, 48000, 96000, 176400, 192000, 384000)

_PA_FLOAT32 = 0x00000001
_PA_CLIP_OFF = 0x00000001
_PA_DITHER_OFF = 0x00000002
_PA_NO_ERROR = 0
_PA_FORMAT_IS_SUPPORTED = 0
_PA_UNANTICIPATED_HOST_ERROR = -9999

#: Streams given up by AudioStream.abandon (kept referenced: PortAudio still holds them).
_ABANDONED: list[Any] = []


@dataclass(frozen=True)
class AudioTarget:
    """What an ``audio://`` URL asks for: ``device`` (None: the default output, an index, or part of a
    name), ``rate_hz``, ``block_frames``, ``channel`` (1-based) and the options the URL wrote (``given``)."""

    device: int | str | None
    rate_hz: int
    block_frames: int
    channel: int
    given: frozenset[str]


def parse_audio_url(url: Url | str) -> AudioTarget:
    """Read an ``audio://`` URL; ConfigError (showing the expected form) for an unknown option or bad value."""
    if isinstance(url, str):
        url = parse_url(url, "output", {"audio": FORMS})
    values = FORMS[0].read(url)
    target = url.target.strip()
    device: int | str | None = int(target) if target.isdigit() else (target or None)
    return AudioTarget(device, values["rate"], values["block"], values["channel"], frozenset(url.options))


def portaudio() -> tuple[Any, Any]:
    """``(ffi, lib)``: sounddevice's cffi handle on the PortAudio library (initialised).

    Raises BackendError when PortAudio is missing (sounddevice raises OSError then).
    sounddevice's ``_ffi`` and ``_lib`` are private, but its public stream classes take
    only Python callbacks (which the audio thread must never run: docs/realtime.md);
    python-rtmixer reaches the same handles to pass a C callback. This function is the
    only place they are read.
    """
    try:
        import sounddevice
    except OSError as error:
        raise BackendError(
            f"audio: PortAudio is not available ({error}); install the system package libportaudio2") from None
    return sounddevice._ffi, sounddevice._lib


def _require_no_lost_stream() -> None:
    """BackendError when a stream was abandoned in this process (PortAudio cannot be used again)."""
    if _ABANDONED:
        raise BackendError("audio: an output stream was lost earlier in this process (device or server gone) "
                           "and PortAudio cannot be re-initialised around it; restart the program")


def rescan_devices() -> None:
    """Re-initialise PortAudio so it sees host APIs that started since (e.g. a JACK server).

    Pa_Terminate closes every stream still open in this process. Raises BackendError
    after a stream was abandoned (module docstring).
    """
    import sounddevice

    _require_no_lost_stream()
    portaudio()
    # sounddevice has no public re-scan; its docs give these two private calls for it.
    sounddevice._terminate()
    sounddevice._initialize()


def _check(code: int, what: str) -> int:
    """``code`` if it is not a PortAudio error, else BackendError ``audio: <what>: <PortAudio's text>``."""
    if code >= _PA_NO_ERROR:
        return code
    ffi, lib = portaudio()
    text = ffi.string(lib.Pa_GetErrorText(code)).decode(errors="replace")
    if code == _PA_UNANTICIPATED_HOST_ERROR:
        info = lib.Pa_GetLastHostErrorInfo()
        text += f" ({ffi.string(info.errorText).decode(errors='replace')}, host error {info.errorCode})"
    raise BackendError(f"audio: {what}: {text} [PaErrorCode {code}]")


@dataclass(frozen=True)
class AudioDevice:
    """A PortAudio output device: ``index``, ``name``, ``host_api``, ``channels`` (max output),
    ``default_rate_hz``, ``low_latency_s`` (its default low output latency)."""

    index: int
    name: str
    host_api: str
    channels: int
    default_rate_hz: float
    low_latency_s: float

    def __str__(self) -> str:
        return f"{self.index} '{self.name}' ({self.host_api})"


def output_devices() -> list[AudioDevice]:
    """Every PortAudio device with output channels; BackendError after a stream was abandoned."""
    _require_no_lost_stream()
    ffi, lib = portaudio()
    devices = []
    for index in range(_check(lib.Pa_GetDeviceCount(), "cannot count the devices")):
        info = lib.Pa_GetDeviceInfo(index)
        if info == ffi.NULL or info.maxOutputChannels < 1:
            continue
        host = lib.Pa_GetHostApiInfo(info.hostApi)
        devices.append(AudioDevice(
            index, ffi.string(info.name).decode(errors="replace"),
            ffi.string(host.name).decode(errors="replace") if host != ffi.NULL else "?",
            info.maxOutputChannels, info.defaultSampleRate, info.defaultLowOutputLatency))
    return devices


def find_output_device(spec: int | str | None) -> AudioDevice:
    """The output device ``spec`` names: None the default, an index, or a case-insensitive part of a name.

    Raises BackendError when there is no such output device, or a name matches several
    (listing the output devices).
    """
    devices = output_devices()
    _, lib = portaudio()
    if spec is None:
        index = lib.Pa_GetDefaultOutputDevice()
        matches = [device for device in devices if device.index == index]
        wanted = "the default output device"
    elif isinstance(spec, int):
        matches = [device for device in devices if device.index == spec]
        wanted = f"output device {spec}"
    else:
        matches = [device for device in devices if spec.lower() in device.name.lower()]
        exact = [device for device in matches if device.name.lower() == spec.lower()]
        matches = exact or matches
        wanted = f"an output device named '{spec}'"
    if len(matches) == 1:
        return matches[0]
    listing = "; ".join(str(device) for device in devices) or "none"
    problem = "several match" if matches else "there is none"
    raise BackendError(f"audio: {wanted}: {problem} (output devices: {listing}); see 'tpad-rt devices'")


def _parameters(device: AudioDevice, channels: int) -> Any:
    """A ``PaStreamParameters*`` for float32 output on ``device`` with its low latency."""
    ffi, _ = portaudio()
    parameters = ffi.new("PaStreamParameters*")
    parameters.device = device.index
    parameters.channelCount = channels
    parameters.sampleFormat = _PA_FLOAT32
    parameters.suggestedLatency = device.low_latency_s
    parameters.hostApiSpecificStreamInfo = ffi.NULL
    return parameters


def accepted_rates(device: AudioDevice, channels: int, rates: tuple[int, ...] = CANDIDATE_RATES) -> list[int]:
    """The rates (Hz) among ``rates`` that ``device`` accepts for ``channels`` float32 outputs."""
    ffi, lib = portaudio()
    parameters = _parameters(device, channels)
    return [rate for rate in rates if lib.Pa_IsFormatSupported(ffi.NULL, parameters, rate) == _PA_FORMAT_IS_SUPPORTED]


class AudioStream:
    """An open (stopped) float32 output stream on ``device`` driven by a native callback.

    ``callback_address`` is a ``PaStreamCallback`` (a numba ``@cfunc``'s ``.address``),
    ``user_data_address`` what it receives as ``userData``; both must outlive the
    stream. ``channels`` interleaved channels, ``block_frames`` frames per callback,
    the device's low latency suggested. Raises BackendError when the device does not
    accept ``rate_hz`` (listing the rates it does) or PortAudio cannot open the stream.
    """

    def __init__(self, device: AudioDevice, rate_hz: int, block_frames: int, channels: int,
                 callback_address: int, user_data_address: int):
        _require_no_lost_stream()
        ffi, lib = portaudio()
        self.device = device
        self.rate_hz = rate_hz
        self.block_frames = block_frames
        parameters = _parameters(device, channels)
        supported = lib.Pa_IsFormatSupported(ffi.NULL, parameters, rate_hz)
        if supported != _PA_FORMAT_IS_SUPPORTED:
            accepted = ", ".join(str(rate) for rate in accepted_rates(device, channels)) or "none of " + ", ".join(
                str(rate) for rate in CANDIDATE_RATES)
            text = ffi.string(lib.Pa_GetErrorText(supported)).decode(errors="replace")
            raise BackendError(f"audio: device {device} does not accept {rate_hz} Hz with {channels} channel(s) "
                               f"({text}); it accepts: {accepted} Hz")
        handle = ffi.new("PaStream**")
        _check(lib.Pa_OpenStream(
            handle, ffi.NULL, parameters, float(rate_hz), block_frames, _PA_CLIP_OFF | _PA_DITHER_OFF,
            ffi.cast("PaStreamCallback*", callback_address), ffi.cast("void*", user_data_address)),
            f"cannot open a {rate_hz} Hz, {block_frames}-frame, {channels}-channel stream on device {device}")
        self._stream = handle[0]
        info = lib.Pa_GetStreamInfo(self._stream)
        self.output_latency_s = float(info.outputLatency) if info != ffi.NULL else float("nan")

    def _call(self, name: str, what: str) -> int:
        """``Pa_<name>(stream)``, checked; BackendError ``audio: <what> on device ...`` on failure."""
        if self._stream is None:
            raise BackendError(f"audio: {what}: the stream on device {self.device} is closed")
        _, lib = portaudio()
        return _check(getattr(lib, name)(self._stream), f"{what} on device {self.device}")

    def start(self) -> None:
        """Start calling the callback."""
        self._call("Pa_StartStream", "cannot start the stream")

    def active(self) -> bool:
        """True while the stream runs (False once it stopped, or the device went away); BackendError on error."""
        return self._call("Pa_IsStreamActive", "cannot poll the stream") == 1

    def lost(self) -> bool:
        """True when the stream ended by itself: started, never stopped, yet no longer active.

        The callbacks tpad-rt opens streams with always continue, so this is a device
        or server that went away. False for a closed stream.
        """
        if self._stream is None:
            return False
        return not self.active() and self._call("Pa_IsStreamStopped", "cannot poll the stream") == 0

    def abandon(self) -> None:
        """Let go of a lost stream without stopping or closing it (module docstring says why).

        Keeps sounddevice's exit handler from calling Pa_Terminate, which would close it;
        afterwards opening or listing devices raises BackendError in this process.
        """
        if self._stream is None:
            return
        import sounddevice

        _ABANDONED.append(self._stream)
        self._stream = None
        # sounddevice registers this private handler at import, with no public way to skip it.
        atexit.unregister(sounddevice._exit_handler)

    def time_s(self) -> float:
        """The stream's clock (s), the clock of the callback's time info."""
        _, lib = portaudio()
        return float(lib.Pa_GetStreamTime(self._stream))

    def stop(self) -> None:
        """Stop after the buffers queued have played (nothing if closed or already stopped)."""
        if self._stream is not None and self._call("Pa_IsStreamStopped", "cannot poll the stream") == 0:
            self._call("Pa_StopStream", "cannot stop the stream")

    def close(self) -> None:
        """Close the stream (stopping it without waiting); a second call does nothing."""
        if self._stream is None:
            return
        try:
            self._call("Pa_CloseStream", "cannot close the stream")
        finally:
            self._stream = None
