"""YAML text to plain data, refusing a key given twice, alias bombs and runaway documents.

Plain YAML keeps the last of two equal keys silently; a configuration file that says one thing
twice is a mistake its author wants to hear about, with the line. Aliases (``*name``) share
one parsed structure, so a file of a few hundred bytes can stand for a structure of billions
of items (the "billion laughs" bomb) that any code walking it, or printing it in an error,
expands: a document whose nodes, every alias expanded, number more than
:data:`MAX_YAML_NODES` is refused before it is built, and so is a recursive alias (a node
that contains itself). A document nested too deeply for the parser is refused too. Every
error is one line naming the file (and the line where YAML gives one).

Example::

    data = load_yaml_file(Path("interfaces/cells/default.yaml"), what="cell file")
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from interfaces.errors import ConfigError, cut
from interfaces.fileio import MAX_CONFIG_BYTES, read_text_capped

_MERGE_TAG = "tag:yaml.org,2002:merge"

MAX_YAML_NODES = 100_000
"""The most nodes (scalars, lists, mappings) a YAML document may have with every alias
expanded; the largest shipped configuration has about 2000."""


class StrictLoader(yaml.SafeLoader):
    """A YAML SafeLoader whose mappings refuse a key given twice (:class:`ConfigError`).

    Keys brought in by a ``<<`` merge may be overridden, as YAML intends; only keys written
    out in the same mapping count. ``name`` (set per load) prefixes the error message.
    """

    name: str = "<yaml>"

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        """The mapping of ``node``; :class:`ConfigError` naming the key and both lines if a
        key is repeated."""
        first: dict[Any, yaml.Node] = {}
        for key_node, _ in node.value:
            if key_node.tag == _MERGE_TAG:
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                earlier = first.setdefault(key, key_node)
            except TypeError:
                continue  # an unhashable key: SafeLoader reports it below
            if earlier is not key_node:
                line, first_line = key_node.start_mark.line + 1, earlier.start_mark.line + 1
                msg = f"{self.name}:{line}: duplicate key {cut(key)} (first on line {first_line})"
                raise ConfigError(msg)
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node: yaml.ScalarNode) -> int:
        """An integer scalar; one of more than :data:`MAX_INT_CHARS` characters is refused
        naming its line (Python refuses to convert one of 4300 digits with a traceback, and no
        value of a configuration is that large)."""
        if len(node.value) > MAX_INT_CHARS:
            line = node.start_mark.line + 1
            msg = f"{self.name}:{line}: an integer of {len(node.value)} characters: too large"
            raise ConfigError(msg)
        value: int = super().construct_yaml_int(node)
        return value


MAX_INT_CHARS = 64
"""The longest integer scalar a YAML configuration may hold (2**64 has 20 digits)."""

StrictLoader.add_constructor("tag:yaml.org,2002:int", StrictLoader.construct_yaml_int)


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def expanded_size(root: yaml.Node, limit: int) -> int:
    """How many nodes ``root`` stands for with every alias expanded, counted without expanding
    anything (each shared node once, memoised); stops counting above ``limit`` (then returns
    ``limit + 1``). Raises :class:`ValueError` for a node that contains itself."""
    sizes: dict[int, int] = {}
    open_nodes: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, children_done = stack.pop()
        key = id(node)
        if children_done:
            open_nodes.discard(key)
            total = 1 + sum(sizes[id(child)] for child in _children(node))
            sizes[key] = min(total, limit + 1)
            continue
        if key in sizes:
            continue
        if key in open_nodes:
            msg = f"line {node.start_mark.line + 1}: a node that contains itself (recursive alias)"
            raise ValueError(msg)
        open_nodes.add(key)
        stack.append((node, True))
        for child in _children(node):
            if id(child) in open_nodes:
                line = child.start_mark.line + 1
                msg = f"line {line}: a node that contains itself (recursive alias)"
                raise ValueError(msg)
            if id(child) not in sizes:
                stack.append((child, False))
    return sizes[id(root)]


def load_yaml_strict(text: str, where: str, *, max_nodes: int = MAX_YAML_NODES) -> Any:
    """Parse YAML ``text`` (safe types only); a one-line :class:`ConfigError` naming ``where``
    and the line for invalid YAML, a key given twice in one mapping, more than ``max_nodes``
    nodes with aliases expanded, a recursive alias, or nesting too deep to parse."""
    loader: StrictLoader | None = None
    try:
        loader = StrictLoader(text)
        loader.name = where
        node = loader.get_single_node()
        if node is None:
            return None
        try:
            size = expanded_size(node, max_nodes)
        except ValueError as exc:
            msg = f"{where}: {exc}: refused"
            raise ConfigError(msg) from None
        if size > max_nodes:
            msg = (
                f"{where}: more than {max_nodes} YAML nodes with every alias expanded: refused "
                "(an alias bomb, or not a configuration file)"
            )
            raise ConfigError(msg)
        return loader.construct_document(node)
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        msg = f"{where}:{line}: not valid YAML: {exc.reason} (character #x{exc.character:04x})"
        raise ConfigError(msg) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        at = f"{where}:{mark.line + 1}:{mark.column + 1}" if mark is not None else where
        what = ", ".join(part for part in (exc.context, exc.problem) if part)
        msg = f"{at}: not valid YAML: {what}"
        raise ConfigError(msg) from None
    except yaml.YAMLError as exc:
        msg = f"{where}: not valid YAML: {cut(str(exc), 300)}"
        raise ConfigError(msg) from None
    except RecursionError:
        msg = f"{where}: not valid YAML: nested too deeply"
        raise ConfigError(msg) from None
    finally:
        if loader is not None:
            loader.dispose()


def load_yaml_file(
    path: Path, *, what: str = "YAML file", max_bytes: int = MAX_CONFIG_BYTES
) -> Any:
    """Read ``path`` (:func:`interfaces.fileio.read_text_capped`: at most ``max_bytes``, UTF-8,
    no NUL) and parse it with :func:`load_yaml_strict`; errors name the file."""
    text = read_text_capped(path, max_bytes=max_bytes, what=what)
    return load_yaml_strict(text, str(path))
