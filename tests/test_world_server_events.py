"""The world server's events (world_server/server.py): what zenoh's threads hand the loop
thread is a small frozen dataclass per kind, and `_handle` dispatches on its type."""

from __future__ import annotations

import dataclasses

import pytest

from protocol.messages import AgentCommand
from tests.conftest import make
from world_server.server import (
    AttachAsked,
    BadInput,
    CommandArrived,
    LivelinessChanged,
    PerturbAsked,
    WorldServer,
)


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


class _Query:
    """What `_refuse_queued` uses of a zenoh Query: its error reply and its end."""

    def __init__(self):
        self.errors: list[bytes] = []
        self.dropped = False

    def reply_err(self, payload: bytes) -> None:
        self.errors.append(payload)

    def drop(self) -> None:
        self.dropped = True


def test_queries_still_queued_when_the_world_stops_are_told_so_not_left_unanswered(bus):
    # A perturbation asked in a world's last moments (CI: 80 lockstep ticks passed before the
    # loop took it) used to get no reply at all, and `conag perturb` waited out its timeout.
    world = make(".A..b..+.")
    server = WorldServer(world, bus.server_session())
    perturb, attach = _Query(), _Query()
    server._events.put(PerturbAsked(perturb))  # type: ignore[arg-type]
    server._events.put(AttachAsked(attach))    # type: ignore[arg-type]
    server._refuse_queued()
    for q in (perturb, attach):
        assert q.errors == [f"world {world.world_id} stopped at tick 0".encode()] and q.dropped
    assert server._events.empty()
