"""TMscript's check refuses no program TMflow 2.24 accepts: a float constant that rounds to
the greatest float, a hexadecimal int constant of 32 bits, switch cases of different types.

[TS]: Programming Language TMscript, software version 2.24, document version 1.00.
[TMF]: Software Manual TMflow, software version 2.24, document version 1.00.
"""

from __future__ import annotations

import struct

import pytest

from tmmaster import TMScriptSyntaxError
from tmmaster.tmscript import ExecState, Execution, NullHost, parse


class _Clock:
    """A clock that advances 10 ms at every reading: waits end without wall time."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        self.now += 0.01
        return self.now


def _main(body: str) -> str:
    return f"main\n{{\n{body}\n}}\n"


def shows(body: str) -> list[str]:
    shown: list[str] = []
    program = parse(_main(body))
    execution = Execution(program, NullHost(on_display=shown.append, clock=_Clock()))
    assert execution.run_to_end(timeout_s=5) == ExecState.ENDED, execution.error
    return shown


def warnings(body: str) -> list[str]:
    return [w.message for w in parse(_main(body)).warnings]


def _float32(text: str) -> float | None:
    """The 32-bit float the constant rounds to (IEEE round to nearest), None if infinite."""
    try:
        (value,) = struct.unpack("<f", struct.pack("<f", float(text)))
    except OverflowError:  # struct refuses a value that rounds to infinity
        return None
    return float(value)


# 3.40282347e38 and 3.4028235e38 are FLT_MAX as C and .NET print it; 3.40282356e38 is the
# last 9-digit constant under the midpoint 2**128 - 2**103 between FLT_MAX and 2**128,
# from which a constant rounds to infinity (3.40282357e38, 3.4028236e38, 1e39).
_FLOATS = [
    "3.40282347e38",
    "3.4028235e38",
    "3.40282356e38",
    "-3.4028235e38",
    "3.40282357e38",
    "3.4028236e38",
    "-3.4028236e38",
    "1e39",
]


@pytest.mark.parametrize("text", _FLOATS)
def test_a_float_constant_is_refused_only_when_it_rounds_to_infinity(text: str) -> None:
    # "Invalid float range": "The operand in the expression is assigned a number out of
    # range" ([TMF] appendix J, 0x0004821C, p. 483). A float is a 32-bit IEEE float ([TS]
    # §2.1): a constant that rounds to the greatest float is in its range; the check
    # compared it with FLT_MAX exactly and refused FLT_MAX as printed.
    rounded = _float32(text)
    body = f"float f = {text}\nDisplay(f)\nfloat[] fa = {{0, {text}}}\nDisplay(fa[1])"
    if rounded is None:
        with pytest.raises(TMScriptSyntaxError, match="out of a float's range"):
            parse(_main(body))
    else:
        sign = "-" if rounded < 0 else ""
        assert abs(rounded) == 3.4028234663852886e38
        assert shows(body) == [f"{sign}3.402823E+38"] * 2


@pytest.mark.parametrize("text", _FLOATS)
def test_a_float_assignment_and_cast_take_what_rounds_to_a_float(text: str) -> None:
    # The same rule where the value is assigned (0x0004821C) and where it is converted
    # ("(float)": [TS] §2.5): the conversion refused what rounds to FLT_MAX at run time.
    if _float32(text) is None:
        with pytest.raises(TMScriptSyntaxError, match="out of a float's range"):
            parse(_main(f"float f = 0\nf = {text}"))
        return
    shown = shows(f"float f = 0\nf = {text}\nDisplay(f)\nDisplay((float){text})")
    sign = "-" if text.startswith("-") else ""
    assert shown == [f"{sign}3.402823E+38"] * 2


def test_string_to_float_of_the_greatest_float_is_a_float() -> None:
    # [TS] §4.12 String_ToFloat, p. 68: a float. "3.4028235E+38" is FLT_MAX as TMflow
    # prints it; it came back unrounded, the double 3.4028235E+38.
    # Widened to a double, the float shows its 15 digits.
    shown = shows('double d = String_ToFloat("3.4028235E+38")\nDisplay(d)')
    assert shown == ["3.40282346638529E+38"]


def test_a_32_bit_hexadecimal_int_constant_is_kept_with_a_warning() -> None:
    # [TS] §2.2, pp. 13-14: "Hexadecimal integer 0x123abc", "For binary and hexadecimal
    # notation, there is no floating-point", a constant takes the smallest type that holds
    # it; §2.7, p. 27: "Ctrl(0x0A0B0C0D0E) // warning // 0x0A0B0C0D0E is not int type
    # (over 32bit)". The manual does not say whether `int i = 0xFFFFFFFF` (32 bits) is
    # -1 or out of range: the check took it as out of range and refused it, where it ran
    # before with a warning, as -1. A user's program is not refused on a guess.
    body = "int i = 0xFFFFFFFF\nDisplay(i)\nint[] a = {0x80000000, 0b" + "1" * 32 + "}\nDisplay(a)"
    assert shows(body) == ["-1", "{-2147483648,-1}"]
    found = warnings(body)
    assert len(found) == 3
    assert "0xFFFFFFFF is over an int's range" in found[0]
    assert "-1" in found[0]


def test_a_32_bit_hexadecimal_constant_is_returned_by_an_int_function_as_assigned() -> None:
    # "If the function defines the return type, it must return with the same type" ([TS]
    # §3.5, p. 32): an integer constant that fits passes, as in an assignment; 0xFFFFFFFF
    # is taken as in an assignment (above), 0x100000000 still is not an int.
    script = "main\n{{\n    int r = F()\n    Display(r)\n}}\nint F()\n{{\n    return {}\n}}\n"
    shown: list[str] = []
    program = parse(script.format("0xFFFFFFFF"))
    execution = Execution(program, NullHost(on_display=shown.append, clock=_Clock()))
    assert execution.run_to_end(timeout_s=5) == ExecState.ENDED, execution.error
    assert shown == ["-1"]
    with pytest.raises(TMScriptSyntaxError, match="returns a int"):
        parse(script.format("0x100000000"))


@pytest.mark.parametrize(
    "text",
    [
        "int i = 0x100000000",
        "int i = 4294967295",
        "int i = 0\n    i = 0x1FFFFFFFF",
        "byte b = 0x100",
    ],
)
def test_a_constant_over_32_bits_or_a_decimal_one_is_still_refused(text: str) -> None:
    # 0x0004821B "Invalid int range" ([TMF] appendix J, p. 482): over 32 bits, or written
    # in decimal, the constant is out of an int's range; a byte's range is 0..255 ([TS]
    # §2.2, p. 15).
    with pytest.raises(TMScriptSyntaxError, match=r"out of an? (int|byte)'s range"):
        parse(_main(f"    {text}"))


def _switch(subject: str, first: str, second: str) -> str:
    return (
        f"switch ({subject})\n{{\ncase {first}\nDisplay(1)\nbreak\n"
        f"case {second}\nDisplay(2)\nbreak\ndefault\nDisplay(3)\nbreak\n}}"
    )


def test_cases_of_equal_value_but_different_number_types_are_not_duplicates() -> None:
    # [TMF] appendix J, 0x0004810D "Duplicated switch case condition" (p. 365); [TS]
    # §3.9.2, pp. 39-40 says only that a case is a condition on the value. 1 (a byte) and
    # 1.0 (a float) are two constants of two types (TMflow is a .NET program: Equals of a
    # boxed Int32 and a boxed Single is false); Python's 1 == 1.0 made them one. The
    # second can never match first: a warning says so.
    body = "int x = 1\n" + _switch("x", "1", "1.0")
    assert shows(body) == ["1"]
    assert any("case 1.0" in w and "never matches" in w for w in warnings(body))
    assert shows("float x = 1.5\n" + _switch("x", ">= 1", ">= 1.0")) == ["1"]


@pytest.mark.parametrize(("subject", "second"), [("true", "1"), ("1", "true")])
def test_case_1_and_case_true_are_not_duplicates(subject: str, second: str) -> None:
    # A bool and a number are two types ([TS] §2.1); a bool is not compared with a number
    # ("a bool cannot be compared with a byte"): that is the error, not a duplicated case.
    first = "true" if second == "1" else "1"
    body = f"var x = {subject}\n" + _switch("x", first, second)
    body = body.replace("var", "bool" if subject == "true" else "int")
    with pytest.raises(TMScriptSyntaxError, match="cannot be compared"):
        parse(_main(body))


@pytest.mark.parametrize(
    ("subject", "first", "second"),
    [("1", "1", "0x1"), ("1.5", "1.50", "1.5"), ("1", ">= 1", ">= 1"), ('"a"', '"a"', '"a"')],
)
def test_the_same_constant_of_the_same_type_is_still_a_duplicate(
    subject: str, first: str, second: str
) -> None:
    # 0x0004810D ([TMF] appendix J, p. 365): the same comparison with a constant of the
    # same type and value, however written.
    typ = {"1": "int", "1.5": "float"}.get(subject, "string")
    body = f"{typ} x = {subject}\n" + _switch("x", first, second)
    with pytest.raises(TMScriptSyntaxError, match="duplicated switch case"):
        parse(_main(body))
