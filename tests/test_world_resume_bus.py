"""The world survives its own death, over real zenoh sessions: an agent whose world goes says
that it waits, attaches by itself to the world resumed from a checkpoint (whose ticks are
lower than the last frame it took), goes on acting there, and still refuses frames of the
world that died."""

from __future__ import annotations

import logging
import threading

import pytest

from agent_runtime import node as agent_node
from agent_runtime.node import AgentOptions, AgentReport, run_agent
from conag.sim.loop import start
from protocol import keys
from protocol.codec import encode
from protocol.messages import CHANNELS, SensorFrame
from tests.conftest import SCENARIOS, Process, RunningWorld, wait_until
from world_server import server as server_node
from world_server.checkpoint import (
    CheckpointError,
    CheckpointPlan,
    checkpoint_world,
    load_world,
    previous_path,
    read_checkpoint,
    resumed_epoch,
    write_checkpoint,
)
from world_server.scenario import parse_scenario
from world_server.server import WorldServer

ONE_AGENT = '''
name = "one"
seed = 3
agents = 1
layout = """
..........
.A.....+..
..b.......
....b.....
..........
"""
[world]
sensor_noise = 0.0
lockstep_timeout = 0.5
'''


@pytest.mark.slow  # the agent's session reconnects to the new world (about two seconds)
def test_an_agent_waits_for_its_world_and_attaches_to_the_resumed_one(bus, start_world, tmp_path, caplog,
                                                                      monkeypatch):
    monkeypatch.setattr(agent_node, "WAIT_QUIET", 0.0)
    caplog.set_level(logging.WARNING, logger="conag.agent")
    path = tmp_path / "w.ckpt"
    first = start_world(ONE_AGENT, checkpoint=CheckpointPlan(str(path), every=20))
    report, stop = AgentReport(), threading.Event()
    agent = threading.Thread(target=run_agent, args=(bus.client_session(), AgentOptions("w0", "a1")),
                             kwargs=dict(stop=stop, report=report), daemon=True)
    agent.start()
    try:
        wait_until(lambda: report.ticks > 50, what="the agent to be stepping")
        link = report.world_link
        old_epoch = link.welcome.epoch
        first.close()                # the world stops: its token goes, a last checkpoint is written
        first.server.session.close()
        last_tick = first.world.tick
        wait_until(lambda: "waiting for world w0" in caplog.text, what="the agent to say it waits")
        # Resume from the periodic checkpoint before the last one: behind what the agent saw.
        world = load_world(previous_path(path))
        assert world.tick < last_tick
        world.epoch = resumed_epoch(world)
        second = RunningWorld(world, bus.server_session(), resumed=True,
                              checkpoint=CheckpointPlan(str(path), every=20))
        try:
            # (Its session reconnects to the new world's endpoint first: zenoh retries with a backoff.)
            wait_until(lambda: link.welcome.epoch == world.epoch, timeout=30,
                       what="the agent to attach to the resumed world")
            assert link.welcome.tick < last_tick
            # The welcome lands (the link sets it) a moment before the agent logs it.
            wait_until(lambda: "re-attached to world w0" in caplog.text, what="the agent to say it re-attached")
            ticks = report.ticks
            wait_until(lambda: report.ticks >= ticks + 30, timeout=30, what="the agent to act in the resumed world")
            # Its first frame there is the Welcome's own tick, which it may have answered
            # before `ticks` was read: 30 steps reach the Welcome's tick + 29 at least.
            assert second.world.tick >= link.welcome.tick + 29
            assert second.world.agents["a1"].restarts == 0  # the same process, not a restart
            # A frame of the world that died (its epoch, a tick just ahead) is refused.
            refused = link.refused_frames
            injector = bus.client_session()
            stale = _frame(second.world.tick + 1, old_epoch, world.cfg.sensor_sectors)

            def inject():
                injector.put(keys.sensors("w0", "a1"), stale)
                return link.refused_frames > refused

            wait_until(inject, what="the agent to refuse a frame of the dead world")
        finally:
            second.close()
    finally:
        stop.set()
        agent.join(10)


