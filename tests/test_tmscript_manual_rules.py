"""Rules of the TMscript 2.24 manual that its worked examples do not show on their own.

Each test names the page whose text it follows.
"""

from __future__ import annotations

import pytest

from tmmaster import TMScriptSyntaxError
from tmmaster.tmscript import ExecState, Execution, NullHost, evaluate, parse


def shows(body: str) -> list[str]:
    shown: list[str] = []
    program = parse(f"main\n{{\n{body}\n}}\n")
    execution = Execution(program, NullHost(on_display=shown.append, clock=lambda: 0.0))
    assert execution.run_to_end(timeout_s=5) == ExecState.ENDED
    return shown


def test_ceil_floor_round_return_the_manuals_float() -> None:
    # float ceil(float), floor(float), round(float) (§6.4-§6.6, pp. 169-171).
    assert evaluate("ceil(2.5) / 4") == (0.75, "float")
    assert evaluate("floor(2.5) / 4") == (0.5, "float")
    assert evaluate("round(2.5) / 4") == (0.75, "float")
    assert evaluate("ceil((double)2.5)")[1] == "double"


@pytest.mark.parametrize("text", ["byte b = -100", "byte b = 300", "byte b = 0\nb = 256"])
def test_a_byte_constant_out_of_range_is_refused(text: str) -> None:
    # "byte b = -100 // -100 mismatches with the value range of byte. // Error" (§2.2, p. 15).
    with pytest.raises(TMScriptSyntaxError, match=r"byte's range 0\.\.255 \(§2\.2, p\. 15"):
        parse(f"main\n{{\n{text}\n}}\n")


def test_a_byte_calculation_keeps_8_bits() -> None:
    # "byte b = 0 - 100 // b = 156" (§2.2, p. 15).
    assert shows("byte b = 0 - 100\nDisplay(b)\nb = 255\nb += 1\nDisplay(b)") == ["156", "0"]


def test_random_never_reaches_its_upper_bound() -> None:
    # MIN <= RND < MAX; an upper bound not above the lower one gives the lower (pp. 173-174).
    for _ in range(100):
        assert evaluate("random(5, 6)") == (5, "int")
        assert evaluate("random(1)") == (0, "int")
    assert evaluate("random(5, -1)") == (5, "int")
    assert evaluate("random(-10)") == (0, "int")
    assert evaluate("random()")[1] == "float"


def test_an_int_argument_chooses_the_float_syntax() -> None:
    # float d2r(float) ... : an int widens to the smaller float first (§2.2 p. 15, p. 181).
    for call in ("d2r(1)", "r2d(1)", "sin(1)", "cos(1)", "tan(1)", "atan2(1, 2)", "log(2)"):
        assert evaluate(call)[1] == "float", call
    assert evaluate("sin((double)30)")[1] == "double"
    assert evaluate("pow(100, 2)") == (10000, "int")


def test_indexing_a_function_result_warns() -> None:
    # [] takes an array variable (§2.4, p. 19); the element is still read.
    program = parse('main\n{\nstring s = String_Split("a,b", ",")[1]\nDisplay(s)\n}\n')
    assert ["§2.4, p. 19" in w.message for w in program.warnings] == [True]
    assert shows('string s = String_Split("a,b", ",")[1]\nDisplay(s)') == ["b"]


def test_an_integer_constant_over_32_bits_warns() -> None:
    # "0x0A0B0C0D0E is not int type (over 32bit) // warning" (§2.7, p. 27).
    program = parse("main\n{\ndouble d = 0x0A0B0C0D0E\nint i = 2147483647\n}\n")
    assert [(w.line, "p. 27" in w.message) for w in program.warnings] == [(3, True)]


def test_invalid_text_converts_to_zero() -> None:
    # "If notation is invalid, returns 0." (§4.11-§4.13, pp. 66-71).
    assert evaluate('String_ToInteger("XYZ")') == (0, "int")
    assert evaluate('String_ToFloat("XYZ")') == (0.0, "float")
    assert evaluate('String_ToDouble("1.2.3")') == (0.0, "double")


def test_array_insert_past_the_end_appends() -> None:
    # "Out of the index. The value will insert in the end of the array." (§4.25, p. 88).
    assert shows("int[] n = {1, 2}\nDisplay(Array_Insert(n, 100, 9))") == ["{1,2,9}"]


@pytest.mark.parametrize("name", ["true", "False", "empty", "newline", "NewLine"])
def test_a_boolean_or_reserved_character_is_no_variable_name(name: str) -> None:
    # A name "cannot be a numeric value, a string, or a Boolean value" (§2.2, p. 14);
    # empty, newline and NewLine are reserved characters (p. 16).
    with pytest.raises(TMScriptSyntaxError, match=r"reserved word.*§2\.2"):
        parse(f"main\n{{\nint {name} = 1\n}}\n")
    with pytest.raises(TMScriptSyntaxError, match=r"reserved word.*§2\.2"):
        parse(f'define\n{{\nModbusTCP {name} = "127.0.0.1"\n}}\nmain\n{{\n}}\n')


@pytest.mark.parametrize(
    ("timeout", "ends"), [(0, True), (10000, True), (10001, False), (-1, False)]
)
def test_a_modbus_timeout_is_0_to_10000_ms(timeout: int, ends: bool) -> None:
    # ModbusTCP's read/write timeout: "0 .. 10000" ms (§16.1, p. 414).
    program = parse(f'define\n{{\nModbusTCP d = "127.0.0.1", 502, {timeout}\n}}\nmain\n{{\n}}\n')
    execution = Execution(program, NullHost(clock=lambda: 0.0))
    state = execution.run_to_end(timeout_s=5)
    assert state == (ExecState.ENDED if ends else ExecState.ERROR)
    if not ends:
        assert "p. 414" in str(execution.error)


@pytest.mark.parametrize(
    ("body", "warned"),
    [
        # The manual's own examples (§2.7, p. 27): each assignment warns.
        ("int i = 0\nfloat f = 1.234\ni = f", "float to int"),
        ("byte b = 100\nint i = 1000\nb = i", "int to byte"),
        ("float f = 1.0\ndouble d = 2.345\nf = d", "double to float"),
        ('int i = "1234"', "string to int"),
        ('string s2 = "123"\nint x = s2', "string to int"),
        ("string s1 = 123", "to string"),
        ("float[] f = {1.5}\nint[] n = {0}\nn[0] = f[0]", "float to int"),
    ],
)
def test_an_assignment_that_may_lose_digits_or_converts_a_string_warns(
    body: str, warned: str
) -> None:
    program = parse(f"main\n{{\n{body}\n}}\n")
    assert [warned in w.message and "p. 27" in w.message for w in program.warnings] == [True]


def test_a_widening_assignment_or_a_byte_calculation_does_not_warn() -> None:
    # Smaller to greater is no loss (§2.2, p. 15); "byte b = 0 - 100 // b = 156" (p. 15).
    body = 'byte b = 0 - 100\nint i = b\nfloat f = i\ndouble d = f\nb += 1\nstring s = "n" + i'
    assert parse(f"main\n{{\n{body}\n}}\n").warnings == ()
