"""The kernel benchmark (bench/kernel/run.py) still runs against the package: its cases render, the real-time
driver's samples equal Pipeline.render's bit for bit, and its NumPy baseline renders the same path (a change to
the kernel's tables once broke the baseline unnoticed, since benchmarks are not run by the suite)."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import pytest

from tpad_rt.device import Device
from tpad_rt.pipeline import RenderOptions

RUN = Path(__file__).resolve().parents[1] / "bench" / "kernel" / "run.py"


@pytest.fixture(scope="module")
def bench():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("bench_kernel_run", RUN)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("kind", ["grating", "layers"])
def test_the_kernel_bench_cases_agree_and_its_numpy_baseline_renders(bench, kind: str) -> None:  # type: ignore[no-untyped-def]
    case = bench.Case(Device.default(), bench.ROOT / "textures" / bench.TEXTURES[kind], RenderOptions())
    checks = case.agreement(0.02)
    assert checks["driver_equals_pipeline"]
    assert checks["max_sample"] > 0.1  # the path drives the plate
    assert math.isfinite(checks["numpy_max_difference_over_max_sample"])
