"""The world server's events (world_server/server.py): what zenoh's threads hand the loop
thread is a small frozen dataclass per kind, and `_handle` dispatches on its type."""

from __future__ import annotations

import dataclasses

import pytest

from protocol.messages import AgentCommand
from tests.conftest import make
from world_server.server import BadInput, CommandArrived, LivelinessChanged, WorldServer


def test_events_are_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        LivelinessChanged("a1", True).alive = False  # type: ignore[misc]
    assert BadInput("x") == BadInput("x", None)


def test_handle_dispatches_on_the_event_type(bus):
    world = make(".A..b..+.")
    server = WorldServer(world, bus.server_session())
    server._handle(BadInput("undecodable"))
    assert world.bad_messages == 1
    server._handle(LivelinessChanged("a1", True))
    assert "a1" in server._tokens
    # A token but no body attached: the command is bad input, answered on the agent's error key.
    server._handle(CommandArrived(AgentCommand("a1", 0, 0.1, 0.0)))
    assert world.bad_messages == 2
    with pytest.raises(TypeError, match="not a world server event"):
        server._handle(("cmd", AgentCommand("a1", 0, 0.1, 0.0)))  # type: ignore[arg-type]
