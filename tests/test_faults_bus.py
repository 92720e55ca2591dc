"""Agents that fail without harm, over real zenoh sessions: a silent agent with a live token
stops slowing a lockstep world after a few missed deadlines and is waited for again once it
answers; an agent refuses forged sensor frames (absurd tick, another epoch) and keeps
answering the world."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from agent_runtime.node import AgentOptions, AgentReport, run_agent
from agent_runtime.world_link import WorldLink
from protocol import keys
from protocol.codec import encode
from protocol.messages import CHANNELS, SensorFrame
from tests.conftest import wait_until
from tests.scripted import ScriptedBody

TWO_AGENTS = '''
name = "two"
seed = 3
agents = 2
layout = """
..........
.A.....+..
..b.......
.A........
..........
"""
[world]
sensor_noise = 0.0
lockstep_timeout = 0.25
lockstep_miss_limit = 3
'''


@pytest.mark.slow  # a few lockstep timeouts
def test_a_silent_agent_with_a_token_stops_slowing_lockstep_and_is_waited_for_again_when_it_answers(
        bus, start_world):
    rw = start_world(TWO_AGENTS)
    cfg = rw.world.cfg
    a1 = ScriptedBody(WorldLink(bus.client_session(), "w0", "a1"))
    silent = WorldLink(bus.client_session(), "w0", "a2")
    silent.attach()
    # It drives east for a few ticks, then falls silent (a frozen process) ...
    last = -1
    for _ in range(5):
        frame = silent.next_frame(last, timeout=5.0)
        assert frame is not None
        silent.send(frame.tick, speed=2.0)
        last = frame.tick
        a1.act()
    # The silent agent costs one timeout per tick, lockstep_miss_limit times ...
    for _ in range(cfg.lockstep_miss_limit + 1):
        a1.act()
    wait_until(lambda: rw.server.lockstep.unresponsive("a2"), what="a2 to be found unresponsive")
    # ... then no more: within three timeouts the world steps far more than three ticks.
    start, deadline = a1.frame.tick, time.monotonic() + 3 * cfg.lockstep_timeout
    while time.monotonic() < deadline:
        a1.act()
    assert a1.frame.tick - start >= 30, f"only {a1.frame.tick - start} ticks in {3 * cfg.lockstep_timeout} s"
    assert rw.world.status().agents_alive == 2  # still attached, frames still sent to it
    # Its body stopped when the world stopped waiting: its last command no longer drives it.
    still = rw.world.agent_poses()[1, :2].copy()
    for _ in range(10):
        a1.act()
    assert np.hypot(*(rw.world.agent_poses()[1, :2] - still)) < 0.05
    # It answers again (its command may name a tick the world has left): it is waited for again,
    # and its commands drive its body.
    frame = silent.next_frame(-1, timeout=5.0)
    silent.send(frame.tick)
    wait_until(lambda: not rw.server.lockstep.unresponsive("a2"), what="a2 to be taken back")
    before = rw.world.agent_poses()[1, :2].copy()
    last = frame.tick
    for _ in range(15):
        a1.act()
        frame = silent.next_frame(last, timeout=5.0)
        assert frame is not None
        silent.send(frame.tick, speed=2.0)
        last = frame.tick
    assert np.hypot(*(rw.world.agent_poses()[1, :2] - before)) > 0.5
    assert rw.server.lockstep.missed.get("a2", 0) == 0


def _forged(tick: int, epoch: int, sectors: int) -> bytes:
    return encode(SensorFrame("a1", tick, 0.0, 0.0, 0.0, sectors, (-1.0,) * (len(CHANNELS) * sectors), True,
                              epoch=epoch))


def test_an_agent_refuses_forged_frames_and_keeps_answering_the_world(bus, start_world):
    rw = start_world(TWO_AGENTS.replace("agents = 2", "agents = 1"))
    report, stop = AgentReport(), threading.Event()
    agent = threading.Thread(target=run_agent, args=(bus.client_session(), AgentOptions("w0", "a1")),
                             kwargs=dict(stop=stop, report=report), daemon=True)
    agent.start()
    try:
        wait_until(lambda: report.ticks > 5, what="the agent to be stepping")
        link = report.world_link
        injector = bus.client_session()
        key = keys.sensors("w0", "a1")
        sectors = rw.world.cfg.sensor_sectors
        for forged in (_forged(2**62, link.welcome.epoch, sectors),           # an absurd tick
                       _forged(rw.world.tick + 1, link.welcome.epoch ^ 1, sectors)):  # not the world's
            refused = link.refused_frames

            def inject(data=forged, refused=refused):
                injector.put(key, data)
                return link.refused_frames > refused

            wait_until(inject, what="the agent to refuse a forged frame")
            # It keeps answering: the world goes on at its pace, never giving up on it.
            ticks = report.ticks
            wait_until(lambda ticks=ticks: report.ticks >= ticks + 50, timeout=20 * rw.world.cfg.lockstep_timeout,
                       what="the agent to keep answering")
            assert not rw.server.lockstep.unresponsive("a1")
    finally:
        stop.set()
        agent.join(10)
