"""Minimal good files of every texture kind and a device file load into the right models."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tpad_rt.config import (
    Bitmap,
    Bumps,
    DeviceFile,
    Edges,
    Gradient,
    Grating,
    Layers,
    Temporal,
    check_file,
    load_any,
    load_device,
    load_texture,
)
from tpad_rt.config.shapes import Circle, Line, Rect
from tpad_rt.config.texture_schema import ImageHeight, LayersLayer, TemporalLayer
from tpad_rt.errors import ConfigError

GOOD_FILES = Path(__file__).parent / "good_files"


@pytest.mark.parametrize(
    ("name", "model"),
    [
        ("grating", Grating),
        ("bitmap", Bitmap),
        ("bitmap_npy", Bitmap),
        ("gradient_bump", Gradient),
        ("gradient_image", Gradient),
        ("bumps_centers", Bumps),
        ("bumps_grid", Bumps),
        ("edges", Edges),
        ("temporal", Temporal),
        ("layers", Layers),
    ],
)
def test_texture_kind_loads_into_its_model(name: str, model: type) -> None:
    path = GOOD_FILES / f"{name}.yaml"
    texture = load_texture(path)
    assert type(texture) is model
    assert load_any(path) == texture
    assert check_file(path) == []


def test_every_kind_has_a_good_file() -> None:
    kinds = {load_texture(path).kind for path in GOOD_FILES.glob("*.yaml") if path.stem != "device"}
    assert kinds == {"grating", "bitmap", "gradient", "bumps", "edges", "temporal", "layers"}


def test_grating_defaults() -> None:
    grating = load_texture(GOOD_FILES / "grating.yaml")
    assert (grating.waveform, grating.angle_deg, grating.phase_deg, grating.duty) == ("sine", 0.0, 0.0, 0.5)
    assert (grating.period_mm, grating.friction.low, grating.friction.high) == (2.5, 0.6, 1.0)


def test_temporal_defaults_to_square() -> None:
    assert Temporal.model_fields["waveform"].default == "square"
    assert load_texture(GOOD_FILES / "temporal.yaml").duty == 0.3


def test_bitmap_fields_and_pixels() -> None:
    bitmap = load_texture(GOOD_FILES / "bitmap.yaml")
    assert (bitmap.size_mm, bitmap.origin_mm, bitmap.wrap, bitmap.invert) == ((40.0, 30.0), (10.0, 5.0), "clamp", True)
    assert bitmap.image == (GOOD_FILES / "checker.png").absolute()
    pixels = bitmap.load_image_array()
    assert pixels.dtype == np.float64 and pixels.shape == (3, 4)
    np.testing.assert_array_equal(pixels[0], [0, 1, 0, 1])
    assert bitmap.load_image_array() is pixels
    assert not pixels.flags.writeable


def test_npy_pixels_match_the_array() -> None:
    bitmap = load_texture(GOOD_FILES / "bitmap_npy.yaml")
    np.testing.assert_array_equal(bitmap.load_image_array(), np.load(GOOD_FILES / "ramp.npy"))
    assert (bitmap.origin_mm, bitmap.wrap, bitmap.invert) == ((0.0, 0.0), "tile", False)


def test_gradient_height_shapes() -> None:
    bump = load_texture(GOOD_FILES / "gradient_bump.yaml")
    assert bump.height.shape == "bump" and bump.gain == 2.0
    assert (bump.friction.base, bump.friction.low, bump.friction.high) == (0.7, 0.4, 1.0)
    image = load_texture(GOOD_FILES / "gradient_image.yaml")
    assert isinstance(image.height, ImageHeight) and image.gain == 3.0
    assert image.height.load_image_array().shape == (3, 4)


def test_bumps_placements() -> None:
    centers = load_texture(GOOD_FILES / "bumps_centers.yaml")
    assert centers.centers_mm == [(10.0, 10.0), (20.0, 10.0), (30.0, 10.0)] and centers.grid is None
    grid = load_texture(GOOD_FILES / "bumps_grid.yaml")
    assert grid.centers_mm is None and grid.grid.spacing_mm == (5.0, 5.0) and grid.grid.offset_mm == (0.0, 0.0)
    assert grid.profile == "gaussian"


def test_edges_shapes() -> None:
    edges = load_texture(GOOD_FILES / "edges.yaml")
    assert [type(outline.shape) for outline in edges.shapes] == [Rect, Circle, Line]
    assert edges.width_mm == 1.0 and edges.profile == "cosine"


def test_layers_nest_four_levels_with_op_and_region() -> None:
    layers = load_texture(GOOD_FILES / "layers.yaml")
    first, second = layers.layers
    assert isinstance(first, Grating) and first.op == "multiply" and first.description is None
    assert isinstance(first.region.shape, Circle)
    assert isinstance(second, LayersLayer) and second.op == "min" and isinstance(second.region.shape, Rect)
    innermost = second.layers[0].layers[0]
    assert innermost.description == "innermost"
    assert isinstance(innermost.layers[0], TemporalLayer)


def test_device_file() -> None:
    device = load_device(GOOD_FILES / "device.yaml")
    assert isinstance(device, DeviceFile) and load_any(GOOD_FILES / "device.yaml") == device
    assert device.label == "SLG_0.56" and device.plate.mode == (20, 0)
    assert device.format_version == 2 and device.carrier_hz == 28000.0
    assert device.circuit.force_n == [0.0, 1.0, 2.0] and device.circuit.gamma_n_per_v == 0.125
    assert device.circuit.motional_r_ohm == [800.0, 1500.0, 2150.0]
    assert device.amplifier.max_voltage_v == 80.0
    defaults = (device.friction_model.mu0, device.friction_model.poisson, device.friction_model.psi_star)
    assert defaults == (0.25, 0.33, 4.69)
    assert device.speed_floor_mm_s == 5.0 and device.preemphasis is True
    assert set(device.source) == {"circuit"}


def test_models_are_frozen() -> None:
    grating = load_texture(GOOD_FILES / "grating.yaml")
    with pytest.raises(Exception, match="frozen"):
        grating.period_mm = 3.0


def test_texture_loaded_as_device_is_an_error() -> None:
    with pytest.raises(ConfigError) as caught:
        load_device(GOOD_FILES / "grating.yaml")
    assert caught.value.errors == [f"{GOOD_FILES / 'grating.yaml'}: a texture file (it has 'kind'), not a device file "
                                   "(which has format_version and a circuit)"]


def test_image_changed_after_loading_is_a_config_error(tmp_path: Path) -> None:
    np.save(tmp_path / "map.npy", np.zeros((2, 2)))
    path = tmp_path / "t.yaml"
    path.write_text("description: d\nkind: bitmap\nimage: map.npy\nsize_mm: [1, 1]\nfriction: {low: 0.5, high: 1}\n")
    bitmap = load_texture(path)
    (tmp_path / "map.npy").unlink()
    with pytest.raises(ConfigError, match="no such file"):
        bitmap.load_image_array()
