"""Codec: every data type round-trips, and nothing that does not fit is ever encoded."""

from __future__ import annotations

import math
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tmmaster._codec import allowed_range, decode, decoder, encode
from tmmaster._exceptions import ValueOutOfRangeError
from tmmaster._profiles import robot_profile
from tmmaster._registers import RegisterField


def field(type_: str, scale: float = 1.0, word_order: str = "big", **kw: Any) -> RegisterField:
    table = "coil" if type_ == "bool" else "holding"
    return RegisterField.model_validate(
        {
            "name": "f",
            "role": "status",
            "table": table,
            "address": 0,
            "type": type_,
            "scale": scale,
            "word_order": word_order,
            **kw,
        }
    )


LIMITS = {
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
}


@pytest.mark.parametrize("type_", list(LIMITS))
@pytest.mark.parametrize("word_order", ["big", "little"])
@given(data=st.data())
def test_integer_round_trip(type_: str, word_order: str, data: st.DataObject) -> None:
    low, high = LIMITS[type_]
    value = data.draw(st.integers(low, high))
    f = field(type_, word_order=word_order)
    words = encode(f, value)
    assert len(words) == f.width
    assert all(0 <= w <= 0xFFFF for w in words)
    assert decode(f, words) == value


@pytest.mark.parametrize("type_", ["int16", "int32"])
@given(value=st.floats(-327.67, 327.67))
def test_scaled_round_trip_within_resolution(type_: str, value: float) -> None:
    f = field(type_, scale=100)
    assert abs(float(decode(f, encode(f, value))) - value) <= 0.005 + 1e-9


@pytest.mark.parametrize("word_order", ["big", "little"])
@given(value=st.floats(width=32, allow_nan=False, allow_infinity=False))
def test_float32_round_trip_exact(word_order: str, value: float) -> None:
    f = field("float32", word_order=word_order)
    assert decode(f, encode(f, value)) == value


@given(value=st.booleans())
def test_bool_round_trip(value: bool) -> None:
    f = field("bool")
    assert decode(f, encode(f, value)) is value


def test_twos_complement_and_word_order() -> None:
    assert encode(field("int16"), -1) == [0xFFFF]
    assert encode(field("int16", scale=100), -200) == [(-20000) & 0xFFFF]
    assert encode(field("int32"), -2) == [0xFFFF, 0xFFFE]
    assert encode(field("int32", word_order="little"), -2) == [0xFFFE, 0xFFFF]
    assert encode(field("float32"), 1.0) == [0x3F80, 0x0000]
    assert encode(field("float32", word_order="little"), 1.0) == [0x0000, 0x3F80]


def test_rounding_is_half_away_from_zero() -> None:
    f = field("int16", scale=100)
    assert encode(f, 0.005) == [1]
    assert encode(f, -0.005) == [0xFFFF]
    assert encode(f, 1.234) == [123]


def test_the_articles_400mm_is_refused_naming_field_value_and_range() -> None:
    x = robot_profile("article").field("target_x")
    with pytest.raises(ValueOutOfRangeError) as info:
        encode(x, 400)
    assert str(info.value) == (
        "target_x: value 400 is out of range (allowed -327.68..327.67 mm, int16 x100)"
    )
    assert info.value.field == "target_x"
    assert isinstance(info.value, ValueError)


def test_declared_range_is_enforced() -> None:
    speed = robot_profile("article").field("speed")
    assert allowed_range(speed) == (1, 100)
    for bad in (0, 101, -5):
        with pytest.raises(ValueOutOfRangeError, match="speed"):
            encode(speed, bad)
    assert encode(speed, 30) == [30]


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, "3", None])
def test_non_numbers_are_refused(bad: Any) -> None:
    with pytest.raises(ValueOutOfRangeError):
        encode(field("float32"), bad)


def test_unsigned_refuses_negative_and_rounding_past_the_edge() -> None:
    with pytest.raises(ValueOutOfRangeError):
        encode(field("uint16"), -1)
    with pytest.raises(ValueOutOfRangeError):
        encode(field("uint16"), 65535.6)
    with pytest.raises(ValueOutOfRangeError):
        encode(field("float32"), 1e39)


def test_bool_refuses_other_numbers() -> None:
    with pytest.raises(ValueOutOfRangeError):
        encode(field("bool"), 2)


def test_decode_checks_word_count() -> None:
    with pytest.raises(ValueError, match="expected 2 words"):
        decode(field("int32"), [1])


@pytest.mark.parametrize("type_", ["int16", "uint16", "int32", "uint32", "float32"])
@pytest.mark.parametrize("word_order", ["big", "little"])
@pytest.mark.parametrize("scale", [1.0, 100.0])
@settings(max_examples=40)
@given(words=st.lists(st.integers(0, 0xFFFF), min_size=4, max_size=4), at=st.integers(0, 2))
def test_the_read_plan_decoder_equals_decode(
    type_: str, word_order: str, scale: float, words: list[int], at: int
) -> None:
    f = field(type_, scale=scale, word_order=word_order)
    expected = decode(f, words[at : at + f.width])
    got = decoder(f)(words, at)
    if isinstance(expected, float) and math.isnan(expected):
        assert isinstance(got, float)
        assert math.isnan(got)
    else:
        assert got == expected
        assert type(got) is type(expected)


def test_the_bool_decoder_equals_decode() -> None:
    f = RegisterField(name="flag", role="status", table="coil", address=0, type="bool")
    assert decoder(f)([0, 1], 1) is decode(f, [1]) is True
    assert decoder(f)([0, 1], 0) is decode(f, [0]) is False


def test_the_encoder_is_built_once_per_field_and_never_shared_with_a_copy() -> None:
    from tmmaster._codec import encoder

    f = field("int16", scale=100, minimum=-300, maximum=300)
    assert encoder(f) is encoder(f)
    narrower = f.model_copy(update={"maximum": 10.0})
    assert encode(f, 20) == [2000]
    with pytest.raises(ValueOutOfRangeError, match="f"):
        encode(narrower, 20)  # the copy's range, not the cached encoder of the original
