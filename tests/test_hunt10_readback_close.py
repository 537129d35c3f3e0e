"""Robot.close() on another thread while a command's read-back is in flight (tmflow).

A command write whose answer never came is not written again blindly: the link is
taken up again and the registers are read back (``seq``, ``ack_seq``) to see whether
it landed (docs/safety.md, "Uncertain writes"). That read-back is outside the command
gate. Here the move's write (FC16 to 9000) is held in the network, it times out, and
the read-back (the read of ``seq`` at 9015) is held too; ``close()`` is called on
another thread while it is. The close must give the command up (its cancel record
uses the number up) while the frame it wrote may still land; both held frames land
only once ``close()`` returned. The simulator's motion log judges: nothing runs.
"""

from __future__ import annotations

import threading

from fault_proxy import FaultProxy, Rule
from test_hunt10_claim_close import moving
from tmmaster import PollPolicy, Robot, TimeoutPolicy
from tmmaster.sim import Simulator


def test_close_during_the_read_back_of_a_lost_command_write_runs_nothing() -> None:
    release = threading.Event()
    with Simulator("tmflow", time_scale=20.0) as sim, FaultProxy(sim.port) as proxy:
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            profile="tmflow",
            gripper=None,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=0.3, ack_timeout_s=2.0),
        )
        outcome: list[str] = []
        try:
            robot.connect()
            robot.wait_until_ready(timeout_s=5)
            proxy.add(Rule("hold", function_code=16, address=9000, release=release))
            mover = moving(robot, outcome)
            sim.wait_for(lambda: proxy.played("hold"), timeout=5)
            # Armed once the write is held: the next read of seq is the read-back.
            read_back = Rule("hold", function_code=3, address=9015, release=release)
            proxy.add(read_back)
            sim.wait_for(lambda: read_back.times == 0, timeout=5)
            assert robot.close(), "close() could not confirm the give-up"
            release.set()  # both held frames land now, after close() returned
            mover.join(10)
            assert not mover.is_alive()
            assert outcome
            assert outcome != ["done"]
            proxy.wait_held()
            ticks = sim.ticks
            sim.wait_for(lambda: sim.ticks >= ticks + 10, timeout=5)
            assert not sim.motion_log(), "a command given up by close() ran"
            assert int(sim.field("ack_seq")) == 1  # its number used up by the cancel record
        finally:
            release.set()
            robot.close()
