"""Register maps: validation rules, TOML loading with overrides, built-in profiles."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from tmmaster._exceptions import ConfigError, RegisterMapError
from tmmaster._profiles import (
    builtin_profile_names,
    gripper_profile,
    load_profile,
    profile_from_data,
    robot_profile,
)
from tmmaster._registers import (
    TARGET_FIELDS,
    Handshake,
    RegisterField,
    RegisterMap,
    RobotProfile,
    Role,
    Table,
)
from tmmaster._transport import encode_writes, group_writes


def _map(*fields: dict[str, Any]) -> RegisterMap:
    return RegisterMap.model_validate({"name": "m", "fields": {f["name"]: f for f in fields}})


def _f(name: str, address: int, type_: str = "uint16", **kw: Any) -> dict[str, Any]:
    return {
        "name": name,
        "role": "status",
        "table": "holding",
        "address": address,
        "type": type_,
        **kw,
    }


def test_overlapping_fields_in_one_table_are_rejected() -> None:
    with pytest.raises(ValueError, match=r"a \(0\.\.1\) and b \(1\.\.1\) overlap in the holding"):
        _map(_f("a", 0, "int32"), _f("b", 1))


def test_same_address_in_different_tables_is_fine() -> None:
    m = _map(_f("a", 0), _f("b", 0, table="input"))
    assert m.field("b").table is Table.INPUT


def test_address_outside_range_is_rejected() -> None:
    with pytest.raises(ValueError, match="less than or equal to 65535"):
        _map(_f("a", 65536))
    with pytest.raises(ValueError, match="greater than or equal to 0"):
        _map(_f("a", -1))


def test_multi_register_value_running_past_the_end_is_rejected() -> None:
    with pytest.raises(ValueError, match="runs past address 65535"):
        _map(_f("a", 65535, "float32"))
    assert _map(_f("a", 65534, "float32")).field("a").end == 65535


@pytest.mark.parametrize("table", ["input", "discrete_input"])
def test_write_access_to_read_only_table_is_rejected(table: str) -> None:
    type_ = "bool" if table == "discrete_input" else "uint16"
    with pytest.raises(ValueError, match="impossible in the read-only"):
        _map(_f("a", 0, type_, table=table, access="rw"))


def test_bool_only_in_bit_tables() -> None:
    with pytest.raises(ValueError, match="does not fit table"):
        _map(_f("a", 0, "bool"))
    with pytest.raises(ValueError, match="does not fit table"):
        _map(_f("a", 0, "uint16", table="coil"))


def test_unknown_keys_are_rejected() -> None:
    with pytest.raises(ValueError, match="Extra inputs are not permitted"):
        _map(_f("a", 0, adress=3))


def test_builtin_profiles_load_and_validate() -> None:
    assert builtin_profile_names() == ["article", "blog-2fg7", "onrobot-2fg7", "tmflow"]
    for name in builtin_profile_names():
        assert load_profile(name).name == name


def test_a_profile_of_the_other_kind_is_refused_by_name() -> None:
    with pytest.raises(RegisterMapError, match="blog-2fg7 is a gripper profile, not a robot"):
        robot_profile("blog-2fg7")
    with pytest.raises(RegisterMapError, match="tmflow is a robot profile, not a gripper"):
        gripper_profile(robot_profile("tmflow"))
    assert gripper_profile(gripper_profile("blog-2fg7")).name == "blog-2fg7"


def test_article_profile_matches_the_article_contract() -> None:
    p = robot_profile("article")
    assert p.handshake is Handshake.CLEAR_ON_ACCEPT
    assert p.field("motion_status").address == 0x0001
    assert p.field("grasp_status").address == 0x0002
    # Moved off 0x0002, where the article's code reads grasp status.
    assert p.field("error_code").address == 0x0003
    assert [f.address for f in p.select(["tcp_x", "tcp_rz"])] == [0x0010, 0x0015]
    assert [f.address for f in p.role(Role.COMMAND)] == list(range(0x0200, 0x0208))
    assert p.field("command").code_of("line") == 2
    assert p.field("gripper_command").address == 0x0210


def test_tmflow_profile_uses_the_real_tm_table() -> None:
    p = robot_profile("tmflow")
    assert p.field("tcp_x").address == 7025
    assert p.field("tcp_rz").end == 7036
    assert p.field("tcp_x").table is Table.INPUT
    assert p.field("estop").address == 7208
    assert p.field("estop").table is Table.DISCRETE_INPUT
    assert p.field("last_error_code").address == 7320
    assert p.field("last_error_code").width == 2
    for name in ("seq", "ack_seq", "done_seq", "target_x"):
        assert 9000 <= p.field(name).address <= 9999


def test_onrobot_profile() -> None:
    p = load_profile("onrobot-2fg7")
    assert p.device_id == 65
    status = p.fields["status"]
    assert status.bit(0b10, "grip_detected")
    assert not status.bit(0b10, "busy")


def test_toml_extends_a_builtin_and_overrides_fields(tmp_path: Path) -> None:
    path = tmp_path / "mine.toml"
    path.write_text(
        'extends = "article"\nname = "mine"\n'
        '[fields.tcp_x]\ntype = "int32"\nscale = 1000\n'
        "[fields.tcp_y]\naddress = 0x0030\n"
    )
    p = robot_profile(path)
    assert p.name == "mine"
    assert p.field("tcp_x").scale == 1000
    assert p.field("tcp_x").width == 2
    assert p.field("tcp_y").address == 0x0030
    # Untouched fields keep the base's definition.
    assert p.field("tcp_z").address == 0x0012


def test_toml_override_that_overlaps_is_rejected_with_file_name(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text('extends = "article"\n[fields.tcp_x]\ntype = "int32"\n')
    with pytest.raises(RegisterMapError, match=r"(?s)bad\.toml.*tcp_x .*tcp_y .*overlap"):
        robot_profile(path)


def test_robot_profile_requires_handshake_fields() -> None:
    with pytest.raises(RegisterMapError, match=r"lacks fields: .*motion_status"):
        profile_from_data({"extends": "article", "remove_fields": ["motion_status"]})


def test_register_map_errors_are_config_errors() -> None:
    assert issubclass(RegisterMapError, ConfigError)
    assert issubclass(RegisterMapError, ValueError)
    with pytest.raises(RegisterMapError, match="unknown profile 'nope'"):
        load_profile("nope")


def test_field_lookup_names_the_map() -> None:
    p: RobotProfile = robot_profile("article")
    with pytest.raises(KeyError, match="no field 'tcp_w'"):
        p.field("tcp_w")
    assert isinstance(p.field("tcp_x"), RegisterField)


# -- atomic command blocks (issue 8 item 4) ------------------------------------


@pytest.mark.parametrize(
    ("override", "named"),
    [
        ({"target_y": {"address": 0x0220}}, "target_y"),  # the old docs example
        ({"speed": {"address": 0x0300}}, "speed"),
        ({"command": {"address": 0x0208}}, "command"),  # trigger left behind a gap
        ({"command": {"table": "coil", "type": "bool"}}, "several tables.*command"),
    ],
)
def test_split_command_block_is_refused_naming_the_fields(
    override: dict[str, Any], named: str
) -> None:
    with pytest.raises(
        RegisterMapError, match=rf"(?s)command block must be one contiguous.*{named}"
    ):
        profile_from_data({"extends": "article", "fields": override})


def test_split_tmflow_block_is_refused() -> None:
    # seq written in a second request would be the trigger arriving apart from its target.
    with pytest.raises(RegisterMapError, match=r"(?s)contiguous.*seq \(holding 9040\)"):
        profile_from_data({"extends": "tmflow", "fields": {"seq": {"address": 9040}}})
    with pytest.raises(RegisterMapError, match=r"(?s)contiguous.*accel_time"):
        profile_from_data({"extends": "tmflow", "fields": {"accel_time": {"address": 9032}}})


def test_moved_but_contiguous_command_block_is_accepted() -> None:
    moved = {n: {"address": 0x0300 + i} for i, n in enumerate([*TARGET_FIELDS, "speed", "command"])}
    p = robot_profile(profile_from_data({"extends": "article", "fields": moved}))
    assert [f.address for f in p.command_block()] == list(range(0x0300, 0x0308))


@pytest.mark.parametrize("name", ["article", "tmflow"])
def test_builtin_command_block_goes_out_as_one_fc16(name: str) -> None:
    p = robot_profile(name)
    values: list[tuple[RegisterField, Any]] = [(f, 1) for f in p.command_block()]
    plans = group_writes(encode_writes(values))
    assert len(plans) == 1
    block, words = plans[0]
    assert block.address == p.command_block()[0].address
    assert len(words) == sum(f.width for f in p.command_block())


@pytest.mark.parametrize(
    ("base", "values", "label"),
    [
        ("article", {"0": "ptp", "1": "none", "2": "line", "3": "stop"}, "ptp"),
        ("article", {"0": "line", "1": "ptp", "3": "stop"}, "line"),  # no "none" label: 0 is none
        ("article", {"5": "none", "1": "ptp", "2": "line", "0": "stop"}, "stop"),
        ("tmflow", {"0": "gripper_open", "1": "ptp", "2": "line"}, "gripper_open"),
        ("tmflow", {"0": "none", "1": "ptp", "2": "line", "7": "none"}, None),
    ],
)
def test_command_code_colliding_with_none_is_refused(
    base: str, values: dict[str, str], label: str | None
) -> None:
    # Replace the base's values entirely (a merge would keep the base's codes).
    data = {"extends": base, "fields": {"command": {"values": values}}}
    if label is None:
        profile_from_data(data)  # two "none" codes are harmless: no action shares one
        return
    with pytest.raises(RegisterMapError, match=rf"code \d+ of '{label}' collides with the 'none'"):
        profile_from_data(data)


def test_register_maps_doc_examples_behave_as_documented(tmp_path: Path) -> None:
    doc = Path(__file__).parent.parent / "docs" / "register-maps.md"
    blocks = re.findall(r"```toml\n(.*?)```", doc.read_text("utf-8"), flags=re.S)
    valid, refused = blocks[0], blocks[1]
    (tmp_path / "ok.toml").write_text(valid)
    assert robot_profile(tmp_path / "ok.toml").field("speed").maximum == 50
    (tmp_path / "bad.toml").write_text(refused)
    with pytest.raises(RegisterMapError, match=r"(?s)contiguous.*target_y"):
        robot_profile(tmp_path / "bad.toml")


@pytest.mark.parametrize("name", ["article", "tmflow"])
def test_write_layout_reused_gives_the_same_blocks_and_words(name: str) -> None:
    # group_writes keeps the grouping per field sequence; a second call with other
    # values (and an order it has already seen) must give what grouping afresh gives.
    from tmmaster._transport import _group_writes, encode_writes, group_writes

    p = robot_profile(name)
    block = list(p.command_block())
    orders = [block, block[::-1], block[1:] + block[:1], [block[0], block[-1]]]
    for order in orders:
        for round_ in range(3):
            values: list[tuple[RegisterField, Any]] = [
                (f, 1 + (round_ + i) % 2) for i, f in enumerate(order)
            ]
            encoded = encode_writes(values)
            assert group_writes(encoded) == _group_writes(encoded)
