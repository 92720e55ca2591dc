"""Deployment: the zenoh configurations in deploy/ parse and say what the README says, and a
world and an agent talk through a zenoh router that runs as its own process."""

from __future__ import annotations

import json
import math
import os
import signal
import socket
from dataclasses import replace

import numpy as np
import pytest
import zenoh

from agent_runtime.world_link import WorldLink
from protocol.bus import BusOptions, make_config, open_session
from tests.conftest import ROOT, SCENARIOS, Process, RunningWorld, free_port
from world_server.scenario import load_scenario
from world_server.world import World

DEPLOY = ROOT / "deploy"

# file -> (mode, listen endpoints, connect endpoints); None = not checked (zenoh's default)
EXPECTED = {
    "single-host/world.json5": ("peer", ["tcp/127.0.0.1:7447"], []),
    "single-host/agent.json5": ("peer", ["tcp/127.0.0.1:0"], ["tcp/127.0.0.1:7447"]),
    "multi-host/router.json5": ("router", ["tcp/0.0.0.0:7447"], None),
    "multi-host/client.json5": ("client", [], ["tcp/ROUTER_HOST:7447"]),
}


def _get(config: zenoh.Config, key: str):
    return json.loads(config.get_json(key))


def test_deploy_holds_exactly_the_documented_configs():
    found = sorted(str(p.relative_to(DEPLOY)) for p in DEPLOY.rglob("*.json5"))
    assert found == sorted(EXPECTED)
    readme = (DEPLOY / "README.md").read_text(encoding="utf-8")
    for name in EXPECTED:
        assert f"deploy/{name}" in readme or name in readme, name
    for needle in ("7447/tcp", "conag router --zenoh-config deploy/multi-host/router.json5",
                   "--connect tcp/ROUTER:7447", "ROUTER_HOST", "conag agent"):
        assert needle in readme, needle


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_config_parses_with_the_key_settings(name):
    config = zenoh.Config.from_file(str(DEPLOY / name))
    mode, listen, connect = EXPECTED[name]
    assert _get(config, "mode") == mode
    assert _get(config, "scouting/multicast/enabled") is False
    if listen is not None:
        assert _get(config, "listen/endpoints") == listen
    if connect is not None:
        assert _get(config, "connect/endpoints") == connect


@pytest.mark.parametrize("name", ["multi-host/router.json5", "multi-host/client.json5"])
def test_multi_host_configs_give_up_a_silent_host_soon_and_queue_a_tick_of_frames(name):
    """deploy/README.md's table: a 3 s lease (a host cut off is seen gone within it), room
    for a burst of frames, and (clients) a reconnect within a second of the link's return."""
    config = zenoh.Config.from_file(str(DEPLOY / name))
    assert _get(config, "transport/link/tx/lease") == 3000
    assert _get(config, "transport/link/tx/queue/size/data") == 16
    if name.endswith("client.json5"):
        assert _get(config, "connect/retry")["period_max_ms"] == 1000
    readme = (DEPLOY / "README.md").read_text(encoding="utf-8")
    for needle in ("transport/link/tx/lease", "transport/link/tx/queue/size/data", "connect/retry"):
        assert needle in readme


def test_command_line_endpoints_replace_the_placeholder():
    opts = BusOptions(zenoh_config=str(DEPLOY / "multi-host/client.json5"), connect=("tcp/10.1.2.3:7447",))
    config = make_config(opts)
    assert _get(config, "connect/endpoints") == ["tcp/10.1.2.3:7447"]
    assert _get(config, "mode") == "client"
    assert _get(config, "scouting/multicast/enabled") is False


def test_single_host_configs_match_the_built_in_defaults():
    """The single-host files write down what `conag` does with no bus options at all."""
    for name, serve in (("single-host/world.json5", True), ("single-host/agent.json5", False)):
        from_file = zenoh.Config.from_file(str(DEPLOY / name))
        default = make_config(BusOptions(), serve=serve)
        for key in ("mode", "scouting/multicast/enabled", "listen/endpoints", "connect/endpoints"):
            assert _get(from_file, key) == _get(default, key), (name, key)


# --- a router process between a world and an agent ------------------------------------------

