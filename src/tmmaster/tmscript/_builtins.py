"""The built-in functions: ONE registry keyed by the manual's section (TMscript 2.24).

Each :class:`Builtin` names its section and page, lists its signatures as the manual
writes them, and has one implementation. A function the manual lists but this registry
lacks is refused when the script is checked (:data:`UNSUPPORTED` names the known ones).

Types in signatures: ``byte int int16 float double bool string`` and arrays ``int[]``;
``?`` is any scalar, ``?[]`` any array, ``*`` anything; a return type ``$0`` is the type
of the first argument.
"""

from __future__ import annotations

import math
import random as _rng
import re
import struct
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass, field

from ._host import Host, ModbusCommunicationError, ModbusDevice, MotionCall
from ._types import (
    ARRAY_MAX,
    STRING_MAX,
    Scalar,
    Value,
    display_text,
    fits_f32,
    to_f32,
    wrap32,
)

__all__ = ["BUILTINS", "UNSUPPORTED", "Builtin", "BuiltinError", "Runtime", "Signature"]


class BuiltinError(Exception):
    """A built-in function refused its arguments (the evaluator adds line and column)."""


#: What a blocking built-in yields while it waits.
BLOCKED = "blocked"
PAUSED = "paused"


@dataclass
class ModbusConfig:
    """A ``ModbusTCP`` variable: where the device is, and its presets (§16.1)."""

    name: str
    host: str
    port: int
    timeout_ms: int
    presets: dict[str, tuple[int, str, int, str, int]] = field(default_factory=dict)
    _devices: dict[int, ModbusDevice] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def device(self, unit: int) -> ModbusDevice:
        """The device a request to slave ``unit`` goes to (made once per unit: immutable)."""
        device = self._devices.get(unit)
        if device is None:
            device = ModbusDevice(self.name, self.host, self.port, unit, self.timeout_ms)
            self._devices[unit] = device
        return device


class ExitRequest(Exception):  # noqa: N818 - a signal, not an error
    """``Exit()`` was called (TMscript 2.24 §5.1)."""

    def __init__(self, code: int, *, wait: bool = True) -> None:
        self.code = code
        #: Exit(false, ...): stop without waiting for the motion to end (§5.1, p. 154).
        self.wait = wait
        super().__init__(code)


class Runtime:
    """What built-ins reach while a script runs: the host and the declared devices."""

    def __init__(self, host: Host) -> None:
        self.host = host
        self.devices: dict[str, ModbusConfig] = {}
        self.motion_allowed = True
        self.paused = False
        #: The host's clock when the project started (GetNowStamp counts from it).
        self.started_s = 0.0
        #: The thread running now: 1 is main (ThreadRun numbers the others from 2).
        self.thread = 1


Impl = Callable[[Runtime, list[Value], tuple[str, ...]], Value]
BlockingImpl = Callable[[Runtime, list[Value], tuple[str, ...]], Generator[str, None, Value]]


@dataclass(frozen=True)
class Signature:
    """One syntax of a function: parameter types and return type."""

    #: The parameters' TMscript types (``"int"``, ``"string[]"``...).
    params: tuple[str, ...]
    #: The return type (``"void"`` for none).
    returns: str


@dataclass(frozen=True)
class Builtin:
    """A built-in function: its manual section and page, its syntaxes, its implementation."""

    #: The function's name, as a script calls it.
    name: str
    #: Its section of the TMscript 2.24 manual.
    section: str
    #: Its page in the manual.
    page: int
    #: Every syntax it accepts.
    signatures: tuple[Signature, ...]
    #: The implementation of a function that returns at once.
    impl: Impl | None = None
    #: The implementation of a function that may wait (a generator).
    blocking: BlockingImpl | None = None
    #: It moves the robot: refused in closestop and errorstop (§3.3, §3.4).
    motion: bool = False
    #: A Modbus function (``blocking`` waits for the link, then calls this): the
    #: evaluator runs the wait and the call in one generator, not two nested ones.
    linked: Impl | None = None


#: Every function this interpreter runs, by name.
BUILTINS: dict[str, Builtin] = {}


def _sigs(*specs: str) -> tuple[Signature, ...]:
    out = []
    for spec in specs:
        ret, _, params = spec.partition("(")
        names = tuple(p.strip() for p in params.rstrip(")").split(",") if p.strip())
        out.append(Signature(names, ret.strip()))
    return tuple(out)


def _register(section: str, page: int, *specs: str, motion: bool = False) -> Callable[[Impl], Impl]:
    def decorate(fn: Impl) -> Impl:
        name = fn.__name__.lstrip("_")
        BUILTINS[name] = Builtin(name, section, page, _sigs(*specs), impl=fn, motion=motion)
        return fn

    return decorate


def _register_linked(section: str, page: int, *specs: str) -> Callable[[Impl], Impl]:
    """A Modbus function: it waits at the call until the host's link can take the request."""

    def decorate(fn: Impl) -> Impl:
        def wait_then_call(
            rt: Runtime, args: list[Value], types: tuple[str, ...]
        ) -> Generator[str, None, Value]:
            device = link_device(rt, args)
            while not rt.host.modbus_ready(device):
                yield BLOCKED
            return fn(rt, args, types)

        name = fn.__name__.lstrip("_")
        BUILTINS[name] = Builtin(
            name, section, page, _sigs(*specs), blocking=wait_then_call, linked=fn
        )
        return fn

    return decorate


def link_device(rt: Runtime, args: list[Value]) -> ModbusDevice:
    """The device whose link a Modbus function's call (``args``) waits for."""
    return _device(rt, args[0], 0)


def _register_blocking(
    section: str, page: int, *specs: str
) -> Callable[[BlockingImpl], BlockingImpl]:
    def decorate(fn: BlockingImpl) -> BlockingImpl:
        name = fn.__name__.lstrip("_")
        BUILTINS[name] = Builtin(name, section, page, _sigs(*specs), blocking=fn)
        return fn

    return decorate


#: What a number is (a tuple: a cheaper isinstance than ``int | float``, called for every
#: numeric argument).
_NUMBER = (int, float)


def _int(v: Value) -> int:
    if v.__class__ is int:  # the common case first (a bool is no int here)
        return v
    if isinstance(v, bool) or not isinstance(v, _NUMBER):
        raise BuiltinError(f"expected a number, got {v!r}")
    return int(v)


def _int_arg(args: list[Value], index: int) -> int:
    """The optional int argument at ``index``, 0 when the call leaves it out."""
    return _int(args[index]) if len(args) > index else 0


def _num(v: Value) -> float:
    if isinstance(v, bool) or not isinstance(v, _NUMBER):
        raise BuiltinError(f"expected a number, got {v!r}")
    return float(v)


def _str(v: Value) -> str:
    if not isinstance(v, str):
        raise BuiltinError(f"expected a string, got {v!r}")
    return v


def _arr(v: Value) -> list[Scalar]:
    if not isinstance(v, list):
        raise BuiltinError(f"expected an array, got {v!r}")
    return list(v)


#: The element types ``bytes()`` may take as they are (a bool is refused by ``_int``).
_PLAIN_INTS = frozenset({int})


def _bytes(v: Value) -> bytes:
    if v.__class__ is list and _PLAIN_INTS.issuperset(map(type, v)):
        try:
            return bytes(v)  # type: ignore[arg-type]
        except ValueError:
            pass  # an element out of 0..255: its low 8 bits, below
    return bytes(_int(b) & 0xFF for b in _arr(v))


def _floats(v: Value) -> list[float]:
    return [_num(x) for x in _arr(v)]


def _checked(items: list[Scalar]) -> list[Scalar]:
    if len(items) > ARRAY_MAX:
        raise BuiltinError(f"an array holds at most {ARRAY_MAX} elements")
    return items


# ---- chapter 4: general functions ------------------------------------------------------


def _endian_bytes(data: bytes, size: int, endian: int) -> bytes:
    # Too short: filled up with zeros before converting (TMscript 2.24 §4.1, p. 52).
    chunk = data[:size].ljust(size, b"\0")
    return chunk if endian == 1 else chunk[::-1]


def _int16(data: bytes, endian: int, unsigned: int) -> int:
    raw = int.from_bytes(_endian_bytes(data, 2, endian), "big")
    return raw if unsigned == 1 else raw - 0x10000 if raw & 0x8000 else raw


