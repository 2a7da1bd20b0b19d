"""No module imports from a layer above its own (docs/architecture.md "Layers"), read from the sources' imports.

Every ``import`` and ``from ... import`` in tpad_rt counts, at module level, in a function, or under
``TYPE_CHECKING``: a function-level import from above is the same dependency, paid later.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "tpad_rt"

#: Bottom to top. A module may import from its own layer and the layers below it. A name is a module or a
#: package (all of its modules); the longest name that matches a module decides its layer. ``tpad_rt`` is the
#: package's facade (its ``__init__``) only: a new module must be placed here, or the test says so.
LAYERS: tuple[tuple[str, ...], ...] = (
    # foundation: errors, limits, files, text and URL parsing, clocks: no tpad_rt module above them
    ("tpad_rt.version", "tpad_rt.errors", "tpad_rt.limits", "tpad_rt.files", "tpad_rt.decimal_text",
     "tpad_rt.json_text", "tpad_rt.urls", "tpad_rt.csv_lines", "tpad_rt.shipped", "tpad_rt.clock",
     "tpad_rt.drive_guard", "tpad_rt.figures", "tpad_rt.compiling", "tpad_rt.compile_events", "tpad_rt.log_histogram",
     "tpad_rt.compile_runner", "tpad_rt.kernel_cache"),
    # physics: the paper's equations, vectorised
    ("tpad_rt.physics",),
    # kernels: numba, pure; and the same callbacks compiled ahead of time (loaded without numba)
    ("tpad_rt.kernel", "tpad_rt.aot"),
    # files and models: the config schemas, textures, the device model
    ("tpad_rt.config", "tpad_rt.texture", "tpad_rt.device", "tpad_rt.felt"),
    # the rendering pipeline and what it describes: the drive, finger samples, recordings, maps
    ("tpad_rt.drive", "tpad_rt.pipeline", "tpad_rt.inputs", "tpad_rt.recording", "tpad_rt.plate_maps"),
    # the real-time arrays and the telemetry log
    ("tpad_rt.realtime", "tpad_rt.telemetry"),
    # outputs by URL, and the amplifier side of the serial protocol
    ("tpad_rt.outputs", "tpad_rt.amp"),
    # drivers: what runs each output's callback
    ("tpad_rt.drivers",),
    # the engines: real time (Renderer), offline, calibration
    ("tpad_rt.engine", "tpad_rt.offline", "tpad_rt.calibrate", "tpad_rt.compile_plan"),
    # the network API
    ("tpad_rt.serve",),
    # the command line, the package's facade, and the script that made the shipped textures' images
    ("tpad_rt.cli", "tpad_rt.__main__", "tpad_rt", "tpad_rt.textures"),
)


def _layer(module: str) -> int | None:
    """The layer of ``module`` (by its longest listed prefix), None if it is not tpad_rt's."""
    best: tuple[int, int] | None = None
    for index, names in enumerate(LAYERS):
        for name in names:
            if module == name or (name != "tpad_rt" and module.startswith(name + ".")):  # the facade: itself only
                if best is None or len(name) > best[0]:
                    best = (len(name), index)
    return None if best is None else best[1]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imported(tree: ast.AST, module: str, is_package: bool) -> list[tuple[int, str]]:
    """(line, module) of each tpad_rt module ``tree`` imports; ``from tpad_rt.x import y`` counts as
    ``tpad_rt.x.y`` when that is a module."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against this module's package
                base = module.split(".")[:len(module.split(".")) - node.level + (1 if is_package else 0)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for alias in node.names:
                candidate = f"{source}.{alias.name}"
                is_module = (PACKAGE.parent / Path(*candidate.split("."))).with_suffix(".py").exists() or \
                    (PACKAGE.parent / Path(*candidate.split(".")) / "__init__.py").exists()
                found.append((node.lineno, candidate if is_module else source))
    return [(line, name) for line, name in found if name == "tpad_rt" or name.startswith("tpad_rt.")]


def _violations() -> list[str]:
    problems = []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = _module_name(path)
        own = _layer(module)
        if own is None:
            problems.append(f"{module}: in no layer (add it to LAYERS)")
            continue
        for line, name in _imported(ast.parse(path.read_text(), str(path)), module, path.name == "__init__.py"):
            target = _layer(name)
            if target is None:
                problems.append(f"{module}:{line} imports {name}, which is in no layer")
            elif target > own:
                problems.append(f"{module}:{line} imports {name} (layer {target}) from layer {own}")
    return problems


def test_no_module_imports_from_a_layer_above_its_own() -> None:
    assert _violations() == []


@pytest.mark.parametrize("source, imported, caught", [
    ("from tpad_rt.engine import Renderer", "tpad_rt.kernel.render", True),
    ("def f():\n    from tpad_rt.cli.show import plate_maps", "tpad_rt.serve.core", True),
    ("import tpad_rt.kernel.layout", "tpad_rt.engine", False),
    ("from tpad_rt import version", "tpad_rt.kernel.render", False),
    ("from ..engine import Renderer", "tpad_rt.kernel.render", True),
    ("from .. import cli", "tpad_rt.drivers.paced", True),
    ("from . import layout", "tpad_rt.kernel.render", False),
])
def test_the_check_sees_imports_at_every_level(source: str, imported: str, caught: bool) -> None:
    """The reader finds module-level, function-level and relative imports, and judges them by layer."""
    own = _layer(imported)
    assert own is not None
    names = _imported(ast.parse(source), imported, False)
    assert names, source
    assert any((_layer(name) or 0) > own for _, name in names) is caught


def test_a_module_in_no_layer_is_named() -> None:
    assert _layer("tpad_rt.brand_new_module") is None
    assert _layer("tpad_rt") == len(LAYERS) - 1
