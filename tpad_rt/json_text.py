"""JSON that every parser accepts: NaN and infinities written as null.

Python's ``json`` writes ``NaN`` and ``Infinity``, which JSON does not have (browsers,
Node, ``jq`` and strict parsers refuse or mangle them). JSON that may hold an
undetermined value (``serve``'s messages, ``calibrate`` and ``design``'s ``--json``)
goes through :func:`json_text`; recordings' metadata refuses non-finite values instead.

API map
-------
json_safe(value) -> value
    ``value`` with NaN and infinities as None and numpy scalars as Python numbers, recursively
json_text(value, indent=None) -> str
    ``json_safe(value)`` as JSON text
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np


def json_safe(value: Any) -> Any:
    """``value`` with NaN and infinities as None and numpy scalars as Python numbers, recursively."""
    if isinstance(value, dict):
        return {str(key): json_safe(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(item) for item in value]
    if isinstance(value, (np.integer, np.bool_)):
        return value.item()
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def json_text(value: Any, indent: int | None = None) -> str:
    """``value`` as JSON text, NaN and infinities as null (:func:`json_safe`)."""
    return json.dumps(json_safe(value), indent=indent, allow_nan=False)