@pytest.fixture
def router():
    ep = f"tcp/127.0.0.1:{free_port()}"
    proc = Process("router", "--listen", ep)
    try:
        proc.wait_for("zenoh router listening")
        yield proc, ep
    finally:
        proc.kill()


@pytest.mark.slow
def test_world_and_agent_talk_through_a_router_process(router):
    proc, ep = router
    scenario = load_scenario(SCENARIOS / "quick_wall.toml")
    # A generous lockstep timeout: every tick below must be stepped by our command, not the clock.
    scenario = replace(scenario, world=replace(scenario.world, lockstep_timeout=10.0))
    sessions, rw, link = [], None, None
    try:
        world_session = open_session(BusOptions(connect=(ep,), mode="client"), serve=True)
        sessions.append(world_session)
        rw = RunningWorld(World(scenario, np.random.default_rng(scenario.seed)), world_session)
        agent_session = open_session(BusOptions(connect=(ep,), mode="client"))
        sessions.append(agent_session)
        link = WorldLink(agent_session, "w0", "a1")
        welcome = link.attach(timeout=10.0)
        assert welcome.agent_id == "a1" and len(welcome.site_xs) == 3

        frame = link.next_frame(welcome.tick - 1, timeout=5.0)
        assert frame is not None and frame.tick == welcome.tick
        start_pose = rw.world.agent_poses()[0].copy()  # the world waits for our command now
        ticks = [frame.tick]
        for i in range(12):
            link.send(frame.tick, speed=1.0, turn=0.1 if i < 6 else 0.0)
            frame = link.next_frame(frame.tick, timeout=5.0)
            assert frame is not None, f"no frame after command {i}"
            ticks.append(frame.tick)
        # Lockstep: exactly one tick per command, in order.
        assert ticks == list(range(ticks[0], ticks[0] + 13))
        pose = rw.world.agent_poses()[0]
        assert rw.world.tick == ticks[-1]
        assert math.dist(pose[:2], start_pose[:2]) > 0.1, "the body did not move"
        assert pose[2] != pytest.approx(start_pose[2]), "the body did not turn"
        assert rw.world.status().agent_distance[0] > 0.1
        assert rw.world.bad_messages == 0
    finally:
        if link is not None:
            link.close()
        if rw is not None:
            rw.close()
        for s in reversed(sessions):
            s.close()

    assert proc.stop(signal.SIGTERM) == 0, proc.err
    assert f"zenoh router listening on {ep}" in proc.out


@pytest.mark.slow
def test_router_listens_where_its_config_file_says(tmp_path):
    """`conag router --zenoh-config FILE` must keep the file's listen endpoints (no loopback default)."""
    port = free_port()
    text = (DEPLOY / "multi-host/router.json5").read_text(encoding="utf-8")
    config = tmp_path / "router.json5"
    config.write_text(text.replace("tcp/0.0.0.0:7447", f"tcp/127.0.0.1:{port}"), encoding="utf-8")
    proc = Process("router", "--zenoh-config", str(config))
    try:
        proc.wait_for("zenoh router listening")
        with socket.create_connection(("127.0.0.1", port), timeout=2):
            pass  # the file's endpoint, not the loopback default 7447
        assert proc.stop(signal.SIGTERM) == 0, proc.err
        assert str(config) in proc.out
    finally:
        proc.kill()


def test_a_router_gets_more_receive_workers_unless_told_otherwise(monkeypatch):
    """deploy/README.md: a link closed with bytes unsent blocks a receive worker (zenoh #1101)."""
    from protocol.bus.session import ROUTER_RUNTIME

    monkeypatch.delenv("ZENOH_RUNTIME", raising=False)
    open_session(BusOptions(listen=(f"tcp/127.0.0.1:{free_port()}",), mode="router"), serve=True).close()
    assert os.environ["ZENOH_RUNTIME"] == ROUTER_RUNTIME
    monkeypatch.setenv("ZENOH_RUNTIME", "(rx: (worker_threads: 3))")
    open_session(BusOptions(listen=(f"tcp/127.0.0.1:{free_port()}",), mode="router"), serve=True).close()
    assert os.environ["ZENOH_RUNTIME"] == "(rx: (worker_threads: 3))"  # the user's own setting stays
    assert "ZENOH_RUNTIME" in (DEPLOY / "README.md").read_text(encoding="utf-8")
