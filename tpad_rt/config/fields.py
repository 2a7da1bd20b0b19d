"""Building blocks shared by the texture and device schemas.

Numbers are strict (``"2.5"`` and ``true`` are not numbers), finite and bounded
(docs/formats.md "Ranges, and why"); every model is frozen and refuses unknown keys.
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


#: Shortest plate length (mm) a texture may use (periods, radii, widths, sizes, spacings): far below
#: the ~0.5 mm a fingertip resolves, and it keeps reciprocals and pixel scales (px per mm) finite.
MIN_LENGTH_MM = 0.01
#: Longest plate length (mm) a texture may use: ten metres, ten times the largest plate.
MAX_LENGTH_MM = 10_000.0
#: Largest |coordinate| (mm) of a centre, corner or origin: ten metres from the plate's corner.
MAX_COORDINATE_MM = 10_000.0
#: Largest |angle| (degrees): ten turns either way.
MAX_ANGLE_DEG = 3600.0

#: Open interval (0, 1): duty cycles.
Fraction = Annotated[float, Strict(), Gt(0), Lt(1)]
#: Relative friction mu' in (0, 1].
FrictionLevel = Annotated[float, Strict(), Gt(0), Le(1)]
#: A length on the plate (mm) in [MIN_LENGTH_MM, MAX_LENGTH_MM].
LengthMm = Annotated[float, Strict(), Ge(MIN_LENGTH_MM), Le(MAX_LENGTH_MM)]
#: A plate coordinate (mm), |value| <= MAX_COORDINATE_MM.
CoordinateMm = Annotated[float, Strict(), Ge(-MAX_COORDINATE_MM), Le(MAX_COORDINATE_MM)]
#: An angle (degrees), |value| <= MAX_ANGLE_DEG.
AngleDeg = Annotated[float, Strict(), Ge(-MAX_ANGLE_DEG), Le(MAX_ANGLE_DEG)]
Text = Annotated[str, Strict(), MinLen(1)]
Flag = Annotated[bool, Strict()]
#: ``[x, y]`` in millimetres.
PointMm = tuple[CoordinateMm, CoordinateMm]
#: ``[width, height]`` in millimetres.
SizeMm = tuple[LengthMm, LengthMm]

def rule_error(message: str, *key: str | int) -> PydanticCustomError:
    """An error for a rule across fields, located at ``key`` below the model raising it."""
    return PydanticCustomError(RULE_ERROR, message, {"key": key})
