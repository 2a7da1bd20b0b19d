"""Texture files: one model per ``kind`` of docs/formats.md, and the ``TextureFile`` union.

Image paths are relative to the texture file: validate with
``context={BASE_DIR: <directory of the file>}`` (default: the working directory).
Images are checked when the file is validated; ``load_image_array()`` reads the
pixels for the renderer.
"""

from __future__ import annotations

import os
from contextvars import ContextVar
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, Union

from annotated_types import Ge, Gt, Le, MaxLen, MinLen
from pydantic import (
    AfterValidator,
    Field,
    PrivateAttr,
    Strict,
    ValidationInfo,
    ValidatorFunctionWrapHandler,
    field_validator,
    model_validator,
)

from tpad_rt.config.fields import (
    AngleDeg,
    Flag,
    Fraction,
    FrictionLevel,
    LengthMm,
    PointMm,
    SizeMm,
    StrictModel,
    Text,
    rule_error,
)
from tpad_rt.config.shapes import Outline, Region
from tpad_rt.errors import ConfigError

if TYPE_CHECKING:  # NumPy and the image reader load with the first image a texture names (check starts without)
    import numpy as np

#: Validation-context key: the directory relative image paths start from.
BASE_DIR = "base_dir"
#: Validation-context key: a one-item list counting the pixels of the images validated so far.
IMAGE_PIXELS = "image_pixels"
#: Validation-context key (optional): the folders images must lie in, resolved (``tpad-rt serve``'s clients).
IMAGE_DIRS = "image_dirs"
#: Most pixels all the images of one texture may hold (each reference counts: every one is loaded).
MAX_TEXTURE_PIXELS = 4096 * 4096
MAX_LAYERS = 16
MAX_LAYER_DEPTH = 4

#: Largest |gradient gain| (friction change per unit slope): a slope of 0.001 then already spans
#: the whole friction range; more is a step, not a gradient.
MAX_GAIN = 1000.0
#: Largest |height| (mm) of a gradient's height map: far above any bump a finger feels.
MAX_HEIGHT_MM = 100.0
#: Slowest and fastest temporal texture (Hz): one cycle in 100 s; above ~1 kHz skin feels no change.
MIN_FREQUENCY_HZ = 0.01
MAX_FREQUENCY_HZ = 1000.0

#: Slowest and fastest finger (mm/s) a texture may be designed for: a crawl (below the ~5 mm/s at which a
#: device's friction model stops following speed) to a fast flick.
MIN_FINGER_SPEED_MM_S = 1.0
MAX_FINGER_SPEED_MM_S = 1000.0
#: Hardest press (N) a texture may be designed for: a pressing finger stays under 10 N.
MAX_FINGER_FORCE_N = 10.0

Gain = Annotated[float, Strict(), Ge(-MAX_GAIN), Le(MAX_GAIN)]
HeightMm = Annotated[float, Strict(), Ge(-MAX_HEIGHT_MM), Le(MAX_HEIGHT_MM)]
Waveform = Literal["sine", "square", "triangle", "sawtooth"]
Wrap = Literal["tile", "clamp"]

_layers_depth: ContextVar[int] = ContextVar("tpad_rt_layers_depth", default=0)


def _usable_image(value: Path, info: ValidationInfo) -> Path:
    """The absolute path of a readable image, relative paths taken from ``context[BASE_DIR]``.

    Counts its pixels in ``context[IMAGE_PIXELS]`` (a one-item list) when the context has
    it: every image a texture names is held in memory once rendered, so all of them
    together may have at most MAX_TEXTURE_PIXELS pixels. With ``context[IMAGE_DIRS]`` an
    image (links resolved) outside those folders is refused before it is opened.
    """
    from tpad_rt.config.images import ImageError, read_image

    context = info.context or {}
    path = Path(context.get(BASE_DIR, ".")) / value
    allowed: list[Path] | None = context.get(IMAGE_DIRS)
    if allowed is not None and not any(Path(os.path.realpath(path)).is_relative_to(folder) for folder in allowed):
        raise rule_error(f"the image {str(value)!r} lies outside the folders this server reads textures from")
    try:
        pixels = read_image(path).size
    except ImageError as err:
        raise rule_error(str(err)) from None
    counted = context.get(IMAGE_PIXELS)
    if counted is not None:
        counted[0] += pixels
        if counted[0] > MAX_TEXTURE_PIXELS:
            raise rule_error(f"the texture's images hold {counted[0]:,} pixels with this one, more than the "
                             f"{MAX_TEXTURE_PIXELS:,} a texture may hold in all (one 4096 x 4096 image)")
    return path.absolute()


