"""The command line people see: the live display, --quiet, plain piped output, run reports
shown and plotted, and --log-json / --log-level meaning the same on every command.

The live display is tested on a rich console forced to behave as a terminal (its output
goes to a StringIO); nothing here asserts a duration.
"""

from __future__ import annotations

import contextlib
import fcntl
import io
import json
import os
import re
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from tmmaster._cli import main as tmmaster_main
from tmmaster.pickplace import RunReport, load_report
from tmmaster.pickplace.__main__ import EXIT_OK, _Output, build_parser, run
from tmmaster.pickplace.__main__ import main as pickplace_main
from tmmaster.pickplace._runner import StateEvent
from tmmaster.report.__main__ import main as report_main

if TYPE_CHECKING:
    from tmmaster.pickplace._live import LiveProgress

ROOT = Path(__file__).resolve().parents[1]
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
#: The quick --sim run every test here uses (simulated time 40x faster, 20 ms polling).
SIM = ["--sim", "--sim-time-scale", "40", "--poll-interval", "0.02"]


@pytest.fixture(scope="module")
def sim_report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A report written by a real ``--sim`` run of two cycles, once per test session.

    The xdist workers share one base temp folder: the first to need the report writes
    it under a lock, the others read that file (a run costs about 2 s of wall time).
    """
    shared = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        shared = shared.parent
    path = shared / "sim-report-run.json"
    with (shared / "sim-report.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not path.exists():
            partial = path.with_suffix(".partial")
            code = pickplace_main([*SIM, "--cycles", "2", "--quiet", "--report", str(partial)])
            assert code == EXIT_OK
            partial.rename(path)
    return path


def _forced_terminal_run(argv: list[str]) -> tuple[int, str]:
    from rich.console import Console

    from tmmaster.pickplace._live import LiveProgress

    buffer = io.StringIO()
    console = Console(file=buffer, force_terminal=True, width=160, color_system="standard")
    live = LiveProgress(console, refresh_per_second=20)
    code = run(
        build_parser().parse_args(argv), output=_Output(quiet=False, live=live, console=console)
    )
    return code, buffer.getvalue()


def test_the_live_display_shows_progress_and_logs_print_above_it() -> None:
    code, raw = _forced_terminal_run([*SIM, "--cycles", "2", "--log-level", "info"])
    assert code == EXIT_OK
    text = ANSI.sub("", raw)
    # The live region: state, cycle k/N, elapsed time, ETA and the last event.
    assert re.search(r"MOVE_TO_\w+\s+cycle 2/2 .*elapsed\s+[\d.]+ s\s+ETA", text), text[-2000:]
    assert "last: " in text
    # Every log record is one whole line of its own: the region is erased before it is
    # printed and redrawn after it, never drawn into the middle of it.
    record = re.compile(r"\d{4}-\d\d-\d\dT[\d:.]+Z \[info\s*\] pickplace\.state ")
    records = [line for line in raw.split("\n") if record.search(ANSI.sub("", line))]
    assert len(records) >= 16  # 8 states x 2 cycles
    for line in records:
        # What a terminal shows of that line: what follows the last "erase line".
        shown = ANSI.sub("", line.split("\x1b[2K")[-1])
        assert record.match(shown), line
        assert "ETA" not in shown
        assert "last:" not in shown
    # The display is transient: it ends with the summary table, not a stale region.
    tail = text[text.rindex("time per state") :]
    assert "MOVE_TO_PICK" in tail
    assert "cycle times (s)" in tail
    assert "ETA" not in tail


def test_a_second_ctrl_c_as_the_display_ends_still_closes_the_robot_and_clears_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A second Ctrl-C raises KeyboardInterrupt once (Ctrl-C is ignored after it) wherever
    # the command is; here in the run's clean-up, as the display is ended (seen once in a
    # terminal: the region left on the screen, the last line glued to it). The robot is
    # closed all the same, and the display cleared by the command's next end.
    from tmmaster.pickplace import __main__ as pickplace_module
    from tmmaster.pickplace._live import LiveProgress

    real_end, real_close, closed, drawn = LiveProgress.end, pickplace_module._close, [], []

    def end_interrupted_once(live: LiveProgress) -> None:
        if not drawn:
            drawn.append(live._live)
            raise KeyboardInterrupt
        real_end(live)

    def close(robot: Any, outcome: Any) -> None:
        closed.append(robot)
        real_close(robot, outcome)

    monkeypatch.setattr(LiveProgress, "end", end_interrupted_once)
    monkeypatch.setattr(pickplace_module, "_close", close)
    code, raw = _forced_terminal_run(SIM)
    assert code == 130
    assert len(closed) == 1
    assert closed[0].state == "closed"
    assert drawn[0] is not None
    assert not drawn[0].is_started, raw[-2000:]


def test_a_second_ctrl_c_as_the_tcp_sampler_stops_keeps_the_run_in_the_report(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # The --sim TCP sampler's stop joins its thread, where a signal handler runs: a
    # second Ctrl-C raises there, right after the run returned. The report keeps the run.
    from tmmaster.pickplace.__main__ import _TcpSampler

    real_stop = _TcpSampler.stop

    def stop_interrupted(sampler: _TcpSampler, origin: float | None) -> None:
        real_stop(sampler, origin)
        raise KeyboardInterrupt

    monkeypatch.setattr(_TcpSampler, "stop", stop_interrupted)
    path = tmp_path / "run.json"
    assert pickplace_main([*SIM, "--quiet", "--report", str(path)]) == 130
    report = load_report(path)
    assert report.result == "interrupted"
    assert report.cycles.completed == 1
    assert report.final_state == "DONE"


def test_a_ctrl_c_before_the_display_s_end_leaves_the_region_to_the_next_end(
    live_at: Callable[..., Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    # The KeyboardInterrupt lands as end() enters its section, before the section holds
    # Ctrl-C back: the region must still be there for the command's next end() to clear.
    from tmmaster.pickplace import _live

    _, live = live_at(120)
    drawn, real, entered = live._live, _live.deferred, []
    assert drawn is not None

    @contextlib.contextmanager
    def interrupted_once() -> Iterator[None]:
        if not entered:
            entered.append(True)
            raise KeyboardInterrupt
        with real():
            yield

    monkeypatch.setattr(_live, "deferred", interrupted_once)
    with pytest.raises(KeyboardInterrupt):
        live.end()
    live.end()
    assert not drawn.is_started


def test_quiet_prints_only_the_final_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert pickplace_main([*SIM, "--quiet"]) == EXIT_OK
    out, err = capsys.readouterr()
    assert err == ""
    (line,) = out.splitlines()
    assert line.startswith("DONE: 1/1 cycle(s) of pick-and-place")


def test_quiet_failure_is_the_one_line_reason(capsys: pytest.CaptureFixture[str]) -> None:
    assert pickplace_main(["--quiet", "--cycles", "0", "--dry-run"]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert len(err.strip().splitlines()) == 1
    assert err == "pickplace: --cycles 0: must be 1..1000000 [exit 2]\n"


def test_piped_output_stays_plain_lines(capsys: pytest.CaptureFixture[str]) -> None:
    # capsys streams are not terminals: no live display, no table, no escape codes.
    assert pickplace_main([*SIM, "-v"]) == EXIT_OK
    out, err = capsys.readouterr()
    assert "\x1b" not in out + err
    assert "time per state" not in out + err
    assert "pickplace.state" in err  # -v: info events, one per line
    assert out.splitlines()[-1].startswith("DONE: 1/1")


# -- the live display ---------------------------------------------------------------------

STEPS = ["MOVE_TO_APPROACH", "MOVE_TO_PICK", "GRIPPER_CLOSE", "CHECK_GRASP", "MOVE_TO_LIFT"]


@pytest.fixture
def live_at() -> Iterator[Callable[..., tuple[io.StringIO, LiveProgress]]]:
    """Live displays of a given width on a plain console (ended after the test)."""
    from rich.console import Console

    from tmmaster.pickplace._live import LiveProgress

    made: list[LiveProgress] = []

    def make(width: int, cycles: int = 2, states: list[str] | None = None) -> Any:
        buffer = io.StringIO()
        console = Console(file=buffer, width=width, force_terminal=False, color_system=None)
        live = LiveProgress(console)
        made.append(live)
        steps = [*STEPS, "MOVE_TO_PLACE", "GRIPPER_OPEN", "MOVE_TO_HOME"]
        live.begin(cycles, 10.0, steps if states is None else states)
        return buffer, live

    yield make
    for live in made:
        live.end()


def _enter(live: LiveProgress, state: str, cycle: int, cycles: int = 2) -> None:
    live(StateEvent(state=state, previous="IDLE", cycle=cycle, cycles=cycles, cycle_elapsed_s=0))


def test_the_bar_advances_with_every_state_of_a_cycle(live_at: Callable[..., Any]) -> None:
    _, live = live_at(120)
    assert live.progress() == (0.0, 2)
    _enter(live, "MOVE_TO_APPROACH", 1)
    assert live.progress() == (0.0, 2)
    _enter(live, "MOVE_TO_PICK", 1)
    assert live.progress() == (1 / 8, 2)  # one state of eight behind
    _enter(live, "MOVE_TO_HOME", 1)
    assert live.progress() == (7 / 8, 2)
    _enter(live, "MOVE_TO_APPROACH", 2)
    assert live.progress() == (1.0, 2)
    _enter(live, "GRIPPER_CLOSE", 2)
    _enter(live, "ERROR", 2)
    assert live.progress() == (1.25, 2)  # stays where the run stopped
    _, one = live_at(120, cycles=1, states=STEPS)
    _enter(one, "MOVE_TO_LIFT", 1, cycles=1)
    assert one.progress() == (0.8, 1)
    _enter(one, "DONE", 1, cycles=1)
    assert one.progress() == (1.0, 1)  # full at DONE, a single cycle too


@pytest.mark.parametrize("width", [40, 60, 80, 120])
def test_the_state_is_never_cut_whatever_the_width(width: int, live_at: Callable[..., Any]) -> None:
    buffer, live = live_at(width)
    _enter(live, "MOVE_TO_APPROACH", 1)
    live.console.print(live.renderable())
    lines = buffer.getvalue().splitlines()
    assert lines[0].startswith("MOVE_TO_APPROACH  cycle 1/2"), lines
    assert all(len(line) <= width for line in lines), lines
    assert "…" not in "".join(lines[:-1])  # only the last event may be shortened
    assert any("elapsed" in line for line in lines)
    assert any("ETA" in line for line in lines)


# -- the report: model, show, plot ------------------------------------------------------


def test_a_sim_report_records_the_tcp_path_and_the_move_states(sim_report: Path) -> None:
    report = load_report(sim_report)
    assert report.result == "done"
    assert report.sim is not None
    path = report.sim.tcp_path
    assert len(path) > 10
    times = [row[0] for row in path]
    assert times == sorted(times)
    # The path reaches the pick (300, -200, 100) and the place (300, 200, 200) poses.
    assert min(row[3] for row in path) == pytest.approx(100, abs=2)
    assert any(abs(row[1] - 300) < 2 and abs(row[2] - 200) < 2 for row in path)
    assert "MOVE_TO_PICK" in report.move_states
    assert "GRIPPER_CLOSE" not in report.move_states


def test_an_older_report_still_reads(tmp_path: Path) -> None:
    # A report of an earlier tmmaster: no move_states, no tcp_path.
    old = {
        "report_version": 1,
        "tmmaster_version": "0.1.0",
        "result": "done",
        "exit_code": 0,
        "reason": None,
        "config": {"file": None, "digest": None},
        "target": {"host": "127.0.0.1", "port": 5020, "profile": "article"},
        "sequence": "pick-and-place",
        "final_state": "DONE",
        "started_at": "2026-01-01T00:00:00.000+00:00",
        "duration_s": 1.0,
        "cycles": {"requested": 1, "completed": 1, "times_s": [1.0]},
        "states": {"MOVE_TO_PICK": {"count": 1, "total_s": 1.0, "mean_s": 1.0, "max_s": 1.0}},
        "timeline": [
            {
                "state": "MOVE_TO_PICK",
                "cycle": 1,
                "started_s": 0,
                "duration_s": 1.0,
                "outcome": "ok",
            }
        ],
        "retries": {"grasp": 0},
        "error": None,
        "reaction": None,
        "stop_delivered": None,
        "transport": {"robot": {"requests": 3, "requests_by_function": {"3": 2, "16": 1}}},
        "sim": {"objects": [], "place": None, "tolerance_mm": 2.0, "on_place": False},
    }
    path = tmp_path / "old.json"
    path.write_text(json.dumps(old))
    report = load_report(path)
    assert report.move_states == []
    assert report.sim is not None
    assert report.sim.tcp_path == []


def test_report_show_prints_the_summary_table(
    sim_report: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert tmmaster_main(["report", "show", str(sim_report)]) == 0
    out = capsys.readouterr().out
    assert "DONE" in out
    assert "cycles 2/2" in out
    assert "time per state" in out
    row = next(line for line in out.splitlines() if "MOVE_TO_PICK" in line)
    assert re.search(r"MOVE_TO_PICK\s+│\s+move\s+│\s+2\s+│", row), row
    assert "cycle times (s):" in out


def test_report_plot_writes_a_png(sim_report: Path, tmp_path: Path) -> None:
    image = tmp_path / "run.png"
    assert report_main(["plot", str(sim_report), "-o", str(image)]) == 0
    data = image.read_bytes()
    assert data.startswith(b"\x89PNG\r\n\x1a\n")
    assert len(data) > 10_000


def _figure_texts(report: RunReport) -> tuple[Any, str]:
    """The report's figure (closed by the caller) and every text drawn on it."""
    from tmmaster.report._plot import _figure

    figure = _figure(report)
    texts = [t.get_text() for t in figure.findobj(lambda o: hasattr(o, "get_text"))]
    return figure, "\n".join(texts)


