"""The live Foxglove server (`conag view --foxglove`, `conag run --foxglove`): the zenoh shell
that serves a running world's Foxglove channels (`conag.foxglove.convert`) over the Foxglove
WebSocket protocol, with the `foxglove-sdk` package's server. Foxglove and Lichtblick connect
to `ws://HOST:PORT`.

What it costs the run follows what the clients look at, and the display rate, not the run's speed:

* zenoh keeps what comes in its own queues (ring channels for the views and the sensor
  frames: only the newest are kept; FIFO channels for the rare messages: states, attaches,
  perturbations, timeouts, maps); no Python callback runs per message;
* `display_hz` times a second the server takes what came, and translates the newest view
  and the rest; with no client subscribed it translates nothing;
* an agent's sensor frames are subscribed to only while a client is subscribed to one of
  its scan topics (one ring per agent), and of those only the frame of the newest view's
  tick is translated; its maps are asked for (a maps request token for that agent) only
  while a client is subscribed to one of its map topics: about once a second whatever the
  run's speed (`conag.viewer.scene.maps_interval`), never more often than every
  `maps_every` ticks, and with many agents watched each less often, about `MAPS_TOTAL_HZ`
  snapshots a second in all (a snapshot is a cost in the agent, on the run's chain). The
  world publishes its views every 10 ticks while the server listens, as for `conag view`.
  Agents' topics are advertised as the views name them.

What a client of every topic of a 10-agent run costs, and what it was made of before these
limits: docs/results/benchmarks.md (Foxglove server overhead).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import foxglove
import zenoh

from conag.foxglove.convert import Derived, SchemaDef, Translator, agent_topics, world_topics
from conag.recording.mcap_log import peek
from conag.viewer.scene import DISPLAY_HZ, MAPS_HZ, maps_interval
from protocol import keys
from protocol.bus import Declarations, undeclare

log = logging.getLogger("conag.foxglove")

DEFAULT_PORT = 8766  # beside `conag view`'s 8765 (Foxglove's own default: a user may pass 8765 with --view off)
RING = 64            # sensor frames of one agent kept between two display periods
RARE = ("state", "welcome", "maps")                  # per-agent keys taken whole (FIFO)
WORLD_RARE = ("perturbed", "lockstep_timeout")       # the world's, taken whole
MAPS_TOTAL_HZ = 2.0  # map snapshots a second, about, asked of all the watched agents together (MAPS_HZ each at most)


class Listener(foxglove.websocket.ServerListener):
    """The topics the clients are subscribed to (the server works for those only), and
    whether a subscription is new (the walls, sent once, are sent again for it)."""

    def __init__(self) -> None:
        self.topics: dict[str, int] = {}
        self.new = threading.Event()
        self.version = 0  # counts the changes of `topics`
        self._lock = threading.Lock()

    def on_subscribe(self, client, channel) -> None:  # noqa: ARG002 -- the SDK's signature
        with self._lock:
            self.topics[channel.topic] = self.topics.get(channel.topic, 0) + 1
            self.version += 1
        self.new.set()

    def on_unsubscribe(self, client, channel) -> None:  # noqa: ARG002 -- the SDK's signature
        with self._lock:
            n = self.topics.get(channel.topic, 0) - 1
            if n > 0:
                self.topics[channel.topic] = n
            else:
                self.topics.pop(channel.topic, None)
            self.version += 1

    def watched(self) -> set[str]:
        """The topics some client is subscribed to now."""
        with self._lock:
            return set(self.topics)

    def watched_since(self, version: int) -> tuple[int, set[str]] | None:
        """(version, the topics watched) if they changed since `version`, else None."""
        with self._lock:
            return None if version == self.version else (self.version, set(self.topics))


def agents_watched(topics: set[str], kind: str) -> set[str]:
    """The agents some of whose `kind` topics (scan, maps) are among `topics`."""
    return {t.split("/")[2] for t in topics if t.startswith("/agents/") and t.split("/")[3:4] == [kind]}


class FoxgloveBridge:
    """One world's bus to Foxglove channels on a WebSocket server (see the module)."""

    def __init__(self, session: zenoh.Session, world_id: str, *, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 display_hz: float = DISPLAY_HZ, maps_every: int = 10, requester: str | None = None,
                 clock: Callable[[], float] = time.monotonic):
        self.session = session
        self.world_id = world_id
        self.display_hz = display_hz
        self.maps_every = maps_every
        self.requester = requester or f"foxglove-{id(self) & 0xFFFFFF:x}"
        self.clock = clock
        self.translator = Translator()
        self.context = foxglove.Context()
        self.listener = Listener()
        self.server = foxglove.start_server(name=f"conag world {world_id}", host=host, port=port,
                                            context=self.context, server_listener=self.listener)
        self.channels: dict[str, foxglove.Channel] = {}
        self.sent = 0
        self._declared = Declarations()
        self._inboxes: list = []
        self._sensors: dict[str, tuple] = {}     # agent -> (its subscriber, its ring)
        self._held: dict[str, zenoh.Sample] = {}  # agent -> its first frame newer than the last view
        self._maps: dict[str, tuple] = {}        # agent -> (its maps request token, its interval)
        self._rate: float | None = None          # the run's ticks a second, measured over about 2 s
        self._speed: tuple[float, int] | None = None  # (clock, tick) when the rate was last measured
        self._watched: tuple[int, set[str], set[str], set[str]] = (0, set(), set(), set())  # version, topics, agents
        self._agents: set[str] = set()
        self._advertise(world_topics())

    @property
    def port(self) -> int:
        """The port the WebSocket server listens on."""
        return self.server.port

    def start(self) -> FoxgloveBridge:
        """Subscribe to the world's keys (each into a zenoh channel, drained by `step`)."""
        w = self.world_id
        root = keys.world_root(w)
        subs: list[tuple[str, Any]] = [(keys.view(w), zenoh.handlers.RingChannel(4))]
        subs += [(keys.all_agents(w, leaf), zenoh.handlers.FifoChannel(4096)) for leaf in RARE]
        subs += [(f"{root}/{leaf}", zenoh.handlers.FifoChannel(256)) for leaf in WORLD_RARE]
        for key, handler in subs:
            self._inboxes.append(self._declared.add(self.session.declare_subscriber(key, handler)).handler)
        return self

    def step(self) -> int:
        """Take what came since the last step; translate and send what a client watches.
        Returns how many Foxglove messages were sent."""
        watched, scans, maps = self._watching()
        self._follow_sensors(scans)
        self._follow_maps(maps)
        samples = [s for inbox in self._inboxes for s in _drain(inbox)]
        if self.listener.new.is_set():
            self.listener.new.clear()
            self.translator.resend_walls()
        if not watched:
            return 0
        views = [s for s in samples if str(s.key_expr).endswith("/view")]
        rest = [s for s in samples if not str(s.key_expr).endswith("/view")]
        now = time.time_ns()
        sent = 0
        for s in rest + views[-1:]:  # only the newest view
            sent += self._feed(s, now)
        view = self.translator.view
        if views and view is not None:  # each agent's frame of the view's tick (its scans), if it came
            for agent, (_, ring) in self._sensors.items():
                frame = self._frame_of(agent, ring, view.tick)
                if frame is not None:
                    sent += self._feed(frame, now)
        for agent in set(view.agent_ids) - self._agents if view is not None else ():
            self._advertise(agent_topics(agent))
            self._agents.add(agent)
        self.sent += sent
        return sent

    def _feed(self, sample: zenoh.Sample, now: int) -> int:
        derived = self.translator.feed(str(sample.key_expr), sample.payload.to_bytes(), now)
        for d in derived:
            self._send(d, now)
        return len(derived)

    def _frame_of(self, agent: str, ring, tick: int) -> zenoh.Sample | None:
        """The frame of `tick` among `agent`'s frames that came (its ring, in the order published),
        taken oldest first up to the first newer frame, which is held for the next view: a frame
        goes out before the view of its tick, so it came before the view did or with it. Between
        two views the frames stay in their ring (which keeps the newest only)."""
        held = self._held.pop(agent, None)
        found = None
        while True:
            sample = held if held is not None else _next(ring)
            held = None
            if sample is None:
                return found
            t = peek(sample.payload.to_bytes())[1]
            if t == tick:
                found = sample
            elif t is not None and t > tick:
                self._held[agent] = sample
                return found

    def _watching(self) -> tuple[set[str], set[str], set[str]]:
        """(the topics watched, the agents whose scans are, whose maps are), worked out again
        only when the clients' subscriptions changed."""
        changed = self.listener.watched_since(self._watched[0])
        if changed is not None:
            version, topics = changed
            self._watched = (version, topics, agents_watched(topics, "scan"), agents_watched(topics, "maps"))
        return self._watched[1:]

    def _advertise(self, topics: dict[str, SchemaDef]) -> None:
        """Open a channel per topic not open yet: the server advertises it to its clients."""
        for topic, sd in topics.items():
            if topic not in self.channels:
                schema = foxglove.Schema(name=sd.name, encoding=sd.encoding, data=sd.data)
                self.channels[topic] = foxglove.Channel(topic, schema=schema, message_encoding=sd.message_encoding,
                                                        context=self.context)

    def _send(self, d: Derived, now: int) -> None:
        if d.topic not in self.channels:
            self._advertise({d.topic: d.schema})
        self.channels[d.topic].log(d.data, log_time=now)

    def _follow_sensors(self, agents: set[str]) -> None:
        """Subscribe to the sensor frames of `agents` (a ring each), and of no other."""
        for agent in set(self._sensors) - agents:
            undeclare(self._sensors.pop(agent)[0])
            self._held.pop(agent, None)
        for agent in agents - set(self._sensors):
            sub = self.session.declare_subscriber(keys.sensors(self.world_id, agent), zenoh.handlers.RingChannel(RING))
            self._sensors[agent] = (sub, sub.handler)

    def _follow_maps(self, agents: set[str]) -> None:
        """Ask `agents`, and no other, for their maps (see the module)."""
        every = self._maps_interval(len(agents)) if agents and self.maps_every else 0
        for agent in set(self._maps) | agents:
            token, asked = self._maps.get(agent, (None, 0))
            want = every if agent in agents else 0
            if want == asked:
                continue
            new = self.session.liveliness().declare_token(
                keys.maps_request_token(self.world_id, self.requester, want, agent)) if want else None
            undeclare(token)  # after the new one is up: the agent is never left without one
            if new is None:
                self._maps.pop(agent, None)
            else:
                self._maps[agent] = (new, want)

    def _maps_interval(self, agents: int) -> int:
        """Ticks between the map snapshots of each of `agents` watched agents: about once a
        second (MAPS_HZ) for the run's speed, measured over about 2 s (`maps_interval`); with
        more agents than MAPS_TOTAL_HZ / MAPS_HZ, each less often. Until the speed is known,
        `maps_every` ticks times the number of agents."""
        v, now = self.translator.view, self.clock()
        tick = v.tick if v is not None else 0
        if self._speed is None:
            self._speed = (now, tick)
        elif now - self._speed[0] >= 2.0:
            self._rate = max((tick - self._speed[1]) / (now - self._speed[0]), 0.0)
            self._speed = (now, tick)
        if self._rate is None:
            return self.maps_every * max(agents, 1)
        return maps_interval(self._rate * max(1.0, agents * MAPS_HZ / MAPS_TOTAL_HZ), self.maps_every)

    def close(self) -> None:
        """Undeclare everything and stop the server (the session is the caller's)."""
        self._follow_sensors(set())
        self._follow_maps(set())
        self._declared.close()
        self.server.stop()


def _drain(inbox) -> list[zenoh.Sample]:
    out: list[zenoh.Sample] = []
    while (sample := _next(inbox)) is not None:
        out.append(sample)
    return out


def _next(inbox) -> zenoh.Sample | None:
    """The oldest sample waiting in a zenoh channel, or None."""
    try:
        return inbox.try_recv()
    except zenoh.ZError:
        return None


def serve_foxglove(session: zenoh.Session, world_id: str, stop: threading.Event, *, host: str = "127.0.0.1",
                   port: int = DEFAULT_PORT, display_hz: float = DISPLAY_HZ, maps_every: int = 10,
                   on_ready: Callable[[str], None] | None = None) -> FoxgloveBridge:
    """Serve world `world_id`'s Foxglove channels on ws://host:port until `stop` is set."""
    bridge = FoxgloveBridge(session, world_id, host=host, port=port, display_hz=display_hz,
                            maps_every=maps_every).start()
    try:
        if on_ready:
            on_ready(f"ws://{host}:{bridge.port}")
        while not stop.wait(1.0 / display_hz):
            bridge.step()
    finally:
        bridge.close()
    return bridge