@pytest.mark.parametrize("resumed", [False, True])
def test_a_resumed_world_lets_go_of_agents_that_did_not_come_back(bus, tmp_path, monkeypatch, resumed):
    """An agent the checkpoint holds alive whose process died meanwhile: its body stops and
    its brick is put down before the resumed world's first tick (without `resumed`, nothing
    tells the world, and the body would keep its brick)."""
    monkeypatch.setattr(server_node, "RESUME_WAIT", 0.2)  # nobody comes back here: no need to wait long
    run = start(parse_scenario(ONE_AGENT))
    for _ in range(400):
        run.step()
        if run.world.agents["a1"].holding >= 0:
            break
    assert run.world.agents["a1"].holding >= 0
    write_checkpoint(tmp_path / "w.ckpt", checkpoint_world(run.world))
    world = load_world(tmp_path / "w.ckpt")
    server = WorldServer(world, bus.server_session(), resumed=resumed, mode="realtime")
    stop = threading.Event()
    thread = threading.Thread(target=server.run, args=(stop,), daemon=True)
    thread.start()
    try:
        if resumed:
            wait_until(lambda: not world.agents["a1"].alive, timeout=10,
                       what="the resumed world to let go of a1")
            assert world.agents["a1"].holding == -1
        else:
            wait_until(lambda: world.tick > 5, what="the world to tick")
            assert world.agents["a1"].alive and world.agents["a1"].holding >= 0
        assert world.discs.bricks_total() == run.world.discs.bricks_total()
    finally:
        stop.set()
        thread.join(10)


def _tick(path) -> int:
    """The tick of the checkpoint at `path`; -1 while there is none."""
    try:
        return read_checkpoint(path)["tick"]
    except (OSError, CheckpointError):
        return -1


def _frame(tick: int, epoch: int, sectors: int) -> bytes:
    return encode(SensorFrame(agent_id="a1", tick=tick, heading=0.0, odom_dx=0.0, odom_dy=0.0, sectors=sectors,
                              ranges=(-1.0,) * (len(CHANNELS) * sectors), holding=False, epoch=epoch))


@pytest.mark.slow  # three processes
def test_a_hand_started_agent_waits_for_a_killed_world_and_attaches_to_the_resumed_one(tmp_path, endpoint):
    # `conag agent` blocks in its frame wait (no stop event): the world's token going must wake it.
    path = tmp_path / "w.ckpt"
    world = Process("world", str(SCENARIOS / "nested_squares.toml"), "--listen", endpoint, "--checkpoint", str(path),
                    "--checkpoint-every", "20")
    agent = Process("agent", "--id", "a1", "--connect", endpoint)
    resumed = None
    try:
        wait_until(lambda: _tick(path) >= 40, timeout=60,
                   what="the world to checkpoint")
        world.kill()  # SIGKILL
        wait_until(lambda: "waiting for world w0 to come back" in agent.err, timeout=30,
                   what="the agent to say it waits")
        resumed = Process("world", "--resume", str(path), "--listen", endpoint)

        def attached_again() -> bool:
            if resumed.proc.poll() is not None:  # (it could not read the checkpoint once: see checkpoint.py)
                raise AssertionError(f"the resumed world exited {resumed.proc.returncode}: {resumed.err}")
            return "re-attached to world w0" in agent.err

        try:
            wait_until(attached_again, timeout=60, what="the agent to attach again")
        except AssertionError as exc:  # say what both processes said: the wait alone cannot tell why
            raise AssertionError(f"{exc}\n--- agent:\n{agent.err}\n--- resumed world:\n{resumed.err}") from None
        resumed.wait_for("resumed from")
        tick = int(agent.err.split("re-attached to world w0 at tick ")[1].split()[0])
        # It goes on: the resumed world checkpoints past where it started.
        wait_until(lambda: _tick(path) >= tick + 40, timeout=60, what="the resumed world to tick")
        assert agent.proc.poll() is None and "Traceback" not in agent.err
    finally:
        for proc in (agent, resumed, world):
            if proc is not None:
                proc.kill()
