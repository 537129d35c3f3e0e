"""RegisterBank: served addresses, read gaps, write refusals, codec round trips."""

from __future__ import annotations

import pytest

from tmmaster._codec import encode
from tmmaster._exceptions import IllegalAddressError, IllegalValueError, ValueOutOfRangeError
from tmmaster._profiles import gripper_profile, profile_from_data, robot_profile
from tmmaster._registers import Table
from tmmaster.sim._bank import RegisterBank


@pytest.fixture
def article() -> RegisterBank:
    return RegisterBank(robot_profile("article"))


@pytest.fixture
def tmflow() -> RegisterBank:
    return RegisterBank(robot_profile("tmflow"))


def test_set_get_round_trip_through_the_codec(article: RegisterBank) -> None:
    article.set("target_y", -200.0)
    assert article.get("target_y") == -200.0
    # Two's complement, x100, exactly what the codec produces.
    assert article.read(Table.HOLDING, 0x0201, 1) == encode(
        article.register_map.field("target_y"), -200.0
    )
    assert article.read(Table.HOLDING, 0x0201, 1) == [(-20000) & 0xFFFF]


def test_set_refuses_values_the_field_cannot_hold(article: RegisterBank) -> None:
    with pytest.raises(ValueOutOfRangeError, match="tcp_x"):
        article.set("tcp_x", 400.0)
    assert article.get("tcp_x") == 0


def test_float32_fields_span_two_words(tmflow: RegisterBank) -> None:
    tmflow.set("tcp_x", 123.5)
    words = tmflow.read(Table.INPUT, 7025, 2)
    assert words == encode(tmflow.register_map.field("tcp_x"), 123.5)
    assert tmflow.get("tcp_x") == 123.5


def test_setting_a_value_again_stores_it_again(tmflow: RegisterBank, article: RegisterBank) -> None:
    # A value set before is not encoded again (RegisterBank caches its words), yet what
    # is stored is always what set was given: after a network write changed the words,
    # after a value of another type, and for -0.0 after 0.0 (a float32 keeps the sign).
    article.set("target_y", -200.0)
    article.write(Table.HOLDING, 0x0201, [7])
    article.set("target_y", -200.0)
    assert article.get("target_y") == -200.0
    tmflow.set("tcp_x", 1.0)
    tmflow.set("tcp_x", 1)
    assert tmflow.read(Table.INPUT, 7025, 2) == encode(tmflow.register_map.field("tcp_x"), 1)
    tmflow.set("tcp_x", 0.0)
    tmflow.set("tcp_x", -0.0)
    assert tmflow.read(Table.INPUT, 7025, 2) == encode(tmflow.register_map.field("tcp_x"), -0.0)
    assert tmflow.read(Table.INPUT, 7025, 2) != encode(tmflow.register_map.field("tcp_x"), 0.0)
    with pytest.raises(ValueOutOfRangeError, match="tcp_x"):
        tmflow.set("tcp_x", float("nan"))


def test_device_may_set_read_only_fields(tmflow: RegisterBank) -> None:
    tmflow.set("project_running", True)
    assert tmflow.read(Table.DISCRETE_INPUT, 7202, 1) == [1]
    tmflow.set("last_error_code", -5)
    assert tmflow.get("last_error_code") == -5


def test_served_ranges_merge_adjacent_fields(article: RegisterBank) -> None:
    assert article.served(Table.HOLDING) == [(0, 4), (0x10, 6), (0x200, 8), (0x210, 1)]
    assert article.served(Table.INPUT) == []


def test_read_unserved_address_is_illegal(article: RegisterBank) -> None:
    with pytest.raises(IllegalAddressError):
        article.read(Table.HOLDING, 0x0100, 1)
    with pytest.raises(IllegalAddressError):
        article.read(Table.INPUT, 0, 1)
    # Running one address past the last field is refused too.
    with pytest.raises(IllegalAddressError):
        article.read(Table.HOLDING, 0x0210, 2)


def test_small_gap_between_fields_is_readable_as_zero(article: RegisterBank) -> None:
    # article: max_read_gap 16; 0x0004..0x000F (12 addresses) lies between two fields.
    article.set("error_code", 9)
    article.set("tcp_x", 1.0)
    words = article.read(Table.HOLDING, 0x0000, 0x16)
    assert words[3] == 9
    assert words[4:16] == [0] * 12
    assert words[16] == 100
    assert (0, 0x16) in article.readable(Table.HOLDING)


def test_gap_larger_than_max_read_gap_is_not_readable(article: RegisterBank) -> None:
    # 0x0016..0x01FF is far more than 16 addresses.
    with pytest.raises(IllegalAddressError):
        article.read(Table.HOLDING, 0x0010, 0x200)


def test_gap_of_exactly_max_read_gap_is_readable() -> None:
    data = {
        "kind": "gripper",
        "name": "gappy",
        "driver": "onrobot-2fg7",
        "device_id": 65,
        "max_read_gap": 2,
        "fields": {
            "a": {"role": "status", "table": "holding", "address": 0, "type": "uint16"},
            "b": {"role": "status", "table": "holding", "address": 3, "type": "uint16"},
            "c": {"role": "status", "table": "holding", "address": 7, "type": "uint16"},
        },
    }
    bank = RegisterBank(profile_from_data(data))
    assert bank.read(Table.HOLDING, 0, 4) == [0, 0, 0, 0]
    with pytest.raises(IllegalAddressError):
        bank.read(Table.HOLDING, 3, 5)  # gap of 3 > max_read_gap 2


