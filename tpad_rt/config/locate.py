"""Follow a pydantic error location through the model types.

Pydantic puts the tag of a discriminated union into error locations
(``('layers', 1, 'grating', 'period_mm')``). Walking the location alongside
the types tells tags from keys, so they can be dropped, and yields the type
expected at each step (for did-you-mean hints and lists of choices).
"""

from __future__ import annotations

import types
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Annotated, Any, Literal, Union, get_args, get_origin

from pydantic import BaseModel
from pydantic.fields import FieldInfo

from tpad_rt.config.breadcrumb import Location


@dataclass(frozen=True)
class Spot:
    """A type expected at some location; ``discriminator`` is set for a tagged union."""

    annotation: Any
    discriminator: str | None = None

    @property
    def model(self) -> type[BaseModel] | None:
        """The model expected here, if any."""
        annotation = self.annotation
        return annotation if isinstance(annotation, type) and issubclass(annotation, BaseModel) else None

    def tags(self) -> dict[str, type[BaseModel]]:
        """``{tag: model}`` of a tagged union, in declaration order; empty otherwise."""
        if self.discriminator is None:
            return {}
        return {_tag_of(model, self.discriminator): model for model in get_args(self.annotation)}

    def choices(self) -> list[Any]:
        """The values a Literal or a tagged union allows; empty otherwise."""
        if get_origin(self.annotation) is Literal:
            return list(get_args(self.annotation))
        return list(self.tags())

    def keys(self) -> list[str]:
        """The keys a model allows; empty if no model is expected here."""
        return list(self.model.model_fields) if self.model else []

    def fixed_length(self) -> int | None:
        """The item count of a fixed-length tuple such as ``[x, y]``."""
        args = get_args(self.annotation)
        if get_origin(self.annotation) is tuple and Ellipsis not in args:
            return len(args)
        return None


_UNKNOWN = Spot(None)


def locate(root: Any, loc: Sequence[str | int]) -> tuple[Location, list[Spot]]:
    """Drop union tags from ``loc``; also return the spot at each prefix of the result.

    ``spots[i]`` is the type expected at ``clean[:i]`` (so ``spots[-1]`` is at
    ``clean`` itself). Past a step the types cannot follow, spots are unknown.
    """
    clean: list[str | int] = []
    spots = [_spot(root)]
    for elem in loc:
        spot = spots[-1]
        tags = spot.tags()
        if isinstance(elem, str) and elem in tags:
            spots[-1] = Spot(tags[elem])
            continue
        clean.append(elem)
        spots.append(_step(spot, elem))
    return tuple(clean), spots


def _step(spot: Spot, elem: str | int) -> Spot:
    """The spot one key or index below ``spot``."""
    model = spot.model
    if model is not None:
        field = model.model_fields.get(elem) if isinstance(elem, str) else None
        return _field_spot(field) if field else _UNKNOWN
    origin, args = get_origin(spot.annotation), get_args(spot.annotation)
    if origin is list and isinstance(elem, int):
        return _spot(args[0])
    if origin is tuple and isinstance(elem, int) and args:
        return _spot(args[0] if Ellipsis in args else args[min(elem, len(args) - 1)])
    if origin is dict:
        return _spot(args[1])
    return _UNKNOWN


def _field_spot(field: FieldInfo) -> Spot:
    spot = _spot(field.annotation)
    return Spot(spot.annotation, field.discriminator) if isinstance(field.discriminator, str) else spot


def _spot(annotation: Any) -> Spot:
    """Unwrap ``Annotated`` and ``X | None`` down to the type that matters."""
    discriminator = None
    while True:
        if get_origin(annotation) is Annotated:
            annotation, *metadata = get_args(annotation)
            for item in metadata:
                if isinstance(item, FieldInfo) and isinstance(item.discriminator, str):
                    discriminator = item.discriminator
        elif get_origin(annotation) in (Union, types.UnionType) and type(None) in get_args(annotation):
            rest = [arg for arg in get_args(annotation) if arg is not type(None)]
            annotation = rest[0] if len(rest) == 1 else Union[tuple(rest)]
        else:
            return Spot(annotation, discriminator)


def _tag_of(model: type[BaseModel], discriminator: str) -> str:
    (tag,) = get_args(model.model_fields[discriminator].annotation)
    return tag
