"""load_yaml_strict: plain safe YAML, except that a key given twice in one mapping is an error."""

from __future__ import annotations

import pytest
import yaml

from interfaces.yamlio import load_yaml_strict
from twin.errors import ConfigError


def test_reads_what_safe_load_reads() -> None:
    text = "a: 1\nb: [x, {c: 2.5}]\nd: null\ne: true\n"
    assert load_yaml_strict(text, "f.yaml") == yaml.safe_load(text)
    assert load_yaml_strict("", "f.yaml") is None


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("a: 1\nb: 2\na: 3\n", r"^grid\.yaml:3: duplicate key 'a' \(first on line 1\)$"),
        ("- {x: 1}\n- {y: 1, y: 2}\n", r"^grid\.yaml:2: duplicate key 'y' \(first on line 2\)$"),
        ("1: a\n2: b\n1.0: c\n", r"^grid\.yaml:3: duplicate key 1\.0 \(first on line 1\)$"),
        ("a: [\n", r"^grid\.yaml:2:1: not valid YAML: while parsing a flow node, expected"),
        ("a: b: c\n", r"^grid\.yaml:1:5: not valid YAML: mapping values are not allowed here$"),
        ("? [1]\n: 2\n", r"^grid\.yaml:1:3: not valid YAML: .*found unhashable key$"),
    ],
)
def test_duplicate_keys_and_bad_yaml_are_one_line_errors_with_the_line(
    text: str, pattern: str
) -> None:
    with pytest.raises(ConfigError, match=pattern):
        load_yaml_strict(text, "grid.yaml")


def test_a_merged_key_may_be_overridden() -> None:
    text = "base: &b {speed: 0.2, mode: lockstep}\ncell:\n  <<: *b\n  speed: 0.4\n"
    assert load_yaml_strict(text, "f.yaml")["cell"] == {"speed": 0.4, "mode": "lockstep"}
