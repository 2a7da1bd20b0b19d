"""Plate shapes: outlines for ``edges`` and regions for ``layers``.

A shape is written as a mapping with exactly one key naming it:
``{rect: {x_mm, y_mm, w_mm, h_mm}}``, ``{circle: {center_mm, radius_mm}}`` or
``{line: {from_mm, to_mm}}``.
"""

from __future__ import annotations

import math
from typing import ClassVar

from pydantic import model_validator

from tpad_rt.config.fields import MIN_LENGTH_MM, CoordinateMm, LengthMm, PointMm, StrictModel, rule_error


class Rect(StrictModel):
    """Axis-aligned rectangle; ``x_mm``, ``y_mm`` is its top-left corner."""

    x_mm: CoordinateMm
    y_mm: CoordinateMm
    w_mm: LengthMm
    h_mm: LengthMm


class Circle(StrictModel):
    """Circle (a disk when used as a region)."""

    center_mm: PointMm
    radius_mm: LengthMm


class Line(StrictModel):
    """Straight segment between two points: the same point (a dot), or at least MIN_LENGTH_MM apart."""

    from_mm: PointMm
    to_mm: PointMm

    @model_validator(mode="after")
    def _not_too_short(self) -> Line:
        length_mm = math.dist(self.from_mm, self.to_mm)
        if 0.0 < length_mm < MIN_LENGTH_MM:
            raise rule_error(
                f"must equal from_mm (a dot) or lie at least {MIN_LENGTH_MM:g} mm from it, got {length_mm:.3g} mm away",
                "to_mm",
            )
        return self


class _OneOf(StrictModel):
    """A mapping holding exactly one of its (optional) fields."""

    shape_keys: ClassVar[tuple[str, ...]]

    @model_validator(mode="after")
    def _exactly_one(self) -> _OneOf:
        given = [name for name in self.shape_keys if getattr(self, name) is not None]
        if len(given) != 1:
            got = " and ".join(given) or "none"
            raise rule_error(f"must hold exactly one of {', '.join(self.shape_keys)}; got {got}")
        return self

    @property
    def shape(self) -> Rect | Circle | Line:
        """The one shape given."""
        return next(getattr(self, name) for name in self.shape_keys if getattr(self, name) is not None)


class Region(_OneOf):
    """Where a layer applies: ``{rect: ...}`` or ``{circle: ...}``."""

    shape_keys = ("rect", "circle")
    rect: Rect | None = None
    circle: Circle | None = None


class Outline(_OneOf):
    """An outline for ``edges``: ``{rect: ...}``, ``{circle: ...}`` or ``{line: ...}``."""

    shape_keys = ("rect", "circle", "line")
    rect: Rect | None = None
    circle: Circle | None = None
    line: Line | None = None
