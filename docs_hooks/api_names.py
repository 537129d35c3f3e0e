"""How the API reference shows a few names: read by docs_hooks/griffe_api.py (the site)
and by tests/test_api_reference.py (the check), so both follow the same rules.

Paths are where the source defines a name (``tmmaster._robot.Robot``), as Griffe and
``inspect`` find it; the values are the public names the reader knows.
"""

from __future__ import annotations

#: The public packages the reference documents, and the page of each.
PAGES = {
    "tmmaster": "docs/api/tmmaster.md",
    "tmmaster.aio": "docs/api/aio.md",
    "tmmaster.sim": "docs/api/sim.md",
    "tmmaster.pickplace": "docs/api/pickplace.md",
    "tmmaster.report": "docs/api/report.md",
    "tmmaster.tmscript": "docs/api/tmscript.md",
}

#: Protocols that stand for a public class in a signature (the module cannot import the
#: class without an import cycle): the reference names the public class.
STAND_INS = {
    "tmmaster._fleet._Closable": "tmmaster.Robot",
    "tmmaster.sim._memory.SimulatorLoop": "tmmaster.sim.Simulator",
}

#: Classes the package makes and hands out (never made by a user): the reference shows
#: them without a constructor.
MADE_BY_THE_PACKAGE = {
    "tmmaster.aio._robot.AsyncGripper",
    "tmmaster.aio._robot.AsyncMotion",
    "tmmaster.aio._robot.AsyncRobotIO",
    "tmmaster._io.RobotIO",
    "tmmaster._command.Motion",
    "tmmaster.tmscript._evaluator.Program",
}

#: Members of public classes that serve the package itself, not its users: left out of
#: the reference.
INTERNAL_MEMBERS = {
    "tmmaster._command.Motion.ticket",
    "tmmaster._transport.Transport.read_plan",
    # The coroutine protocol an AsyncMotion speaks to asyncio (a task made of the handle).
    "tmmaster.aio._robot._Primed.close",
    "tmmaster.aio._robot._Primed.send",
    "tmmaster.aio._robot._Primed.throw",
    # The runner's count of every pass; a run's records and cycle times are its output.
    "tmmaster.pickplace._runner.RunResult.log",
    "tmmaster.sim._simulator.Simulator.device_server",
    "tmmaster.tmscript._evaluator.Program.script",
    "tmmaster.tmscript._evaluator.Program.define",
    "tmmaster.tmscript._evaluator.Program.globals_size",
    "tmmaster.tmscript._evaluator.Program.sections",
}

#: Functions made at import time with a class's signature (``connect =
#: _connected(Robot)``): the reference shows them with the class's parameters.
MADE_LIKE = {
    "tmmaster._robot.connect": "tmmaster._robot.Robot",
    "tmmaster.aio._robot.connect": "tmmaster._robot.Robot",
}

#: Classes whose members are made at import time from another class's (``move_to =
#: _awaited(Robot.move_to)``, a docstring taken from ``Robot.connect``): the reference
#: shows each as it is at run time, an ``async`` method with the other's parameters and
#: the docstring made for it.
DERIVED = {
    "tmmaster.aio._robot.AsyncGripper",
    "tmmaster.aio._robot.AsyncMotion",
    "tmmaster.aio._robot.AsyncRobot",
    "tmmaster.aio._robot.AsyncRobotIO",
}

#: Public names documented by their package's docstring, not rendered on their own.
NOT_RENDERED = {"tmmaster.__version__"}
