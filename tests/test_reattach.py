"""An agent whose world goes and comes back attaches again by itself, over real zenoh sessions
(in-process; the network partition itself is tests/test_partition.py): the world that had
it gone gives its body back as a restart, and the agent goes on with a fresh brain. Also:
`max_tick_rate` caps a lockstep world's pace, and the partition report reads the world's
statuses right."""

from __future__ import annotations

import threading
import time

import pytest

from agent_runtime.node import AgentOptions, AgentReport, run_agent
from agent_runtime.world_link import WorldLink
from faults.partition import PartitionRun, measure
from tests.conftest import RunningWorld, make, wait_until
from tests.scripted import ScriptedBody
from world_server.server import WorldServer

ONE = '''
name = "one"
seed = 3
agents = 1
layout = """
..........
.A.....+..
..b.......
..........
"""
[world]
sensor_noise = 0.0
body_grace_ticks = 0
'''


@pytest.mark.slow  # two seconds: a world stopped and started again
def test_an_agent_the_world_had_gone_attaches_again_when_its_world_is_back(bus, start_world):
    rw = start_world(ONE)
    report, stop = AgentReport(), threading.Event()
    agent = threading.Thread(target=run_agent, args=(bus.client_session(), AgentOptions("w0", "a1")),
                             kwargs=dict(stop=stop, report=report), daemon=True)
    agent.start()
    try:
        wait_until(lambda: report.ticks > 5, what="the agent to be stepping")
        link = report.world_link
        first = link.welcome
        # What a partition does: the agent loses its world (the world's token goes), and the
        # world, which saw the agent's token go, stops its body and lets it leave.
        world, session = rw.world, rw.server.session
        rw.close()
        world.detach("a1")
        world.step()
        assert world.status().agent_alive == (False,) and world.status().agent_present == (False,)
        gone_at = world.tick
        time.sleep(0.2)  # a step under way when the world stopped ends
        ticks = report.ticks
        time.sleep(0.3)
        assert report.ticks == ticks  # no world, no frames, no steps: it waits
        # The world is back (the same world, on the same bus): the agent attaches again by itself.
        back = RunningWorld(world, session)
        try:
            wait_until(lambda: link.welcome is not first, what="the agent to attach again")
            assert link.welcome.restarts == 1 and link.welcome.tick >= gone_at
            wait_until(lambda: report.ticks >= ticks + 20, what="the agent to step again")
            st = world.status()
            assert st.agent_alive == (True,) and st.agent_present == (True,) and st.agent_restarts == (1,)
        finally:
            back.close()
    finally:
        stop.set()
        agent.join(10)
    assert not agent.is_alive()


def test_a_world_that_comes_back_without_having_lost_the_agent_is_not_a_restart(bus, start_world):
    rw = start_world(ONE)
    report, stop = AgentReport(), threading.Event()
    agent = threading.Thread(target=run_agent, args=(bus.client_session(), AgentOptions("w0", "a1")),
                             kwargs=dict(stop=stop, report=report), daemon=True)
    agent.start()
    try:
        wait_until(lambda: report.ticks > 5, what="the agent to be stepping")
        link, first = report.world_link, report.world_link.welcome
        world, session = rw.world, rw.server.session
        rw.close()  # the world's token goes; the world never saw the agent go
        back = RunningWorld(world, session)
        try:
            wait_until(lambda: link.welcome is not first, what="the agent to attach again")
            assert link.welcome.restarts == 0  # the same process, still alive in the world's eyes
            ticks = report.ticks
            wait_until(lambda: report.ticks >= ticks + 20, what="the agent to step again")
        finally:
            back.close()
    finally:
        stop.set()
        agent.join(10)


def test_max_tick_rate_caps_the_lockstep_pace(bus, start_world):
    rw = start_world(ONE, max_tick_rate=10.0)
    body = ScriptedBody(WorldLink(bus.client_session(), "w0", "a1"))
    start, t0 = body.frame.tick, time.monotonic()
    while time.monotonic() - t0 < 0.6:
        body.act()  # answers at once: uncapped, hundreds of ticks a second
    ticks, elapsed = body.frame.tick - start, time.monotonic() - t0
    assert 1 <= ticks <= 10.0 * elapsed + 2, f"{ticks} ticks in {elapsed:.2f} s"
    assert rw.world.tick == body.frame.tick


def test_a_non_positive_max_tick_rate_is_refused(bus):
    with pytest.raises(ValueError, match="max_tick_rate"):
        WorldServer(make("A.+"), bus.server_session(), max_tick_rate=0.0)


def _status(tick: int, alive: tuple, present: tuple, distance: tuple, restarts=(0, 0, 0), bricks: int = 34) -> dict:
    return {"tick": tick, "agent_ids": ["a3", "a1", "a2"], "agent_alive": list(alive),
            "agent_present": list(present), "agent_distance": list(distance), "agent_restarts": list(restarts),
            "bricks_total": bricks}


def test_measure_reads_dead_left_and_back_from_the_statuses():
    T, F = True, False
    statuses = [
        (0.0, _status(100, (T, T, T), (T, T, T), (1.0, 1.0, 1.0))),
        (10.0, _status(150, (T, T, T), (T, T, T), (2.0, 2.0, 2.0))),   # the cut at t = 10
        (13.0, _status(400, (T, F, F), (T, T, T), (5.0, 2.0, 2.0))),   # seen dead
        (14.5, _status(500, (T, F, F), (T, F, F), (6.0, 2.0, 2.0))),   # bodies gone
        (21.0, _status(900, (T, F, T), (T, F, T), (9.0, 2.0, 2.0), (0, 0, 1))),  # a2 back, 1 s after
        (22.0, _status(950, (T, T, T), (T, T, T), (9.5, 2.0, 2.5), (0, 1, 1))),  # a1 back, 2 s after
        (40.0, _status(2000, (T, T, T), (T, T, T), (20.0, 7.0, 9.0), (0, 1, 1))),
    ]
    run = measure(statuses, 10.0, 20.0, ["a1", "a2"], ["a3"], PartitionRun(bricks_expected=34))
    assert run.dead_after == {"a1": 3.0, "a2": 3.0} and run.left_after == {"a1": 4.5, "a2": 4.5}
    assert run.back_after == {"a1": 2.0, "a2": 1.0}
    assert run.moved_after_back == {"a1": 5.0, "a2": 7.0}
    assert run.kept_alive and run.bricks_seen == [34] and run.restarts == {"a3": 0, "a1": 1, "a2": 1}
    # The kept agent dead once after the cut, or a brick lost: the report says so.
    statuses[4][1]["agent_alive"][0] = False
    statuses[5][1]["bricks_total"] = 33
    run = measure(statuses, 10.0, 20.0, ["a1", "a2"], ["a3"], PartitionRun(bricks_expected=34))
    assert not run.kept_alive and run.bricks_seen == [33, 34]
