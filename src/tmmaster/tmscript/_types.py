"""TMscript types, conversions and display format (TMscript 2.24 §2.1, §2.5, §2.6).

A value is a Python ``int`` (byte, int16, int), ``float`` (float, double), ``bool``, ``str``
or a ``list`` of those (an array). The TMscript type travels beside it, known when the
script is checked: a float is kept rounded to 32 bits, an int wraps at 32 bits.
"""

from __future__ import annotations

import math
import struct
from typing import TypeAlias

__all__ = [
    "ARRAY_MAX",
    "STRING_MAX",
    "ConversionError",
    "Scalar",
    "Value",
    "convert",
    "display_text",
    "element_type",
    "fits_f32",
    "is_array",
    "is_numeric",
    "to_f32",
    "truthy",
    "wrap32",
]

#: One element: byte/int16/int are ``int``, float/double are ``float``.
Scalar: TypeAlias = int | float | bool | str
#: A TMscript value: a scalar or a one-dimensional array.
Value: TypeAlias = Scalar | list[int] | list[float] | list[bool] | list[str] | list[Scalar]

#: The most elements an array holds (TMscript 2.24 §2.3, p. 18).
ARRAY_MAX = 2048
#: The most characters a string holds. The manual states no limit: this one is
#: tmmaster's, so that a program doubling a string ends with an error, not out of memory.
STRING_MAX = 65536

INTEGRAL = frozenset({"byte", "int16", "int", "int32"})
NUMERIC = INTEGRAL | {"float", "double"}
SCALARS = NUMERIC | {"bool", "string"}
_F32 = struct.Struct("<f")
FLOAT_MAX = 3.4028234663852886e38
#: Half a unit in the last place above FLOAT_MAX: a number this great or greater rounds to
#: infinity as a float (IEEE 754 round to nearest, a tie to the even 2**128), one below it
#: to a finite float (3.4028235e38, FLOAT_MAX as .NET shows it, is FLOAT_MAX).
FLOAT_LIMIT = 2.0**128 - 2.0**103


def fits_f32(value: float) -> bool:
    """Whether ``value`` rounds to a finite 32-bit float (NaN does not)."""
    return abs(value) < FLOAT_LIMIT


class ConversionError(Exception):
    """A value cannot be converted (raised to the evaluator, which adds line and column)."""


def is_array(typ: str) -> bool:
    """Whether ``typ`` (``"int[]"``...) is an array type."""
    return typ.endswith("[]")


def element_type(typ: str) -> str:
    """The element type of an array type (``"int[]"`` -> ``"int"``)."""
    return typ[:-2] if typ.endswith("[]") else typ


def is_numeric(typ: str) -> bool:
    """Whether ``typ`` is byte, int16, int, float or double."""
    return typ in NUMERIC


def wrap32(value: int) -> int:
    """Keep the low 32 bits as a signed int, as TMscript does (§2.2, p. 15)."""
    return ((value + 0x80000000) & 0xFFFFFFFF) - 0x80000000


def _wrap16(value: int) -> int:
    return ((value + 0x8000) & 0xFFFF) - 0x8000


def to_f32(value: float) -> float:
    """Round to the nearest 32-bit float (TMscript float, §2.1).

    :raises ConversionError: the value is out of a float's range, NaN or infinite (§2.5).
    """
    if not fits_f32(value):
        raise ConversionError(f"{_number_text(value, 'double')} cannot be converted to float")
    result: float = _F32.unpack(_F32.pack(value))[0]
    return result


def _parse_number(text: str) -> int | float:
    # Strings hold decimal, hexadecimal (0x) or binary (0b) numbers (§2.7, p. 27).
    body = text.strip()
    lower = body.lower()
    sign = -1 if lower.startswith("-") else 1
    digits = lower.lstrip("+-")
    try:
        if digits.startswith("0x"):
            return sign * int(digits[2:], 16)
        if digits.startswith("0b"):
            return sign * int(digits[2:], 2)
        if lower in ("nan", "inf", "-inf", "+inf", "infinity", "-infinity"):
            raise ValueError(lower)
        number = float(body)
    except ValueError:
        raise ConversionError(f'unable to convert "{text}" to a value') from None
    return number


