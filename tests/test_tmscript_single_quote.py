"""A single quote in a string constant is a compile warning in TMflow (TMscript 2.24 §2.7,
p. 27: "There is single quotation mark inside the string constant"; §2.2, p. 16: 'x' in a
string constant is read as the variable x). The robot program must compile without it.
"""

from __future__ import annotations

from tmmaster.tmscript import parse


def test_a_single_quote_in_a_string_constant_is_warned_of() -> None:
    program = parse('main\n{\nDisplay("the master\'s heartbeat")\n}\n')
    assert [(w.line, "§2.7 p. 27" in w.message) for w in program.warnings] == [(3, True)]


def test_a_string_constant_without_a_single_quote_is_not() -> None:
    program = parse('main\n{\nDisplay("the heartbeat of the master" + ", twice ""quoted""")\n}\n')
    assert program.warnings == ()