def test_report_plot_marks_the_pick_and_place_poses(sim_report: Path) -> None:
    from matplotlib import pyplot as plt

    report = load_report(sim_report)
    assert report.sim is not None
    assert report.sim.pick == [300, -200, 100, 180, 0, 90]
    figure, texts = _figure_texts(report)
    try:
        (path,) = [ax for ax in figure.axes if ax.get_title().startswith("TCP path")]
        legend = [t.get_text() for t in path.get_legend().get_texts()]
        assert "pick (300, -200, 100)" in legend
        assert "place (300, 200, 200)" in legend
        marks = {t.get_text(): t.xy for t in path.texts}
        assert marks == {"pick": (300, -200), "place": (300, 200)}
        assert "pick-and-place: done, 2/2 cycle(s)" in texts
    finally:
        plt.close(figure)


def _failed_report(outcome: str, timeline: list[dict[str, Any]]) -> RunReport:
    return RunReport.model_validate(
        {
            "tmmaster_version": "0",
            "result": outcome,
            "exit_code": 130 if outcome == "interrupted" else 4,
            "reason": f"{outcome.replace('_', ' ')} in {timeline[-1]['state']} (cycle 0)",
            "sequence": "pick-and-place",
            "duration_s": 0.5,
            "cycles": {"requested": 3, "completed": 0},
            "timeline": timeline,
        }
    )


