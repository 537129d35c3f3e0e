"""What a close sends before its Stop on a slow link (tmflow).

Every request of the link takes 0.6 s (answered well inside its timeout). A
``Fleet.close(timeout_s=0.5)`` of a robot on a long move returned after about 6 s, its
Stop pressed about 4.2 s after the close began, the arm running on meanwhile: before the
Stop went the close's look at the move (three reads), a read of the TCP pose for the
report, and three heartbeat writes, queued one behind the other on the link. The
heartbeat now stops as the close begins (the robot program expires whatever the close
leaves), and the look reads no pose: the Stop follows the look's reads (measured: the
close 3.0 s, the Stop at 1.8 s).

Judged on what the robot received, in order (the simulator's request log), not on time.
"""

from __future__ import annotations

import time

from test_hunt4_fleet_slow_close import FAR, SLOW, cell, slower_than_the_budget

#: tmflow's registers: the heartbeat block, the TCP pose, the Stop button.
HEARTBEAT, POSE, STOP_COIL = 9050, 7025, 7105


def test_a_close_on_a_slow_link_sends_no_beat_and_no_pose_read_before_its_stop() -> None:
    with cell("tmflow") as c:
        # Started, not waited for: the close is the one to give the moves up (a thread
        # waiting on one may give it up first, without the look).
        motions = [c.robots[name].start_move(FAR, speed=SLOW) for name in ("a", "b")]
        c.wait_moving("a", "b")
        slower_than_the_budget(c)
        sim = c.sims["b"]
        sim.clear_request_log()
        closed_at = time.time()
        c.fleet.close(timeout_s=0.5)
        log = [r for r in sim.request_log if r.time >= closed_at - 0.7]  # one in flight
        stops = [k for k, r in enumerate(log) if r.function_code == 5 and r.address == STOP_COIL]
        assert stops, f"no Stop reached the robot: {log}"
        before = log[: stops[0]]
        beats = [r for r in before if r.address == HEARTBEAT and r.time > closed_at + 0.7]
        assert not beats, f"heartbeats written after the close began, before its Stop: {beats}"
        poses = [r for r in before if r.function_code == 4 and r.address == POSE]
        assert not poses, f"the TCP pose read before the Stop: {poses}"
        assert len(before) <= 4, f"more than the look's reads before the Stop: {before}"
        assert all(motion.abandoned for motion in motions)
