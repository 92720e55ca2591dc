"""The world server: the zenoh shell around `world_server.world.World` (W7, S1, S2 in docs/design.md).

Everything arriving on the bus (commands, liveliness changes, attach, perturb) is put, as a
small typed event (`CommandArrived`, `LivelinessChanged`, ...), on
one queue by zenoh's callback threads and applied by the single loop thread, so the
world itself is never touched concurrently. The loop:

* lockstep: tick t is stepped once every live agent has sent its command for t, or
  after `lockstep_timeout`. Ticks are driven by agents only, never by the wall clock:
  the world does not tick before `wait_agents` agents have attached, nor while no agent
  is live, so the same seed and the same agents give the same run. `max_tick_rate` caps
  the pace (a tick at most every 1/max_tick_rate wall seconds): it delays steps, it never
  changes one, so a capped run gives the same frames;
* realtime: a tick every 1/tick_rate seconds, the latest command of each agent wins.

Agents come and go: an agent is waited for only while its liveliness token exists.
When the token disappears (process killed), its body stops, its brick is put down where
nothing needs it, and after `body_grace_ticks` the body leaves the world; when a process
with the same id attaches again, it gets its body back (`World.detach`, `World.attach`).
An agent that holds its token but misses `lockstep_miss_limit` deadlines in a row is no
longer waited for until it sends a command again (`world_server.lockstep.LockstepWaits`);
every step taken without some live agent's command is published as a LockstepTimeout.
Bad input of any kind is counted in `WorldStatus.bad_messages`, logged at INFO (`-v`) and
otherwise ignored; a rejected command (undecodable, another agent's id, an agent not
attached, in lockstep a tick other than the world's) is also answered with a
CommandRejected on the agent's `command_error` key, saying why.

For whoever listens besides the asker (a recorder, `conag echo`), every Welcome is also
published on the agent's `welcome` key and every perturbation, with its tick and outcome,
as a `Perturbed` on the world's `perturbed` key (both reliable): the queries themselves
reach the world alone. A lockstep step taken without some agents' commands (the timeout
passed) is published as a `LockstepTimeout`, so a replay can step without them too.

For a viewer (`conag view`), a WorldView (discs, sites, bodies, walls) is published at every
tick that is a multiple of `view_every` and after each perturbation, only while some subscriber matches its key
(zenoh's matching status: a world nobody watches builds none); the `view` queryable
answers a fresh one, built by the loop thread like everything that reads the world.

The loop keeps where its time goes (`self.times`, `world_server.loop_times.LoopTimes`:
stepping, publishing frames, waiting for commands; `conag world --profile PATH` writes it).
With a `CheckpointPlan` the server checkpoints the world (`world_server.checkpoint`) after
every tick that is a multiple of its interval, and once more when it stops (SIGTERM): the
world is written atomically and its physics rebuilt from what was written, so a world
resumed from the file steps on as this one does. A write that fails is logged and the
checkpoint before it kept; the world goes on. A server started on a resumed world
(`resumed`) waits for the agents to come back: it does not tick before every agent the
checkpoint holds alive whose process still holds its liveliness token has attached again
(or `RESUME_WAIT` seconds have passed), and then lets go of every such agent without a
token (it died while the world was down: its body stops and its brick is put down, as for
any agent that dies).

A perturbation that changes the blueprint (add_site, remove_site) is followed by the new
Blueprint, published reliably (RELIABLE, congestion control BLOCK: an agent must not miss
a site); a queryable on the same key answers the current one. The agents' AgentState
reports are kept (the last per agent) for the final summary's behaviour counts.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import zenoh

from protocol import keys
from protocol.bus import Declarations, token_event, watch_tokens
from protocol.codec import ProtocolError, decode, encode
from protocol.messages import (
    MAX_STRING,
    SITE_OPS,
    AgentCommand,
    AgentState,
    CommandRejected,
    Hello,
    LockstepTimeout,
    Perturbation,
    Perturbed,
    WorldStatus,
)
from world_server.checkpoint import CheckpointError, CheckpointPlan, checkpoint_world, write_checkpoint
from world_server.lockstep import LockstepWaits
from world_server.loop_times import LoopTimes
from world_server.world import World

log = logging.getLogger("conag.world")
RESUME_WAIT = 10.0  # wall seconds a resumed world waits for its live agents to attach again
RECORDER_WAIT = 10.0  # wall seconds a recorded world waits for a recorder's link before agents may attach
WAIT_REPORT = 5.0   # wall seconds between the lines a lockstep world logs while it cannot tick


# What zenoh's threads hand the loop thread (`WorldServer._handle` dispatches on the type) ------
@dataclass(frozen=True)
class CommandArrived:
    """A decoded AgentCommand whose agent_id matches its key."""

    cmd: AgentCommand


@dataclass(frozen=True)
class LivelinessChanged:
    """An agent's liveliness token appeared (`alive`) or disappeared."""

    agent: str
    alive: bool


