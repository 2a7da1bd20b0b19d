"""``tpad-rt schema texture|device [--out FILE]``: print a file format's JSON Schema."""

from __future__ import annotations

import argparse
import json
import sys

from tpad_rt.cli.arguments import Subparsers
from tpad_rt.config.json_schema import SCHEMA_KINDS, schema_json
from tpad_rt.files import NewFile


def add_parser(subparsers: Subparsers) -> None:
    """Register ``schema``."""
    parser = subparsers.add_parser(
        "schema",
        help="print the JSON Schema of texture or device files",
        description="Print the JSON Schema of texture or device files, for editors that validate YAML.",
    )
    parser.add_argument("kind", choices=SCHEMA_KINDS, help="which file format")
    parser.add_argument("--out", metavar="FILE", help="write the schema to FILE instead of standard output")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print or write the schema (through :class:`tpad_rt.files.NewFile`); raises TpadError if FILE cannot be
    written, or exists and is not a regular file (a FIFO would block the write until something read it)."""
    text = json.dumps(schema_json(args.kind), indent=2) + "\n"
    if args.out is None:
        sys.stdout.write(text)
        return 0
    with NewFile(args.out, "schemas") as new:
        new.file.write(text.encode("utf-8"))
    print(f"wrote the JSON Schema of {args.kind} files to {args.out} ({len(text.encode())} bytes)")
    return 0
