"""orjson decoding is used only where it gives exactly what the standard ``json`` module gives."""

from __future__ import annotations

import json
import re
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from meshgen import loaders
from meshgen.jsondoc import LONG_DIGITS, NOT_DECODED, has_long_digit_run, loads_exact
from meshgen.loaders import ImageSource, parse_labelme


def _same(a: Any, b: Any) -> bool:
    """Equal values of equal types all the way down (floats compared bit for bit)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return struct.pack("<d", a) == struct.pack("<d", b)
    if isinstance(a, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict):
        return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    return bool(a == b)


def _number_texts() -> list[str]:
    """Number literals that test float parsing: shortest reprs, long digit strings, exponents,
    subnormals, halfway cases, integers around the 64-bit limits."""
    rng = np.random.default_rng(8)
    floats = np.concatenate(
        (
            rng.uniform(-2000.0, 2000.0, 300),
            rng.standard_normal(100) * 10.0 ** rng.integers(-300, 300, 100),
            np.frombuffer(rng.bytes(8 * 200), dtype=np.float64),
        )
    )
    texts = [repr(float(v)) for v in floats if np.isfinite(v)]
    texts += [f"{float(v):.25e}" for v in floats[:200]]  # more digits than a double holds
    texts += ["".join(map(str, rng.integers(0, 10, n))).lstrip("0") or "0" for n in range(1, 40)]
    texts += [f"0.{'0' * k}1" for k in range(0, 30, 3)]
    texts += ["5e-324", "2.4703282292062327e-324", "2.2250738585072011e-308", "9007199254740993"]
    texts += ["1.7976931348623157e308", "1e400", "-1e400", "-0", "-0.0", "1E5", "1e-400"]
    texts += [str(2**63 - 1), str(2**63), str(-(2**63)), str(-(2**63) - 1), str(2**64), "0"]
    return texts


def test_loads_exact_gives_json_loads_or_nothing() -> None:
    texts = _number_texts()
    decoded = 0
    for number in texts:
        for doc in (f"[{number}]", f'{{"a": [[{number}, 1], [2, {number}]]}}', number):
            data = doc.encode()
            got = loads_exact(data)
            if got is NOT_DECODED:
                continue
            decoded += 1
            assert _same(got, json.loads(doc)), doc
    assert decoded > 2 * len(texts)  # most documents are decoded by orjson
    # the whole list at once: one document of many numbers
    kept = [t for t in texts if loads_exact(f"[{t}]".encode()) is not NOT_DECODED]
    doc = "[" + ",".join(kept) + "]"
    assert _same(loads_exact(doc.encode()), json.loads(doc))


@pytest.mark.parametrize(
    "doc",
    [
        b"[NaN]",
        b"[Infinity]",
        b"[1e400]",
        b'["\\ud800"]',
        b"\xef\xbb\xbf{}",
        b'["\xff"]',
        b'["\xed\xa0\x80"]',
        b"[" * 2000 + b"]" * 2000,
        b"[18446744073709551616]",
        b"[-9223372036854775809]",
        b"[1234567890123456789]",
        b'{"shapes": [',
        b"",
        b"  ",
    ],
)
def test_loads_exact_leaves_what_orjson_would_change_or_reject_to_json(doc: bytes) -> None:
    assert loads_exact(doc) is NOT_DECODED


def test_has_long_digit_run_matches_a_regular_expression() -> None:
    rng = np.random.default_rng(2)
    alphabet = b"0123456789 .,-e[]x\n\xff"
    pattern = re.compile(rb"[0-9]{%d}" % LONG_DIGITS)
    for length in (0, 5, 18, 19, 20, 40, 200):
        for _ in range(50):
            weights = np.array([8.0] * 10 + [1.0] * (len(alphabet) - 10))
            picks = rng.choice(len(alphabet), size=length, p=weights / weights.sum())
            data = bytes(alphabet[i] for i in picks)
            assert has_long_digit_run(data) == (pattern.search(data) is not None)
    assert has_long_digit_run(b"1" * LONG_DIGITS)
    assert not has_long_digit_run(b"1" * (LONG_DIGITS - 1) + b".1")


LABELME_FILES = {
    "plain.json": '{"imageWidth": 100, "imageHeight": 80, "shapes": [{"label": "brick", '
    '"points": [[10, 10], [50, 10.5], [30, 40]]}, {"label": "wood", "points": [[1, 1]]}]}',
    "nan.json": '{"imageWidth": 100, "imageHeight": 80, "shapes": [{"label": "brick", '
    '"points": [[10, NaN], [50, 10], [30, 40]]}]}',
    "bigint.json": '{"imageWidth": 100, "imageHeight": 80, "shapes": [{"label": "brick", '
    '"shape_type": 100000000000000000000, "points": [[10, 10], [50, 10], [30, 40]]}, '
    '{"label": "wood", "points": [[10, 10], [50, 100000000000000000000], [30, 40]]}]}',
    "bigwidth.json": '{"imageWidth": 100000000000000000000, "imageHeight": 80, "shapes": '
    '[{"label": "brick", "points": [[10, 10], [50, 10], [30, 40]]}]}',
    "bools.json": '{"imageWidth": 100, "imageHeight": 80, "shapes": [{"label": "brick", '
    '"points": [[10, true], [50, 10], [30, 40]]}]}',
    "surrogate.json": '{"imageWidth": 100, "imageHeight": 80, "shapes": [{"label": "\\ud800", '
    '"points": [[10, 10], [50, 10], [30, 40]]}]}',
    "truncated.json": '{"shapes": [',
    "blank.json": "  \n",
    "bom.json": "\ufeff{}",
    "crlf.json": '{"imageWidth": 100,\r\n "imageHeight": 80, "shapes": [\r\n{"label": "x",'
    ' "points": [[10, 10], [50, 10], [30, 40]]}]}\r\n',
}


def test_parse_labelme_is_the_same_with_and_without_orjson(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    for name, text in LABELME_FILES.items():
        (tmp_path / name).write_text(text, encoding="utf-8", newline="")
    (tmp_path / "latin1.json").write_bytes(b'{"shapes": ["caf\xe9"]}')
    sources = [
        ImageSource(fmt="labelme", stem=path.stem, path=path)
        for path in sorted(tmp_path.glob("*.json"))
    ]
    sources.append(ImageSource(fmt="labelme", stem="gone", path=tmp_path / "gone.json"))

    def parsed() -> list[tuple[Any, list[Any]]]:
        out = []
        for source in sources:
            ann, skips = parse_labelme(source, tmp_path)
            polygons = (
                [] if ann is None else [(p.where, p.points_px.tolist()) for p in ann.polygons]
            )
            out.append((None if ann is None else (ann.width_px, polygons, ann.skips), skips))
        return out

    fast = parsed()
    monkeypatch.setattr(loaders, "loads_exact", lambda data: NOT_DECODED)
    assert fast == parsed()
    assert any(ann is not None and ann[1] for ann, _ in fast)  # some files gave polygons
