"""Commands that render nothing start without numba and the kernels (issue 23, "Start fast").

Each command runs in a fresh interpreter, as a user starts it, and reports the modules it
imported. Building the parser (``tpad-rt --help``, ``tpad-rt X --help``) imports no subcommand's
implementation, and a command's parser is built without the other subcommands' modules; ``check``, ``schema``, ``design``, ``devices``, ``plot`` and the calibration fits
import neither numba nor a kernel. ``tpad_rt.kernel.layout`` is allowed: it is the kernels'
constant indices (telemetry columns, flags), plain ints that import nothing. Pydantic, which
validates files, loads only for the commands that read a texture or device file or print
its schema. The times are measured, not asserted here (docs/architecture.md "Start-up").
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tpad_rt.cli import build_parser

REPO = Path(__file__).resolve().parents[1]

#: Runs ``main`` on each argument list of the JSON in argv[2] (a --help's SystemExit ends only that one), then
#: writes the exit statuses and every imported module's name to the file argv[1].
PROBE = """
import json, sys
from tpad_rt.cli import main
statuses = []
for argv in json.loads(sys.argv[2]):
    try:
        statuses.append(main(argv))
    except SystemExit as end:
        statuses.append(end.code)
with open(sys.argv[1], "w") as out:
    json.dump({"statuses": statuses, "modules": sorted(sys.modules)}, out)
"""


def _commands(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every subcommand (and action, such as ``amp emulate``) under ``parser``, as the words that name it."""
    found = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found += [(*prefix, name), *_commands(sub, (*prefix, name))]
    return found


#: Every parser's --help: the top level, each subcommand and each action (a new one is in the list by itself).
HELPS = [["--help"], ["--version"]] + [[*command, "--help"] for command in _commands(build_parser())]


def imported(runs: list[list[str]], tmp_path: Path) -> tuple[list[object], set[str]]:
    """The exit statuses of ``tpad-rt ARGS`` for each of ``runs``, in one fresh interpreter started in the
    repository, and the modules it had imported at the end."""
    report = tmp_path / "modules.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run([sys.executable, "-c", PROBE, str(report), json.dumps(runs)], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    result = json.loads(report.read_text())
    return result["statuses"], set(result["modules"])


def kernel_code(modules: set[str]) -> set[str]:
    """numba, llvmlite and the kernel modules among ``modules`` (the kernel's layout of constants is none)."""
    return {name for name in modules
            if name.split(".")[0] in ("numba", "llvmlite")
            or (name.startswith("tpad_rt.kernel.") and name != "tpad_rt.kernel.layout")}


def test_every_help_imports_neither_numba_nor_pydantic(tmp_path: Path) -> None:
    assert ["amp", "emulate", "--help"] in HELPS and ["calibrate", "sweep", "--help"] in HELPS
    statuses, modules = imported(HELPS, tmp_path)
    assert statuses == [0] * len(HELPS)
    assert kernel_code(modules) == set()
    assert "pydantic" not in modules and "tpad_rt.device" not in modules


@pytest.mark.parametrize(("args", "statuses", "reads_files"), [
    (["check", "textures/grating.yaml"], (0,), True),
    (["check", "tests/good_files/device.yaml", "default"], (0,), True),
    (["schema", "device"], (0,), True),
    (["design", "--plate", "MyGlass:0.5:2.5:70"], (0,), False),
    (["devices"], (0, 1), False),  # 1: no PortAudio on this host, which the command says in one line
    (["plot", "no-such-recording.npz", "--out", "plot.png"], (1,), False),
    (["calibrate", "impedance", "examples/calibration/sweeps.csv", "--json"], (0,), False),
], ids=["check-texture", "check-device", "schema", "design", "devices", "plot", "calibrate-impedance"])
def test_commands_that_render_nothing_import_no_kernel(args: list[str], statuses: tuple[int, ...],
                                                       reads_files: bool, tmp_path: Path) -> None:
    (status,), modules = imported([args], tmp_path)
    assert status in statuses
    assert kernel_code(modules) == set()
    assert ("pydantic" in modules) == reads_files  # the file models load only where a file is read
    # The parser is built for the command alone: no other subcommand's module is imported.
    assert {name for name in modules if name.startswith("tpad_rt.cli.")} == {"tpad_rt.cli.arguments",
                                                                             f"tpad_rt.cli.{args[0]}"}


def test_the_probe_sees_the_kernels_a_command_loads(tmp_path: Path) -> None:
    """``show`` draws the texture kernel's maps: its run imports the texture and numba, and the probe reports
    them (here before it refuses --out)."""
    (status,), modules = imported([["show", "textures/grating.yaml", "--out", "map.jpg"]], tmp_path)
    assert status == 1
    assert "numba" in kernel_code(modules)
