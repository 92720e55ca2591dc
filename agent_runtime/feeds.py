"""The agent process's side traffic: blueprint changes in, state reports out, brick news.

`AgentFeeds` subscribes to the world's Blueprint key through a FIFO inbox (reliable and
never "latest wins": a blueprint change must not be lost), and must be created before
the agent attaches: a change published after the Welcome was made is then certain to
arrive, and the Welcome itself carries the sites and version as of attaching. Before each
decision step the newest Blueprint that has arrived goes to the brain, which ignores
versions it already has.

Every `every` ticks, and once more on the way out, the agent publishes the brain's
AgentState (what it is doing, what blocks it): `conag run` prints the last one per agent
when a build stalls, and the world keeps it for the run summary's behaviour counts.

While some liveliness token `keys.maps_request_token(world, requester, N, agent)` for this
agent or for all is up (a recorder with `--maps-every N` asks all agents, a viewer the one
its page shows), the agent also publishes its maps
(`agent_runtime.snapshot`: the ESMs, both NMs, the Matching grid; one AgentMap per layer)
at every tick that is a multiple of the smallest such N; with none up it publishes nothing.

With `news` (`AgentConfig.share_bricks`) the agent publishes the brain's BrickNews on its
bricks key after the steps that make one, and hands the brain, before each step, every
report the other agents published since (agent_runtime.brick_news). Reports wait in a FIFO
inbox; each says all its sender knows, so one dropped on a full inbox costs nothing lasting.
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from collections.abc import Iterator
from typing import TypeVar

import zenoh

from agent_runtime.snapshot import map_snapshot
from protocol import keys
from protocol.bus import Declarations, Inbox, token_event
from protocol.codec import ProtocolError, decode, encode
from protocol.messages import Blueprint, BrickNews

log = logging.getLogger("conag.agent")

T = TypeVar("T")
STATE_EVERY = 100  # ticks between AgentState reports


class AgentFeeds:
    """Blueprint changes in (a FIFO inbox), the brain's AgentState reports out (see the module)."""

    def __init__(self, session: zenoh.Session, world_id: str, agent_id: str, every: int = STATE_EVERY,
                 news: bool = False):
        self.world_id, self.agent_id, self.every = world_id, agent_id, every
        self.bad = 0
        self._last_report: int | None = None
        self._declared = Declarations()
        self._blueprints = self._declared.add(Inbox(256).subscribe(session, keys.blueprint(world_id)))
        self._states = self._declared.add(session.declare_publisher(keys.agent_state(world_id, agent_id),
                                                                    reliability=zenoh.Reliability.RELIABLE))
        # Map snapshots: only while a maps request token is up (its last segment is the period).
        self._maps_lock = threading.Lock()
        self._maps_requests: Counter[int] = Counter()
        self._maps = self._declared.add(session.declare_publisher(
            keys.agent_maps(world_id, agent_id), congestion_control=zenoh.CongestionControl.DROP))
        for key in keys.maps_requests_for(world_id, agent_id):
            self._declared.add(session.liveliness().declare_subscriber(key, self._on_maps_token, history=True))
        self._news_in = self._news_out = None
        if news:
            self._news_in = self._declared.add(Inbox(1024).subscribe(session, keys.all_agents(world_id, "bricks")))
            self._news_out = self._declared.add(session.declare_publisher(
                keys.bricks(world_id, agent_id), congestion_control=zenoh.CongestionControl.DROP))

    def _on_maps_token(self, sample: zenoh.Sample) -> None:
        key, (_, up) = str(sample.key_expr), token_event(sample)
        self.on_maps_request(key, up)

    def on_maps_request(self, key: str, up: bool) -> None:
        """A maps request token `key` came up or went; one whose period is not a count of
        ticks is ignored, with a warning as it comes up (it is no request of ours)."""
        every = keys.maps_request_every(key)
        if every is None:
            if up:
                log.warning("agent %s ignored the maps request token %r: its last segment is no period "
                            "(1 to %d ticks, in ASCII digits)", self.agent_id, key, keys.MAPS_EVERY_MAX)
            return
        with self._maps_lock:
            self._maps_requests[every] += 1 if up else -1
            self._maps_requests = +self._maps_requests  # drop the zeros

    @property
    def maps_every(self) -> int:
        """Ticks between map snapshots: the smallest asked for; 0 when nobody asks."""
        with self._maps_lock:
            return min(self._maps_requests, default=0)

    def newest_blueprint(self) -> Blueprint | None:
        """The highest-version Blueprint among those that arrived since the last call."""
        best = None
        for _, bp in self._arrived(self._blueprints, Blueprint):
            if bp.world_id == self.world_id and (best is None or bp.version > best.version):
                best = bp
        return best

    def _arrived(self, inbox: Inbox, cls: type[T]) -> Iterator[tuple[zenoh.Sample, T]]:
        """(sample, message) for each `cls` message waiting in `inbox`; bad ones counted and skipped."""
        while (sample := inbox.get(0)) is not None:
            try:
                yield sample, decode(sample.payload.to_bytes(), cls)
            except ProtocolError as exc:
                self.bad += 1
                log.debug("agent %s ignored a bad %s: %s", self.agent_id, cls.__name__, exc)

    def before_step(self, brain) -> None:
        """Hand the brain the newest blueprint, if one came (it keeps only newer versions),
        and the other agents' brick news that came."""
        bp = self.newest_blueprint()
        if bp is not None and brain.set_blueprint(bp.version, bp.site_xs, bp.site_ys):
            log.info("agent %s: blueprint version %d, %d sites", self.agent_id, bp.version, len(bp.site_xs))
        if self._news_in is not None:
            for news in self.brick_news():
                brain.hear_bricks(news)

    def brick_news(self) -> list[BrickNews]:
        """The other agents' BrickNews that arrived since the last call (bad ones counted)."""
        assert self._news_in is not None
        out = []
        for sample, news in self._arrived(self._news_in, BrickNews):
            if keys.agent_of(str(sample.key_expr)) != news.agent_id:
                # Told in another's name: on a secure bus only a1 publishes on a1's key.
                self.bad += 1
                log.debug("agent %s ignored news of %s on %s", self.agent_id, news.agent_id, sample.key_expr)
            elif news.agent_id != self.agent_id:
                out.append(news)
        return out

    def after_step(self, brain, tick: int) -> None:
        """Publish the brain's state report if `every` ticks have passed since the last one."""
        # A lower tick: a world resumed from a checkpoint, counting from there again.
        if self._last_report is None or not 0 <= tick - self._last_report < self.every:
            self.report(brain, tick)
        if self._news_out is not None:
            news = brain.brick_news()
            if news is not None:
                self._news_out.put(encode(news))
        every = self.maps_every
        if every and tick % every == 0 and hasattr(brain, "maps"):  # (a worker keeps no maps)
            for layer in map_snapshot(brain, tick):
                self._maps.put(encode(layer))

    def report(self, brain, tick: int) -> None:
        """Publish the brain's AgentState as of `tick`."""
        self._states.put(encode(brain.state_report(tick)))
        self._last_report = tick

    def close(self, brain=None, tick: int = 0) -> None:
        """A last state report (if there is a brain), then undeclare everything."""
        try:
            if brain is not None:
                self.report(brain, tick)
        except Exception as exc:  # noqa: BLE001 -- on the way out (a signal mid-step, a closing session): never fatal
            log.debug("agent %s: no final state report: %s", self.agent_id, exc)
        self._declared.close()
