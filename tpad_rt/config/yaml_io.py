"""Safe YAML loading with limits, and the line number of any value in the file.

Only plain YAML data is accepted (``yaml.safe_load`` semantics): mappings,
lists, strings, numbers, booleans, null and timestamps. The file is composed
into a node graph first, so that limits hold before anything is built (an
alias bomb is refused while it is being read, not after it has exploded),
duplicate keys can be found, and every value keeps its line number.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from yaml.events import AliasEvent, MappingStartEvent, SequenceStartEvent
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from tpad_rt.config.breadcrumb import Location, breadcrumb, show_value
from tpad_rt.config.messages import listed
from tpad_rt.errors import ConfigError
from tpad_rt.files import read_regular

MAX_FILE_BYTES = 4 * 1024 * 1024
MAX_DEPTH = 32
MAX_LIST_ITEMS = 100_000
#: Values in the file once every alias is expanded (defeats "billion laughs").
MAX_VALUES = 1_000_000

_YAML_TAG = "tag:yaml.org,2002:"
_MERGE_TAG = _YAML_TAG + "merge"
_MAP_TAG = _YAML_TAG + "map"
_PLAIN_TAGS = frozenset(tag for tag in yaml.SafeLoader.yaml_constructors if tag) | {_MERGE_TAG}


@dataclass(frozen=True)
class YamlDocument:
    """A loaded file: its top-level mapping and the node graph it came from."""

    data: dict[Any, Any]
    root: MappingNode
    #: Each looked-up mapping's keys (``id(node)`` -> ``{key: (line, value node)}``), built on its first lookup,
    #: so that locating every error of a file is linear in the file, not in errors x keys.
    _keys: dict[int, dict[str, tuple[int, Node]]] = field(default_factory=dict, init=False, repr=False,
                                                          compare=False)

    def line_at(self, loc: Sequence[str | int]) -> int:
        """1-based line of the value at ``loc``, or of the nearest enclosing value present."""
        node: Node = self.root
        line = node.start_mark.line + 1
        for elem in loc:
            found = self._child(node, elem)
            if found is None:
                break
            line, node = found
        return line

    def _child(self, node: Node, elem: str | int) -> tuple[int, Node] | None:
        """``(line, child)`` for a key of a mapping (the key's line; the last of a repeated key) or an index
        of a list."""
        if isinstance(node, MappingNode):
            keys = self._keys.get(id(node))
            if keys is None:
                keys = self._keys[id(node)] = {key.value: (key.start_mark.line + 1, value)
                                               for key, value in node.value if isinstance(key, ScalarNode)}
            return keys.get(str(elem))
        if isinstance(node, SequenceNode) and isinstance(elem, int) and 0 <= elem < len(node.value):
            item = node.value[elem]
            return item.start_mark.line + 1, item
        return None


def load_yaml(path: Path, source: str) -> YamlDocument:
    """Read ``path`` as plain YAML whose top level is a mapping.

    Raises ConfigError (lines prefixed with ``source``) when the file cannot be
    read, is not a regular file (a FIFO, a device, a directory: refused before
    reading, :func:`tpad_rt.files.open_regular`) or exceeds 4 MiB, is not valid YAML, nests deeper than 32 levels, has a
    list longer than 100,000 items or more than 1,000,000 values once aliases
    are expanded, uses a tag other than plain data, repeats a key, or its top
    level is not a mapping.
    """
    if source == "":  # Path("") is the current folder: say what was given instead
        raise ConfigError("'': the file name is empty; give the path of a texture or device file")
    return parse_yaml(read_regular(path, "texture and device files", MAX_FILE_BYTES, source), source)


def parse_yaml(text: bytes, source: str) -> YamlDocument:
    """``text`` (a texture or device file's bytes, at most MAX_FILE_BYTES) as :func:`load_yaml` reads a file;
    ConfigError (lines prefixed with ``source``) as there."""
    if len(text) > MAX_FILE_BYTES:
        raise ConfigError(breadcrumb(source, (), f"{len(text):,} bytes, more than the {MAX_FILE_BYTES:,} a texture "
                                     "or device file may hold"))
    try:
        return _compose_and_construct(text, source)
    except _LimitExceeded as err:
        raise ConfigError(breadcrumb(source, (), err.message, err.line)) from None
    except yaml.MarkedYAMLError as err:
        raise ConfigError(breadcrumb(source, (), f"invalid YAML: {_describe(err)}", _line(err))) from None
    except yaml.reader.ReaderError as err:
        raise ConfigError(breadcrumb(source, (), f"invalid YAML: {_describe_reader(err)}")) from None


def _compose_and_construct(text: bytes, source: str) -> YamlDocument:
    """Compose under limits, check tags and keys, then build the data.

    Raises yaml.YAMLError, _LimitExceeded, or ConfigError (bad top level, tags, repeated keys).
    """
    loader = _LimitedLoader(text)
    try:
        root = loader.get_single_node()
        if not isinstance(root, MappingNode) or root.tag != _MAP_TAG:
            message = f"top level must be a mapping of keys to values, got {_kind(root)}"
            raise ConfigError(breadcrumb(source, (), message))
        problems = _check_nodes(root, (), source, set())
        if problems:
            raise ConfigError(listed(problems, source))
        return YamlDocument(loader.construct_document(root), root)
    finally:
        loader.dispose()




class _LimitExceeded(Exception):
    """A limit of this module was hit at ``line``."""

    def __init__(self, message: str, mark: yaml.Mark):
        super().__init__(message)
        self.message = message
        self.line = mark.line + 1


class _LimitedLoader(yaml.SafeLoader):
    """SafeLoader whose composer enforces depth, list length and expanded size.

    For every composed collection it records ``(values, height)``: the number of values
    in it with aliases expanded, and the number of nested collections in it.
    Raises _LimitExceeded when a limit is hit, including an alias to a node that
    is still being composed (a recursive structure).
    """

    def __init__(self, stream: bytes):
        super().__init__(stream)
        self._open_collections = 0
        self._values = 0
        self._sizes: dict[int, tuple[int, int]] = {}

    def compose_node(self, parent: Node | None, index: Any) -> Node:
        event = self.peek_event()
        if isinstance(parent, SequenceNode) and index >= MAX_LIST_ITEMS:
            raise _LimitExceeded(f"list longer than {MAX_LIST_ITEMS:,} items", event.start_mark)
        if isinstance(event, AliasEvent):
            return self._compose_alias(parent, index)
        opens = isinstance(event, (MappingStartEvent, SequenceStartEvent))
        self._open_collections += opens
        if self._open_collections > MAX_DEPTH:
            raise _LimitExceeded(f"nested deeper than {MAX_DEPTH} levels", event.start_mark)
        try:
            node = _present(super().compose_node(parent, index), event.start_mark)
        finally:
            self._open_collections -= opens
        if opens:
            children: list[tuple[int, int]] = []
            for child in _children(node):
                size = self._size(child)
                if size is None:  # a child still being composed: only a recursive alias, which is refused
                    raise _LimitExceeded("alias refers to a value that contains it (recursive structure)",
                                         event.start_mark)
                children.append(size)
            self._sizes[id(node)] = (
                1 + sum(values for values, _ in children),
                1 + max((height for _, height in children), default=0),
            )
        self._count(1, event.start_mark)
        return node

    def _size(self, node: Node) -> tuple[int, int] | None:
        """``(values, height)`` of a composed node; None while it is still being composed."""
        return (1, 0) if isinstance(node, ScalarNode) else self._sizes.get(id(node))

    def _compose_alias(self, parent: Node | None, index: Any) -> Node:
        mark = self.peek_event().start_mark
        node = _present(super().compose_node(parent, index), mark)
        size = self._size(node)
        if size is None:
            raise _LimitExceeded("alias refers to a value that contains it (recursive structure)", mark)
        values, height = size
        if self._open_collections + height > MAX_DEPTH:
            raise _LimitExceeded(f"nested deeper than {MAX_DEPTH} levels once this alias is expanded", mark)
        self._count(values, mark)
        return node

    def _count(self, values: int, mark: yaml.Mark) -> None:
        self._values += values
        if self._values > MAX_VALUES:
            raise _LimitExceeded(f"more than {MAX_VALUES:,} values once aliases are expanded", mark)

    def construct_object(self, node: Node, deep: bool = False) -> Any:
        """As SafeLoader's, but a bad scalar (``2024-13-01``, ``!!int x``) is a marked YAML error."""
        try:
            return super().construct_object(node, deep)
        except (ValueError, TypeError, OverflowError) as err:
            raise yaml.constructor.ConstructorError(None, None, f"bad value: {err}", node.start_mark) from None


def _check_nodes(node: Node, loc: Location, source: str, seen: set[int]) -> list[str]:
    """Breadcrumbs for tags that are not plain data and for repeated keys, in file order."""
    if id(node) in seen:
        return []
    seen.add(id(node))
    line = node.start_mark.line + 1
    if node.tag not in _PLAIN_TAGS:
        tag = node.tag.replace(_YAML_TAG, "!!")
        return [breadcrumb(source, loc, f"tag '{tag}' is not allowed: files hold plain data only (safe YAML)", line)]
    problems: list[str] = []
    if isinstance(node, SequenceNode):
        for index, item in enumerate(node.value):
            problems += _check_nodes(item, (*loc, index), source, seen)
    elif isinstance(node, MappingNode):
        first_lines: dict[tuple[str, str], int] = {}
        for key, value in node.value:
            label = key.value if isinstance(key, ScalarNode) else "<complex key>"
            key_line = key.start_mark.line + 1
            problems += _check_nodes(key, (*loc, label), source, seen)
            if isinstance(key, ScalarNode) and key.tag != _MERGE_TAG:
                ident = (key.tag, key.value)
                if ident in first_lines:
                    message = f"duplicate key (first given on line {first_lines[ident]})"
                    problems.append(breadcrumb(source, (*loc, label), message, key_line))
                first_lines.setdefault(ident, key_line)
            problems += _check_nodes(value, (*loc, label), source, seen)
    return problems



def _present(node: Node | None, mark: yaml.Mark) -> Node:
    """``node``: PyYAML's ``compose_node`` always returns one, though its stubs say Optional."""
    if node is None:
        raise _LimitExceeded("a value is missing", mark)
    return node


def _children(node: Node) -> list[Node]:
    if isinstance(node, SequenceNode):
        return list(node.value)
    if isinstance(node, MappingNode):
        return [child for pair in node.value for child in pair]
    return []


def _kind(node: Node | None) -> str:
    if node is None:
        return "an empty file"
    if isinstance(node, ScalarNode):
        return f"the single value {show_value(node.value)}"
    return "a list" if node.tag == _YAML_TAG + "seq" else f"a {node.tag.replace(_YAML_TAG, '!!')} collection"


def _describe(err: yaml.MarkedYAMLError) -> str:
    return f"{err.context}: {err.problem}" if err.context and err.problem else str(err.problem or err.context)


def _describe_reader(err: yaml.reader.ReaderError) -> str:
    if err.encoding == "unicode":
        return f"character #x{err.character:04x} is not allowed"
    return f"cannot decode as {err.encoding}: byte #x{err.character:02x} at offset {err.position} ({err.reason})"


def _line(err: yaml.MarkedYAMLError) -> int | None:
    mark = err.problem_mark or err.context_mark
    return mark.line + 1 if mark else None


class _Dumper(yaml.SafeDumper):
    """Block mappings, flow (one-line) lists: how tpad-rt writes device files."""


def _flow_list(dumper: yaml.SafeDumper, data: list[Any]) -> yaml.Node:
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=True)


_Dumper.add_representer(list, _flow_list)


def dump_yaml(document: dict[str, Any], header: str = "") -> str:
    """``document`` as YAML text (safe: plain data only), keys in their order, lists on one line, after
    ``header`` (comment lines, each ending in a newline)."""
    return header + yaml.dump(document, Dumper=_Dumper, sort_keys=False, width=1000, allow_unicode=True)
