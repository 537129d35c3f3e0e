"""Encode engineering values into register words and back, for one field at a time.

This is the only place that knows about scale, rounding, two's complement and word
order. Every value is checked against its field before anything is sent: a value
that does not fit raises :class:`ValueOutOfRangeError` naming the field, the value
and the allowed range.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence

from ._exceptions import ValueOutOfRangeError
from ._registers import DataType, RegisterField, WordOrder

#: An engineering value as the user sees it.
Value = float | int | bool

_FLOAT32_MAX = 3.4028234663852886e38

_INT_LIMITS = {
    DataType.INT16: (-(2**15), 2**15 - 1),
    DataType.UINT16: (0, 2**16 - 1),
    DataType.INT32: (-(2**31), 2**31 - 1),
    DataType.UINT32: (0, 2**32 - 1),
}


def allowed_range(field: RegisterField) -> tuple[float, float]:
    """The engineering range a field accepts: its declared range cut to what its type holds.

    Args:
        field: A register field.

    Returns:
        ``(lowest, highest)`` engineering value.
    """
    if field.dtype is DataType.BOOL:
        return (0.0, 1.0)
    if field.dtype is DataType.FLOAT32:
        low, high = -_FLOAT32_MAX / field.scale, _FLOAT32_MAX / field.scale
    else:
        raw_low, raw_high = _INT_LIMITS[field.dtype]
        low, high = raw_low / field.scale, raw_high / field.scale
    if field.minimum is not None:
        low = max(low, field.minimum)
    if field.maximum is not None:
        high = min(high, field.maximum)
    return (low, high)


def describe_range(field: RegisterField) -> str:
    """Human-readable allowed range, with the encoding that limits it."""
    if field.dtype is DataType.BOOL:
        return "true or false"
    low, high = allowed_range(field)
    encoding = field.dtype.value if field.scale == 1 else f"{field.dtype.value} x{field.scale:g}"
    unit = f" {field.unit}" if field.unit else ""
    return f"{low:g}..{high:g}{unit}, {encoding}"


def encode(field: RegisterField, value: Value) -> list[int]:
    """Register words (or one 0/1 for a bit) for ``value``; raises if it can't fit.

    Args:
        field: The field the value is for (type, scale, word order, range).
        value: The engineering value.

    Returns:
        ``field.width`` words.

    Raises:
        ValueOutOfRangeError: The value is outside :func:`allowed_range` or not finite.
    """
    return encoder(field)(value)


#: Encodes one value of one field; built once per field by :func:`encoder`.
Encoder = Callable[[Value], list[int]]

# Encoders by the identity of their field; each entry holds the field, so its id cannot
# be reused while the entry lives. Bounded: fields of ad-hoc maps are not kept forever.
_ENCODERS: dict[int, tuple[RegisterField, Encoder]] = {}
_MAX_ENCODERS = 4096


def encoder(field: RegisterField) -> Encoder:
    """A function ``value -> words`` equal to :func:`encode` for ``field``, built once.

    The checks are the same (type, finite, the field's allowed range, the range after
    rounding); what depends on the field alone (range, scale, word order) is computed
    here once instead of at every call.
    """
    entry = _ENCODERS.get(id(field))
    if entry is not None and entry[0] is field:
        return entry[1]
    built = _build_encoder(field)
    if len(_ENCODERS) >= _MAX_ENCODERS:
        _ENCODERS.clear()
    _ENCODERS[id(field)] = (field, built)
    return built


def _build_encoder(field: RegisterField) -> Encoder:
    name, dtype = field.name, field.dtype

    def refuse(value: object) -> ValueOutOfRangeError:
        return ValueOutOfRangeError(name, value, describe_range(field))

    if dtype is DataType.BOOL:

        def encode_bool(value: Value) -> list[int]:
            if isinstance(value, bool) or value in (0, 1):
                return [int(bool(value))]
            raise refuse(value)

        return encode_bool
    low, high = allowed_range(field)
    scale = field.scale
    big = field.word_order is WordOrder.BIG
    isfinite = math.isfinite

    def checked(value: Value) -> float:
        # bool is an int: refused explicitly, as is anything that is not a number.
        if value.__class__ is bool or not isinstance(value, int | float):
            raise refuse(value)
        # The range first: it compares an int too large for a float exactly, where
        # isfinite() would raise OverflowError.
        if not low <= value <= high or not isfinite(value):
            raise refuse(value)
        return value * scale

    if dtype is DataType.FLOAT32:
        pack = _FLOAT32.pack

        def encode_float32(value: Value) -> list[int]:
            packed = pack(checked(value))
            high_word = packed[0] << 8 | packed[1]
            low_word = packed[2] << 8 | packed[3]
            return [high_word, low_word] if big else [low_word, high_word]

        return encode_float32
    raw_low, raw_high = _INT_LIMITS[dtype]
    floor, copysign = math.floor, math.copysign

    def rounded(value: Value) -> int:
        scaled = checked(value)
        raw = int(copysign(floor(abs(scaled) + 0.5), scaled))  # half away from zero
        if not raw_low <= raw <= raw_high:
            # Rounding can push a value that passed the range check over the edge.
            raise refuse(value)
        return raw

    if dtype.width == 1:
        return lambda value: [rounded(value) & 0xFFFF]

    def encode_word32(value: Value) -> list[int]:
        unsigned = rounded(value) & 0xFFFFFFFF
        high_word, low_word = unsigned >> 16, unsigned & 0xFFFF
        return [high_word, low_word] if big else [low_word, high_word]

    return encode_word32


def decode(field: RegisterField, words: Sequence[int]) -> Value:
    """The engineering value stored in ``words`` (exactly ``field.width`` words).

    Args:
        field: The field the words belong to.
        words: Its register words (0..65535 each), as read.

    Returns:
        The engineering value (a bool for a bit).

    Raises:
        ValueError: Not ``field.width`` words, or a word out of 0..65535.
    """
    if len(words) != field.width:
        raise ValueError(f"{field.name}: expected {field.width} words, got {len(words)}")
    if field.dtype is not DataType.BOOL and any(not 0 <= w <= 0xFFFF for w in words):
        raise ValueError(f"{field.name}: register words must be 0..65535, got {list(words)}")
    return decoder(field)(words, 0)


#: Decodes one field's words; built once per field by :func:`decoder`.
Decoder = Callable[[Sequence[int], int], Value]

_FLOAT32 = struct.Struct(">f")
_TWO_WORDS = struct.Struct(">HH")


def decoder(field: RegisterField) -> Decoder:
    """A function ``(words, offset) -> value`` equal to ``decode(field, words[offset:...])``.

    Built once per field (read plans cache it), so the hot path does no per-call type
    dispatch or slicing. The words come from pymodbus, which guarantees 0..65535.
    """
    scale = field.scale
    big = field.word_order is WordOrder.BIG
    dtype = field.dtype
    if dtype is DataType.BOOL:
        return lambda words, at: bool(words[at])
    if dtype is DataType.FLOAT32:
        pack, unpack = _TWO_WORDS.pack, _FLOAT32.unpack

        def float32(words: Sequence[int], at: int) -> Value:
            high, low = (words[at], words[at + 1]) if big else (words[at + 1], words[at])
            number = float(unpack(pack(high, low))[0])
            return number / scale if scale != 1 else number

        return float32
    if dtype.width == 1:
        signed = dtype is DataType.INT16

        def word16(words: Sequence[int], at: int) -> Value:
            raw = words[at]
            if signed and raw >= 0x8000:
                raw -= 0x10000
            return raw / scale if scale != 1 else raw

        return word16
    signed32 = dtype is DataType.INT32

    def word32(words: Sequence[int], at: int) -> Value:
        high, low = (words[at], words[at + 1]) if big else (words[at + 1], words[at])
        raw = high << 16 | low
        if signed32 and raw >= 0x80000000:
            raw -= 0x100000000
        return raw / scale if scale != 1 else raw

    return word32
