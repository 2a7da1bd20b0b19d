"""The ``tpad-rt`` command line: one module per subcommand.

Each subcommand module defines ``add_parser(subparsers)`` (which registers the
subcommand and sets ``func`` to its ``run(args) -> int``), and imports at module level
only what its parser needs: the device model, the texture, the kernels and the engine
are imported by the functions that run them. ``main`` imports the module of the
subcommand it runs, and every module only for ``tpad-rt --help`` (docs/architecture.md
"Start-up"). It turns every :class:`~tpad_rt.errors.TpadError` and every bad flag into
one message on stderr and exit status 1, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import NoReturn, Sequence

from tpad_rt.errors import TpadError

#: Subcommand modules, in the order ``tpad-rt --help`` lists them.
_SUBCOMMANDS = ("check", "schema", "design", "show", "render", "plot", "play", "serve", "devices", "amp", "calibrate", "warm")


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors exit 1 with one clear line."""

    def error(self, message: str) -> NoReturn:
        self.exit(1, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The ``tpad-rt`` parser with every subcommand registered; with ``only`` (a subcommand's name), the others
    are registered by name alone, and only that one's module is imported."""
    from tpad_rt.version import __version__

    parser = _Parser(
        prog="tpad-rt",
        description="Real-time haptic rendering for ultrasonic friction-modulation displays (TPaDs).",
    )
    parser.add_argument("--version", action="version", version=f"tpad-rt {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    subparsers.required = True
    for name in _SUBCOMMANDS:
        if only is None or name == only:
            importlib.import_module(f"tpad_rt.cli.{name}").add_parser(subparsers)
        else:
            subparsers.add_parser(name)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``tpad-rt`` with ``argv`` (default: ``sys.argv[1:]``); returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    chosen = argv[0] if argv and argv[0] in _SUBCOMMANDS else None  # else --help, --version or a usage error
    args = build_parser(chosen).parse_args(argv)
    command = " ".join(name for name in (args.command, getattr(args, "action", None)) if name)  # "amp emulate"
    try:
        return int(args.func(args) or 0)
    except TpadError as err:
        print(f"tpad-rt {command}: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"tpad-rt {command}: interrupted", file=sys.stderr)
        return 130


def _entry() -> NoReturn:
    sys.exit(main())


if __name__ == "__main__":
    _entry()
