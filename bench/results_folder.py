"""The ``--out`` folder of every bench script: checked before the run, never bench/results for a smoke run.

API map
-------
RESULTS
    bench/results, where measuring runs write their JSON and Markdown by default
folder(text) -> Path
    an argparse ``type``: the folder ``text`` names, made if missing; ArgumentTypeError (one line from
    argparse, exit 2) when it is a file or cannot be made or written, so a run never ends by losing its results
refuse_smoke_into_results(parser, smoke, out)
    ``parser.error`` when a smoke run (figures that mean nothing) would write into bench/results
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def folder(text: str) -> Path:
    """The folder ``text`` names, made if missing (argparse type); ArgumentTypeError when it is not one or not
    writable."""
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise argparse.ArgumentTypeError(f"cannot make the folder {text}: {err.strerror}") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"cannot write into {text}")
    return path


def refuse_smoke_into_results(parser: argparse.ArgumentParser, smoke: bool, out: Path) -> None:
    """Stop (``parser.error``) when a smoke run would write into bench/results: its figures mean nothing."""
    if smoke and out.resolve() == RESULTS:
        parser.error("--smoke figures mean nothing: give --out DIR, a folder other than bench/results")