ImageFile = Annotated[Path, AfterValidator(_usable_image)]


# --- friction levels -------------------------------------------------------


class FrictionRange(StrictModel):
    """``{low, high}`` with ``0 < low <= high <= 1``."""

    low: FrictionLevel
    high: FrictionLevel

    @model_validator(mode="after")
    def _ordered(self) -> FrictionRange:
        if self.low > self.high:
            raise rule_error(f"must be <= high ({self.high:g}), got {self.low:g}", "low")
        return self


class FrictionAroundBase(FrictionRange):
    """``{base, low, high}`` with ``0 < low <= base <= high <= 1``."""

    base: FrictionLevel

    @model_validator(mode="after")
    def _base_inside(self) -> FrictionAroundBase:
        if self.low <= self.high and not self.low <= self.base <= self.high:
            raise rule_error(f"must be between low ({self.low:g}) and high ({self.high:g}), got {self.base:g}", "base")
        return self


class BumpFriction(StrictModel):
    """Friction at a bump's centre and away from bumps."""

    inside: FrictionLevel
    outside: FrictionLevel


class EdgeFriction(StrictModel):
    """Friction on an outline's band and elsewhere."""

    edge: FrictionLevel
    background: FrictionLevel


# --- shared parts of kinds ---------------------------------------------------


class Finger(StrictModel):
    """The finger a texture is designed for: its stroke speed (mm/s) and contact force (N), what ``tpad-rt play``
    swipes with when it picks the input."""

    speed_mm_s: Annotated[float, Strict(), Ge(MIN_FINGER_SPEED_MM_S), Le(MAX_FINGER_SPEED_MM_S)]
    force_n: Annotated[float, Strict(), Gt(0), Le(MAX_FINGER_FORCE_N)]


class _Texture(StrictModel):
    description: Text
    finger: Finger | None = None


class _Periodic(_Texture):
    """A waveform repeating in space or time; ``duty`` only for square and triangle."""

    waveform: Waveform = "sine"
    duty: Fraction = 0.5

    @model_validator(mode="after")
    def _duty_needs_shape(self) -> _Periodic:
        if "duty" in self.model_fields_set and self.waveform in ("sine", "sawtooth"):
            raise rule_error(f"not allowed with waveform '{self.waveform}' (only square and triangle)", "duty")
        return self


class _ImageMap(StrictModel):
    """A greyscale image laid on the plate."""

    image: ImageFile
    size_mm: SizeMm
    origin_mm: PointMm = (0.0, 0.0)
    wrap: Wrap = "tile"
    _pixels: np.ndarray | None = PrivateAttr(default=None)

    def load_image_array(self) -> np.ndarray:
        """The image as a read-only float64 array in [0, 1], row 0 at the top; read once.

        Raises ConfigError if the file is no longer usable (changed since validation).
        """
        if self._pixels is None:
            from tpad_rt.config.images import ImageError, read_image

            try:
                self._pixels = read_image(self.image)
            except ImageError as err:
                raise ConfigError(str(err)) from None
        return self._pixels


# --- gradient height maps ----------------------------------------------------


class BumpHeight(StrictModel):
    """Raised-cosine bump."""

    shape: Literal["bump"]
    center_mm: PointMm
    radius_mm: LengthMm
    height_mm: HeightMm


class RidgeHeight(StrictModel):
    """Infinite raised-cosine ridge through ``center_mm`` running along ``angle_deg``."""

    shape: Literal["ridge"]
    center_mm: PointMm
    angle_deg: AngleDeg = 0.0
    width_mm: LengthMm
    height_mm: HeightMm


class SineHeight(StrictModel):
    """Sinusoidal corrugation varying along ``angle_deg``."""

    shape: Literal["sine"]
    period_mm: LengthMm
    angle_deg: AngleDeg = 0.0
    height_mm: HeightMm


class ImageHeight(_ImageMap):
    """Greyscale height map; value 1 is ``height_mm`` high."""

    shape: Literal["image"]
    height_mm: HeightMm


HeightMap = Annotated[Union[BumpHeight, RidgeHeight, SineHeight, ImageHeight], Field(discriminator="shape")]


# --- kinds -------------------------------------------------------------------


class Grating(_Periodic):
    """Periodic bars."""

    kind: Literal["grating"]
    period_mm: LengthMm
    angle_deg: AngleDeg = 0.0
    phase_deg: AngleDeg = 0.0
    friction: FrictionRange


