"""Render-pipeline throughput: ns per output sample by block size and texture kind.

    python bench/kernel/run.py            # full run: writes bench/results/kernel.{json,md}
    python bench/kernel/run.py --quick    # a short run (same outputs, rougher figures)
    python bench/kernel/run.py --smoke --out DIR  # seconds: every section once at one block (figures meaningless)

Three implementations render the same finger path (a sweep across the plate, 1 kHz
samples, 40-115 mm/s, force 0.3-1.3 N) with the same texture, in the same run:

- ``kernel``: ``render_block`` called the way the real-time engine calls it, from a
  numba ``@cfunc`` on raw pointers (bench/kernel/realtime_driver.py): the kernel's cost.
- ``Pipeline.render``: called from Python per block (the offline ``tpad-rt render``
  path): the kernel plus numba's unboxing of 14 arguments per call.
- ``numpy``: the same pipeline in vectorised NumPy (bench/kernel/numpy_pipeline.py).

Each figure is the median (with p10 and p90) over repeated runs, each a fresh stream, in
ns per output sample; ``x real time`` is the 192 kHz sample period over the kernel's
median. The run checks that the driver's samples equal ``Pipeline.render``'s bit for
bit and records how far the NumPy samples are from them.

Today's kernel against an earlier revision's, in paired alternating runs that also compare
their samples: bench/kernel/compare.py. Nothing here is a pass/fail threshold
(docs/realtime.md "Measuring").
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numba
import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "bench"))  # results_folder: the --out checks every bench script shares
import results_folder  # noqa: E402
sys.path[:0] = [str(HERE), str(ROOT / "tests")]  # the siblings; the NumPy texture reference

from numpy_pipeline import NumpyPipeline  # noqa: E402
from realtime_driver import RENDER_STREAM, render_stream  # noqa: E402

from tpad_rt.config import load_texture  # noqa: E402
from tpad_rt.device import Device  # noqa: E402
from tpad_rt.inputs import open_input  # noqa: E402
from tpad_rt.offline import OfflineRender  # noqa: E402
from tpad_rt.outputs.sim import SimOutput  # noqa: E402
from tpad_rt.pipeline import Pipeline, RenderOptions  # noqa: E402
from tpad_rt.realtime import CallbackTable  # noqa: E402
from tpad_rt.texture import compile_texture  # noqa: E402

FS_HZ = 192000
BLOCKS = (16, 32, 64, 128, 256, 1024, 4096)
#: One shipped texture per kind.
TEXTURES = {
    "grating": "grating.yaml",
    "bitmap": "bitmap_logo.yaml",
    "gradient": "gradient_bump.yaml",
    "bumps": "bumps_grid.yaml",
    "edges": "edges_buttons.yaml",
    "temporal": "temporal_pulse.yaml",
    "layers": "layers_window.yaml",
}
#: The offline section: ``tpad-rt render textures/grating.yaml --input OFFLINE_INPUT`` (sim://) at these blocks.
OFFLINE_INPUT = "scripted://swipe?speed_mm_s=100&repeat=3&back_and_forth=1"
OFFLINE_BLOCKS = (16, 64, 256, 1024)
#: Control intervals compared for the grating (kernel only).
INTERVALS = (16, 32, 64, 128)
Run = Callable[[], int]


@dataclass(frozen=True)
class Plan:
    """Seconds of audio per run and runs per figure, for each implementation; the block sizes measured
    (``blocks``; ``offline_blocks`` for the offline section) and the control intervals swept (at
    ``sweep_blocks``)."""

    kernel_s: float
    kernel_runs: int
    pipeline_s: float
    pipeline_runs: int
    numpy_s: float
    numpy_runs: int
    agreement_s: float
    offline_runs: int
    blocks: tuple[int, ...] = BLOCKS
    offline_blocks: tuple[int, ...] = OFFLINE_BLOCKS
    intervals: tuple[int, ...] = INTERVALS
    sweep_blocks: tuple[int, ...] = (64, 4096)


FULL = Plan(kernel_s=10.0, kernel_runs=31, pipeline_s=2.0, pipeline_runs=11, numpy_s=0.25, numpy_runs=5, agreement_s=1.0,
            offline_runs=21)
QUICK = Plan(kernel_s=0.25, kernel_runs=5, pipeline_s=0.1, pipeline_runs=3, numpy_s=0.03, numpy_runs=2,
             agreement_s=0.1, offline_runs=3)
#: The test suite's smoke run (tests/test_bench_smoke.py): every section once, at one block size.
SMOKE = Plan(kernel_s=0.01, kernel_runs=1, pipeline_s=0.01, pipeline_runs=1, numpy_s=0.005, numpy_runs=1,
             agreement_s=0.01, offline_runs=1, blocks=(64,), offline_blocks=(64,), intervals=(32,), sweep_blocks=(64,))


def finger_path(duration_s: float) -> np.ndarray:
    """Rows ``(t_s, x_mm, y_mm, force_n, down)`` at 1 kHz: from the plate centre, a sweep over x 10-120, y 15-45 mm."""
    t = np.arange(0.0, duration_s + 0.01, 0.001)
    x = 65.0 + 55.0 * np.sin(2 * np.pi * 0.4 * t)
    y = 30.0 + 15.0 * np.sin(2 * np.pi * 0.25 * t)
    force = 0.8 - 0.5 * np.cos(2 * np.pi * 0.7 * t)
    return np.column_stack([t, x, y, force, np.ones_like(t)])


def ns_per_sample(prepare: Callable[[], Run], runs: int) -> dict[str, float]:
    """Median, p10 and p90 of ns per sample over ``runs`` runs, each prepared (untimed) by ``prepare``."""
    results = []
    for _ in range(runs):
        run = prepare()
        start = time.perf_counter()
        samples = run()
        results.append((time.perf_counter() - start) * 1e9 / samples)
    return {
        "median": statistics.median(results),
        "p10": float(np.percentile(results, 10)),
        "p90": float(np.percentile(results, 90)),
        "runs": runs,
    }


class Case:
    """One texture with options: fresh streams of each implementation, on demand."""

    def __init__(self, device: Device, path: Path, options: RenderOptions):
        self.device, self.options = device, options
        self.model = load_texture(path)
        self.compiled = compile_texture(self.model)

    def _pipeline(self) -> Pipeline:
        pipeline = Pipeline(self.device, self.compiled, fs_hz=FS_HZ, options=self.options)
        pipeline.start()
        return pipeline

    def kernel(self, block: int, seconds: float, out: np.ndarray | None = None, driver: object = RENDER_STREAM) -> Run:
        """A fresh stream through the @cfunc ``driver`` (``out``: keep every sample there)."""
        table = CallbackTable(self._pipeline().arrays, self.compiled)
        path = finger_path(seconds)
        blocks = round(seconds * FS_HZ / block)
        buffer = np.zeros(block, dtype=np.float32) if out is None else out
        return lambda: render_stream(table, path, block, blocks, buffer, driver)

    def python_calls(self, block: int, seconds: float, out: np.ndarray | None = None) -> Run:
        """A fresh stream through Pipeline.render, finger samples pushed as the offline loop does."""
        pipeline = self._pipeline()
        path = finger_path(seconds)
        blocks = round(seconds * FS_HZ / block)
        buffer = np.zeros(blocks * block, dtype=np.float32) if out is None else out

        def run() -> int:
            pushed = 0
            for index in range(blocks):
                end_s = (index + 1) * block / FS_HZ
                while pushed < len(path) and path[pushed, 0] <= end_s:
                    t_s, x_mm, y_mm, force_n, _ = path[pushed]
                    pipeline.push_finger(t_s, x_mm, y_mm, force_n)
                    pushed += 1
                pipeline.render(buffer[index * block : (index + 1) * block])
            return blocks * block

        return run

    def numpy(self, block: int, seconds: float, out: np.ndarray | None = None) -> Run:
        """A fresh stream through the NumPy pipeline (the whole path pushed upfront)."""
        stream = NumpyPipeline(self.device, self.model, FS_HZ, self.options)
        stream.start()
        stream.push_fingers(finger_path(seconds))
        blocks = round(seconds * FS_HZ / block)
        buffer = np.zeros(blocks * block, dtype=np.float32) if out is None else out

        def run() -> int:
            for index in range(blocks):
                stream.render(buffer[index * block : (index + 1) * block])
            return blocks * block

        return run

    def offline(self, block: int) -> Run:
        """A fresh ``tpad-rt render`` loop (OfflineRender into sim://) over OFFLINE_INPUT, warmed up untimed."""
        source = open_input(OFFLINE_INPUT)
        pipeline = Pipeline(self.device, self.compiled, fs_hz=FS_HZ, options=self.options)
        tail_s = self.options.ramp_ms * 1e-3 + (self.options.control_interval + block) / FS_HZ
        render = OfflineRender(pipeline, source, [SimOutput(self.device, FS_HZ)], block_frames=block,
                               input_s=float(source.duration_s or 0.0), tail_s=tail_s)
        render.warm_up()

        def run() -> int:
            while not render.done:
                render.step()
            source.close()
            return render.blocks_done * block

        return run

    def agreement(self, seconds: float, block: int = 64) -> dict[str, float | bool]:
        """Driver samples == Pipeline.render's (bit for bit); NumPy's largest difference over the largest sample."""
        total = round(seconds * FS_HZ / block) * block
        samples = {name: np.zeros(total, dtype=np.float32) for name in ("kernel", "pipeline", "numpy")}
        for name, make in (("kernel", self.kernel), ("pipeline", self.python_calls), ("numpy", self.numpy)):
            make(block, seconds, samples[name])()
        scale = max(float(np.abs(samples["pipeline"]).max()), float(np.finfo(np.float32).tiny))  # JSON: a float
        return {
            "driver_equals_pipeline": bool(np.array_equal(samples["kernel"], samples["pipeline"])),
            "numpy_max_difference_over_max_sample": float(np.abs(samples["numpy"] - samples["pipeline"]).max()) / scale,
            "max_sample": scale,
        }


def measure(plan: Plan, log: Callable[[str], None]) -> dict[str, object]:
    """Every figure of the benchmark (see the module docstring)."""
    device = Device.default()
    rows = []
    for kind, file_name in TEXTURES.items():
        case = Case(device, ROOT / "textures" / file_name, RenderOptions())
        assert case.model.kind == kind, f"{file_name} is a {case.model.kind} texture"
        checks = case.agreement(plan.agreement_s)
        for block in plan.blocks:
            kernel = ns_per_sample(lambda: case.kernel(block, plan.kernel_s), plan.kernel_runs)
            pipeline = ns_per_sample(lambda: case.python_calls(block, plan.pipeline_s), plan.pipeline_runs)
            numpy = ns_per_sample(lambda: case.numpy(block, plan.numpy_s), plan.numpy_runs)
            rows.append({
                "kind": kind, "texture": file_name, "block": block, **checks,
                "kernel_ns_per_sample": kernel, "pipeline_ns_per_sample": pipeline, "numpy_ns_per_sample": numpy,
                "numpy_over_kernel": numpy["median"] / kernel["median"],
                "x_real_time": 1e9 / FS_HZ / kernel["median"],
            })
            log(f"{kind:9s} block {block:5d}: kernel {kernel['median']:6.2f} ns/sample, "
                f"Pipeline.render {pipeline['median']:7.1f}, numpy {numpy['median']:8.0f}")
    offline = measure_offline(plan, log)
    sweep = []
    for interval in plan.intervals:
        case = Case(device, ROOT / "textures" / TEXTURES["grating"], RenderOptions(control_interval=interval))
        for block in plan.sweep_blocks:
            kernel = ns_per_sample(lambda: case.kernel(block, plan.kernel_s), plan.kernel_runs)
            sweep.append({"control_interval": interval, "block": block, "kernel_ns_per_sample": kernel})
            log(f"grating, control_interval {interval:3d}, block {block:4d}: kernel {kernel['median']:6.2f} ns/sample")
    return {"rows": rows, "offline": offline, "control_interval_sweep": sweep}


def measure_offline(plan: Plan, log: Callable[[str], None]) -> list[dict[str, object]]:
    """The offline section: OfflineRender into sim:// against the kernel's @cfunc path, grating, per block."""
    device = Device.default()
    offline: list[dict[str, object]] = []
    grating = Case(device, ROOT / "textures" / TEXTURES["grating"], RenderOptions())
    for block in plan.offline_blocks:
        kernel = ns_per_sample(lambda: grating.kernel(block, plan.kernel_s), plan.kernel_runs)
        whole = ns_per_sample(lambda: grating.offline(block), plan.offline_runs)
        offline.append({"block": block, "kernel_ns_per_sample": kernel, "offline_ns_per_sample": whole,
                        "offline_over_kernel": whole["median"] / kernel["median"],
                        "offline_x_real_time": 1e9 / FS_HZ / whole["median"]})
        log(f"offline render, block {block:4d}: {whole['median']:6.2f} ns/sample "
            f"({1e9 / FS_HZ / whole['median']:.0f}x real time), kernel {kernel['median']:6.2f}")
    return offline


def machine() -> dict[str, object]:
    """Where the figures were measured."""
    cpuinfo = Path("/proc/cpuinfo")
    names = [line.split(":", 1)[1].strip() for line in cpuinfo.read_text().splitlines()
             if line.startswith("model name")] if cpuinfo.exists() else []
    cpu = names[0] if names else platform.processor()
    return {
        "cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "numba": numba.__version__,
        "numpy": np.__version__, "platform": platform.platform(),
        "load_average_at_start": os.getloadavg() if hasattr(os, "getloadavg") else None,
    }


def markdown(report: dict[str, object]) -> str:
    """The report as Markdown tables."""
    flag = " --smoke" if report.get("smoke") else " --quick" if report["quick"] else ""

    def band(figure: dict[str, float], digits: int) -> str:
        return f"{figure['median']:.{digits}f} ({figure['p10']:.{digits}f}-{figure['p90']:.{digits}f})"

    lines = [
        "# Render pipeline throughput",
        "",
        f"Generated by `python bench/kernel/run.py{flag}`; "
        f"fs = {FS_HZ} Hz, default RenderOptions (control_interval 32); "
        f"{report['machine']['cpu']}, {report['machine']['cores']} cores, numba {report['machine']['numba']}.",
        "ns per output sample: median (p10-p90) over fresh runs. kernel: `render_block` from a `@cfunc` "
        "(the real-time path); Pipeline.render: called from Python per block; numpy: the same pipeline in "
        "vectorised NumPy. x RT: real-time factor of the kernel at 192 kHz.",
        "",
        "| kind | block | kernel ns/sample | x RT | Pipeline.render ns/sample | numpy ns/sample | numpy / kernel |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for row in report["rows"]:
        lines.append(
            f"| {row['kind']} | {row['block']} | {band(row['kernel_ns_per_sample'], 2)} | {row['x_real_time']:.0f} "
            f"| {band(row['pipeline_ns_per_sample'], 1)} | {band(row['numpy_ns_per_sample'], 0)} "
            f"| {row['numpy_over_kernel']:.0f} |"
        )
    lines += ["", f"Offline render (`tpad-rt render textures/grating.yaml --input \"{OFFLINE_INPUT}\"`, sim://: "
              "OfflineRender's step loop, the plate simulated, telemetry kept) next to the kernel above in the "
              "same run:", "",
              "| block | offline ns/sample | x RT | kernel ns/sample | offline / kernel |",
              "| ---: | ---: | ---: | ---: | ---: |"]
    for row in report.get("offline", []):
        lines.append(f"| {row['block']} | {band(row['offline_ns_per_sample'], 2)} | {row['offline_x_real_time']:.0f} "
                     f"| {band(row['kernel_ns_per_sample'], 2)} | {row['offline_over_kernel']:.2f} |")
    lines += ["", "Kernel vs control interval (grating):", "",
              "| control_interval | block | kernel ns/sample |", "| ---: | ---: | ---: |"]
    for row in report["control_interval_sweep"]:
        lines.append(f"| {row['control_interval']} | {row['block']} | {band(row['kernel_ns_per_sample'], 2)} |")
    checks = {row["kind"]: row for row in report["rows"]}
    lines += ["", "Agreement (blocks of 64): kernel driver == Pipeline.render bit for bit: "
              + ", ".join(f"{kind} {'yes' if row['driver_equals_pipeline'] else 'NO'}" for kind, row in checks.items())
              + "; NumPy's largest difference over the largest sample: "
              + ", ".join(f"{kind} {row['numpy_max_difference_over_max_sample']:.1e}" for kind, row in checks.items())
              + "."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="short runs (rougher figures)")
    parser.add_argument("--smoke", action="store_true",
                        help="the test suite's check that the bench runs: every section once at one block (seconds; "
                             "figures meaningless)")
    parser.add_argument("--out", type=results_folder.folder, default=ROOT / "bench" / "results", help="folder for kernel.json/.md")
    parser.add_argument("--offline-only", action="store_true",
                        help="measure the offline section only; keep the rest of kernel.json as it is")
    args = parser.parse_args(argv)
    results_folder.refuse_smoke_into_results(parser, args.smoke, args.out)
    plan = SMOKE if args.smoke else QUICK if args.quick else FULL
    log = lambda line: print(line, flush=True)  # noqa: E731
    if args.offline_only:
        report = json.loads((args.out / "kernel.json").read_text())
        report["offline"] = measure_offline(plan, log)
        report["offline_machine"] = machine()
    else:
        report = {"quick": args.quick, "smoke": args.smoke, "fs_hz": FS_HZ, "plan": asdict(plan), "machine": machine(),
                  **measure(plan, log)}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "kernel.json").write_text(json.dumps(report, indent=1) + "\n")
    (args.out / "kernel.md").write_text(markdown(report))
    print(f"wrote {args.out / 'kernel.json'} and {args.out / 'kernel.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
