"""One robot named two ways ("127.0.0.1", "localhost"): the process's debts are the robot's.

Three registries keep, for the whole process, what one ``Robot`` of it left unsettled
on a robot, so that the next ``Robot`` on that robot honours it (docs/safety.md): an
article Stop the link could not carry (``_command._STOPS_OWED``), a level output's
write left unanswered whose frame may still land (``_io._WATCHED``), a stand-alone
gripper's stop frame left unanswered (``_gripper._STOP_DOUBTS``). They were keyed by
the host *as the caller spelled it*, so a program that connects its second ``Robot``
as "localhost" after its first as "127.0.0.1" (a config file and a CLI flag, a retry
with the other spelling) found no debt, and the robot ran on or was undone unseen.

The scenarios, with the second Robot naming the robot by the other spelling, are the
``second_host`` cases of tests/test_hunt6_owed_stop_new_robot.py (the article move the
first Robot gave up is stopped) and tests/test_hunt6_new_robot_output.py (the gripper
register the second Robot closed stays closed when the first Robot's late open lands).
Here: which spellings make one key. A robot is who answers at an address: the key is
the address the link reached (loopback only here).
"""

from __future__ import annotations

import socket

import pytest

from tmmaster import ModbusTransport


def test_every_spelling_of_one_robot_is_one_key_and_other_robots_are_not() -> None:
    def key(host: str, port: int = 502, device_id: int = 1) -> tuple[str, int, int]:
        link = ModbusTransport(host, port, device_id=device_id, timeout=0.1)
        return link.endpoint

    assert key("localhost") == key("127.0.0.1") == key("::1") == key("127.0.0.1")
    assert key("127.0.0.1", 503) != key("localhost")
    assert key("127.0.0.1", device_id=2) != key("localhost")
    assert key("192.0.2.7") != key("localhost")
    assert key("robot.invalid") == ("robot.invalid", 502, 1)  # unresolved: its own key


def test_a_name_with_several_addresses_is_one_key_whatever_order_they_come_in(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A resolver may rotate a name's addresses (round-robin DNS), and give IPv6 first.
    v4 = [(socket.AF_INET, socket.SOCK_STREAM, 6, "", (a, 502)) for a in ("10.0.0.7", "10.0.0.3")]
    v6 = [(socket.AF_INET6, socket.SOCK_STREAM, 6, "", ("fd00::7", 502, 0, 0))]
    keys = set()
    for answer in (v6 + v4, v4[::-1] + v6, v4):
        monkeypatch.setattr(socket, "getaddrinfo", lambda *_a, answer=answer, **_k: answer)
        keys.add(ModbusTransport("tm5.lan", 502, device_id=1, timeout=0.1).endpoint)
    assert keys == {("10.0.0.3", 502, 1)}
