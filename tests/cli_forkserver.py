"""A fork server for the CLI tests: imports tpad-rt once, then forks a fresh ``python -m tpad_rt`` per request.

    python tests/cli_forkserver.py      (driven by tests/cli_run.py over its stdin and stdout)

Most CLI tests run a command that refuses its input in one line; in a new interpreter
each would spend about a second importing numpy, numba and tpad-rt (what the command
imports when it runs), before a few milliseconds of work. Here that import happens once. Each request is one JSON line,
``{"args": [...], "cwd": DIR, "env": {...}, "stdout": FILE, "stderr": FILE}``; the
server forks, answers ``{"pid": PID}`` (the child leads a session of its own, so a
timeout can kill it and whatever it started), and when the child ends, answers
``{"status": EXIT_CODE, "peak_kb": PEAK_RSS_KB}``.

The child is the command as a user runs it: stdin is /dev/null, stdout and stderr are
the request's files, the environment is the request's, ``tpad_rt`` runs as
``__main__`` through runpy as ``python -m`` does, and the child exits as the
interpreter would (an uncaught exception's traceback and exit status 1, non-daemon
threads joined, atexit handlers run, output flushed) but without the module teardown. Its peak memory includes the server's imports (every command's
module, and what they import when they run) and the default device it loads, which the command would have made itself. Modules imported here read some of the environment once (numba its
``NUMBA_*`` settings): cli_run.py runs a request that changes those in a new interpreter.
"""

from __future__ import annotations

import atexit
import json
import os
import runpy
import sys
import threading

sys.path[0] = os.getcwd()  # as ``python -m`` has it: the repository (the server's cwd), not tests/

import importlib  # noqa: E402

import numba  # noqa: E402,F401  (the imports the commands make)
import numpy  # noqa: E402,F401

import tpad_rt.cli  # noqa: E402,F401
from tpad_rt.device import Device  # noqa: E402

#: What the commands import when they run (their parser imports none of it: tests/test_startup.py): the
#: device model and the files, the kernels, every output, the offline render, the emulator and the fits.
COMMAND_IMPORTS = ("tpad_rt.config.loader", "tpad_rt.config.json_schema", "tpad_rt.compiling", "tpad_rt.offline",
                   "tpad_rt.plate_maps", "tpad_rt.outputs.serial_amp", "tpad_rt.outputs.sim", "tpad_rt.outputs.wav",
                   "tpad_rt.amp.emulator", "tpad_rt.calibrate.device_file")
for _name in COMMAND_IMPORTS:
    importlib.import_module(_name)
Device.default()  # the shipped default device, which most commands load first
tpad_rt.cli.build_parser()  # imports every command's module


def _lines(fd: int):  # type: ignore[no-untyped-def]
    """The newline-ended lines read from ``fd`` (bytes), unbuffered so that a child inherits no read-ahead."""
    pending = b""
    while chunk := os.read(fd, 65536):
        pending += chunk
        while b"\n" in pending:
            line, pending = pending.split(b"\n", 1)
            yield line


def _exit_status(code: object) -> int:
    """The exit status the interpreter makes of ``SystemExit(code)`` (a non-int code is printed to stderr)."""
    if code is None:
        return 0
    if isinstance(code, int):
        return code & 0xFF
    print(code, file=sys.stderr)
    return 1


def _child(request: dict, requests_fd: int, replies_fd: int) -> None:
    """Become the command, then exit as the interpreter does; never returns."""
    os.close(requests_fd)
    os.close(replies_fd)
    os.setsid()
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.close(devnull)
    for fd, path in ((1, request["stdout"]), (2, request["stderr"])):
        target = os.open(path, os.O_WRONLY | os.O_TRUNC)
        os.dup2(target, fd)
        os.close(target)
    os.chdir(request["cwd"])
    os.environ.clear()
    os.environ.update(request["env"])
    sys.argv = ["tpad-rt", *request["args"]]
    try:
        runpy.run_module("tpad_rt", run_name="__main__", alter_sys=True)
        status = 0
    except SystemExit as exit_:
        status = _exit_status(exit_.code)
    except BaseException:  # noqa: BLE001  (what the interpreter does with an uncaught exception)
        sys.excepthook(*sys.exc_info())
        status = 1
    # The interpreter's exit up to its module teardown: wait for non-daemon threads, run atexit handlers,
    # flush. The teardown itself (0.35 s here, every page of the server's imports copied on write) is
    # skipped; the CLI tests that run a new interpreter (test_render_cli.py, test_play_cli.py) keep it.
    threading._shutdown()  # type: ignore[attr-defined]
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    os._exit(status)


def serve() -> None:
    """Answer requests until stdin closes."""
    requests_fd, replies_fd = os.dup(0), os.dup(1)
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.close(devnull)
    sys.stdout.flush()
    for line in _lines(requests_fd):
        request = json.loads(line)
        pid = os.fork()
        if pid == 0:
            _child(request, requests_fd, replies_fd)
        os.write(replies_fd, json.dumps({"pid": pid}).encode() + b"\n")
        _, status, usage = os.wait4(pid, 0)
        reply = {"status": os.waitstatus_to_exitcode(status), "peak_kb": usage.ru_maxrss}
        os.write(replies_fd, json.dumps(reply).encode() + b"\n")


if __name__ == "__main__":
    serve()
