"""Rows of numbers to text for many rows at once, with exactly the bytes of Python's ``%``.

Formatting floats one at a time with ``%`` is a Python-level call per number, which adds up over
the tens of thousands of coordinates a run writes. :func:`render` lays out rows such as
``"v %.6f %.6f %.6f\\n"`` for all rows together in a byte buffer:

- every row is first the same template (the literal text, a ``-`` where a column may be
  negative, ``0`` digits), repeated;
- each column's digits are written into it with a few whole-column array operations: a value
  is rounded to an integer (``v * 10**N``, see :func:`round_scaled`) whose digits are looked
  up two at a time in a table and stored through a strided view of the buffer;
- the unused characters (the ``-`` of non-negative values, leading zeros of the integer part)
  are dropped in one pass, which also gives the end offset of every row.

``"%.Nf" % v`` rounds the exact binary value of ``v`` half to even, and so does
:func:`round_scaled`. Values that are not finite or too large for exact integer arithmetic
make the whole call fall back to Python's own formatting (same result, slower).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
U8Array = npt.NDArray[np.uint8]
BoolArray = npt.NDArray[np.bool_]

_POWERS = 10 ** np.arange(19, dtype=np.int64)
"""``10**k`` for ``k = 0..18``, every power of ten an ``int64`` holds."""
_SCALED_LIMIT = 2.0**51
"""Scaled magnitudes below this are rounded in arrays (their halves are exact floats)."""
_INT_LIMIT = 10**18
"""Integer magnitudes below this are written in arrays."""
_NEAR_HALF = 2.0**-50
"""Scaled values within this relative distance of a half-integer are rounded exactly."""
_SPLITTER = 2.0**27 + 1.0
"""Veltkamp's constant for splitting a ``float64`` into two 26-bit halves."""
_PAIR_TEXT = np.frombuffer("".join(f"{i:02d}" for i in range(100)).encode("ascii"), np.uint16)
"""Entry ``i`` holds the two ASCII digits of ``i`` (``00`` to ``99``) as one 16-bit word."""
_ZERO = ord("0")


@dataclass(frozen=True, slots=True)
class Fixed:
    """A column of ``float64`` values written as ``%.{decimals}f`` (``1 <= decimals <= 15``)."""

    values: FloatArray
    decimals: int


@dataclass(frozen=True, slots=True)
class Whole:
    """A column of ``int64`` values written as ``%d``."""

    values: IntArray


Part = Fixed | Whole | str


@dataclass(frozen=True, slots=True)
class Rendered:
    """Rows laid out with a fixed width: ``chars`` is ``(rows, width)``, padded with NUL bytes.

    Row ``i``'s text is ``chars[i]`` without its NUL bytes, ``lengths[i]`` characters long;
    :meth:`take` picks rows, :meth:`text` joins them. ``signs`` is only known for rows
    :func:`render` laid out in arrays (empty after Python's formatting).
    """

    chars: U8Array
    lengths: IntArray
    signs: tuple[int, ...] = ()
    """Per numeric column, where its ``-`` stands in a row (-1 when no value is negative)."""

    def take(self, rows: IntArray) -> Rendered:
        """The given rows, in that order."""
        return Rendered(np.take(self.chars, rows, axis=0), self.lengths[rows], self.signs)

    def text(self, bounds: Sequence[int] | IntArray) -> tuple[str, list[int]]:
        """All rows' text in one string, and where each row of ``bounds`` starts in it.

        ``bounds`` are row numbers (``rows`` for the end); blocks of rows between them are
        slices of the string between the returned offsets.
        """
        data = self.chars.tobytes()
        if self.chars.size != int(self.lengths.sum()):
            data = data.translate(None, b"\0")
        ends = np.concatenate(([0], np.cumsum(self.lengths)))
        offsets: list[int] = ends[np.asarray(bounds, dtype=np.int64)].tolist()
        return data.decode("ascii"), offsets


