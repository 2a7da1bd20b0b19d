"""compile_texture / load_compiled: the arrays' form, the layers program, baked pixels, errors."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from test_texture_eval import EXAMPLES, GOOD, GOOD_TEXTURES, texture_model

from tpad_rt.config import load_texture
from tpad_rt.errors import ConfigError
from tpad_rt.kernel import layout
from tpad_rt.texture import CompiledTexture, compile_texture, load_compiled


@pytest.mark.parametrize("path", EXAMPLES + GOOD_TEXTURES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_arrays_are_read_only_contiguous_and_exactly_typed(path: Path) -> None:
    compiled = load_compiled(path)
    model = load_texture(path)
    assert (compiled.kind, compiled.description) == (model.kind, model.description)
    assert compiled.prog.dtype == np.int64 and compiled.prog.shape[1] == layout.TEX_PROG_COLS
    for array, dtype in ((compiled.prog, np.int64), (compiled.params, np.float64), (compiled.img, np.float64)):
        assert array.dtype == dtype and array.flags.c_contiguous and not array.flags.writeable
    assert np.all((compiled.img >= 0.0) & (compiled.img <= 1.0))
    assert compiled.stack_depth >= 1
    offsets = compiled.prog[:, 1]
    assert np.all((offsets >= 0) & (offsets <= compiled.params.size))


def test_compiled_texture_is_frozen() -> None:
    compiled = load_compiled(GOOD / "grating.yaml")
    with pytest.raises(dataclasses.FrozenInstanceError):
        compiled.stack_depth = 3  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        compiled.params[0] = 0.0


def test_layers_compile_to_push_one_then_each_layer_and_its_combine() -> None:
    compiled = load_compiled(GOOD.parent.parent / "textures" / "layers_nested.yaml")
    ops = compiled.prog[:, [0, 2, 3]].tolist()
    assert ops == [
        [layout.OP_PUSH_ONE, 0, 0],
        [layout.OP_PUSH_ONE, 0, 0],  # the nested layers texture: its own start value
        [layout.OP_GRATING, layout.WAVE_SINE, 0],
        [layout.OP_COMBINE, layout.COMBINE_REPLACE, layout.SHAPE_EVERYWHERE],
        [layout.OP_GRATING, layout.WAVE_SINE, 0],
        [layout.OP_COMBINE, layout.COMBINE_MULTIPLY, layout.SHAPE_EVERYWHERE],
        [layout.OP_COMBINE, layout.COMBINE_REPLACE, layout.SHAPE_RECT],
        [layout.OP_GRATING, layout.WAVE_TRIANGLE, 0],
        [layout.OP_COMBINE, layout.COMBINE_MIN, layout.SHAPE_RECT],
    ]
    assert compiled.stack_depth == 3
    first_region = compiled.params[compiled.prog[6, 1]:][:4]
    assert first_region.tolist() == [5.0, 5.0, 60.0, 55.0]


def test_invert_is_baked_into_the_pixels() -> None:
    model = load_texture(GOOD / "bitmap.yaml")
    assert model.invert
    assert np.array_equal(compile_texture(model).img, 1.0 - model.load_image_array().ravel())


def test_bumps_centres_are_sorted_by_x() -> None:
    model = texture_model({"description": "t", "kind": "bumps", "centers_mm": [[30, 1], [10, 2], [20, 3]],
                           "radius_mm": 1, "friction": {"inside": 0.5, "outside": 1.0}})
    compiled = compile_texture(model)
    assert compiled.prog[0, 3] == 3
    assert compiled.params[-6:].tolist() == [10.0, 20.0, 30.0, 2.0, 3.0, 1.0]


def test_evaluate_broadcasts() -> None:
    compiled = load_compiled(GOOD / "grating.yaml")
    x = np.linspace(0.0, 5.0, 6)[:, None]
    values = compiled.evaluate(x, np.zeros(4), 1.0, 0.0, 0.0)
    assert values.shape == (6, 4)
    assert np.array_equal(values, np.repeat(compiled.evaluate(x[:, 0], 0.0), 4).reshape(6, 4))


def test_load_compiled_reports_a_bad_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("description: x\nkind: grating\nperiod_mm: -2\nfriction: {low: 0.5, high: 1.0}\n")
    with pytest.raises(ConfigError, match=r"bad.yaml: period_mm: must be >= 0.01"):
        load_compiled(bad)


def test_a_hand_built_compiled_texture_gets_the_exact_form() -> None:
    compiled = CompiledTexture(prog=[[layout.OP_PUSH_ONE, 0, 0, 0]], params=[], img=[], stack_depth=1,
                               kind="layers", description="vibration off")
    assert compiled.prog.dtype == np.int64 and compiled.prog.shape == (1, layout.TEX_PROG_COLS)
    assert compiled.params.dtype == np.float64 and not compiled.img.flags.writeable
    assert compiled.evaluate(1.0, 2.0).item() == 1.0


def test_evaluate_passes_the_kernel_the_array_types_the_pipeline_does() -> None:
    """numba compiles the texture kernel once per array type: evaluate() must pass writable arrays, as the
    pipeline does, or a first run compiles the whole texture kernel twice (about 4 s). They are the memory
    behind the read-only public arrays."""
    import numba

    from tpad_rt.device import Device
    from tpad_rt.pipeline import Pipeline

    texture = load_compiled(EXAMPLES[0])
    arrays = Pipeline(Device.default(), texture).arrays
    for kernel_array, pipeline_array, public in zip(texture._kernel_arrays, (arrays.prog, arrays.params, arrays.img),
                                                    (texture.prog, texture.params, texture.img)):
        assert numba.typeof(kernel_array) == numba.typeof(pipeline_array)
        assert np.shares_memory(kernel_array, public) and not public.flags.writeable
