"""Building blocks shared by the texture and device schemas.

Numbers are strict (``"2.5"`` and ``true`` are not numbers) and finite; every
model is frozen and refuses unknown keys.
"""

from __future__ import annotations

from typing import Annotated

from annotated_types import Ge, Gt, Le, Lt, MinLen
from pydantic import BaseModel, ConfigDict, Strict
from pydantic_core import PydanticCustomError

#: Error type of the cross-field rules; ``ctx["key"]`` holds the sub-location they concern.
RULE_ERROR = "tpad_rule"


class StrictModel(BaseModel):
    """Base of every file model: frozen, unknown keys and NaN/infinities are errors."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, str_strip_whitespace=True)


Number = Annotated[float, Strict()]
Positive = Annotated[float, Strict(), Gt(0)]
NonNegative = Annotated[float, Strict(), Ge(0)]
#: Open interval (0, 1): duty cycles.
Fraction = Annotated[float, Strict(), Gt(0), Lt(1)]
#: Relative friction mu' in (0, 1].
FrictionLevel = Annotated[float, Strict(), Gt(0), Le(1)]
Text = Annotated[str, Strict(), MinLen(1)]
Flag = Annotated[bool, Strict()]
#: ``[x, y]`` in millimetres.
PointMm = tuple[Number, Number]
#: ``[width, height]`` in millimetres, each > 0.
SizeMm = tuple[Positive, Positive]


def rule_error(message: str, *key: str | int) -> PydanticCustomError:
    """An error for a rule across fields, located at ``key`` below the model raising it."""
    return PydanticCustomError(RULE_ERROR, message, {"key": key})