@_register("4.1", 52, "int(byte[], int, int)", "int(byte[], int)", "int(byte[])")
def _Byte_ToInt16(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.1 Byte_ToInt16, p. 52: 2 bytes, 0 Little / 1 Big Endian, signed/unsigned."""
    endian = _int_arg(args, 1)
    unsigned = _int_arg(args, 2)
    return _int16(_bytes(args[0]), endian, unsigned)


def _int32(data: bytes, endian: int) -> int:
    return int.from_bytes(_endian_bytes(data, 4, endian), "big", signed=True)


@_register("4.2", 54, "int(byte[], int)", "int(byte[])")
def _Byte_ToInt32(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.2 Byte_ToInt32, p. 54: 4 bytes, 0 Little (default) / 1 Big Endian."""
    endian = _int_arg(args, 1)
    return _int32(_bytes(args[0]), endian)


def _float32(data: bytes, endian: int) -> float:
    value: float = struct.unpack(">f", _endian_bytes(data, 4, endian))[0]
    return value


@_register("4.3", 55, "float(byte[], int)", "float(byte[])")
def _Byte_ToFloat(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.3 Byte_ToFloat, p. 55: IEEE-754 single from 4 bytes."""
    endian = _int_arg(args, 1)
    return _float32(_bytes(args[0]), endian)


def _float64(data: bytes, endian: int) -> float:
    value: float = struct.unpack(">d", _endian_bytes(data, 8, endian))[0]
    return value


@_register("4.4", 56, "double(byte[], int)", "double(byte[])")
def _Byte_ToDouble(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.4 Byte_ToDouble, p. 56: IEEE-754 double from 8 bytes."""
    return _float64(_bytes(args[0]), _int_arg(args, 1))


def _chunks(data: bytes, size: int) -> list[bytes]:
    return [data[i : i + size] for i in range(0, len(data), size)]


# The arrays convert each chunk as the scalar function does; the endianness (and
# signedness) arguments are checked once, when there is a chunk to convert.


@_register("4.5", 57, "int[](byte[], int, int)", "int[](byte[], int)", "int[](byte[])")
def _Byte_ToInt16Array(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.5 Byte_ToInt16Array, p. 57: every 2 bytes to an int16."""
    return int16_array(_bytes(args[0]), args)


def int16_array(data: bytes, args: list[Value]) -> list[int]:
    """Byte_ToInt16Array of the bytes ``data`` with its call's ``args`` (the byte order
    and signedness at 1 and 2; the bytes at 0 are not read): a new list.

    Raises:
        BuiltinError: A byte order or signedness that is not a number.
    """
    if not data:
        return []
    # _int_arg() of plain ints written out: a program converts every register read so.
    count = len(args)
    endian = args[1] if count > 1 and args[1].__class__ is int else _int_arg(args, 1)
    unsigned = args[2] if count > 2 and args[2].__class__ is int else _int_arg(args, 2)
    if len(data) & 1:
        data += b"\0"  # the last chunk filled up with a zero, as _int16 does
    # One unpack of every chunk, as _int16 converts each: 1 Big Endian, any other Little.
    order = ">" if endian == 1 else "<"
    return list(struct.unpack(f"{order}{len(data) // 2}{'H' if unsigned == 1 else 'h'}", data))


@_register("4.6", 59, "int[](byte[], int)", "int[](byte[])")
def _Byte_ToInt32Array(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.6 Byte_ToInt32Array, p. 59: every 4 bytes to an int."""
    chunks = _chunks(_bytes(args[0]), 4)
    if not chunks:
        return []
    endian = _int_arg(args, 1)
    return [_int32(c, endian) for c in chunks]


@_register("4.7", 60, "float[](byte[], int)", "float[](byte[])")
def _Byte_ToFloatArray(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.7 Byte_ToFloatArray, p. 60: every 4 bytes to a float."""
    chunks = _chunks(_bytes(args[0]), 4)
    if not chunks:
        return []
    endian = _int_arg(args, 1)
    return [_float32(c, endian) for c in chunks]


@_register("4.8", 61, "double[](byte[], int)", "double[](byte[])")
def _Byte_ToDoubleArray(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.8 Byte_ToDoubleArray, p. 61: every 8 bytes to a double."""
    chunks = _chunks(_bytes(args[0]), 8)
    if not chunks:
        return []
    endian = _int_arg(args, 1)
    return [_float64(c, endian) for c in chunks]


@_register("4.9", 62, "string(byte[], int)", "string(byte[])")
def _Byte_ToString(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.9 Byte_ToString, p. 62: 0 UTF-8, 1 hexadecimal, 2 ASCII (stop at 0x00)."""
    data = _bytes(args[0])
    mode = _int_arg(args, 1)
    if mode == 1:
        return data.hex().upper()
    text = data.split(b"\0", 1)[0]
    if mode == 2:
        return "".join(chr(b) if b < 0x80 else "?" for b in text)
    return text.decode("utf-8", errors="replace")


def _concat_part(items: list[Scalar], start: int, count: int) -> list[Scalar]:
    # A start < 0 is 0; a count < 0 or past the end takes the rest (§4.10 syntaxes 3, 4).
    start = max(start, 0)
    return items[start:] if count < 0 else items[start : start + count]


def _concat_any(args: list[Value], types: tuple[str, ...]) -> list[Scalar]:
    # Syntax 5: each byte or byte[] in order; any other type is left out (p. 65).
    out: list[Scalar] = []
    for value, typ in zip(args, types, strict=True):
        if typ == "byte[]":
            out.extend(_arr(value))
        elif typ == "byte":
            out.append(_int(value) & 0xFF)
    return out


@_register(
    "4.10",
    63,
    "byte[](byte[], byte[])",
    "byte[](byte[], byte)",
    "byte[](byte[], byte[], int)",
    "byte[](byte[], int, int, byte[], int, int)",
    "byte[](*, *, *...)",
)
def _Byte_Concat(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.10 Byte_Concat, pp. 63-65: an array and a byte or an array (1, 2),
    part of the second array (3), parts of both (4), or any bytes and byte arrays (5)."""
    if types == ("byte[]", "byte[]", "int"):
        part = _concat_part(_arr(args[1]), 0, _int(args[2]))
        return _checked([*_arr(args[0]), *part])
    if types == ("byte[]", "int", "int", "byte[]", "int", "int"):
        first = _concat_part(_arr(args[0]), _int(args[1]), _int(args[2]))
        return _checked([*first, *_concat_part(_arr(args[3]), _int(args[4]), _int(args[5]))])
    if len(types) > 2:
        return _checked(_concat_any(args, types))
    second = args[1]
    tail: list[Scalar] = list(second) if isinstance(second, list) else [second]
    return _checked([*_arr(args[0]), *(_int(b) & 0xFF for b in tail)])


_DIGITS = {10: "0123456789", 16: "0123456789abcdef", 2: "01"}
_DECIMAL = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")


def _notation(text: str, base: int) -> tuple[int, str] | None:
    """The base and digits of an integer text, or None when it is not valid in ``base``.

    Base 10 also detects the 0x and 0b prefixes; base 16 takes an 0x prefix and base 2 an
    0b prefix (TMscript 2.24 §4.11, p. 66: "0b1100" in base 16 is 0x0B1100). A sign goes
    only before decimal digits ("-0x1234" is not valid).
    """
    body = text.strip().lower()
    prefix = {16: "0x", 2: "0b"}
    if base == 10:
        for detected, mark in prefix.items():
            if body.startswith(mark):
                base, body = detected, body[2:]
                break
        else:
            if body[:1] in ("+", "-") and body[1:2].isdigit():
                return (10, body) if body[1:].isdigit() else None
    elif base in prefix and body.startswith(prefix[base]):
        body = body[2:]
    if base not in _DIGITS or not body or any(c not in _DIGITS[base] for c in body):
        return None
    return base, body


def _parse_int(text: str, base: int) -> int:
    # Text that is not valid in the notation gives 0 (TMscript 2.24 §4.11, p. 66).
    found = _notation(text, base)
    return 0 if found is None else wrap32(int(found[1], found[0]))


@_register("4.11", 66, "int(string, int)", "int(string)", "int[](string[], int)", "int[](string[])")
def _String_ToInteger(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.11 String_ToInteger, p. 66: base 10 (or 0x/0b), 16 or 2; invalid: 0."""
    base = _int(args[1]) if len(args) > 1 else 10
    if isinstance(args[0], list):
        return [_parse_int(_str(s), base) for s in args[0]]
    return _parse_int(_str(args[0]), base)


def _parse_real(text: str, base: int, size: int) -> float:
    """A float (``size`` 4) or double (8) from text; invalid text gives 0 (§4.12, §4.13).

    Decimal text is read as a number; hexadecimal or binary text (by base or by its 0x/0b
    prefix) gives the IEEE-754 number with those bits ("0x1234" is 6.53E-42 as a float).
    """
    if base == 10 and _DECIMAL.fullmatch(text.strip()):
        value = float(text.strip())
        return to_f32(value) if size == 4 and fits_f32(value) else value
    found = _notation(text, base)
    if found is None or found[0] == 10:
        return 0.0
    bits = int(found[1], found[0]) & ((1 << (8 * size)) - 1)
    (value,) = struct.unpack("<f" if size == 4 else "<d", bits.to_bytes(size, "little"))
    return 0.0 if math.isnan(value) or math.isinf(value) else float(value)


def _to_real(args: list[Value], size: int) -> Value:
    base = _int(args[1]) if len(args) > 1 else 10
    if isinstance(args[0], list):
        return [_parse_real(_str(s), base, size) for s in args[0]]
    return _parse_real(_str(args[0]), base, size)


@_register(
    "4.12", 68, "float(string, int)", "float(string)", "float[](string[], int)", "float[](string[])"
)
def _String_ToFloat(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.12 String_ToFloat, p. 68: base 10 (or 0x/0b), 16 or 2; invalid: 0."""
    return _to_real(args, 4)


@_register(
    "4.13",
    70,
    "double(string, int)",
    "double(string)",
    "double[](string[], int)",
    "double[](string[])",
)
def _String_ToDouble(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.13 String_ToDouble, p. 70: base 10 (or 0x/0b), 16 or 2; invalid: 0."""
    return _to_real(args, 8)


def _hex_bytes(text: str) -> list[Scalar]:
    # Hexadecimal digits up to the first that is not one, two a byte, the last one filled
    # with 0; none at all gives {0x00} (TMscript 2.24 §4.14, p. 72).
    digits = ""
    for char in text:
        if char.lower() not in _DIGITS[16]:
            break
        digits += char
    digits = (digits or "0") + "0" * (len(digits or "0") % 2)
    return list(bytes.fromhex(digits))


@_register("4.14", 72, "byte[](string, int)", "byte[](string)")
def _String_ToByte(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.14 String_ToByte, p. 72: 0 UTF-8 (default), 1 hexadecimal, 2 ASCII."""
    text, mode = _str(args[0]), _int_arg(args, 1)
    if mode == 1:
        return _checked(_hex_bytes(text))
    if mode == 2:
        return _checked(list(text.encode("ascii", errors="replace")))
    return _checked(list(text.encode("utf-8")))


@_register(
    "4.15",
    73,
    "int(string, string, int)",
    "int(string, string)",
    "int(string[], string, int)",
    "int(string[], string)",
)
def _String_IndexOf(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.15 String_IndexOf, p. 73: first index of the substring, -1 if none.

    In a string array (syntaxes 3, 4): the first element from ``start`` that holds it.
    """
    sub, start = _str(args[1]), _int_arg(args, 2)
    if isinstance(args[0], list):
        items = [_str(item) for item in args[0]]
        return next((i for i in range(max(start, 0), len(items)) if sub in items[i]), -1)
    text = _str(args[0])
    if start < 0 or start > len(text):
        return -1
    return text.find(sub, start)


@_register(
    "4.16",
    75,
    "int(string, string, int)",
    "int(string, string)",
    "int(string[], string, int)",
    "int(string[], string)",
)
def _String_LastIndexOf(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.16 String_LastIndexOf, p. 75: last index of the substring, -1 if none.

    In a string array (syntaxes 3, 4): the last element up to ``start`` that holds it.
    """
    sub = _str(args[1])
    if isinstance(args[0], list):
        items = [_str(item) for item in args[0]]
        start = min(_int(args[2]), len(items) - 1) if len(args) > 2 else len(items) - 1
        return next((i for i in range(start, -1, -1) if sub in items[i]), -1)
    text = _str(args[0])
    if len(args) > 2:
        start = _int(args[2])
        if start < 0:
            return -1
        return text.rfind(sub, 0, start + len(sub))
    return text.rfind(sub)


@_register("4.17", 77, "int(string, string, int)", "int(string, string)")
def _String_DiffIndexOf(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.17 String_DiffIndexOf, p. 77: where two strings first differ from
    ``start``: -1 when they match, -2 when ``start`` is past both (a shorter string reads
    as '\\0' past its end)."""
    first, second, start = _str(args[0]), _str(args[1]), max(_int_arg(args, 2), 0)
    if first == second:
        return -1
    if start >= max(len(first), len(second)):
        return -2
    for i in range(start, max(len(first), len(second))):
        if first[i : i + 1] != second[i : i + 1]:
            return i
    return -1


def _substring(text: str, start: int, length: int) -> str:
    if start < 0 or start >= len(text):
        return ""
    return text[start:] if length < 0 else text[start : start + length]


def _between(text: str, prefix: str, suffix: str, count: int) -> str:
    """The ``count``-th part of ``text`` from ``prefix`` to ``suffix`` (§4.18 syntax 5)."""
    if not prefix and not suffix:
        return text
    if count <= 0:
        return ""
    if not prefix:
        end = len(text)
        for _ in range(count):  # suffixes counted from the back (p. 80)
            end = text.rfind(suffix, 0, end)
            if end < 0:
                return ""
        return text[: end + len(suffix)]
    at = 0
    for _ in range(count):
        begin = text.find(prefix, at)
        if begin < 0:
            return ""
        finish = text.find(suffix, begin + len(prefix)) if suffix else len(text)
        if finish < 0:
            return ""
        at = finish + len(suffix) if suffix else begin + len(prefix)
    return text[begin : finish + len(suffix)] if suffix else text[begin:]


@_register(
    "4.18",
    78,
    "string(string, int, int)",
    "string(string, int)",
    "string(string, string, int)",
    "string(string, string)",
    "string(string, string, string, int)",
    "string(string, string, string)",
)
def _String_Substring(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.18 String_Substring, pp. 78-80: by start index and length
    (syntaxes 1, 2), from a target string (3, 4), or between a prefix and a suffix (5, 6).

    A start out of the string gives ``""``; a negative or too long length runs to the end.
    """
    text = _str(args[0])
    if types[1] == "string" and len(types) > 2 and types[2] == "string":
        count = _int(args[3]) if len(args) > 3 else 1
        return _between(text, _str(args[1]), _str(args[2]), count)
    length = _int(args[2]) if len(args) > 2 else -1
    if types[1] == "string":
        start = text.find(_str(args[1]))
        return "" if start < 0 else _substring(text, start, length)
    return _substring(text, _int(args[1]), length)


def _split_quoted(text: str, sep: str) -> list[str]:
    # A separator inside double quotation marks does not split (§4.19 options 2, 3).
    parts, current, quoted, i = [], "", False, 0
    while i < len(text):
        if text[i] == '"':
            quoted = not quoted
        elif not quoted and text.startswith(sep, i):
            parts.append(current)
            current, i = "", i + len(sep)
            continue
        current += text[i]
        i += 1
    return [*parts, current]


@_register("4.19", 81, "string[](string, string, int)", "string[](string, string)")
def _String_Split(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.19 String_Split, p. 81: options 0/2 keep empty strings, 1/3 drop
    them; 2 and 3 do not split inside double quotation marks."""
    text, sep = _str(args[0]), _str(args[1])
    option = _int_arg(args, 2)
    if option not in (0, 1, 2, 3):
        raise BuiltinError(f"option {option} is not 0, 1, 2 or 3")
    if not sep:
        parts: list[Scalar] = [text]
    else:
        parts = list(_split_quoted(text, sep) if option >= 2 else text.split(sep))
    if option in (1, 3):
        parts = [p for p in parts if p != ""]
    return _checked(parts)


@_register("4.20", 82, "string(string, string, string)")
def _String_Replace(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.20 String_Replace, p. 82 (an empty search string replaces nothing)."""
    text, old, new = _str(args[0]), _str(args[1]), _str(args[2])
    if not old:
        return text
    # Counted before it is built: a short text can grow past any memory.
    length = len(text) + text.count(old) * (len(new) - len(old))
    if length > STRING_MAX:
        raise BuiltinError(f"a string holds at most {STRING_MAX} characters, not {length}")
    return text.replace(old, new)


def _trim_start(text: str, word: str) -> str:
    while word and text.startswith(word):
        text = text[len(word) :]
    return text


def _trim_end(text: str, word: str) -> str:
    while word and text.endswith(word):
        text = text[: -len(word)]
    return text


@_register("4.21", 83, "string(string)", "string(string, string)", "string(string, string, string)")
def _String_Trim(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.21 String_Trim, pp. 83-84: white space off both ends (syntax 1), or
    every leading repeat of a string (2) and every trailing repeat of another (3)."""
    text = _str(args[0])
    if len(args) == 1:
        return text.strip()
    text = _trim_start(text, _str(args[1]))
    return _trim_end(text, _str(args[2])) if len(args) > 2 else text


@_register("4.22", 85, "string(string)")
def _String_ToLower(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.22 String_ToLower, p. 85."""
    return _str(args[0]).lower()


@_register("4.23", 86, "string(string)")
def _String_ToUpper(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.23 String_ToUpper, p. 86."""
    return _str(args[0]).upper()


@_register("4.24", 87, "$0(?[], *)")
def _Array_Append(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.24 Array_Append, p. 87: an element or an array at the end."""
    second = args[1]
    tail: list[Scalar] = list(second) if isinstance(second, list) else [second]
    return _checked([*_arr(args[0]), *tail])


@_register("4.25", 88, "$0(?[], int, *)")
def _Array_Insert(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.25 Array_Insert, p. 88: an element or an array before ``index``.

    An index < 0 stops the project; one past the end appends (p. 88: "Out of the index. The
    value will insert in the end of the array").
    """
    items, index = _arr(args[0]), _int(args[1])
    if index < 0:
        raise BuiltinError(f"index {index} is out of the array (0..{len(items)})")
    second = args[2]
    middle: list[Scalar] = list(second) if isinstance(second, list) else [second]
    return _checked([*items[:index], *middle, *items[index:]])


@_register("4.26", 89, "$0(?[], int, int)", "$0(?[], int)")
def _Array_Remove(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.26 Array_Remove, p. 89: ``count`` elements (default 1) from ``index``."""
    items, index = _arr(args[0]), _int(args[1])
    count = _int(args[2]) if len(args) > 2 else 1
    if index < 0 or index >= len(items):
        raise BuiltinError(f"index {index} is out of the array")
    return [*items[:index], *items[index + max(count, 0) :]]


@_register("4.27", 90, "bool(?[], ?[])", "bool(?[], int, ?[], int, int)")
def _Array_Equals(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.27 Array_Equals, pp. 90-91: the whole arrays (syntax 1), or ``count``
    elements of each from a start index (syntax 2: 0 elements are equal; a count < 0, a
    start out of its array or a range past its end is not)."""
    if len(args) == 2:
        return _arr(args[0]) == _arr(args[1])
    first, second = _arr(args[0]), _arr(args[2])
    start1, start2, count = _int(args[1]), _int(args[3]), _int(args[4])
    if count == 0:
        return True
    if count < 0 or min(start1, start2) < 0:
        return False
    if start1 + count > len(first) or start2 + count > len(second):
        return False
    return first[start1 : start1 + count] == second[start2 : start2 + count]


@_register("4.28", 92, "int(?[], ?, int)", "int(?[], ?)")
def _Array_IndexOf(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.28 Array_IndexOf, p. 92: first index of the element, -1 if none."""
    items = _arr(args[0])
    start = _int_arg(args, 2)
    for i in range(max(start, 0), len(items)):
        if items[i] == args[1]:
            return i
    return -1


@_register("4.29", 94, "int(?[], ?, int)", "int(?[], ?)")
def _Array_LastIndexOf(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.29 Array_LastIndexOf, p. 94: last index of the element at or before
    ``start`` (default: the last element), -1 if none."""
    items = _arr(args[0])
    start = min(_int(args[2]), len(items) - 1) if len(args) > 2 else len(items) - 1
    for i in range(start, -1, -1):
        if items[i] == args[1]:
            return i
    return -1


@_register("4.30", 96, "$0(?[])", "$0(?[], int)")
def _Array_Reverse(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.30 Array_Reverse, p. 96: the whole array, or within sections of N."""
    items = _arr(args[0])
    if len(args) == 1:
        return items[::-1]
    size = _int(args[1])
    if size <= 0:
        raise BuiltinError(f"section size {size} must be at least 1")
    out: list[Scalar] = []
    for i in range(0, len(items), size):
        out.extend(items[i : i + size][::-1])
    return out


@_register("4.31", 98, "$0(?[], int)", "$0(?[])")
def _Array_Sort(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.31 Array_Sort, p. 98: 0 ascending (default), 1 descending."""
    items = _arr(args[0])
    descending = len(args) > 1 and _int(args[1]) == 1
    return sorted(
        items, key=lambda v: (str(v), 0) if isinstance(v, str) else ("", v), reverse=descending
    )


@_register("4.32", 99, "$0(?[], int, int)", "$0(?[], int)")
def _Array_SubElements(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.32 Array_SubElements, p. 99: ``count`` elements from ``index``.

    "If sub-element number <0, sub-elements starts at starting index to the last element".
    """
    items, index = _arr(args[0]), _int(args[1])
    if index < 0 or index >= len(items):
        return []
    count = _int(args[2]) if len(args) > 2 else len(items)
    return items[index:] if count < 0 else items[index : index + count]


def _value_bytes(value: Value, typ: str) -> bytes:
    # Little Endian by default (TMscript 2.24 §2.6, p. 25).
    if isinstance(value, list):
        elem = typ[:-2] if typ.endswith("[]") else "?"
        return b"".join(_value_bytes(v, elem) for v in value)
    if isinstance(value, bool):
        return b"\x01" if value else b"\x00"
    if isinstance(value, str):
        return value.encode("utf-8")
    if isinstance(value, float):
        return struct.pack("<f" if typ == "float" else "<d", value)
    if typ == "byte":
        return bytes([value & 0xFF])
    if typ == "int16":
        return struct.pack("<h", ((value + 0x8000) & 0xFFFF) - 0x8000)
    return struct.pack("<i", wrap32(value))


def _int_bytes(value: int, big: bool, mode: int) -> bytes:
    # Mode 0 int32; 1 int16 when the value fits one, else int32; 2 int16, the low 16 bits
    # (TMscript 2.24 §4.34 syntaxes 3 and 4, p. 107).
    short = mode == 2 or (mode == 1 and -0x8000 <= value <= 0x7FFF)
    data = (
        struct.pack("<h", ((value + 0x8000) & 0xFFFF) - 0x8000)
        if short
        else _value_bytes(value, "int")
    )
    return data[::-1] if big else data


@_register(
    "4.34",
    105,
    "byte[](int, int, int)",
    "byte[](int[], int, int)",
    "byte[](*, int)",
    "byte[](*)",
)
def _GetBytes(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.34 GetBytes, pp. 105-108: 0 Little Endian (default), 1 Big Endian
    per value; a string array with 1 puts 0x00 0x00 between its strings; an int or int[]
    with a third argument: 0 int32, 1 int16 where it fits, 2 int16."""
    big = len(args) > 1 and _int(args[1]) == 1
    value, typ = args[0], types[0]
    if len(args) == 3:
        items = value if isinstance(value, list) else [value]
        mode = _int(args[2])
        return _checked([b for item in items for b in _int_bytes(_int(item), big, mode)])
    if typ == "string[]" and big:
        joined = b"\0\0".join(_str(item).encode("utf-8") for item in _arr(value))
        return _checked(list(joined))
    if not big or isinstance(value, str):
        return _checked(list(_value_bytes(value, typ)))
    items = value if isinstance(value, list) else [value]
    elem = typ[:-2] if typ.endswith("[]") else typ
    out: list[Scalar] = []
    for item in items:
        out.extend(_value_bytes(item, elem)[::-1])
    return _checked(out)


@_register("4.39", 128, "int()", "double(bool)")
def _GetNowStamp(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.39 GetNowStamp, p. 128: the project's run time, ms (-1: overflow)."""
    # A host whose clock runs faster than the wall clock (a simulator's time_scale)
    # counts its seconds in wall seconds here, the clock a master's heartbeat keeps.
    scale = getattr(rt.host, "stamp_scale", 1.0)
    ms = int((rt.host.now_s() - rt.started_s) * 1000.0 / scale)
    if args and args[0]:
        return float(ms)
    stamp = ms if ms <= 2**31 - 1 else -1
    return float(stamp) if args else stamp  # GetNowStamp(false): a double (Syntax 2)


# ThreadRun(statement, bool) runs its statement in a thread of its own: the evaluator
# compiles it (TMscript 2.24 §3.12.1, p. 47); this entry gives its signatures.
@_register("3.12.1", 47, "int(*, bool)", "int(*)")
def _ThreadRun(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §3.12.1 ThreadRun, p. 47 (compiled by the evaluator)."""
    raise BuiltinError("ThreadRun is compiled by the evaluator")  # pragma: no cover


@_register("4.42", 133, "int(*)")
def _Length(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §4.42 Length, p. 133: bytes of a number, characters, or elements."""
    value, typ = args[0], types[0]
    if isinstance(value, list | str):
        return len(value)
    return len(_value_bytes(value, typ))


# ---- chapter 5: script functions -------------------------------------------------------


@_register("5.1", 154, "void(bool, int)", "void(bool)", "void()", "void(int)")
def _Exit(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §5.1 Exit, p. 154: > 0 closestop, 0 by whether it erred, < 0 errorstop."""
    code = 0
    wait = True
    for arg, typ in zip(args, types, strict=True):
        if typ != "bool":
            code = _int(arg)
        else:
            wait = bool(arg)
    raise ExitRequest(code, wait=wait)


@_register_blocking("5.2", 156, "bool()")
def _Pause(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Generator[str, None, Value]:  # noqa: N802
    """TMscript 2.24 §5.2 Pause, p. 156: the host pauses; the script waits for a resume.

    Pause stops "the project and the motion of the robot other than non-paused threads":
    a non-pause thread that calls it goes on (§3.12, p. 47).
    """
    rt.host.pause()
    rt.paused = True
    threads = getattr(rt, "threads", ())
    if any(t.ident == rt.thread and t.nonpause for t in threads):
        return True
    while rt.paused:
        yield PAUSED
    return True


@_register("5.3", 157, "bool()")
def _Resume(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §5.3 Resume, p. 157: "Resume the project and the motion of the robot".

    Called while the project is paused (from a non-pause thread, §3.12 p. 47; §5.2 p. 156:
    "Use Resume() or press the Play button"), the host resumes it, where it can.
    """
    resume = getattr(rt.host, "resume", None)
    if resume is not None:
        resume()
    return True


def _wait_ms(rt: Runtime, ms: int) -> Generator[str, None, Value]:
    if ms < 0:
        return False  # "invalid" (TMscript 2.24 §5.5, p. 159)
    now_s = rt.host.now_s  # looked up once: a program's poll loop sleeps in every turn
    until = now_s() + ms / 1000.0
    while now_s() < until:
        yield BLOCKED
    return True


@_register_blocking("5.5", 159, "bool(int)")
def _Sleep(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Generator[str, None, Value]:  # noqa: N802
    """TMscript 2.24 §5.5 Sleep, p. 159: waits on the host's clock."""
    return (yield from _wait_ms(rt, _int(args[0])))


# WaitFor(bool, int) evaluates its condition again on every poll: the evaluator compiles it
# (TMscript 2.24 §5.4, p. 158); this entry gives its signatures and WaitFor(int).
@_register_blocking("5.4", 158, "bool(bool, int)", "bool(int)")
def _WaitFor(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Generator[str, None, Value]:  # noqa: N802
    """TMscript 2.24 §5.4 WaitFor, p. 158 (syntax 2: a time)."""
    return (yield from _wait_ms(rt, _int(args[0])))


@_register(
    "5.6", 160, "bool(string, string, string, string)", "bool(string, string)", "bool(string)"
)
def _Display(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §5.6 Display, p. 160: the text goes to the host (colours are dropped).

    With a headline (syntaxes 1 and 2) the host gets ``headline: text``.
    """
    texts = [_str(a) for a in args]
    if len(texts) == 4:
        texts = texts[2:]
    text = texts[-1] if len(texts) == 1 or texts[0] == "" else f"{texts[0]}: {texts[1]}"
    rt.host.display(text)
    return True


# ---- chapter 6: math -------------------------------------------------------------------


def _real(value: float, types: tuple[str, ...]) -> float:
    """A result in the syntax's type: a float syntax (float arguments) returns a float."""
    return to_f32(value) if types and types[0] == "float" and fits_f32(value) else value


def _math1(section: str, page: int, name: str, fn: Callable[[float], float]) -> None:
    # Syntax 1 float(float), syntax 2 double(double): an int argument widens to a float
    # (TMscript 2.24 §2.2, p. 15; d2r(1) is 0.017453292, a float, p. 181).
    def impl(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
        try:
            result = fn(_num(args[0]))
        except (ValueError, OverflowError):
            raise BuiltinError(f"{name}({display_text(args[0], types[0])}) is undefined") from None
        return _real(result, types)

    impl.__doc__ = f"TMscript 2.24 §{section} {name}, p. {page}."
    BUILTINS[name] = Builtin(
        name, section, page, _sigs("float(float)", "double(double)"), impl=impl
    )


@_register("6.1", 165, "$0(?)")
def _abs(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §6.1 abs, p. 165: same type as the argument."""
    value = args[0]
    if isinstance(value, int) and not isinstance(value, bool):
        return wrap32(abs(value))
    return abs(_num(value))


@_register("6.2", 166, "int(int, double)", "float(float, double)", "double(double, double)")
def _pow(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §6.2 pow, pp. 166-167: in the base's type (an int base: the power
    truncated to an int, pow(100, -2) is 0); NaN is an error."""
    try:
        power = math.pow(_num(args[0]), _num(args[1]))
    except (ValueError, OverflowError, ZeroDivisionError):
        raise BuiltinError("the power is undefined") from None
    if types[0] == "int":
        if math.isinf(power) or abs(power) >= 2**63:
            raise BuiltinError("the power is out of an int's range")
        return wrap32(int(power))
    return _real(power, types)


_math1("6.3", 168, "sqrt", math.sqrt)
_math1("6.4", 169, "ceil", lambda x: float(math.ceil(x)))
_math1("6.5", 170, "floor", lambda x: float(math.floor(x)))


@_register("6.6", 171, "float(float, int)", "float(float)", "double(double, int)", "double(double)")
def _round(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §6.6 round, pp. 171-172: half away from zero, in the argument's type;
    digits 0..15, any other number of digits is 0."""
    value = _num(args[0])
    places = _int_arg(args, 1)
    if not 0 <= places <= 15:
        places = 0
    scale = 10.0**places
    rounded = math.copysign(math.floor(abs(value) * scale + 0.5) / scale, value)
    return _real(rounded + 0.0, types)


@_register("6.7", 173, "float()", "int(int)", "int(int, int)")
def _random(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §6.7 random, pp. 173-174: a float in [0, 1); an int in [0, max) (0 when
    max <= 0); an int in [min, max) (min when max <= min)."""
    rng = getattr(rt.host, "random", _rng)  # a host may keep its own (a simulator's)
    if not args:
        return to_f32(rng.random()) % 1.0
    low, high = (0, _int(args[0])) if len(args) == 1 else (_int(args[0]), _int(args[1]))
    return low if high <= low else rng.randrange(low, high)


def _numbers(args: list[Value]) -> list[float]:
    # Each argument, or each element of an array argument (§6.8-§6.13, pp. 175-180).
    out: list[float] = []
    for arg in args:
        out.extend(_floats(arg) if isinstance(arg, list) else [_num(arg)])
    return out


def _in_type(value: float, types: tuple[str, ...]) -> Value:
    # sum, min, max: an int when every argument is an integer type, else a double (p. 175).
    integral = all(t.removesuffix("[]") in ("byte", "int", "int16") for t in types)
    return wrap32(int(value)) if integral else value


@_register("6.8", 175, "$num(*, *...)")
def _sum(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §6.8 sum, p. 175: of the arguments and of their arrays' elements."""
    return _in_type(math.fsum(_numbers(args)), types)


@_register("6.9", 176, "double(*, *...)")
def _average(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §6.9 average, p. 176: of the arguments and of their arrays' elements."""
    values = _numbers(args)
    if not values:
        raise BuiltinError("the average of an empty array")
    return math.fsum(values) / len(values)


@_register("6.12", 179, "$num(*, *...)")
def _min(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §6.12 min, p. 179: the smallest argument or array element."""
    values = _numbers(args)
    if not values:
        raise BuiltinError("the minimum of an empty array")
    return _in_type(min(values), types)


@_register("6.13", 180, "$num(*, *...)")
def _max(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §6.13 max, p. 180: the largest argument or array element."""
    values = _numbers(args)
    if not values:
        raise BuiltinError("the maximum of an empty array")
    return _in_type(max(values), types)


_math1("6.14", 181, "d2r", math.radians)
_math1("6.15", 182, "r2d", math.degrees)
# The trigonometric functions take and return degrees (TMscript 2.24 §6.16-§6.22).
_math1("6.16", 183, "sin", lambda d: math.sin(math.radians(d)))
_math1("6.17", 184, "cos", lambda d: math.cos(math.radians(d)))
_math1("6.18", 185, "tan", lambda d: math.tan(math.radians(d)))
_math1("6.19", 186, "asin", lambda x: math.degrees(math.asin(x)))
_math1("6.20", 187, "acos", lambda x: math.degrees(math.acos(x)))
_math1("6.21", 188, "atan", lambda x: math.degrees(math.atan(x)))
_math1("6.24", 192, "log10", math.log10)


@_register("6.22", 189, "float(float, float)", "double(double, double)")
def _atan2(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §6.22 atan2, p. 189: degrees, of (y, x); floats for int arguments."""
    return _real(math.degrees(math.atan2(_num(args[0]), _num(args[1]))), types)


@_register(
    "6.23", 190, "float(float, double)", "double(double, double)", "float(float)", "double(double)"
)
def _log(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §6.23 log, pp. 190-191: natural logarithm, or of (value, base)."""
    try:
        if len(args) == 2:
            return _real(math.log(_num(args[0]), _num(args[1])), types)
        return _real(math.log(_num(args[0])), types)
    except (ValueError, ZeroDivisionError):
        raise BuiltinError("the logarithm is undefined") from None


@_register("6.35", 207, "float[](float[])", "float[](float[], int[])", "float[](float[], float[])")
def _inversekin(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §6.35 inversekin, p. 207: computed by the host (the robot's model)."""
    reference = _floats(args[1]) if len(args) > 1 else None
    return list(rt.host.inversekin(_floats(args[0]), reference))


@_register("6.36", 209, "float[](float[])")
def _forwardkin(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §6.36 forwardkin, p. 209: computed by the host (the robot's model)."""
    return list(rt.host.forwardkin(_floats(args[0])))


# ---- chapter 13: motion ----------------------------------------------------------------


def _tag(value: Value) -> int:
    tag = _int(value)
    if not 1 <= tag <= 15:
        raise BuiltinError(f"tag number {tag} is not 1..15")
    return tag


@_register_blocking("13.1", 320, "bool(int, int)", "bool(int)")
def _QueueTag(  # noqa: N802
    rt: Runtime, args: list[Value], types: tuple[str, ...]
) -> Generator[str, None, Value]:
    """TMscript 2.24 §13.1 QueueTag, p. 320: tag the queue; wait 1 waits until it is done."""
    tag = _tag(args[0])
    wait = _int_arg(args, 1)
    rt.host.queue_tag(tag, wait)
    while wait == 1 and not rt.host.queue_tag_done(tag):
        yield BLOCKED
    return True


@_register_blocking("13.2", 321, "int(int, int)", "int(int)")
def _WaitQueueTag(  # noqa: N802
    rt: Runtime, args: list[Value], types: tuple[str, ...]
) -> Generator[str, None, Value]:
    """TMscript 2.24 §13.2 WaitQueueTag, p. 321: 1 done, 0 timed out, -1 no such tag.

    A timeout < 0 waits without end; 0 checks once. Tag 0 is invalid but waits for a
    timeout > 0 (the manual gives no return value for it: -1, as for a tag out of 1..15).
    """
    tag = _int(args[0])
    timeout = _int(args[1]) if len(args) > 1 else -1
    if tag == 0 and timeout > 0:
        # "0: Invalid tag number, but waits for the timeout" (p. 321).
        yield from _wait_ms(rt, timeout)
    if not 1 <= tag <= 15:
        return -1
    start = rt.host.now_s()
    while True:
        done = rt.host.queue_tag_done(tag)
        if done is None:
            return -1
        if done:
            return 1
        if timeout == 0 or (timeout > 0 and rt.host.now_s() - start >= timeout / 1000.0):
            return 0
        yield BLOCKED


@_register("13.3", 322, "int(int)")
def _CheckQueueTag(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §13.3 CheckQueueTag, p. 322: 1 done, 0 not yet, -1 no such tag."""
    tag = _int(args[0])
    if not 1 <= tag <= 15:
        return -1
    done = rt.host.queue_tag_done(tag)
    return -1 if done is None else 1 if done else 0


@_register("13.4", 324, "bool()", motion=True)
def _StopAndClearBuffer(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §13.4 StopAndClearBuffer, p. 324."""
    rt.host.stop_and_clear_buffer()
    return True


@_register(
    "13.5",
    325,
    "bool(string)",
    "bool(float[])",
    "bool(float, float, float, float, float, float)",
    motion=True,
)
def _ChangeBase(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §13.5 ChangeBase, p. 325: a base name or X, Y, Z, RX, RY, RZ."""
    if len(args) == 1 and isinstance(args[0], str):
        rt.host.change_base(args[0])
    else:
        rt.host.change_base(_numbers(args))
    return True


@_register(
    "13.6",
    327,
    "bool(string)",
    "bool(float[])",
    "bool(float[], float)",
    "bool(float[], float, float[])",
    "bool(" + ", ".join(["float"] * 6) + ")",
    "bool(" + ", ".join(["float"] * 7) + ")",
    "bool(" + ", ".join(["float"] * 16) + ")",
    motion=True,
)
def _ChangeTCP(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §13.6 ChangeTCP, pp. 327-329: a TCP name, or values, mass and inertia.

    Syntaxes 1-4 (pp. 327-328): a name, or ``float[]`` values, mass, ``float[]`` inertia;
    syntaxes 5-7 (pp. 328-329): the same as 6, 7 or 16 separate numbers.
    """
    if isinstance(args[0], str):
        rt.host.change_tcp(args[0])
        return True
    if types[0] != "float[]":  # syntaxes 5-7: X..RZ[, mass[, nine inertia values]]
        numbers = [_num(a) for a in args]
        mass = numbers[6] if len(numbers) > 6 else None
        inertia = numbers[7:] if len(numbers) > 7 else None
        rt.host.change_tcp(numbers[:6], mass, inertia)
        return True
    mass = _num(args[1]) if len(args) > 1 else None
    inertia = _floats(args[2]) if len(args) > 2 else None
    rt.host.change_tcp(_floats(args[0]), mass, inertia)
    return True


def _motion(kind: str, args: list[Value]) -> MotionCall:
    fmt = _str(args[0])
    target = _floats(args[1])
    if len(target) != 6:
        raise BuiltinError(f"the target needs 6 values, got {len(target)}")
    pose: tuple[int, ...] | None = None
    joints: tuple[float, ...] | None = None
    if len(args) > 6:
        extra = args[6]
        if kind == "PTP" and len(_arr(extra)) == 3:
            pose = tuple(_int(v) for v in _arr(extra))
        elif kind == "PTP":
            joints = tuple(_floats(extra))
    return MotionCall(
        kind="PTP" if kind == "PTP" else "Line",
        format=fmt,
        target=tuple(target),
        speed=_int(args[2]),
        accel_time_ms=_int(args[3]),
        blending=_int(args[4]),
        disable_precise_positioning=bool(args[5]),
        pose=pose,
        reference_joints=joints,
    )


@_register(
    "13.8",
    331,
    "bool(string, float[], int, int, int, bool)",
    "bool(string, float[], int, int, int, bool, int[])",
    "bool(string, float[], int, int, int, bool, float[])",
    motion=True,
)
def _PTP(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §13.8 PTP, p. 331: queue a point-to-point motion ("CPP" or "JPP").

    With a pose configuration or reference joints (syntaxes 2 and 3, pp. 332-335) the
    format is "CPP" only.
    """
    if _str(args[0]) not in (("CPP", "JPP") if len(args) == 6 else ("CPP",)):
        return False  # "Command rejected (format error)"
    return rt.host.motion(_motion("PTP", args))


@_register("13.10", 337, "bool(string, float[], int, int, int, bool)", motion=True)
def _Line(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §13.10 Line, p. 337: queue a linear motion ("C" + P/A/D + P/R)."""
    fmt = _str(args[0])
    if len(fmt) != 3 or fmt[0] != "C" or fmt[1] not in "PAD" or fmt[2] not in "PR":
        return False
    return rt.host.motion(_motion("Line", args))


@_register(
    "13.12",
    343,
    "bool(string, float[], float[], int, int, int, int, bool)",
    "bool(string, float[], float[], int, int, int, int, int, bool)",
    motion=True,
)
def _Circle(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:  # noqa: N802
    """TMscript 2.24 §13.12 Circle, pp. 343-344: queue an arc ("CPP", "CAP" or "CDP")."""
    fmt = _str(args[0])
    if fmt not in ("CPP", "CAP", "CDP"):
        return False  # "Command rejected (format error)"
    via, target = _floats(args[1]), _floats(args[2])
    if len(via) != 6 or len(target) != 6:
        raise BuiltinError(
            f"the point on the arc and the end need 6 values each, got {len(via)} and {len(target)}"
        )
    rotation = _int(args[7]) if len(args) == 9 else None
    return rt.host.motion(
        MotionCall(
            kind="Circle",
            format=fmt,
            target=tuple(target),
            speed=_int(args[3]),
            accel_time_ms=_int(args[4]),
            blending=_int(args[5]),
            disable_precise_positioning=bool(args[-1]),
            via=tuple(via),
            arc_angle=_int(args[6]),
            rotation=rotation,
        )
    )


# ---- chapter 16: Modbus ----------------------------------------------------------------

_READ_CODES = {"DO": 1, "DI": 2, "RO": 3, "RI": 4}
_TYPE_WORDS = {"bool": 1, "byte": 1, "int16": 1, "int32": 2, "int": 2, "float": 2, "double": 4}


def _device(rt: Runtime, name: Value, unit: int) -> ModbusDevice:
    # _str() and ModbusConfig.device() written out: every Modbus call of a program
    # (most of an idle robot program's work) looks its device up.
    key = (name if name.__class__ is str else _str(name)).strip()
    config = rt.devices.get(key)
    if config is None:
        raise BuiltinError(f'no ModbusTCP device named "{key}" is declared')
    device = config._devices.get(unit)
    return device if device is not None else config.device(unit)


def read_registers(rt: Runtime, args: list[Value]) -> bytes:
    """What ``modbus_read(device, slave, type, address, count)`` reads, as bytes (the
    byte array it returns holds them).

    Raises:
        BuiltinError: An argument the call refuses.
        HostError: The host's refusal of the request.
    """
    kind, words = _read(rt, args)
    return _as_bytes(kind, words)


def _read(rt: Runtime, args: list[Value]) -> tuple[str, list[int]]:
    # _int() and _str() of the plain int and str arguments written out (as in _device).
    unit, kind, address, count = args[1], args[2], args[3], args[4]
    device = _device(rt, args[0], (unit if unit.__class__ is int else _int(unit)) & 0xFF)
    if kind.__class__ is not str:
        kind = _str(kind)
    code = _READ_CODES.get(kind)
    if code is None:
        raise BuiltinError(f'read type "{kind}" is not DO, DI, RO or RI')
    if count.__class__ is not int:
        count = _int(count)
    if address.__class__ is not int:
        address = _int(address)
    words = rt.host.modbus_request(device, code, address, count, None)
    return kind, list(words)


def _as_bytes(kind: str, words: list[int]) -> bytes:
    # Bits: one byte each; registers: two bytes each, high byte first (§16.5, p. 424).
    if kind in ("DO", "DI"):
        return bytes(1 if w else 0 for w in words)
    fmt = f">{len(words)}H"
    try:
        # Words of 0..0xFFFF (what a slave answers) are packed as they are: the same
        # bytes as their low 16 bits, without a list of them.
        return struct.pack(fmt, *words)
    except struct.error:
        return struct.pack(fmt, *[w & 0xFFFF for w in words])


def _ordered(chunk: bytes, endian: int) -> bytes:
    # Big Endian (AB CD) as read; Little Endian (CD AB) swaps the 16-bit words (§16.7).
    if endian == 1:
        return chunk
    words = _chunks(chunk, 2)
    return b"".join(reversed(words))


def _decode_all(data: bytes, size: int, fmt: str, endian: int) -> list[Scalar]:
    out: list[Scalar] = []
    for chunk in _chunks(data, size):
        raw = _ordered(chunk.ljust(size, b"\0"), endian)
        out.append(struct.unpack(fmt, raw)[0])
    return out


def _preset(rt: Runtime, args: list[Value]) -> tuple[ModbusConfig, tuple[int, str, int, str, int]]:
    """The device named by ``args[0]`` and its preset named by ``args[1]`` (§16.1.1)."""
    name, preset_name = args[0], args[1]
    # _str() of the plain str arguments written out (as in _device).
    config = rt.devices.get((name if name.__class__ is str else _str(name)).strip())
    if config is None:
        raise BuiltinError(f'no ModbusTCP device named "{_str(args[0])}" is declared')
    preset = config.presets.get(preset_name if preset_name.__class__ is str else _str(preset_name))
    if preset is None:
        raise BuiltinError(f'device "{config.name}" has no preset "{_str(args[1])}"')
    return config, preset


def _preset_read(rt: Runtime, args: list[Value]) -> Value:
    config, preset = _preset(rt, args)
    unit, kind, address, typ, suffix = preset
    count = suffix if typ == "string" else _TYPE_WORDS[typ]
    kind_, words = _read(rt, [config.name, unit, kind, address, count])
    data = _as_bytes(kind_, words)
    endian = 1 if typ == "string" else suffix
    if typ == "bool":
        return bool(words[0])
    if typ == "byte":
        return words[0] & 0xFF if kind in ("RO", "RI") else int(bool(words[0]))
    if typ == "int16":
        return _decode_all(data, 2, ">h", 1)[0]
    if typ in ("int32", "int"):
        return _decode_all(data, 4, ">i", endian)[0]
    if typ == "float":
        return _decode_all(data, 4, ">f", endian)[0]
    if typ == "double":
        return _decode_all(data, 8, ">d", endian)[0]
    return data.split(b"\0", 1)[0].decode("utf-8", errors="replace")


@_register_linked("16.5", 423, "?(string, string)", "byte[](string, byte, string, int, int)")
def _modbus_read(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §16.5 modbus_read, p. 423: by preset, or a byte array (Big Endian)."""
    if len(args) == 2:
        return _preset_read(rt, args)
    return list(read_registers(rt, args))


def _endian_arg(args: list[Value]) -> int:
    return _int(args[5]) if len(args) > 5 else 1


@_register_linked(
    "16.6",
    426,
    "int[](string, byte, string, int, int, int)",
    "int[](string, byte, string, int, int)",
)
def _modbus_read_int16(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §16.6 modbus_read_int16, p. 426: every 2 bytes to an int16."""
    kind, words = _read(rt, args)
    return _decode_all(_as_bytes(kind, words), 2, ">h", 1)


@_register_linked(
    "16.7",
    428,
    "int[](string, byte, string, int, int, int)",
    "int[](string, byte, string, int, int)",
)
def _modbus_read_int32(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §16.7 modbus_read_int32, p. 428: 1 Big Endian (AB CD), 0 Little (CD AB)."""
    kind, words = _read(rt, args)
    return _decode_all(_as_bytes(kind, words), 4, ">i", _endian_arg(args))


@_register_linked(
    "16.8",
    430,
    "float[](string, byte, string, int, int, int)",
    "float[](string, byte, string, int, int)",
)
def _modbus_read_float(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §16.8 modbus_read_float, p. 430: every 4 bytes to a float."""
    kind, words = _read(rt, args)
    return _decode_all(_as_bytes(kind, words), 4, ">f", _endian_arg(args))


@_register_linked(
    "16.9",
    432,
    "double[](string, byte, string, int, int, int)",
    "double[](string, byte, string, int, int)",
)
def _modbus_read_double(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §16.9 modbus_read_double, p. 432: every 8 bytes to a double."""
    kind, words = _read(rt, args)
    return _decode_all(_as_bytes(kind, words), 8, ">d", _endian_arg(args))


@_register_linked(
    "16.10",
    434,
    "string(string, byte, string, int, int, int)",
    "string(string, byte, string, int, int)",
)
def _modbus_read_string(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §16.10 modbus_read_string, p. 434: UTF-8, stops at 0x00."""
    kind, words = _read(rt, args)
    return _as_bytes(kind, words).split(b"\0", 1)[0].decode("utf-8", errors="replace")


def _encode_registers(value: Value, typ: str) -> bytes:
    # User-defined writes are Big Endian (AB CD); int means int32 (§16.11, p. 438).
    if isinstance(value, list):
        elem = typ[:-2]
        if elem == "byte":  # the bytes as they are: {0x10, 0x27} writes 0x10, 0x27 (p. 438)
            return bytes(_int(v) & 0xFF for v in value)
        return b"".join(_encode_registers(v, elem) for v in value)
    if isinstance(value, bool):
        return b"\x00\x01" if value else b"\x00\x00"
    if isinstance(value, str):
        return value.encode("utf-8")
    if isinstance(value, float):
        return struct.pack(">f" if typ == "float" else ">d", value)
    if typ == "byte":
        return bytes([0, value & 0xFF])
    return struct.pack(">i", wrap32(value))


def _preset_data(value: Scalar, typ: str, suffix: int, count: int) -> bytes:
    """The bytes an RO preset of type ``typ`` (over one register) writes for ``value``.

    A string is UTF-8, cut or padded with 0x00 to ``count`` registers (none: to an even
    length); a number is packed in the preset's word order ``suffix``.
    """
    if typ == "string":
        data = _str(value).encode("utf-8")
        if count > 0:
            return data[: 2 * count].ljust(2 * count, b"\0")
        return data + b"\0" if len(data) % 2 else data
    fmt = {"int32": ">i", "int": ">i", "float": ">f", "double": ">d"}[typ]
    number = wrap32(_int(value)) if fmt == ">i" else float(value)
    return _ordered(struct.pack(fmt, number), suffix)


def _preset_write(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """§16.11 syntaxes 1 and 2 (p. 436): one value through a preset, never an array.

    DO: FC 05; RO: an int16, byte or bool preset is one register (FC 06), an int32,
    float, double or string preset FC 16, in the preset's word order (strings UTF-8,
    padded with 0x00 to the preset's address count, or to the given count).
    """
    config, preset = _preset(rt, args)
    unit, kind, address, typ, suffix = preset
    value = args[2]
    if isinstance(value, list):
        raise BuiltinError("writing an array is not supported with a preset (§16.11, p. 436)")
    if value == "":
        return False  # "the input data is empty" (p. 437)
    device = config._devices.get(unit) or config.device(unit)
    if kind == "DO":
        rt.host.modbus_request(device, 5, address, 1, [1 if value else 0])
        return True
    if kind != "RO":
        raise BuiltinError(f'preset "{_str(args[1])}" is {kind}: only DO and RO are written')
    if typ in ("int16", "byte", "bool"):
        word = (
            (1 if value else 0)
            if typ == "bool"
            else _int(value) & (0xFF if typ == "byte" else 0xFFFF)
        )
        rt.host.modbus_request(device, 6, address, 1, [word])
        return True
    count = _int(args[3]) if typ == "string" and len(args) > 3 else suffix
    data = _preset_data(value, typ, suffix, count)
    words = [int.from_bytes(c, "big") for c in _chunks(data, 2)]
    rt.host.modbus_request(device, 16, address, len(words), words)
    return True


def _coil_bits(value: Value, limit: int) -> list[int]:
    """The coils a DO write sets: one per value (an array: each), at most ``limit`` if > 0."""
    bits = [1 if v else 0 for v in value] if isinstance(value, list) else [1 if value else 0]
    if limit > 0:
        bits = bits[:limit]
    return bits


@_register_linked(
    "16.11",
    436,
    "bool(string, byte, string, int, *, int)",
    "bool(string, byte, string, int, *)",
    "bool(string, string, *, int)",
    "bool(string, string, *)",
)
def _modbus_write(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """TMscript 2.24 §16.11 modbus_write, p. 436: by preset (syntaxes 1 and 2) or by address.

    By address (syntaxes 3 and 4): DO: FC 05 for one value, FC 15 for an array; RO: FC 06
    for a byte or a bool, else FC 16.
    """
    try:
        if types[1] == "string":
            return _preset_write(rt, args, types)
        return _address_write(rt, args, types)
    except ModbusCommunicationError:
        return False  # "an error occurred in Modbus communication" (p. 436)


def _address_write(rt: Runtime, args: list[Value], types: tuple[str, ...]) -> Value:
    """§16.11 syntaxes 3 and 4 (p. 436): by device, slave id, type and address."""
    device = _device(rt, args[0], _int(args[1]) & 0xFF)
    kind, address, value, typ = _str(args[2]), _int(args[3]), args[4], types[4]
    limit = _int_arg(args, 5)
    if value == "" or value == []:
        return False  # "the input data is empty" (p. 438)
    if kind == "DO":
        bits = _coil_bits(value, limit)
        code = 15 if isinstance(value, list) else 5
        rt.host.modbus_request(device, code, address, len(bits), bits)
        return True
    if kind != "RO":
        raise BuiltinError(f'write type "{kind}" is not DO or RO')
    data = _encode_registers(value, typ)
    if len(data) % 2:
        data += b"\0"
    words = [int.from_bytes(c, "big") for c in _chunks(data, 2)]
    if limit > 0 and (isinstance(value, str) or typ == "string[]"):
        words = words[:limit]  # "only effective to string type data" (p. 438)
    # FC 06 for a byte or a bool, FC 16 for a number of 32 bits or more, a string and
    # any array (§16.11 Syntax 3 table, pp. 437-438).
    single = len(words) == 1 and not isinstance(value, list | str)
    code = 6 if single else 16
    rt.host.modbus_request(device, code, address, len(words), words)
    return True


#: Functions of the manual this interpreter refuses, by name (checked when a script is read).
UNSUPPORTED: frozenset[str] = frozenset(
    {
        "GetString",
        "GetToken",
        "GetAllTokens",
        "GetNow",
        "GetVarValue",
        "SetVarValue",
        "Ctrl",
        "XOR8",
        "SUM8",
        "SUM16",
        "SUM32",
        "CRC16",
        "CRC32",
        "ListenPacket",
        "ListenSend",
        "VarSync",
        "ExecText",
        "ExecFile",
        "RedirectToProject",
        "ThreadID",
        "ThreadState",
        "ThreadExit",
        "stdevp",
        "stdevs",
        "norm2",
        "dist",
        "trans",
        "inversetrans",
        "applytrans",
        "interpoint",
        "changeref",
        "points2coord",
        "intercoord",
        "coorshift",
        "ValueReverse",
        "Move_PTP",
        "Move_Line",
        "PLine",
        "Move_PLine",
        "ChangeLoad",
        "modbus_open",
        "modbus_close",
        "IODDPreset",
    }
)


def _unused(_: Sequence[object]) -> None:  # keeps Sequence imported for type checkers
    return None
