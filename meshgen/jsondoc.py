"""Fast decoding of annotation JSON with orjson, only where it equals the standard ``json`` module.

Decoding the labelme files is one of the larger costs of a run (pretty-printed point lists,
mostly), and ``orjson.loads`` does it markedly faster than ``json.loads``. Both give the
same Python values for every document orjson accepts, except integers outside the 64-bit range
(at least 19 digits), which orjson turns into floats. orjson rejects what ``json`` accepts
beyond strict JSON (``NaN``, ``Infinity``, numbers that overflow to infinity, lone surrogate
escapes), and invalid UTF-8, a byte order mark and deep nesting.

A UTF-8 byte order mark at the start of an annotation file is not part of the document: the
loaders remove it first (:func:`without_bom`) on both routes (the standard one reads the text
as ``utf-8-sig``), so a file saved with one decodes like the same file without it.

:func:`loads_exact` therefore answers only when orjson's result is certainly ``json``'s: the
document has no run of 19 digits and orjson accepts it. Otherwise it returns
:data:`NOT_DECODED` and the caller takes the standard route (``read_text`` and ``json.loads``),
which also gives every error message exactly as before.
"""

from __future__ import annotations

import codecs
from typing import Any, Final

import orjson

UTF8_BOM: Final = codecs.BOM_UTF8
"""The UTF-8 byte order mark, ``EF BB BF``."""

LONG_DIGITS = 19
"""Digit runs at least this long may be integers orjson would not keep as ``int``
(``2**63`` has 19 digits)."""

_DIGITS_TO_ZERO = bytes(0x30 if 0x30 <= b <= 0x39 else 0x20 for b in range(256))
"""``bytes.translate`` table: every ASCII digit to ``0``, every other byte to a space."""
_LONG_RUN = b"0" * LONG_DIGITS


class _NotDecoded:
    """Type of :data:`NOT_DECODED`."""

    def __repr__(self) -> str:
        return "NOT_DECODED"


NOT_DECODED: Final = _NotDecoded()
"""What :func:`loads_exact` returns when the standard ``json`` module must decode the data."""


def has_long_digit_run(data: bytes) -> bool:
    """True when ``data`` holds :data:`LONG_DIGITS` or more ASCII digits in a row."""
    return _LONG_RUN in data.translate(_DIGITS_TO_ZERO)


def loads_exact(data: bytes) -> Any:
    """``json.loads(data.decode("utf-8"))`` by orjson, or :data:`NOT_DECODED`.

    Returns :data:`NOT_DECODED` when orjson rejects ``data`` or ``data`` has a long digit run
    (see the module docstring); any other result is the value ``json.loads`` gives.
    """
    if has_long_digit_run(data):
        return NOT_DECODED
    try:
        return orjson.loads(data)
    except orjson.JSONDecodeError:
        return NOT_DECODED


def without_bom(data: bytes) -> bytes:
    """``data`` without one leading UTF-8 byte order mark (``data`` itself when it has none)."""
    return data[len(UTF8_BOM) :] if data.startswith(UTF8_BOM) else data