@dataclass(frozen=True)
class AttachAsked:
    """A query on an agent's attach key (a Hello)."""

    query: zenoh.Query


@dataclass(frozen=True)
class PerturbAsked:
    """A query on the world's perturb key (a Perturbation)."""

    query: zenoh.Query


@dataclass(frozen=True)
class ViewAsked:
    """A query on the world's view key."""

    query: zenoh.Query


@dataclass(frozen=True)
class GoWithout:
    """The first tick does not wait for this agent (its process died before attaching)."""

    agent: str


@dataclass(frozen=True)
class BadInput:
    """Input that could not be decoded or did not match its key; a command's `agent` is
    answered on its error key."""

    detail: str
    agent: str | None = None


@dataclass(frozen=True)
class RecorderHeard:
    """A recorder's liveliness token reached the world: its link to the recorder is up."""


Event = (CommandArrived | LivelinessChanged | AttachAsked | PerturbAsked | ViewAsked | GoWithout | BadInput
         | RecorderHeard)


class WorldServer:
    """The world on the bus: one loop thread applies every event and steps a `World`.

    Commands, liveliness changes, attach requests (Hello) and perturbations arrive on one
    queue from zenoh's threads; `run(stop)` declares the keys, then ticks in lockstep or
    realtime `mode` (the scenario's by default) until `stop` is set, `max_ticks` is reached
    or, with `stop_when_complete`, the structure is complete. It publishes each agent's
    SensorFrame after a tick, a WorldStatus periodically (also handed to `on_status`) and a
    new Blueprint when a perturbation changes the sites. `clock` is the time source
    (injected for tests); in lockstep, `wait_agents` agents must attach before the first
    tick.
    """

    def __init__(self, world: World, session: zenoh.Session, *, mode: str | None = None,
                 max_ticks: int | None = None, stop_when_complete: bool = False, wait_agents: int = 1,
                 clock: Callable[[], float] = time.monotonic,
                 on_status: Callable[[WorldStatus], None] | None = None, block_frames: bool = False,
                 view_every: int = 10, checkpoint: CheckpointPlan | None = None, resumed: bool = False,
                 max_tick_rate: float | None = None, recorded: bool = False):
        self.world = world
        self.session = session
        self.mode = mode or world.scenario.tick_mode
        self.max_ticks = max_ticks
        self.stop_when_complete = stop_when_complete
        self.wait_agents = wait_agents
        self.clock = clock
        self.on_status = on_status
        # Realtime frames are "latest wins" (DROP); a driver that must see every frame (conag.env)
        # asks for BLOCK. Lockstep frames always BLOCK: the world waits for each one's answer, and
        # zenoh drops a DROP message that finds the link's queue full for a moment (a burst of
        # frames to a host of 20 agents, a busy machine): a lost frame cost a lockstep timeout (1 s).
        block = block_frames or self.mode == "lockstep"
        self._frame_congestion = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        self.cfg = world.cfg
        self._events: queue.SimpleQueue[Event] = queue.SimpleQueue()
        self._tokens: set[str] = set()
        self._answered: set[str] = set()
        self._publishers: dict[str, zenoh.Publisher] = {}  # sensor frames, per agent
        self._status_bytes = encode(world.status())
        self._blueprint_bytes = encode(world.blueprint())
        self.agent_states: dict[str, AgentState] = {}  # the last report of each agent (for summaries)
        self._declared = Declarations()
        self._last_status = float("-inf")
        self._status_seq = 0  # WorldStatus.seq of the last status published
        self.view_every = view_every  # ticks between WorldView publications (0: only on query)
        self._view_failed = False
        self.lockstep = LockstepWaits(self.cfg.lockstep_miss_limit)
        self.times = LoopTimes()  # where the loop's time goes (conag world --profile)
        self.checkpoint = checkpoint
        self.checkpoints_written = 0
        self._checkpointed = -1  # the tick of the last checkpoint written
        self._unclaimed = resumed  # a resumed world: agents without a token are let go before the first tick
        # Recorded: no attach before a recorder's token came (its link is up), for RECORDER_WAIT at most.
        self._recorder_deadline: float | None = clock() + RECORDER_WAIT if recorded else None
        self._resume_deadline: float | None = (clock() + RESUME_WAIT + (RECORDER_WAIT if recorded else 0.0)
                                               if resumed else None)
        self._attached: set[str] = set()  # agents that attached to this server
        if max_tick_rate is not None and not max_tick_rate > 0:
            raise ValueError("max_tick_rate must be > 0 ticks per second")
        self._min_period = 1.0 / max_tick_rate if max_tick_rate else 0.0  # lockstep: wall seconds between ticks
        self._not_awaited: set[str] = set()  # agents the first tick does not wait for (`go_without`)
        self._idle_since: float | None = None  # lockstep: since when the world cannot tick (None: it can)
        self._idle_reported = 0.0

    def go_without(self, agent: str) -> None:
        """The first tick does not wait for `agent` (its process died before attaching: `conag
        run` says so): `wait_agents` counts the others. Thread-safe; if it attaches later it
        takes part as any agent does."""
        self._events.put(GoWithout(agent))

    # zenoh callbacks: decode if cheap, then hand over to the loop thread ------------------
    def _on_command(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            cmd = decode(sample.payload.to_bytes(), AgentCommand)
            if cmd.agent_id != keys.agent_of(key):
                raise ProtocolError(f"command agent_id {cmd.agent_id!r} does not match its key")
            self._events.put(CommandArrived(cmd))
        except ProtocolError as exc:
            self._events.put(BadInput(f"command on {key}: {exc}", keys.agent_of(key)))

    def _on_token(self, agent: str, alive: bool) -> None:
        self._events.put(LivelinessChanged(agent, alive))

    def _on_status_query(self, query: zenoh.Query) -> None:
        query.reply(query.key_expr, self._status_bytes)  # the latest, swapped atomically

    def _on_blueprint_query(self, query: zenoh.Query) -> None:
        query.reply(query.key_expr, self._blueprint_bytes)  # swapped atomically by the loop

    def _on_agent_state(self, sample: zenoh.Sample) -> None:
        try:
            state = decode(sample.payload.to_bytes(), AgentState)
            if state.agent_id != keys.agent_of(str(sample.key_expr)):
                raise ProtocolError("AgentState agent_id does not match its key")
        except ProtocolError as exc:
            self._events.put(BadInput(f"agent state on {sample.key_expr}: {exc}"))
            return
        self.agent_states[state.agent_id] = state  # one dict store: safe from zenoh's thread

    def _declare(self) -> None:
        """Declare everything the server serves; `self._declared` undeclares it all (`run`)."""
        w, s, add = self.world.world_id, self.session, self._declared.add
        add(s.liveliness().declare_token(keys.world_token(w)))
        add(watch_tokens(s, keys.all_agent_tokens(w), self._on_token))
        if self._recorder_deadline is not None:
            add(watch_tokens(s, keys.all_recorder_tokens(w),
                             lambda _recorder, alive: self._events.put(RecorderHeard()) if alive else None))
        add(s.declare_subscriber(keys.all_agents(w, "command"), self._on_command))
        add(s.declare_queryable(keys.all_agents(w, "attach"), lambda q: self._events.put(AttachAsked(q))))
        add(s.declare_queryable(keys.perturb(w), lambda q: self._events.put(PerturbAsked(q))))
        add(s.declare_queryable(keys.view(w), lambda q: self._events.put(ViewAsked(q))))
        # Views are "latest wins" like frames: a slow viewer is never queued behind.
        self._view_pub = add(s.declare_publisher(keys.view(w), congestion_control=zenoh.CongestionControl.DROP))
        add(s.declare_queryable(keys.status(w), self._on_status_query))
        add(s.declare_queryable(keys.blueprint(w), self._on_blueprint_query))
        add(s.declare_subscriber(keys.all_agents(w, "state"), self._on_agent_state))
        self._status_pub = add(s.declare_publisher(keys.status(w)))
        reliable = dict(reliability=zenoh.Reliability.RELIABLE, congestion_control=zenoh.CongestionControl.BLOCK)
        self._blueprint_pub = add(s.declare_publisher(keys.blueprint(w), **reliable))
        self._perturbed_pub = add(s.declare_publisher(keys.perturbed(w), **reliable))
        self._timeout_pub = add(s.declare_publisher(keys.lockstep_timeouts(w), **reliable))

    # the loop --------------------------------------------------------------------------------
    def run(self, stop: threading.Event) -> WorldStatus:
        """Serve until `stop` is set, `max_ticks` is reached or (optionally) the build completes."""
        with self._declared:
            self._declare()
            self._publish_status()
            last_tick = self.clock()
            timer = time.perf_counter
            # Realtime ticks before anyone is there: count from two seconds after all came.
            warmup = int(2 * self.cfg.tick_rate) if self.mode == "realtime" else 0
            t0 = timer()
            while self._wait_for_tick(last_tick, stop):
                t1 = timer()
                self.world.step()
                last_tick = self._tick_time(last_tick)
                self._answered.clear()
                t2 = timer()
                self._publish_frames()
                t3 = timer()
                self.times.tick_done(self.world.tick, self._all_came(), warmup,
                                     time.monotonic(), wait=t1 - t0, step=t2 - t1, publish=t3 - t2)
                if self.checkpoint is not None and self.checkpoint.due(self.world.tick):
                    self._checkpoint()
                if (self.max_ticks is not None and self.world.tick >= self.max_ticks) or (
                        self.stop_when_complete and self.world.completed()):
                    break
                self._publish_status_if_due()
                if self.view_every and self.world.tick % self.view_every == 0:
                    self._publish_view()
                t0 = timer()
                self.times.other_done(t0 - t3)
            self._publish_view()
            if self.checkpoint is not None and self.checkpoint.path and self._checkpointed != self.world.tick:
                self._checkpoint()  # stopped (SIGTERM), complete or out of ticks: the state as it ends
            self._refuse_queued()
            return self._publish_status()

    def _refuse_queued(self) -> None:
        """Answer the queries still queued as the loop ends with an error saying so: a
        perturbation or attach asked in the last moments would otherwise get no reply at all,
        and its sender wait out its timeout for "no world answered". A view is answered."""
        while True:
            try:
                event = self._events.get_nowait()
            except queue.Empty:
                return
            match event:
                case PerturbAsked(query) | AttachAsked(query):
                    query.reply_err(f"world {self.world.world_id} stopped at tick {self.world.tick}".encode())
                    query.drop()
                case ViewAsked(query):
                    self._answer_view(query)

    def _tick_time(self, last_tick: float) -> float:
        """When this tick counts as taken, for the next one's deadline. Lockstep: now (the
        timeout runs from here). Realtime: when it was due, so stepping and publishing do not
        stretch the period (they had made 50 Hz come out at about 46); after a stall of more
        than a period, now (no burst of ticks to catch up)."""
        now = self.clock()
        if self.mode != "realtime":
            return now
        due = last_tick + 1.0 / self.cfg.tick_rate
        return due if now - due < 1.0 / self.cfg.tick_rate else now
    def _checkpoint(self) -> None:
        """Checkpoint the world now (its space rebuilt from what is written; see the module)."""
        started = time.monotonic()
        data = checkpoint_world(self.world, self.checkpoint.every)
        if not self.checkpoint.path:
            return
        try:
            write_checkpoint(self.checkpoint.path, data)
        except (OSError, CheckpointError) as exc:
            log.error("tick %d: checkpoint not written (%s); the one before it is kept", self.world.tick, exc)
            return
        self.checkpoints_written += 1
        self._checkpointed = self.world.tick
        log.debug("tick %d: checkpoint written to %s (%d bytes, %.1f ms)", self.world.tick, self.checkpoint.path,
                  len(data), 1000 * (time.monotonic() - started))

    def _resuming(self, live: list[str]) -> bool:
        """A resumed world still waits for some live agent to attach again (see the module)."""
        if self._resume_deadline is None:
            return False
        waiting = not live or any(a not in self._attached for a in live)  # (no token seen yet: realtime)
        if waiting and self.clock() < self._resume_deadline:
            return True
        self._resume_deadline = None
        return False

    def _let_go_of_unclaimed(self) -> None:
        """A resumed world, about to tick for the first time: agents the checkpoint holds alive
        whose process has no token died while the world was down; they are let go as usual."""
        self._unclaimed = False
        missing = [a for a in self.world.live_agents() if a not in self._tokens]
        if not missing:
            return
        # One query for every token there is (not one per agent: a world may hold hundreds).
        held = {token_event(r.ok)[0] for r in self.session.liveliness().get(
            keys.all_agent_tokens(self.world.world_id), timeout=0.5) if r.ok is not None}
        for agent in missing:
            if agent not in held:
                log.info("agent %s did not come back to the resumed world; its body stops", agent)
                self.world.detach(agent)

    def _live(self) -> list[str]:
        return [a for a in self.world.live_agents() if a in self._tokens]

    def _wait_for_tick(self, last_tick: float, stop: threading.Event) -> bool:
        """Handle bus events until the next tick is due; False once `stop` is set."""
        while not stop.is_set():
            self._publish_status_if_due()
            live = self._live()
            awaited = self.lockstep.awaited(live)
            # Realtime ticks by the clock; lockstep only once agents are there to drive it.
            armed = self.mode == "realtime" or (bool(live) and self._all_came())
            armed = armed and not self._resuming(live)
            self._report_idle(armed, live)
            if self._unclaimed and armed:
                self._let_go_of_unclaimed()
                continue
            if self.mode == "lockstep" and armed and self._answered.issuperset(awaited):
                early = last_tick + self._min_period - self.clock()
                if early <= 0:
                    self._stepping_without(sorted(set(live) - self._answered))
                    return True
                self._next_event(early)  # every command is in: only the rate cap holds the step back
                continue
            now = self.clock()
            if not armed:
                last_tick = now  # a lockstep timeout counts from when there is someone to wait for
                timeout = 0.05
            else:
                period = 1.0 / self.cfg.tick_rate if self.mode == "realtime" else self.cfg.lockstep_timeout
                if now >= last_tick + period:
                    if self.mode == "lockstep":
                        late = sorted(set(awaited) - self._answered)
                        log.info("tick %d: no command from %s in time", self.world.tick, ", ".join(late))
                        for agent in self.lockstep.deadline_passed(late):
                            log.info("tick %d: agent %s missed %d deadlines in a row: not waiting for it "
                                     "until it answers; its body stops", self.world.tick, agent,
                                     self.cfg.lockstep_miss_limit)
                            # A frozen process's last command would drive its body on until
                            # zenoh's lease ends (seconds): 25-36 units of odometry were seen.
                            self.world.halt(agent)
                        self._stepping_without(sorted(set(live) - self._answered))
                    return True
                timeout = min(last_tick + period - now, 0.05)
            self._next_event(timeout)
        return False

    def _all_came(self) -> bool:
        """Whether the agents the first tick waits for have attached (`wait_agents`, less
        those it goes without)."""
        came = len(self.world.agents.keys() - self._not_awaited)
        return came >= self.wait_agents - len(self._not_awaited)

    def _report_idle(self, armed: bool, live: list[str]) -> None:
        """A lockstep world that cannot tick says why every WAIT_REPORT seconds (from the
        WAIT_REPORT-th on): it never waits in silence."""
        if self.mode != "lockstep" or armed:
            self._idle_since = None
            return
        now = self.clock()
        if self._idle_since is None:
            self._idle_since = self._idle_reported = now
            return
        if now - self._idle_reported < WAIT_REPORT:
            return
        self._idle_reported = now
        waited = now - self._idle_since
        tick = self.world.tick
        if self._resume_deadline is not None:
            missing = sorted(set(live) - self._attached)
            log.warning("tick %d: waiting %.0f s for the agents of the resumed world to attach again (%s)", tick,
                        waited, ", ".join(missing) or "none holds its token yet")
        elif not self._all_came():
            came = len(self.world.agents.keys() - self._not_awaited)
            log.warning("tick %d: waiting %.0f s for agents to attach: %d of %d so far; no tick before they all have",
                        tick, waited, came, self.wait_agents - len(self._not_awaited))
        else:
            gone = sorted(a for a in self.world.agents if a not in live)
            log.warning("tick %d: no live agent for %.0f s (%s gone): waiting for one to attach; no tick before",
                        tick, waited, ", ".join(gone) or "all")

    def _next_event(self, timeout: float) -> None:
        """Handle the next bus event, if one comes within `timeout` seconds, and every event
        queued behind it: what is due is worked out again only after the lot (it costs a
        pass over the live agents, which once per command made a tick quadratic in the
        agents: a host's commands come in a burst)."""
        try:
            event = self._events.get(timeout=timeout)
        except queue.Empty:
            return
        self._handle(event)
        for _ in range(self._events.qsize()):  # those queued now: a flood cannot hold the loop here
            self._handle(self._events.get_nowait())

    def _stepping_without(self, agents: list[str]) -> None:
        """Tell a recorder that this step goes without the commands of `agents` (late, or
        unresponsive and not waited for): a replay steps them the same way."""
        if agents:
            self._timeout_pub.put(encode(LockstepTimeout(self.world.world_id, self.world.tick, tuple(agents))))

    def _handle(self, event: Event) -> None:
        match event:
            case CommandArrived(cmd):
                self._command(cmd)
            case LivelinessChanged(agent, alive):
                self._liveliness(agent, alive)
            case AttachAsked(query):
                self._attach(query)
            case PerturbAsked(query):
                self._perturb(query)
            case ViewAsked(query):
                self._answer_view(query)
            case RecorderHeard():
                if self._recorder_deadline is not None:
                    self._recorder_deadline = None
                    log.info("tick %d: a recorder is linked: agents may attach", self.world.tick)
            case GoWithout(agent):
                if agent not in self._not_awaited:
                    self._not_awaited.add(agent)
                    log.info("agent %s will not be waited for before the first tick", agent)
            case BadInput(detail, agent):
                self._bad(detail, agent)
            case _:
                raise TypeError(f"not a world server event: {event!r}")

    def _command(self, cmd: AgentCommand) -> None:
        rec = self.world.agents.get(cmd.agent_id)
        if cmd.agent_id not in self._tokens or rec is None or not rec.alive:
            self._bad(f"command from agent {cmd.agent_id!r}, which is not attached (declare its liveliness "
                      "token, then attach)", cmd.agent_id)
            return
        if self.lockstep.heard(cmd.agent_id):
            log.info("tick %d: agent %s answers again: waiting for it", self.world.tick, cmd.agent_id)
        if self.mode == "lockstep" and cmd.tick != self.world.tick:
            # Not taken: lockstep applies a command to the tick it answers, and only to that one.
            self._bad(f"command from {cmd.agent_id!r} for tick {cmd.tick}, but the world is at tick "
                      f"{self.world.tick} (answer the newest frame's tick)", cmd.agent_id)
        else:
            self.world.set_command(cmd.agent_id, cmd.speed, cmd.turn, cmd.action,
                                   (cmd.mark_dx, cmd.mark_dy, cmd.mark_kind))
            self.times.command(self.world.tick - cmd.tick)
            if cmd.tick == self.world.tick:
                self._answered.add(cmd.agent_id)

    def _liveliness(self, agent: str, alive: bool) -> None:
        if alive:
            self._tokens.add(agent)
        elif not self._token_exists(agent):
            self._tokens.discard(agent)
            if agent in self.world.agents and self.world.agents[agent].alive:
                log.info("agent %s is gone at tick %d; its body stops", agent, self.world.tick)
            self.world.detach(agent)
            self.lockstep.forget(agent)

    def _token_exists(self, agent: str) -> bool:
        """Whether some process still holds `agent`'s liveliness token.

        A killed process and its restarted successor hold tokens with the same key, and
        the old one's removal can arrive after the new one's declaration; without this
        check the world would stop the body of a perfectly live agent.
        """
        key = keys.agent_token(self.world.world_id, agent)
        return any(r.ok is not None for r in self.session.liveliness().get(key, timeout=0.5))

    def _bad(self, detail: str, agent: str | None = None) -> None:
        """Count and log bad input; a command for `agent` is also answered on its error key."""
        self.world.bad_messages += 1
        log.info("tick %d: ignored bad message: %s", self.world.tick, detail)
        if agent is not None:
            reply = CommandRejected(agent, self.world.tick, detail[:MAX_STRING])
            # DROP: a flood of bad commands must not hold the world's loop back.
            self.session.put(keys.command_error(self.world.world_id, agent), encode(reply),
                             congestion_control=zenoh.CongestionControl.DROP)

    def _attach(self, query: zenoh.Query) -> None:
        try:
            payload = query.payload
            hello = decode(payload.to_bytes() if payload is not None else b"", Hello)
            if hello.agent_id != keys.agent_of(str(query.key_expr)):
                raise ProtocolError("Hello agent_id does not match its key")
        except ProtocolError as exc:
            self._bad(f"attach: {exc}")
            query.reply_err(f"bad attach request: {exc}".encode())
            query.drop()
            return
        if self._awaiting_recorder():
            # A recorder links to a world started again seconds after the agents do: attaches
            # answered before it came would be missing from the recording.
            query.reply_err(b"the world waits for its recorder's link (a recorded run); retry")
            query.drop()
            return
        if hello.agent_id not in self._tokens:
            # Waiting for a process that has no token would stall lockstep forever.
            query.reply_err(b"declare your liveliness token before attaching, then retry")
            query.drop()
            return
        welcome = self.world.attach(hello.agent_id, hello.pid)
        self.lockstep.forget(hello.agent_id)
        self._attached.add(hello.agent_id)
        data = encode(welcome)
        query.reply(query.key_expr, data)
        query.drop()
        self.session.put(keys.welcome(self.world.world_id, hello.agent_id), data,
                         congestion_control=zenoh.CongestionControl.BLOCK)
        log.info("agent %s (pid %d) attached to body %d%s", hello.agent_id, hello.pid, welcome.body,
                 f", restart {welcome.restarts}" if welcome.restarts else "")
        self._publish_frame(hello.agent_id, encode(self.world.frame(hello.agent_id)))

    def _awaiting_recorder(self) -> bool:
        """Whether a recorded world still waits for its recorder's link (see `RECORDER_WAIT`)."""
        if self._recorder_deadline is None:
            return False
        if self.clock() < self._recorder_deadline:
            return True
        log.warning("tick %d: no recorder linked within %g s: agents attach without it (the recording may lack "
                    "their attaches)", self.world.tick, RECORDER_WAIT)
        self._recorder_deadline = None
        return False

    def _perturb(self, query: zenoh.Query) -> None:
        try:
            payload = query.payload
            p = decode(payload.to_bytes() if payload is not None else b"", Perturbation)
        except ProtocolError as exc:
            self._bad(f"perturb: {exc}")
            query.reply_err(f"bad perturbation: {exc}".encode())
            query.drop()
            return
        result = self.world.perturb(p)
        log.info("perturbation at tick %d: %s", self.world.tick, result.message)
        if result.ok and p.op in SITE_OPS:
            # Before the reply: whoever asked for the change can rely on it being out.
            self._blueprint_bytes = encode(self.world.blueprint())
            self._blueprint_pub.put(self._blueprint_bytes)
        query.reply(query.key_expr, encode(result))
        query.drop()
        self._perturbed_pub.put(encode(Perturbed.of(p, result)))
        if result.ok:
            self._publish_view()

    def _view_bytes(self) -> bytes | None:
        """The encoded WorldView of now, or None for a world too large to draw in one message."""
        try:
            return encode(self.world.view())
        except (ValueError, ProtocolError) as exc:
            if not self._view_failed:
                log.warning("no WorldView for this world: %s", exc)
                self._view_failed = True
            return None

    def _publish_view(self) -> None:
        if not self._view_pub.matching_status.matching:
            return  # nobody watches: build nothing
        data = self._view_bytes()
        if data is not None:
            self._view_pub.put(data)

    def _answer_view(self, query: zenoh.Query) -> None:
        data = self._view_bytes()
        if data is None:
            query.reply_err(b"this world is too large for a WorldView")
        else:
            query.reply(query.key_expr, data)
        query.drop()

    def _publish_frame(self, agent_id: str, data: bytes) -> None:
        pub = self._publishers.get(agent_id)
        if pub is None:
            # Sensor frames are "latest wins": drop rather than queue behind a slow agent. Not
            # express: the frames of one tick go out back to back, and zenoh then writes those to
            # one host in one batch (one system call and one wake-up of the host for all of
            # them, not one each); a lone frame still leaves at once (bench/bench_scale.py:
            # publishing 30 frames took 2.9 ms a tick express, 1.0 ms not, at the same rate).
            pub = self._declared.add(self.session.declare_publisher(
                keys.sensors(self.world.world_id, agent_id), congestion_control=self._frame_congestion))
            self._publishers[agent_id] = pub
        pub.put(data)

    def _publish_frames(self) -> None:
        for agent_id, data in self.world.encoded_frames():
            if agent_id in self._tokens:
                self._publish_frame(agent_id, data)

    def _publish_status_if_due(self) -> None:
        if self.clock() - self._last_status >= self.cfg.status_period:
            self._publish_status()

    def _publish_status(self) -> WorldStatus:
        self._status_seq += 1
        status = self.world.status(seq=self._status_seq)
        self._last_status = self.clock()
        self._status_bytes = encode(status)
        self._status_pub.put(self._status_bytes)
        if self.on_status:
            self.on_status(status)
        return status


def read_go_without_requests(server: WorldServer, stream) -> threading.Thread:
    """A daemon thread feeding the `without ID` lines of `stream` (the world's stdin, from
    `conag run`) to `server.go_without`; other lines are ignored."""

    def read() -> None:
        for line in stream:
            words = line.split()
            if len(words) == 2 and words[0] == "without" and keys.valid_id(words[1]):
                server.go_without(words[1])

    thread = threading.Thread(target=read, name="world-stdin", daemon=True)
    thread.start()
    return thread
