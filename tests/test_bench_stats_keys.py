"""Every key the benchmarks read from a Renderer's ``stats()`` is one it has (issue 23: the latency bench once
broke on a key that was renamed, and nothing noticed). The benchmarks' code is scanned, not run: each
``stats[KEY]``, ``stats.get(KEY)`` and ``….stats()[KEY]`` with a literal key (or a loop variable over a tuple of
literals) is checked against the keys of a real Renderer's ``stats()`` on ``null://``.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator

from conftest import REPO_ROOT

from tpad_rt.engine import Renderer

BENCH = REPO_ROOT / "bench"
#: Keys a Renderer has only on some outputs: the output, and the smoke run that reads them for real.
ONLY_ON = {"amplifier": "serial:// (its link's counters: bench/latency/serial_run.py's smoke run reads them)"}


def _is_stats(node: ast.expr) -> bool:
    """``stats`` (a name) or ``anything.stats()``: a Renderer's stats in the benchmarks' code."""
    if isinstance(node, ast.Name):
        return node.id == "stats"
    return (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "stats"
            and not node.args)


def _loop_values(tree: ast.Module) -> dict[str, list[str]]:
    """Each comprehension or for-loop variable that runs over a tuple or list of string literals: those strings."""
    values: dict[str, list[str]] = {}
    for node in ast.walk(tree):
        loops = node.generators if isinstance(node, (ast.ListComp, ast.SetComp, ast.DictComp, ast.GeneratorExp)) \
            else [node] if isinstance(node, ast.For) else []
        for loop in loops:
            if isinstance(loop.target, ast.Name) and isinstance(loop.iter, (ast.Tuple, ast.List)):
                values[loop.target.id] = [item.value for item in loop.iter.elts
                                          if isinstance(item, ast.Constant) and isinstance(item.value, str)]
    return values


def _keys(key: ast.expr, loops: dict[str, list[str]]) -> list[str]:
    if isinstance(key, ast.Constant) and isinstance(key.value, str):
        return [key.value]
    if isinstance(key, ast.Name):
        return loops.get(key.id, [])
    return []


def stats_reads(source: str) -> Iterator[tuple[int, str]]:
    """``(line, key)`` for each key ``source`` reads from a Renderer's stats (module docstring)."""
    tree = ast.parse(source)
    loops = _loop_values(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.Subscript) and _is_stats(node.value):
            yield from ((node.lineno, key) for key in _keys(node.slice, loops))
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get"
              and _is_stats(node.func.value) and node.args):
            yield from ((node.lineno, key) for key in _keys(node.args[0], loops))


def test_the_scan_finds_the_keys_of_each_way_of_reading_them() -> None:
    source = ("stats = renderer.stats()\nstats['a']\nstats.get('b', 0)\nr.stats()['c']\n"
              "{k: stats[k] for k in ('d', 'e')}\ntable.stats[3]\nother['f']\n")
    assert sorted(key for _, key in stats_reads(source)) == ["a", "b", "c", "d", "e"]


def test_every_stats_key_the_benchmarks_read_is_a_key_of_a_real_renderer() -> None:
    with Renderer(output="null://", texture=REPO_ROOT / "textures" / "grating.yaml") as renderer:
        keys = set(renderer.stats())
    reads = {path.relative_to(REPO_ROOT).as_posix(): list(stats_reads(path.read_text()))
             for path in sorted(BENCH.rglob("*.py"))}
    # Each file that asks a Renderer for its stats reads keys the scan sees: the scan knows the benchmarks' idioms.
    asking = [name for name in reads if ".stats()" in (REPO_ROOT / name).read_text()]
    assert asking and all(reads[name] for name in asking), reads
    unknown = [f"{name}:{line}: {key!r}" for name, found in reads.items() for line, key in found
               if key not in keys and key not in ONLY_ON]
    assert unknown == [], f"not a key of Renderer.stats() (it has {sorted(keys)})"
