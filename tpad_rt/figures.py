"""Where tpad-rt's figures go: checked image names, matplotlib without a screen, one save path.

API map
-------
FORMATS
    the image suffixes accepted
figure_target(option, text) -> Path
    the image path an option names; ConfigError for another suffix, or an existing non-regular file
pyplot() -> matplotlib.pyplot
    pyplot on the Agg backend (no display needed), imported on first use
save(figure, out)
    write ``figure`` to ``out`` at 150 dpi, through tpad_rt.files.NewFile; BackendError when it cannot be written
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import Any

from tpad_rt.errors import ConfigError, printable
from tpad_rt.files import NewFile, check_writable_target

FORMATS = (".png", ".pdf", ".svg")


def figure_target(option: str, text: str) -> Path:
    """The image path ``option`` (``--out``) gives as ``text``; ConfigError unless it ends in one of FORMATS,
    or when it exists and is not a regular file."""
    out = Path(text)
    if out.suffix.lower() not in FORMATS:
        raise ConfigError(f"{option}: must end in {', '.join(FORMATS)}, got '{printable(text)}'")
    check_writable_target(out, "figures")
    return out


def pyplot() -> ModuleType:
    """matplotlib's pyplot on the Agg backend. Imported here, on first use: it costs every command that
    draws nothing about half a second."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    return plt


def save(figure: Any, out: Path) -> None:
    """Write ``figure`` to ``out`` (150 dpi, in the format its suffix names), complete or not at all
    (:class:`tpad_rt.files.NewFile`), and close it; ConfigError when ``out`` is no place to write,
    BackendError when the file cannot be written."""
    try:
        with NewFile(out, "figures") as new:
            figure.savefig(new.file, dpi=150, format=out.suffix[1:].lower())
    finally:
        pyplot().close(figure)