def test_tmflow_bridges_no_gap_across_7206(tmflow: RegisterBank) -> None:
    # 7206 is only a coil in TMflow 2.24 appendix C: the tmflow profile (max_read_gap 0)
    # reads 7201-7205 and 7207-7208 apart, and a read across 7206 is refused.
    assert tmflow.read(Table.DISCRETE_INPUT, 7201, 5) == [0] * 5
    assert tmflow.read(Table.DISCRETE_INPUT, 7207, 2) == [0] * 2
    with pytest.raises(IllegalAddressError):
        tmflow.read(Table.DISCRETE_INPUT, 7201, 8)


def test_network_write_stores_words(article: RegisterBank) -> None:
    article.write(Table.HOLDING, 0x0200, [100, (-20000) & 0xFFFF, 5000, 0, 0, 0, 50, 1])
    assert article.get("target_x") == 1.0
    assert article.get("target_y") == -200.0
    assert article.get("command") == 1
    assert article.field_writes("command") == 1
    assert article.network_writes == 1


def test_write_to_read_only_table_is_illegal(tmflow: RegisterBank) -> None:
    with pytest.raises(IllegalAddressError, match="read-only"):
        tmflow.write(Table.INPUT, 7025, [0])
    with pytest.raises(IllegalAddressError, match="read-only"):
        tmflow.write(Table.DISCRETE_INPUT, 7201, [1])


def test_write_to_device_only_field_is_illegal(article: RegisterBank) -> None:
    with pytest.raises(IllegalAddressError, match="motion_status"):
        article.write(Table.HOLDING, 0x0001, [0])


def test_write_is_all_or_nothing(article: RegisterBank) -> None:
    # command (0x0207) is writable, 0x0208 is not served: nothing is stored.
    with pytest.raises(IllegalAddressError):
        article.write(Table.HOLDING, 0x0207, [1, 1])
    assert article.get("command") == 0
    assert article.network_writes == 0


def test_write_into_a_readable_gap_is_illegal(article: RegisterBank) -> None:
    with pytest.raises(IllegalAddressError):
        article.write(Table.HOLDING, 0x0005, [1])


def test_write_refuses_words_out_of_range(article: RegisterBank) -> None:
    with pytest.raises(IllegalValueError):
        article.write(Table.HOLDING, 0x0207, [0x10000])


def test_coils_hold_bits(tmflow: RegisterBank) -> None:
    tmflow.write(Table.COIL, 7104, [1, 1])
    assert tmflow.get("play_pause") is True
    assert tmflow.get("stop_project") is True
    with pytest.raises(IllegalValueError):
        tmflow.write(Table.COIL, 7104, [2])


def test_version_counts_changes_only(article: RegisterBank) -> None:
    start = article.version
    article.set("speed", 50)
    assert article.version == start + 1
    article.set("speed", 50)
    assert article.version == start + 1
    article.write(Table.HOLDING, 0x0206, [50])
    assert article.version == start + 1
    assert article.field_writes("speed") == 1  # the write is still counted per field


def test_changes_count_the_changed_words_of_each_table(tmflow: RegisterBank) -> None:
    start = {table: tmflow.changes(table) for table in Table}
    tmflow.set("tcp_x", 12.5)
    tmflow.set("tcp_x", 12.5)
    assert tmflow.changes(Table.INPUT) == start[Table.INPUT] + 1
    tmflow.write(Table.HOLDING, 9000, [7])
    tmflow.write(Table.HOLDING, 9000, [7])
    tmflow.write(Table.HOLDING, 9000, [8], device=True)
    assert tmflow.changes(Table.HOLDING) == start[Table.HOLDING] + 2
    assert tmflow.changes(Table.INPUT) == start[Table.INPUT] + 1
    assert tmflow.changes(Table.COIL) == start[Table.COIL]


def test_banks_of_one_map_have_memories_of_their_own() -> None:
    # Banks of the same map share its layout (built once), never their words.
    profile = robot_profile("tmflow")
    first, second = RegisterBank(profile), RegisterBank(profile)
    first.set("tcp_x", 12.5)
    first.write(Table.HOLDING, 9000, [7])
    assert second.get("tcp_x") == 0
    assert second.read(Table.HOLDING, 9000, 1) == [0]
    runs = first.readable(Table.HOLDING)
    runs.clear()
    assert second.readable(Table.HOLDING) == first.readable(Table.HOLDING) != []
    assert RegisterBank(profile).get("tcp_x") == 0


def test_gripper_maps() -> None:
    onrobot = RegisterBank(gripper_profile("onrobot-2fg7"))
    assert onrobot.served(Table.HOLDING) == [
        (0, 4),
        (256, 8),
        (544, 10),  # firmware identity words OnRobot's ROS 2 test fixture serves
        (1028, 2),
        (1031, 1),
        (1536, 1),
        (1540, 2),
    ]
    blog = RegisterBank(gripper_profile("blog-2fg7"))
    assert blog.served(Table.INPUT) == [(258, 3)]
    with pytest.raises(IllegalAddressError):
        blog.read(Table.INPUT, 261, 1)


def test_bad_range_is_illegal(article: RegisterBank) -> None:
    with pytest.raises(IllegalAddressError):
        article.read(Table.HOLDING, 0, 0)
    with pytest.raises(IllegalAddressError):
        article.read(Table.HOLDING, 65535, 2)
