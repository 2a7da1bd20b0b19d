"""``tpad-rt check FILE...``: validate texture and device files.

Prints ``ok  FILE (texture: KIND)`` or ``ok  FILE (device: LABEL)`` for each good
file and every breadcrumb error of each bad one (on stderr), then a summary
when more than one file was given. Colour only on a terminal. Exit status 1 if
any file is bad.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from tpad_rt.cli.arguments import Subparsers
from tpad_rt.errors import ConfigError

if TYPE_CHECKING:
    from rich.console import Console


def add_parser(subparsers: Subparsers) -> None:
    """Register ``check``."""
    parser = subparsers.add_parser(
        "check",
        help="validate texture and device files",
        description="Validate texture and device YAML files (told apart by content) against docs/formats.md.",
    )
    parser.add_argument("files", nargs="+", metavar="FILE", help="texture or device file")
    parser.add_argument("-q", "--quiet", action="store_true", help="print only errors")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Check every file; 1 if any is bad, else 0."""
    from rich.text import Text

    from tpad_rt.config import DeviceFile, load_any

    out = _console(stderr=False)
    err = _console(stderr=True)
    bad = 0
    for name in args.files:
        try:
            model = load_any(name)
            if isinstance(model, DeviceFile):  # what play and render also refuse: derived values out of bounds
                from tpad_rt.device import Device  # the device model: only for a device file

                Device.from_spec(model, name)
        except ConfigError as error:
            bad += 1
            for line in error.errors:
                err.print(Text(line, style="red"))
            continue
        if not args.quiet:
            summary = f"device: {model.label}" if isinstance(model, DeviceFile) else f"texture: {model.kind}"
            out.print(Text.assemble(("ok", "bold green"), f"  {name} ({summary})"))
    if len(args.files) > 1 and not args.quiet:
        good = len(args.files) - bad
        out.print(Text(f"{len(args.files)} files checked: {good} ok, {bad} with errors", style="bold"))
    return 1 if bad else 0


def _console(stderr: bool) -> Console:
    """A console that never wraps, highlights or interprets markup (plain when not a terminal)."""
    from rich.console import Console

    return Console(stderr=stderr, soft_wrap=True, highlight=False, markup=False, emoji=False)

