"""Shared fixtures: real zenoh sessions in-process on loopback, and a world server thread."""

from __future__ import annotations

import socket
import threading
from pathlib import Path

import numpy as np
import pytest

from bus import BusOptions, open_session
from nodes.world_server import WorldServer
from world_server.scenario import load_scenario, parse_scenario
from world_server.world import World

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ROOT / "scenarios"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def endpoint() -> str:
    return f"tcp/127.0.0.1:{free_port()}"


class Bus:
    """Opens peer sessions (multicast off, explicit loopback endpoints) and closes them all."""

    def __init__(self, endpoint: str):
        self.endpoint = endpoint
        self.sessions = []

    def server_session(self):
        s = open_session(BusOptions(listen=(self.endpoint,)), serve=True)
        self.sessions.append(s)
        return s

    def client_session(self):
        s = open_session(BusOptions(connect=(self.endpoint,)))
        self.sessions.append(s)
        return s

    def close(self):
        for s in reversed(self.sessions):
            try:
                s.close()
            except Exception:
                pass


@pytest.fixture
def bus(endpoint):
    b = Bus(endpoint)
    yield b
    b.close()


class RunningWorld:
    """A WorldServer serving in a thread of this process until stopped."""

    def __init__(self, world: World, session, **kwargs):
        self.world = world
        self.stop = threading.Event()
        self.server = WorldServer(world, session, **kwargs)
        self.result = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        self.result = self.server.run(self.stop)

    def close(self, timeout: float = 10.0):
        self.stop.set()
        self.thread.join(timeout)
        assert not self.thread.is_alive(), "world server did not stop"
        return self.result


@pytest.fixture
def start_world(bus):
    running = []

    def start(scenario, *, seed=None, world_id="w0", **kwargs) -> RunningWorld:
        if isinstance(scenario, (str, Path)) and Path(scenario).suffix == ".toml":
            scenario = load_scenario(scenario)
        elif isinstance(scenario, str):
            scenario = parse_scenario(scenario)
        rng = np.random.default_rng(scenario.seed if seed is None else seed)
        rw = RunningWorld(World(scenario, rng, world_id=world_id), bus.server_session(), **kwargs)
        running.append(rw)
        return rw

    yield start
    for rw in running:
        if rw.thread.is_alive():
            rw.close()