def _split(value: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Veltkamp split: ``hi + lo == value`` exactly, each with at most 26 significant bits."""
    spread = _SPLITTER * value
    high: FloatArray = spread - (spread - value)
    return high, value - high


def _round_exact(magnitude: FloatArray, scale: float) -> IntArray:
    """``magnitude * scale`` rounded half to even, the product taken exactly.

    The product is rounded once (``scaled``); its exact rounding error comes from Dekker's
    two-product, so the exact product lies above the half-integer over ``floor(scaled)`` when
    ``(scaled - half) + error`` is positive (the difference is exact, and a rounded sum keeps
    the sign of the exact sum and is zero only when that is).
    """
    scale_hi, scale_lo = (float(v) for v in _split(np.array(scale)))
    scaled = magnitude * scale
    mag_hi, mag_lo = _split(magnitude)
    error = ((mag_hi * scale_hi - scaled) + mag_hi * scale_lo + mag_lo * scale_hi) + (
        mag_lo * scale_lo
    )
    low = np.floor(scaled).astype(np.int64)
    above = (scaled - (low + 0.5)) + error
    rounded: IntArray = low + ((above > 0.0) | ((above == 0.0) & (low % 2 == 1)))
    return rounded


def round_scaled(magnitude: FloatArray, decimals: int) -> IntArray:
    """``magnitude * 10**decimals`` rounded half to even as ``%.{decimals}f`` rounds it.

    ``magnitude`` must be finite, >= 0 and below ``2**51 / 10**decimals``. The float product
    is off the exact one by less than ``2**-52`` of it, so it rounds the same way unless it is
    that close to a half-integer; those few are rounded from the exact product
    (:func:`_round_exact`).
    """
    scale = float(10**decimals)
    scaled = magnitude * scale
    low = np.floor(scaled)
    above = scaled - low - 0.5
    rounded: IntArray = low.astype(np.int64) + (above > 0.0)
    near = np.flatnonzero(np.abs(above) <= _NEAR_HALF * scaled)
    if len(near):
        rounded[near] = _round_exact(magnitude[near], scale)
    return rounded


def _digit_counts(magnitude: IntArray) -> IntArray:
    """Number of decimal digits of each non-negative value (1 for 0)."""
    counts: IntArray = np.searchsorted(_POWERS, magnitude, side="right")
    return np.maximum(counts, 1)


def _quads(pad: str, zero: str) -> npt.NDArray[np.uint32]:
    """For ``i < 10**4`` the four ASCII bytes of ``i`` right-aligned (``pad`` on the left,
    ``zero`` for ``i == 0``) as one 32-bit word."""
    texts = [zero.rjust(4, pad)] + [str(i).rjust(4, pad) for i in range(1, 10**4)]
    return np.frombuffer("".join(texts).encode("ascii"), dtype=np.uint32)


_QUAD_ZERO = _quads("0", "0")
"""``i`` as four digits with leading zeros (the inner groups of a number)."""
_QUAD_LEAD = _quads("\0", "")
"""``i`` without leading zeros, NUL-padded, nothing for 0 (a group before the first digit)."""
_QUAD_LAST = _quads("\0", "0")
"""``i`` without leading zeros, NUL-padded, ``0`` for 0 (the last group of a number)."""
_QUAD_DIGITS = np.maximum(np.searchsorted(_POWERS, np.arange(10**4), side="right"), 1)
"""Digits of ``i`` (1 for 0)."""


@dataclass(frozen=True, slots=True)
class _Rows:
    """``count`` rows of ``width`` bytes each, one after another in ``flat``."""

    flat: U8Array
    width: int
    count: int

    def column(self, dtype: type[np.generic], offset: int) -> U8Array:
        """The bytes at ``offset`` of every row, read as one ``dtype`` value per row."""
        view: U8Array = np.ndarray(
            (self.count,), dtype=dtype, buffer=self.flat, offset=offset, strides=(self.width,)
        )
        return view

    def write_whole(self, end: int, value: IntArray, groups: int) -> IntArray:
        """Store non-negative ``value`` right-aligned, NUL-padded, in the ``4 * groups`` bytes
        before ``end`` of every row; return each value's digit count."""
        start = end - 4 * groups
        if groups == 1:
            self.column(np.uint32, start)[...] = _QUAD_LAST[value]
            digits: IntArray = _QUAD_DIGITS[value]
            return digits
        for j in range(groups):
            group = value // _POWERS[4 * (groups - 1 - j)] % 10**4
            text = (_QUAD_LEAD if j < groups - 1 else _QUAD_LAST)[group]
            if j:  # groups after a non-zero one keep their leading zeros
                text = np.where(value >= _POWERS[4 * (groups - j)], _QUAD_ZERO[group], text)
            self.column(np.uint32, start + 4 * j)[...] = text
        return _digit_counts(value)

    def write_fraction(self, point: int, value: IntArray, decimals: int) -> None:
        """Store ``value`` (< ``10**decimals``) as ``decimals`` digits after the ``.`` at
        ``point`` of every row."""
        rest = value
        end = point + 1 + decimals
        left = decimals
        while left >= 4:
            rest, group = np.divmod(rest, 10**4)
            end -= 4
            left -= 4
            self.column(np.uint32, end)[...] = _QUAD_ZERO[group]
        if left == 3:  # "0ddd" over the point, then the point again
            self.column(np.uint32, point)[...] = _QUAD_ZERO[rest]
            self.flat[point :: self.width] = ord(".")
        elif left == 2:
            self.column(np.uint16, point + 1)[...] = _PAIR_TEXT[rest]
        elif left == 1:
            self.flat[point + 1 :: self.width] = (rest + _ZERO).astype(np.uint8)


@dataclass(frozen=True, slots=True)
class _Column:
    """One numeric column taken apart: sign, integer part and fraction of every value."""

    negative: BoolArray | None  # None: no value is negative (no sign slot)
    whole: IntArray
    digits: int  # the most digits an integer part has
    fraction: IntArray | None  # None for a Whole column
    decimals: int


def _column(part: Fixed | Whole) -> _Column | None:
    """Integer part, fraction and sign of one column, or None when Python must format it."""
    if isinstance(part, Fixed):
        values = np.asarray(part.values, dtype=np.float64)
        magnitude = np.abs(values)
        if not (magnitude < _SCALED_LIMIT / 10**part.decimals).all():
            return None  # NaN, infinite or too large
        negative = np.signbit(values)
        whole, fraction = np.divmod(round_scaled(magnitude, part.decimals), 10**part.decimals)
        decimals: int = part.decimals
    else:
        ints = np.asarray(part.values, dtype=np.int64)
        negative = ints < 0
        whole = np.abs(ints)
        if len(whole) and not (whole < _INT_LIMIT).all():
            return None  # the int64 minimum, or more digits than the table covers
        fraction, decimals = None, 0
    top = int(whole.max()) if len(whole) else 0
    return _Column(negative if negative.any() else None, whole, len(str(top)), fraction, decimals)


def render(parts: Sequence[Part], rows: int) -> Rendered:
    """Each row the parts side by side: literal ``str`` parts (ASCII, no NUL) and
    :class:`Fixed`/:class:`Whole` columns of ``rows`` values each; row ``i`` reads exactly as
    ``%``-formatting its values gives.

    An integer part of ``d`` digits is written as whole 4-byte table words ending where its
    slot ends, so the first word may start up to 3 bytes before the slot and overwrite what
    lies there. Columns are therefore written right to left (each digits first, then its
    sign), and the literal bytes (and decimal points) such a word can reach are written again
    at the end. A column too close to the row start for that gets a slot of whole words.
    """
    laid: list[_Column | str] = []
    for part in parts:
        column = part if isinstance(part, str) else _column(part)
        if column is None:
            return _python_render(parts, rows)
        laid.append(column)
    slots: list[tuple[_Column, int, int]] = []  # column, sign position, integer slot end
    pieces: list[str] = []
    fixed: set[int] = set()  # positions of literal bytes and decimal points
    offset = 0
    for item in laid:
        if isinstance(item, str):
            pieces.append(item)
            fixed.update(range(offset, offset + len(item)))
            offset += len(item)
            continue
        sign = 0 if item.negative is None else 1
        digits = item.digits
        if offset + sign + digits < 4 * -(-digits // 4):
            digits = 4 * -(-digits // 4)  # no room before the slot: pad to whole words
        text = "-" * sign + "\0" * digits
        if item.fraction is not None:
            fixed.add(offset + len(text))
            text += "." + "0" * item.decimals
        pieces.append(text)
        slots.append((item, offset, offset + sign + digits))
        offset += len(text)
    template = "".join(pieces).encode("ascii")
    width = len(template)
    out = _Rows(np.frombuffer(bytearray(template * rows), dtype=np.uint8), width, rows)
    lengths = np.full(rows, width, dtype=np.int64)
    reached: set[int] = set()
    for column, sign_at, end in reversed(slots):
        groups = -(-column.digits // 4)
        if column.fraction is not None:
            out.write_fraction(end, column.fraction, column.decimals)
        lengths -= (end - sign_at) - out.write_whole(end, column.whole, groups)
        reached.update(range(end - 4 * groups, end))
        if column.negative is not None:
            out.flat[sign_at::width] = column.negative.astype(np.uint8) * np.uint8(ord("-"))
            lengths += column.negative
    for at in sorted(reached & fixed):  # overwritten by a word that began before its slot
        out.flat[at::width] = template[at]
    signs = tuple(-1 if c.negative is None else at for c, at, _ in slots)
    return Rendered(out.flat.reshape(rows, width), lengths, signs)


def _python_render(parts: Sequence[Part], rows: int) -> Rendered:
    """:func:`render` by Python's ``%`` formatting (for values it cannot write in arrays)."""
    pattern = "".join(
        p.replace("%", "%%")
        if isinstance(p, str)
        else (f"%.{p.decimals}f" if isinstance(p, Fixed) else "%d")
        for p in parts
    )
    values = [
        (p.values.tolist() if isinstance(p, Fixed) else np.asarray(p.values).tolist())
        for p in parts
        if not isinstance(p, str)
    ]
    texts = [(pattern % row).encode("ascii") for row in zip(*values, strict=True)]
    if not values:
        texts = [pattern.replace("%%", "%").encode("ascii")] * rows
    width = max((len(t) for t in texts), default=0)
    chars = np.zeros((rows, width), dtype=np.uint8)
    for i, text in enumerate(texts):
        chars[i, : len(text)] = np.frombuffer(text, dtype=np.uint8)
    return Rendered(chars, np.array([len(t) for t in texts], dtype=np.int64).reshape(rows))