def _to_integer(value: Scalar, typ: str, source: str) -> int:
    if isinstance(value, bool) or source == "bool":
        raise ConversionError(f"unable to convert {display_text(value, 'bool')} to {typ}")
    if isinstance(value, str):
        value = _parse_number(value)
    if isinstance(value, float):
        if math.isnan(value) or math.isinf(value):
            raise ConversionError(f"unable to convert {value} to {typ}")
        value = int(value)  # truncates toward zero: (int)1.23 == 1 (§2.5, p. 23)
    if typ == "byte":
        return value & 0xFF  # 8 bits kept: (byte)1000 == 232, -100 -> 156 (§2.2)
    if typ == "int16":
        return _wrap16(value)
    return wrap32(value)


def convert(value: Value, source: str, target: str) -> Value:
    """Convert ``value`` of type ``source`` to type ``target`` (TMscript 2.24 §2.5, p. 22-24).

    Arrays convert element by element; a scalar never becomes an array nor the reverse.

    :param value: the value.
    :param source: its TMscript type (``"?"`` when only known at run time).
    :param target: the type wanted.
    :returns: the converted value.
    :raises ConversionError: the documented conversion errors: a bool to a number, a
        string that is not a number to a number, a double out of a float's range.
    """
    if source == target and target not in ("float", "float[]"):
        return value
    if is_array(target):
        if not isinstance(value, list):
            raise ConversionError(f"a {source} cannot be converted to an array ({target})")
        elem = element_type(target)
        src_elem = element_type(source) if source != "?" else "?"
        return [_convert_scalar(item, src_elem, elem) for item in value]
    if isinstance(value, list):
        raise ConversionError(f"an array ({source}) cannot be converted to {target}")
    return _convert_scalar(value, source, target)


def _convert_scalar(value: Scalar | list[Scalar], source: str, target: str) -> Scalar:
    if isinstance(value, list):
        raise ConversionError("an array inside an array")
    if source == "?":
        source = _runtime_type(value)
    if target in INTEGRAL:
        return _to_integer(value, target, source)
    if target in ("float", "double"):
        if isinstance(value, bool) or source == "bool":
            raise ConversionError(f"unable to convert {display_text(value, 'bool')} to {target}")
        number = _parse_number(value) if isinstance(value, str) else value
        result = float(number)
        if target == "float":
            return to_f32(result)
        if math.isnan(result) or math.isinf(result):
            raise ConversionError(f"{result} is not a valid double")
        return result
    if target == "bool":
        if isinstance(value, str):
            # "true" is true, "false" false, other non-empty strings true (§2.5, p. 23).
            if value.lower() == "false":
                return False
            return value != ""
        return bool(value)
    if target == "string":
        return display_text(value, source)
    return value


def _runtime_type(value: Scalar) -> str:
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "int"
    if isinstance(value, float):
        return "double"
    return "string"


def truthy(value: Value) -> bool:
    """A condition's value (TMscript 2.24 §3.9.1, p. 39).

    Booleans as they are; numbers true when not zero; strings true only for ``true`` or
    ``True``.
    """
    if isinstance(value, bool):
        return value
    if isinstance(value, str):
        return value in ("true", "True")
    if isinstance(value, list):
        return len(value) > 0
    return value != 0


def _number_text(value: float, typ: str) -> str:
    # TMflow shows a float with 7 significant digits and a double with 15, exponents as
    # E+38 / E-34 (TMscript 2.24 §2.1 and the examples of §16.8, §16.9).
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "Infinity" if value > 0 else "-Infinity"
    text = ("%.7G" if typ == "float" else "%.15G") % value
    if "E" in text:
        mantissa, exponent = text.split("E")
        sign = exponent[0]
        digits = exponent[1:].lstrip("0").rjust(2, "0")
        text = f"{mantissa}E{sign}{digits}"
    if text in ("-0", "-0.0"):
        text = "0"
    return text


def display_text(value: Value, typ: str) -> str:
    """``value`` as TMflow shows it: ``Display()`` and string conversion (§2.5, §5.6).

    Booleans are ``true``/``false``; arrays ``{1,2,3}``; floats 7 significant digits.

    Args:
        value: A TMscript value.
        typ: Its TMscript type (``"float"``, ``"int[]"``...).

    Returns:
        The text.
    """
    if isinstance(value, list):
        elem = element_type(typ)
        return "{" + ",".join(display_text(item, elem) for item in value) + "}"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return _number_text(value, "float" if typ == "float" else "double")
    if isinstance(value, int):
        return str(value)
    return value


def default_value(typ: str) -> Value:
    """The value of a variable declared without one: 0, 0.0, false, empty, ``{}``."""
    if is_array(typ):
        return []
    if typ in INTEGRAL:
        return 0
    if typ in ("float", "double"):
        return 0.0
    if typ == "bool":
        return False
    return ""