@pytest.mark.parametrize("outcome", ["interrupted", "robot_fault"])
def test_a_failed_run_plots_what_it_recorded_and_says_so(outcome: str) -> None:
    from matplotlib import pyplot as plt

    # It failed while the robot was getting ready: IDLE, before cycle 1, is all it has.
    idle = {"state": "IDLE", "cycle": 0, "started_s": 0, "duration_s": 0.5, "outcome": "failed"}
    report = _failed_report(outcome, [idle])
    figure, texts = _figure_texts(report)
    try:
        cycles = next(ax for ax in figure.axes if ax.get_title() == "states per cycle")
        assert len(cycles.patches) == 1  # the IDLE bar, not empty axes
        assert [t.get_text() for t in cycles.get_yticklabels()] == ["start"]
        said = "INTERRUPTED" if outcome == "interrupted" else "FAILED (robot fault)"
        assert f"pick-and-place: {said}, 0/3 cycle(s)" in figure.get_suptitle()
        assert report.reason is not None
        assert report.reason in figure.get_suptitle()
        assert "nothing to plot" not in texts
    finally:
        plt.close(figure)


def test_report_plot_without_matplotlib_names_the_extra(
    sim_report: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib -> ImportError
    assert report_main(["plot", str(sim_report), "-o", str(tmp_path / "x.png")]) == 1
    err = capsys.readouterr().err
    assert err.strip().splitlines() == [
        "report: plotting needs matplotlib: pip install 'tmmaster[plot]' [exit 1]"
    ]
    assert not (tmp_path / "x.png").exists()


def test_report_show_of_a_bad_file_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text('{"result": 3}')
    assert report_main(["show", str(bad)]) == 2
    assert report_main(["show", str(tmp_path / "missing.json")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 2
    assert lines[0].startswith(f"report: {bad}: not a tmmaster run report:")
    assert "cannot read the report" in lines[1]


def test_the_report_model_round_trips(sim_report: Path) -> None:
    data = json.loads(sim_report.read_text())
    assert RunReport.model_validate(data).model_dump(mode="json") == data


# -- --log-json and --log-level everywhere ------------------------------------------------


def test_log_json_is_json_lines_on_stderr_for_pickplace(capsys: pytest.CaptureFixture[str]) -> None:
    assert pickplace_main([*SIM, "--log-json"]) == EXIT_OK
    err = capsys.readouterr().err
    events = [json.loads(line) for line in err.splitlines()]
    assert {"pickplace.run_started", "sim.initialised"} <= {e["event"] for e in events}


@pytest.mark.parametrize(
    "argv",
    [
        ["profile", "list"],
        ["profile", "show", "article"],
        ["schema"],
        ["report", "show", "RUN"],
        ["report", "plot", "RUN"],
        ["sim"],
        ["pickplace"],
    ],
    ids=lambda a: " ".join(a),
)
def test_every_command_takes_log_json_and_log_level(argv: list[str]) -> None:
    from tmmaster._cli import build_parser as tmmaster_parser

    args = tmmaster_parser().parse_args([*argv, "--log-json", "--log-level", "debug"])
    assert args.log_json is True
    assert args.log_level == "debug"


def test_a_run_that_never_started_still_shows_and_plots(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "bad.json"
    assert pickplace_main(["--dry-run", "--cycles", "0", "--quiet", "--report", str(path)]) == 2
    assert report_main(["show", str(path)]) == 0
    out = capsys.readouterr().out
    assert "CONFIG_ERROR" in out
    assert "--cycles 0: must be 1..1000000" in out
    assert report_main(["plot", str(path)]) == 0  # default: the report's name, .png
    assert path.with_suffix(".png").read_bytes().startswith(b"\x89PNG")
    (line,) = capsys.readouterr().out.splitlines()
    assert line.startswith(f"wrote {path.with_suffix('.png')}: nothing to plot, the run ended")
    assert "--cycles 0: must be 1..1000000" in line
    from matplotlib import pyplot as plt

    figure, texts = _figure_texts(load_report(path))
    plt.close(figure)
    assert figure.axes == []  # no empty axes: the picture says why
    assert "nothing to plot: the run ended before its first state" in texts
    assert "FAILED (config error)" in texts
