"""Files read as configuration: alias bombs, runaway documents, binary and oversized files are
refused with one short line naming the file; values in errors are cut; a small file is
rewritten in place when no new file can be created."""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest

from interfaces.errors import MAX_MESSAGE_CHARS, CdwTwinError, ConfigError, cut, cut_message
from interfaces.fileio import overwrite_in_place, read_text_capped
from interfaces.yamlio import MAX_YAML_NODES, expanded_size, load_yaml_file, load_yaml_strict

LOL = '["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]'


def _bomb(levels: int) -> str:
    """The "billion laughs": ``levels`` lists of nine aliases of the list before (9**levels)."""
    lines = [f"a0: &a0 {LOL}"]
    for i in range(1, levels):
        aliases = ", ".join([f"*a{i - 1}"] * 9)
        lines.append(f"a{i}: &a{i} [{aliases}]")
    lines.append(f"stations: [*a{levels - 1}]")
    return "\n".join(lines) + "\n"


def test_an_alias_bomb_is_refused_at_once_without_expanding_it() -> None:
    text = _bomb(9)  # 9**9 = 387 million strings, 700 bytes of YAML
    assert len(text) < 1000
    t0 = time.perf_counter()
    with pytest.raises(ConfigError) as info:
        load_yaml_strict(text, "cell.yaml")
    assert time.perf_counter() - t0 < 1.0
    message = str(info.value)
    assert message.startswith(f"cell.yaml: more than {MAX_YAML_NODES} YAML nodes")
    assert len(message) < 200


def test_shared_aliases_below_the_bound_are_still_yaml() -> None:
    data = load_yaml_strict("base: &b {x: 1}\none: *b\ntwo: {<<: *b, y: 2}\n", "f.yaml")
    assert data == {"base": {"x": 1}, "one": {"x": 1}, "two": {"x": 1, "y": 2}}


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("a: &a [1, *a]\n", r"f\.yaml: line 1: a node that contains itself \(recursive alias\)"),
        ("[" * 5000 + "]" * 5000, r"f\.yaml: not valid YAML: nested too deeply"),
        ("seed: " + "9" * 5000 + "\n", r"f\.yaml:1: an integer of 5000 characters: too large"),
        ("a: 1\x07\n", r"f\.yaml:1: not valid YAML: special characters are not allowed"),
        ("a: [1, 2\n", r"f\.yaml:2:1: not valid YAML"),
        ('"' + "k" * 900 + '": 1\n"' + "k" * 900 + '": 2\n', r"f\.yaml:2: duplicate key 'kkk"),
    ],
    ids=["recursive alias", "deep nesting", "huge integer", "control character", "unclosed",
         "long duplicate key"],
)  # fmt: skip
def test_runaway_yaml_is_one_short_line(text: str, pattern: str) -> None:
    with pytest.raises(ConfigError, match=pattern) as info:
        load_yaml_strict(text, "f.yaml")
    assert "\n" not in str(info.value)
    assert len(str(info.value)) < 300


def test_expanded_size_counts_shared_nodes_as_often_as_they_are_used() -> None:
    import yaml

    node = yaml.compose(_bomb(3), Loader=yaml.SafeLoader)
    assert node is not None
    # the mapping, its 4 keys, a0 (10 nodes), a1 (1 + 9 x 10), a2 (1 + 9 x 91) and stations
    # (1 + a2): a shared node counts once per use
    assert expanded_size(node, 10**9) == 1 + 4 + 10 + 91 + 820 + 821
    assert expanded_size(node, 50) == 51


@pytest.mark.parametrize(
    ("data", "pattern"),
    [
        (b"name: a\x00b\n", r"cell\.yaml:1:8: cell file holds a NUL character"),
        (b"name: ok\nx: \xff\xfe\n", r"cell\.yaml:2:4: cell file is not UTF-8 text \(byte 0xff\)"),
        (b"x" * 2001, r"cell\.yaml: cell file larger than 2000 bytes: refused"),
    ],
    ids=["NUL", "invalid UTF-8", "too large"],
)
def test_binary_or_oversized_files_are_refused_naming_file_line_and_column(
    tmp_path: Path, data: bytes, pattern: str
) -> None:
    path = tmp_path / "cell.yaml"
    path.write_bytes(data)
    with pytest.raises(ConfigError, match=re.escape(str(tmp_path)) + "/" + pattern):
        load_yaml_file(path, what="cell file", max_bytes=2000)


def test_a_byte_order_mark_is_dropped_and_a_missing_file_named(tmp_path: Path) -> None:
    path = tmp_path / "a.yaml"
    path.write_bytes(b"\xef\xbb\xbfname: a\n")
    assert load_yaml_file(path) == {"name": "a"}
    with pytest.raises(ConfigError, match=r"b\.yaml: cannot read scenario: No such file"):
        read_text_capped(tmp_path / "b.yaml", what="scenario")


def test_the_error_class_is_the_callers(tmp_path: Path) -> None:
    class ReadError(CdwTwinError):
        pass

    path = tmp_path / "x.json"
    path.write_bytes(b"\x00")
    with pytest.raises(ReadError, match="NUL"):
        read_text_capped(path, error=ReadError)


def test_cut_never_expands_a_huge_shared_structure() -> None:
    value: list[object] = ["lol"]
    for _ in range(60):  # 2**60 leaves, shared
        value = [value, value]
    t0 = time.perf_counter()
    text = cut(value)
    assert time.perf_counter() - t0 < 0.01
    assert len(text) <= 120
    assert "..." in cut("x" * 10_000)
    assert len(cut("x" * 10_000)) <= 120
    assert cut(10**5000) == "<an integer of 16610 bits>"
    assert cut((0.35, -0.35)) == "(0.35, -0.35)"


def test_cut_message_keeps_the_start_and_the_end() -> None:
    text = "file.yaml: key = " + "v" * 100_000 + ": must be positive"
    short = cut_message(text)
    assert len(short) < MAX_MESSAGE_CHARS + 60
    assert short.startswith("file.yaml: key = vvv")
    assert short.endswith(": must be positive")
    assert "characters cut" in short


def test_a_file_is_rewritten_in_place_over_its_own_blocks(tmp_path: Path) -> None:
    path = tmp_path / "status.json"
    path.write_text('{"state": "running", "padding": "' + "x" * 500 + '"}\n', encoding="utf-8")
    inode = path.stat().st_ino
    overwrite_in_place(path, '{"state": "failed"}\n')
    assert path.read_text(encoding="utf-8") == '{"state": "failed"}\n'
    assert path.stat().st_ino == inode
