"""``tmmaster tmscript``: the logging options every command takes, syntax errors placed
where the text ends too early, and ``check`` reporting every error of a script in one run."""

from __future__ import annotations

import argparse
import importlib
import json
from collections.abc import Iterator
from pathlib import Path

import pytest

import tmmaster
from tmmaster import TMScriptSyntaxError, _cli
from tmmaster._cli import build_parser as tmmaster_parser
from tmmaster._cli import main as tmmaster_main
from tmmaster._cliparse import UsageError
from tmmaster.tmscript import evaluate, parse
from tmmaster.tmscript.__main__ import main
from tmmaster.tmscript._parser import MAX_ERRORS

# -- --log-json and --log-level on every command and every module -------------------------


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    parser.format_help()  # a command's parser may get its options only once it is used
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _leaves(
    parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """Each command that runs (``tmscript check``, ``sim``...) with its parser."""
    children = _subcommands(parser)
    if not children:
        yield path, parser
    for name, child in children.items():
        yield from _leaves(child, (*path, name))


def _required(parser: argparse.ArgumentParser) -> list[str]:
    """Values for a command's required arguments (enough to get past the parser)."""
    argv: list[str] = []
    for action in parser._actions:
        value = str(next(iter(action.choices))) if action.choices else "X"
        if not action.option_strings and action.nargs in (None, 1, "+"):
            argv.append(value)
        elif action.option_strings and action.required:
            argv += [action.option_strings[0], value]
    return argv


def _entry_points() -> dict[str, argparse.ArgumentParser]:
    """``tmmaster`` and every ``python -m tmmaster.X`` there is."""
    found = {"tmmaster": tmmaster_parser()}
    for package in sorted(Path(tmmaster.__file__).parent.iterdir()):
        if (package / "__main__.py").is_file():
            module = importlib.import_module(f"tmmaster.{package.name}.__main__")
            found[f"python -m tmmaster.{package.name}"] = module.build_parser()
    return found


def test_every_command_and_module_takes_log_json_and_log_level() -> None:
    entries = _entry_points()
    assert {"python -m tmmaster.tmscript", "python -m tmmaster.sim"} <= set(entries)
    refused: list[str] = []
    checked: list[str] = []
    for prog, parser in entries.items():
        for path, leaf in _leaves(parser):
            argv = [*path, *_required(leaf), "--log-json", "--log-level", "DEBUG"]
            checked.append(" ".join([prog, *path]))
            try:
                args = parser.parse_args(argv)
            except UsageError as exc:
                refused.append(f"{prog} {' '.join(argv)}: {exc}")
                continue
            if args.log_json is not True or args.log_level != "debug":
                refused.append(f"{prog} {' '.join(argv)}: {args}")
    assert "tmmaster tmscript check" in checked
    assert "python -m tmmaster.tmscript eval" in checked
    assert refused == []


def _events(err: str) -> list[dict[str, object]]:
    return [json.loads(line) for line in err.splitlines() if line.startswith("{")]


def test_tmscript_logs_json_events_with_its_own_options(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    script = tmp_path / "ok.tms"
    script.write_text('main {\n  Display("hi")\n}\n', encoding="utf-8")
    assert main(["check", str(script), "--log-json", "--log-level", "info"]) == 0
    out, err = capsys.readouterr()
    assert out == f"{script}: OK\n"
    (event,) = _events(err)
    assert event["event"] == "tmscript.checked"
    assert event["errors"] == 0
    assert main(["run", str(script), "--log-json", "--log-level", "INFO"]) == 0
    out, err = capsys.readouterr()
    assert out == "hi\n"
    assert [e["event"] for e in _events(err)] == ["tmscript.ran"]


def test_tmscript_takes_the_logging_options_given_before_the_command(
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv = ["--log-level", "debug", "--log-json", "tmscript", "eval", "6 * 7"]
    assert tmmaster_main(argv) == 0
    out, err = capsys.readouterr()
    assert out == "42\n"
    assert [e["event"] for e in _events(err)] == ["tmscript.evaluated"]
    # Quiet by default: warnings only.
    assert tmmaster_main(["tmscript", "eval", "6 * 7", "--log-json"]) == 0
    assert capsys.readouterr() == ("42\n", "")


# -- where a syntax error is --------------------------------------------------------------

INCOMPLETE = [
    # (expression, column of the error: just after the expression's last character)
    ("1 +", 4),
    ("x =", 4),
    ("1 ? 2 :", 8),
    ("(1 +", 5),
    ("1 + (2", 7),
    ("{1, 2", 6),
    ('Length("ab"', 12),
]


@pytest.mark.parametrize(("expression", "column"), INCOMPLETE, ids=[e for e, _ in INCOMPLETE])
def test_eval_of_an_incomplete_expression_points_where_it_ends(
    expression: str, column: int, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["eval", expression]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"<expr>:1:{column}: unexpected end of the expression"), line
    with pytest.raises(TMScriptSyntaxError) as caught:
        evaluate(expression)
    assert (caught.value.line, caught.value.column) == (1, column)


def test_eval_says_what_is_missing(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["eval", "1 +"]) == 2
    assert capsys.readouterr().err == (
        "<expr>:1:4: unexpected end of the expression: an operand is missing\n"
    )
    assert main(["eval", "1 + 2)"]) == 2  # not past the end: the ")" itself
    assert capsys.readouterr().err == "<expr>:1:6: unexpected ')'\n"


SCRIPTS_ENDING_EARLY = [
    # (script, line, column, message): the end of the line or text where it is incomplete
    ("main {\n  x = 1 +\n}\n", 2, 10, "unexpected end of line: an operand is missing"),
    ("main {\n  x = 1 +", 2, 10, "unexpected end of the script: an operand is missing"),
    ("main {\n  int x = 1\n", 2, 12, "unexpected end of the script (a missing '}' or ')'?)"),
    ("main {\n  if (x > 1\n}\n", 3, 1, "unexpected '}', expected ')'"),
    ("main {\n  x = a[1\n}\n", 3, 1, "unexpected '}', expected ']'"),
    (
        'main {\n  Display("hi)\n}\n',
        2,
        11,
        "a string constant without its closing '\"' on this line",
    ),
]


def test_a_script_ending_early_is_placed_where_it_does() -> None:
    found = []
    for text, *_ in SCRIPTS_ENDING_EARLY:
        with pytest.raises(TMScriptSyntaxError) as caught:
            parse(text)
        found.append((text, caught.value.line, caught.value.column, caught.value.reason))
    assert found == SCRIPTS_ENDING_EARLY


# -- check: every error in one run ----------------------------------------------------------


def _check(tmp_path: Path, text: str, capsys: pytest.CaptureFixture[str]) -> tuple[int, list[str]]:
    script = tmp_path / "s.tms"
    script.write_text(text, encoding="utf-8")
    code = main(["check", str(script)])
    out, err = capsys.readouterr()
    assert out == ("" if code else f"{script}: OK\n")
    return code, [line.replace(str(script), "s.tms") for line in err.splitlines()]


def test_check_reports_every_syntax_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = (
        "define {\n"
        "  int a =\n"  # 2
        "}\n"
        "main {\n"
        "  int b = 2 2\n"  # 5
        "  if (b > 1) {\n"
        "    b = b +\n"  # 7
        "  }\n"
        "  Display(b $ 1)\n"  # 9
        "}\n"
        "int f() {\n"
        "  return 1 *\n"  # 12
        "}\n"
    )
    assert _check(tmp_path, text, capsys) == (
        2,
        [
            "s.tms:2:10: unexpected end of line: an operand is missing",
            "s.tms:5:13: unexpected '2'",
            "s.tms:7:12: unexpected end of line: an operand is missing",
            "s.tms:9:13: unexpected character '$'",
            "s.tms:12:13: unexpected end of line: an operand is missing",
            "s.tms: 5 errors",
        ],
    )


def test_check_reports_every_unknown_function_and_wrong_call(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = (
        "define {\n"
        "  int limit = Nope()\n"  # 2: the variable still exists below
        "}\n"
        "main {\n"
        '  Display123("a")\n'  # 5
        "  int n = Length(1, 2, 3)\n"  # 6
        "  n = n + limit\n"
        "  if (n > 1) {\n"
        "    Foo()\n"  # 9
        "  }\n"
        "  Display(n)\n"
        "}\n"
        "int f(int x) {\n"
        "  return Bar(x)\n"  # 14
        "}\n"
    )
    code, lines = _check(tmp_path, text, capsys)
    assert code == 2
    assert [line.split(": ")[0] for line in lines] == [
        "s.tms:2:15",
        "s.tms:5:3",
        "s.tms:6:11",
        "s.tms:9:5",
        "s.tms:14:10",
        "s.tms",
    ]
    assert "unknown function Nope()" in lines[0]
    assert "unknown function Display123()" in lines[1]
    assert "Length(" in lines[2]
    assert lines[-1] == "s.tms: 5 errors"


def test_check_says_where_it_stopped_looking(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = "main {\n" + "  x = 1 +\n" * (MAX_ERRORS + 20) + "}\n"
    code, lines = _check(tmp_path, text, capsys)
    assert code == 2
    assert len(lines) == MAX_ERRORS + 1
    assert lines[-1] == f"s.tms: {MAX_ERRORS} errors (check stops at {MAX_ERRORS})"


HOSTILE = [
    # (text, how many errors check finds)
    ("}\n" * 50, 1),  # outside any section: nothing to pick up at
    ("main {\n" + "if (1) {\n" * 300 + "x = 1 2\n" * 3, 4),  # 3 lines, and the "}" missing
    ("main {\n  x = " + "(" * 500 + "\n}\n", 1),
    ("$" * 500 + "\n" + '"' * 3, 1),  # the first on each line
    ("main {\n  x = (1 +\n  y = 2\n}\nclosestop {\n  z = 1 *\n}\n", 3),
    ("main {\n  if (x > 1\n  }\n  Display(1\n  int z = 3 $\n}\n", 3),
]


def test_check_of_a_mangled_script_begins_with_the_error_run_reports(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    script = tmp_path / "s.tms"
    for text, count in HOSTILE:
        script.write_text(text, encoding="utf-8")
        assert main(["run", str(script)]) == 2
        (first,) = capsys.readouterr().err.splitlines()
        assert main(["check", str(script)]) == 2
        lines = capsys.readouterr().err.splitlines()
        assert lines[0] == first
        assert len(lines) == (1 if count == 1 else count + 1), (text[:40], lines)
        if count > 1:
            assert lines[-1] == f"{script}: {count} errors"


@pytest.mark.parametrize(
    ("argv", "level"),
    [
        (["--log-level", "debug", "report", "show", "run.json"], "debug"),
        (["--log-level", "debug", "profile", "list"], "debug"),
        (["--log-level", "debug", "tmscript", "eval", "1"], "debug"),
        (["--log-level", "debug", "report", "show", "run.json", "--log-level", "error"], "error"),
    ],
)
def test_a_log_level_before_the_command_reaches_its_sub_command(
    argv: list[str], level: str
) -> None:
    # Sub-commands of sub-commands (report show, profile list) have their own default.
    args = _cli.build_parser().parse_args(argv)
    _cli._apply_global_logging(args, argv)
    assert args.log_level == level
