"""The agent's end of the world link: liveliness, attach, sensor frames, commands.

A `WorldLink` declares the agent's liveliness token, subscribes to its own sensor frames
("latest wins": a zenoh ring channel of one, so a slow agent always acts on the newest
frame), attaches by id (retrying until a world answers) and publishes commands. It holds
no agent logic; the scripted test controller and the agent process both drive a body
through it. Frames are taken with a blocking `recv` in the caller's thread (no Python
callback thread in between: that hand-off cost more than the rest of the round trip);
zenoh's `recv` still lets SIGINT/SIGTERM handlers run.

Frames are checked before they are handed out (anyone on the bus can publish on the
agent's key): a frame for another agent, of another epoch than the Welcome's (not from
the world this agent attached to), or whose tick is further ahead of the last frame taken
than the world could have stepped meanwhile (`tick_slack` plus `max_tick_rate` ticks per
second since then: a frame of tick 2^62 would otherwise make the agent wait for ever for a
newer one) is refused and counted in `refused_frames`.

The link also watches the world's liveliness token. When it goes (the world process died
or stopped) `world_lost` is set and a wait for a frame returns at once (a session-local
empty sample wakes a blocked `recv`); the agent then waits for a world to come back
(`wait_for_world`) and attaches again. The new Welcome resets what frames are checked
against: a world resumed from a checkpoint is at a lower tick than the last frame taken,
and has an epoch of its own, so frames of the dead world are refused from then on.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable

import zenoh

from protocol import keys
from protocol.bus import Declarations, wait_for_token, watch_tokens
from protocol.codec import ProtocolError, decode, encode
from protocol.messages import AgentCommand, Hello, SensorFrame, Welcome

log = logging.getLogger("conag.agent")


WAKE = b""  # the payload that wakes a frame wait: no frame is empty


class AttachError(RuntimeError):
    """No world answered the attach request in time."""


class WorldLink:
    """One agent's link to the world: its liveliness token, attach, sensor frames in, commands out.

    A context manager; see the module for the frame channel ("latest wins").
    """

    def __init__(self, session: zenoh.Session, world_id: str, agent_id: str, *, block: bool = True,
                 tick_slack: int = 1000, max_tick_rate: float = 10_000.0,
                 clock: Callable[[], float] = time.monotonic):
        """`block` (the default): commands are published RELIABLE with congestion control
        BLOCK, so a busy machine delays one (a few bytes a tick) rather than losing it: a lost
        command costs a lockstep timeout, and a recording that lacks one cannot be replayed.
        `tick_slack`, `max_tick_rate`: how far ahead of the last frame taken a frame's tick may
        be (ticks, plus ticks per second of `clock` since that frame)."""
        self.session, self.world_id, self.agent_id = session, world_id, agent_id
        self.bad_frames = 0
        self.refused_frames = 0
        self.welcome: Welcome | None = None
        self.tick_slack, self.max_tick_rate, self.clock = tick_slack, max_tick_rate, clock
        self._last_tick = -1            # the tick of the last frame taken (the Welcome's at attach)
        self._last_time = clock()
        self._declared = Declarations()  # undeclared in reverse: the token goes last
        self._declared.add(session.liveliness().declare_token(keys.agent_token(world_id, agent_id)))
        self._sub = self._declared.add(session.declare_subscriber(keys.sensors(world_id, agent_id),
                                                                  zenoh.handlers.RingChannel(1)))
        qos = dict(congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE) \
            if block else {}
        # Not express: the commands of a host's agents, sent together (agent_runtime.host),
        # leave in one batch; a lone command still leaves at once.
        self._pub = self._declared.add(session.declare_publisher(keys.command(world_id, agent_id), **qos))
        self._world_up = threading.Event()  # the world's liveliness token is there
        self.world_lost = False             # the token went since the last attach
        self._declared.add(watch_tokens(session, keys.world_token(world_id), self._on_world_token))

    def _on_world_token(self, _world: str, alive: bool) -> None:
        if alive:
            self._world_up.set()
            return
        self._world_up.clear()
        self.world_lost = True
        # Wake a frame wait blocked in recv (only this session's subscriber gets it).
        try:
            self.session.put(keys.sensors(self.world_id, self.agent_id), WAKE,
                             allowed_destination=zenoh.Locality.SESSION_LOCAL)
        except zenoh.ZError:
            pass  # this session is closing (the process stops): nobody waits for a frame any more

    def wait_for_world(self, timeout: float) -> bool:
        """Wait up to `timeout` seconds for the world's liveliness token; whether it is there."""
        return self._world_up.wait(timeout)

    def _decode(self, sample: zenoh.Sample | None) -> SensorFrame | None:
        if sample is None:
            return None
        payload = sample.payload.to_bytes()
        if payload == WAKE:
            return None  # the world's token went (see _on_world_token), or an empty sample
        try:
            frame = decode(payload, SensorFrame)
        except ProtocolError:
            self.bad_frames += 1
            return None
        reason = self.refusal(frame)
        if reason:
            self.refused_frames += 1
            # Once, then every 1000th: a flood of forged frames must not flood the log too.
            if self.refused_frames % 1000 == 1:
                log.warning("agent %s refused a sensor frame (%d so far): %s", self.agent_id,
                            self.refused_frames, reason)
            return None
        return frame

    def refusal(self, frame: SensorFrame) -> str | None:
        """Why `frame` cannot be from the world this link attached to (None: it can)."""
        if frame.agent_id != self.agent_id:
            return f"it is for agent {frame.agent_id!r}"
        if self.welcome is None:
            return None
        if frame.epoch != self.welcome.epoch:
            return f"epoch {frame.epoch}, not the Welcome's {self.welcome.epoch}"
        if self._last_tick >= 0:
            ahead = self.tick_slack + self.max_tick_rate * max(self.clock() - self._last_time, 0.0)
            if frame.tick > self._last_tick + ahead:
                return f"tick {frame.tick} is too far ahead of the last frame's ({self._last_tick})"
        return None

    def wait_for_recorder(self, timeout: float, poll: float = 0.05) -> bool:
        """Wait until a recorder's liveliness token reaches this session; False if none came
        within `timeout`. On the default one-host bus (peers that do not forward for each
        other) a token comes only over a direct link, and only then does the recorder get
        what this agent publishes: before it, an agent attached at once lost its first
        commands from the recording (its link to an idle-priority recorder on a busy machine
        took seconds), and a replay of it could not go past them."""
        return wait_for_token(self.session, keys.all_recorder_tokens(self.world_id), timeout, poll)

    def attach(self, timeout: float = 10.0, retry: float = 0.05) -> Welcome:
        """Ask the world for this agent's body; retry until it answers or `timeout` passes."""
        hello = encode(Hello(self.agent_id, os.getpid()))
        self.world_lost = False  # a world that goes from now on is lost again
        while self._sub.try_recv() is not None:
            pass  # a frame of a world that died must not pass for the new one's
        deadline = time.monotonic() + timeout
        last_error = "no world answered"
        while time.monotonic() < deadline:
            for reply in self.session.get(keys.attach(self.world_id, self.agent_id), payload=hello,
                                          timeout=min(1.0, max(deadline - time.monotonic(), 0.05))):
                if reply.ok is not None:
                    try:
                        welcome = decode(reply.ok.payload.to_bytes(), Welcome)
                    except ProtocolError as exc:
                        last_error = f"bad Welcome: {exc}"
                    else:
                        self.welcome = welcome
                        self._last_tick, self._last_time = welcome.tick, self.clock()
                        return welcome
                else:
                    last_error = reply.err.payload.to_bytes().decode(errors="replace")
            time.sleep(retry)
        raise AttachError(f"agent {self.agent_id} could not attach to world {self.world_id}: {last_error}")

    def next_frame(self, after_tick: int = -1, timeout: float | None = 5.0) -> SensorFrame | None:
        """The newest frame with tick > `after_tick`; None if none came within `timeout`, or
        at once when the world is lost (`world_lost`: its liveliness token went).

        With `timeout=None` it blocks until a frame comes (the world keeps publishing:
        lockstep steps on after its own timeout, realtime at its rate) or the world is lost.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        pause = 0.0001
        while True:
            if self.world_lost:
                return None
            if deadline is None:
                frame = self._decode(self._sub.recv())
                if frame is None:
                    continue
            else:
                frame = self._decode(self._sub.try_recv())
                if frame is None:
                    if time.monotonic() >= deadline:
                        return None
                    # zenoh's recv has no timeout: poll, finely at first, then backing off
                    # so a waiting agent does not take a core from the world.
                    time.sleep(pause)
                    pause = min(pause * 2, 0.002)
                    continue
            if frame.tick > after_tick:
                if frame.tick > self._last_tick:
                    self._last_tick, self._last_time = frame.tick, self.clock()
                return frame

    def send(self, tick: int, speed: float = 0.0, turn: float = 0.0, action: str = "none",
             mark: tuple[float, float, str] | None = None) -> None:
        """Publish the command (speed, turn, one-shot action) answering the frame of `tick`;
        `mark`: a mark / unmark action's (dx, dy, cue kind)."""
        dx, dy, kind = mark if mark is not None else (0.0, 0.0, "site")
        self._pub.put(encode(AgentCommand(self.agent_id, tick, speed, turn, action, dx, dy, kind)))

    def close(self) -> None:
        """Undeclare everything; the world sees the token go and stops this body."""
        self._declared.close()

    def __enter__(self) -> WorldLink:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
