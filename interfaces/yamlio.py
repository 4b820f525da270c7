"""YAML text to plain data, refusing a key given twice in one mapping.

Plain YAML keeps the last of two equal keys silently; a configuration file that says one thing
twice is a mistake its author wants to hear about, with the line.
"""

from __future__ import annotations

from typing import Any

import yaml

from interfaces.errors import ConfigError

_MERGE_TAG = "tag:yaml.org,2002:merge"


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
                msg = f"{self.name}:{line}: duplicate key {key!r} (first on line {first_line})"
                raise ConfigError(msg)
        return super().construct_mapping(node, deep=deep)


def load_yaml_strict(text: str, where: str) -> Any:
    """Parse YAML ``text`` (safe types only); a one-line :class:`ConfigError` naming ``where``
    and the line for invalid YAML and for a key given twice in one mapping."""
    loader = StrictLoader(text)
    loader.name = where
    try:
        return loader.get_single_data()
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        at = f"{where}:{mark.line + 1}:{mark.column + 1}" if mark is not None else where
        what = ", ".join(part for part in (exc.context, exc.problem) if part)
        msg = f"{at}: not valid YAML: {what}"
        raise ConfigError(msg) from None
    except yaml.YAMLError as exc:
        msg = f"{where}: not valid YAML: {exc}"
        raise ConfigError(msg) from None
    finally:
        loader.dispose()