class Bitmap(_ImageMap, _Texture):
    """Friction map from an image or array (value 0: ``low``, 1: ``high``)."""

    kind: Literal["bitmap"]
    invert: Flag = False
    friction: FrictionRange


class Gradient(_Texture):
    """Virtual bumps: friction ``base + gain * slope`` of a height map, clamped to [low, high]."""

    kind: Literal["gradient"]
    height: HeightMap
    gain: Gain = 2.0
    friction: FrictionAroundBase


class BumpGrid(StrictModel):
    """An infinite grid of bump centres."""

    spacing_mm: SizeMm
    offset_mm: PointMm = (0.0, 0.0)


class Bumps(_Texture):
    """Round patches at ``centers_mm`` or on a ``grid`` (exactly one of the two)."""

    kind: Literal["bumps"]
    centers_mm: Annotated[list[PointMm], MinLen(1)] | None = None
    grid: BumpGrid | None = None
    radius_mm: LengthMm
    profile: Literal["cosine", "gaussian", "disk"] = "cosine"
    friction: BumpFriction

    @model_validator(mode="after")
    def _one_placement(self) -> Bumps:
        if self.centers_mm is None and self.grid is None:
            raise rule_error("one of centers_mm and grid is required")
        if self.centers_mm is not None and self.grid is not None:
            raise rule_error("not allowed together with centers_mm (give one of them)", "grid")
        return self


class Edges(_Texture):
    """Bands along the outlines of shapes."""

    kind: Literal["edges"]
    shapes: Annotated[list[Outline], MinLen(1)]
    width_mm: LengthMm = 1.0
    profile: Literal["step", "cosine"] = "step"
    friction: EdgeFriction


class Temporal(_Periodic):
    """Friction changing with time wherever the finger slides."""

    kind: Literal["temporal"]
    waveform: Waveform = "square"
    frequency_hz: Annotated[float, Strict(), Ge(MIN_FREQUENCY_HZ), Le(MAX_FREQUENCY_HZ)]
    friction: FrictionRange


class Layers(_Texture):
    """Composition of 1 to 16 textures, nested at most 4 levels deep."""

    kind: Literal["layers"]
    layers: Annotated[list[Layer], MinLen(1), MaxLen(MAX_LAYERS)]

    @field_validator("layers", mode="wrap")
    @classmethod
    def _limit_nesting(cls, value: Any, handler: ValidatorFunctionWrapHandler) -> Any:
        depth = _layers_depth.get() + 1
        if depth > MAX_LAYER_DEPTH:
            raise rule_error(f"layers nest at most {MAX_LAYER_DEPTH} levels deep")
        token = _layers_depth.set(depth)
        try:
            return handler(value)
        finally:
            _layers_depth.reset(token)


TextureFile = Annotated[
    Union[Grating, Bitmap, Gradient, Bumps, Edges, Temporal, Layers], Field(discriminator="kind")
]


# --- layers: every kind, with an optional description, op and region ---------


# A layer's description is optional where a file's is required: each Layer class lists _LayerFields
# first, so pydantic (and Python's MRO) take its Optional field; mypy flags the two bases' types
# differing (misc), which is the point.
class _LayerFields(StrictModel):
    description: Text | None = None
    op: Literal["multiply", "min", "max", "add"] = "multiply"
    region: Region | None = None

    @model_validator(mode="after")
    def _finger_at_top(self) -> _LayerFields:
        if "finger" in self.model_fields_set:
            raise rule_error("not allowed in a layer (the file's top level states the finger it is designed for)",
                             "finger")
        return self


class GratingLayer(_LayerFields, Grating):  # type: ignore[misc]
    """A grating used as a layer."""


class BitmapLayer(_LayerFields, Bitmap):  # type: ignore[misc]
    """A bitmap used as a layer."""


class GradientLayer(_LayerFields, Gradient):  # type: ignore[misc]
    """A gradient used as a layer."""


class BumpsLayer(_LayerFields, Bumps):  # type: ignore[misc]
    """Bumps used as a layer."""


class EdgesLayer(_LayerFields, Edges):  # type: ignore[misc]
    """Edges used as a layer."""


class TemporalLayer(_LayerFields, Temporal):  # type: ignore[misc]
    """A temporal texture used as a layer."""


class LayersLayer(_LayerFields, Layers):  # type: ignore[misc]
    """A nested composition used as a layer."""


Layer = Annotated[
    Union[GratingLayer, BitmapLayer, GradientLayer, BumpsLayer, EdgesLayer, TemporalLayer, LayersLayer],
    Field(discriminator="kind"),
]

Layers.model_rebuild()
LayersLayer.model_rebuild()
