"""Replaying a recording: when to re-publish each message, and how a live world reproduces it.

`paced` says when each recorded message goes out again: at its recorded offset from the
first one replayed, divided by the rate (`rate=2` is twice as fast; `rate=0`, as fast as
possible), from the first message of tick `from_tick` on.

`LockstepScript` is what a world in lockstep needs to reproduce a recording tick for
tick: which agents attached at which tick (in the order the world welcomed them: body
numbers and the world's random draws depend on it), the commands to send at each tick,
the perturbations applied before each tick's step, and the frames the world sent, to
compare. Fed the same attaches, commands and perturbations at the same ticks, a world
built from the same scenario and seed sends the same frames, byte for byte (lockstep is
deterministic: docs/design.md, "Determinism").

A command is sent at the tick the world was at when it arrived: the world keeps each
agent's newest command and steps once every live agent has answered the current tick, or
when its lockstep timeout passes (an agent compiling its kernels on a first run answers
its first frames seconds late). A command answers a frame, so it arrives at the tick it
names, unless the world stepped on without it: then the world published a
LockstepTimeout naming the agent, and the command reached the world at the tick of the
newest frame recorded before it (at least one later), where the world refused it (in
lockstep a command counts for the tick it names only) and counted it bad; the replay
sends it there too, to be refused the same way. (The recorder's order alone cannot tell:
a command on time may reach it after the next frame.) For the step the world took
without it, the script adds a stand-in command of that tick holding what the world then
had: the speed set point of the agent's last command taken (0 after an attach), no turn
and no action (those are one-shot). So a
replayed world never has to time out itself, and `conag replay --verify` runs it with
the timeout off: a busy machine slows the replay down, it does not change it.
What a recording cannot replay exactly, and `LockstepScript.limits` names:
an agent that went away mid-run (the world stops its body when its liveliness token
goes, at a tick the recording does not hold) and so one restarted.

A world process that died and was started again (`conag run` resumes it from its newest
checkpoint) makes a recording of several runs of the world, which `world_runs` tells
apart: a new run's frames and Welcomes carry another epoch (a resumed world's is a digest
of its checkpoint), an agent's frames go back in ticks (a world started again from the
start has the same epoch), or the world's status count (`WorldStatus.seq`, per process)
starts again. Each run is replayed from where it started: the first from the seed, a
resumed one from the replayed world's own state at the tick of the checkpoint it was
resumed from (a world that checkpoints rebuilds its physics there, so that state is the
checkpoint). The ticks a dead run went past its checkpoint were undone by the restart and
are not replayed. An agent sent commands for those ticks to both runs: over its one link
to the recorder the dead run's came first, so for a tick an earlier run also reached, a
run takes the agent's last command recorded for that tick.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from typing import TypeVar, cast

from conag.recording.mcap_log import Entry
from protocol.codec import ProtocolError, decode
from protocol.messages import (
    AgentCommand,
    LockstepTimeout,
    Perturbation,
    Perturbed,
    SensorFrame,
    Welcome,
    WorldStatus,
)

T = TypeVar("T")


def _decode(data: bytes, cls: type[T]) -> T:
    return cast(T, decode(data, cls))


def paced(entries: Iterable[Entry], rate: float = 1.0, from_tick: int = 0) -> Iterator[tuple[float, Entry]]:
    """(seconds after the start of the replay, entry) for every entry of tick >= `from_tick`,
    in recorded order; `rate` > 0 scales the recorded gaps by 1/rate, `rate` 0 sends at once."""
    if rate < 0:
        raise ValueError("the replay rate must be >= 0 (0: as fast as possible)")
    first: int | None = None
    for e in entries:
        if e.tick < from_tick:
            continue
        if first is None:
            first = e.log_time
        yield (0.0 if rate == 0 else max(e.log_time - first, 0) / 1e9 / rate), e


@dataclass
class LockstepScript:
    """A recording as a lockstep world needs it (see the module); built by `from_entries`."""

    world_id: str = ""
    attaches: dict[int, list[Welcome]] = field(default_factory=lambda: defaultdict(list))
    commands: dict[int, list[AgentCommand]] = field(default_factory=lambda: defaultdict(list))
    perturbations: dict[int, list[Perturbation]] = field(default_factory=lambda: defaultdict(list))
    frames: dict[tuple[int, str], list[bytes]] = field(default_factory=lambda: defaultdict(list))
    last_tick: int = 0
    missed: set[tuple[int, str]] = field(default_factory=set)  # (tick, agent): stepped without its command
    limits: list[str] = field(default_factory=list)  # why this recording may not replay exactly
    cut_short: str = ""   # why the script ends before the recorded frames do (see `_end_at_the_last_full_tick`)
    first_tick: int = 0   # the tick the run starts at (that of the checkpoint it was resumed from)
    end: int | None = None  # the tick the next run of the world was resumed from (None: the last run)
    epoch: int | None = None  # the run's epoch, as its frames and Welcomes carry it

    @property
    def resumed(self) -> bool:
        """Whether this run of the world was resumed from a checkpoint (not started afresh)."""
        return self.first_tick > 0

    @classmethod
    def from_entries(cls, entries: Iterable[Entry], first_tick: int = 0, end: int | None = None) -> LockstepScript:
        """Sort a recording's welcomes, commands, perturbations and frames by tick; with
        `first_tick` and `end`, only a run of the world from `first_tick` to `end` (see
        `world_runs`): its frames up to `end`, what it did before stepping from `end` not."""
        script = cls(first_tick=first_tick, end=end, last_tick=first_tick)
        within = _window(first_tick, end)
        welcomed: dict[str, Welcome] = {}
        world_tick = 0  # the newest frame's tick: where the world was
        entries = list(entries)
        missed = script.missed
        for e in entries:
            if e.key.endswith("/lockstep_timeout"):
                try:
                    t = _decode(e.data, LockstepTimeout)
                except ProtocolError:
                    continue
                if within(t.tick):
                    missed.update((t.tick, a) for a in t.agent_ids)
        for e in entries:
            try:
                world_tick = script._take(e, welcomed, world_tick, within)
            except ProtocolError:
                continue  # what the world did not understand either changed nothing
        for tick, welcomes in script.attaches.items():
            # A resumed world's agents attach again in the order they came; body numbers,
            # from the checkpoint, say nothing of it.
            if not (script.resumed and tick == first_tick):
                _order_welcomes(welcomes)
        script._add_stand_ins()
        script._end_at_the_last_full_tick()
        return script

    def _take(self, e: Entry, welcomed: dict[str, Welcome], world_tick: int, within: Callable[[int], bool]) -> int:
        """File one entry under its tick (if the run's window holds it); returns the newest
        frame's tick so far (where the world was)."""
        leaf = e.key.rsplit("/", 1)[-1]
        if leaf == "welcome":
            w = _decode(e.data, Welcome)
            if within(w.tick):
                if w.agent_id in welcomed and w.restarts > welcomed[w.agent_id].restarts:
                    self.limits.append(f"agent {w.agent_id} was restarted at tick {w.tick}")
                welcomed[w.agent_id] = w
                self.world_id, self.epoch = w.world_id, w.epoch
                self.attaches[w.tick].append(w)
        elif leaf == "command":
            c = _decode(e.data, AgentCommand)
            at = max(c.tick + 1, world_tick) if (c.tick, c.agent_id) in self.missed else c.tick
            if within(at):
                self.commands[at].append(c)
                self.last_tick = max(self.last_tick, at)
        elif leaf == "perturbed":
            p = _decode(e.data, Perturbed)
            if p.ok and within(p.tick):
                self.perturbations[p.tick].append(p.perturbation())
        elif leaf == "sensors":
            f = _decode(e.data, SensorFrame)
            if within(f.tick) or f.tick == self.end:  # the frames of `end` are compared too
                self.frames[f.tick, f.agent_id].append(e.data)
                world_tick = max(world_tick, f.tick)
                self.epoch = f.epoch
        return world_tick

    def _add_stand_ins(self) -> None:
        """A command for each (tick, agent) the world stepped without (see the module)."""
        missed: dict[int, list[str]] = defaultdict(list)
        for t, a in sorted(self.missed):
            missed[t].append(a)
        speed: dict[str, float] = {}
        for tick in range(self.first_tick, self.last_tick + 1):
            for w in self.attaches.get(tick, ()):
                speed[w.agent_id] = 0.0
            for c in self.commands.get(tick, ()):
                if c.tick == tick:  # taken; a late one naming an earlier tick was refused
                    speed[c.agent_id] = c.speed
            for a in missed.get(tick, ()):
                self.commands[tick].append(AgentCommand(a, tick, speed.get(a, 0.0), 0.0, "none"))

    def _end_at_the_last_full_tick(self) -> None:
        """End the script before the first tick from which the recorded world stepped while
        the recording holds no command (nor stand-in) of an agent it waited for there: a
        world fed the script past that tick would wait for ever for it.

        The world waited at tick t for the agents it sent frames of t and of t + 1 (one that
        went away has its frames end with its commands: it cuts nothing). A tick whose frames
        the recording lacks altogether (its recorder lost the world's link for a while, or
        stopped before the run's last frames reached it) keeps the agents of the tick before.
        A recorder stopped while some agent's last commands were still on their way (an
        idle-priority recorder on a busy machine reads its socket late) holds that agent's
        frames but not its commands: the last tick of a run is often one such. A recorder
        that lost its links for a while lacks ticks in the middle: the replay ends there."""
        agents_at: dict[int, set[str]] = defaultdict(set)
        for t, a in self.frames:
            agents_at[t].add(a)
        taken: dict[int, set[str]] = defaultdict(set)
        for t, cmds in self.commands.items():
            taken[t].update(c.agent_id for c in cmds if c.tick == t)
        live: set[str] = set()
        for t in range(self.first_tick, self.last_tick + 1):
            live = agents_at.get(t) or live
            missing = sorted((live & (agents_at.get(t + 1) or live)) - taken[t])
            if missing:
                self._cut_before(t, missing[0], max(u for u, a in self.frames if a == missing[0]))
                return

    def _cut_before(self, tick: int, agent: str, last_frame: int) -> None:
        """End the script at `tick` - 1: the recording holds no command of `agent` for `tick`."""
        why = ("the recorder stopped before they reached it" if last_frame <= tick + 1 else
               "the recorder lost them and the world's messages for a while: it fell behind")
        self.cut_short = (f"the recording holds no command of {agent} after tick {tick - 1}, though it holds its "
                          f"frames to tick {last_frame} ({why})")
        self.last_tick = max(tick - 1, self.first_tick)
        if tick - 1 < self.first_tick:
            # Not one tick holds the command of every agent (cut short right after the
            # attaches): the replay compares the attaches' frames and takes no step (a
            # world fed some of tick 0's commands would wait for the others for ever).
            self.commands.pop(self.first_tick, None)

    @property
    def end_tick(self) -> int:
        """The last tick whose frames the replay compares: the step after `last_tick`, if
        the script holds commands of `last_tick` to take it."""
        return self.last_tick + 1 if self.commands.get(self.last_tick) else self.last_tick

    def agents(self) -> list[str]:
        """Every agent that attached, in the order it first did."""
        return list(dict.fromkeys(w.agent_id for tick in sorted(self.attaches) for w in self.attaches[tick]))

    def attached_by(self, tick: int) -> list[str]:
        """The agents attached at or before `tick` (every one of them is then waited for)."""
        return list(dict.fromkeys(w.agent_id for t in sorted(self.attaches) if t <= tick for w in self.attaches[t]))


def _window(first: int, end: int | None) -> Callable[[int], bool]:
    """Whether a tick is one a run of the world from `first` took part in before `end`."""
    return lambda tick: first <= tick and (end is None or tick < end)


_WORLD_LEAVES = ("sensors", "welcome", "status", "perturbed", "lockstep_timeout")


@dataclass
class WorldRun:
    """One run of the world process in a recording, as `world_runs` finds it."""

    start: int = 0                 # the tick it started at: 0, or its checkpoint's
    entries: list[tuple[int, Entry]] = field(default_factory=list)  # (recorded index, entry) of what it published
    epoch: int | None = None
    frames: set[tuple[int, str]] = field(default_factory=set)      # (tick, agent) of its frames
    _newest: dict[str, int] = field(default_factory=dict)           # agent -> its newest frame's tick
    _seq: int = 0                                                   # the newest status count heard

    def starts_anew(self, leaf: str, tick: int, epoch: int | None, agent: str | None, seq: int | None) -> bool:
        """Whether a message of the world (its key's last part, tick, epoch, the agent of a
        frame, the count of a status) was published by another process than this run's (see
        the module). Within a run, a Welcome comes at the world's tick, after its frames."""
        return ((epoch is not None and self.epoch is not None and epoch != self.epoch)
                or (agent is not None and tick < self._newest.get(agent, -1))
                or (leaf == "welcome" and tick < max(self._newest.values(), default=-1))
                or (seq is not None and seq < self._seq))

    def add(self, index: int, e: Entry, tick: int, epoch: int | None, agent: str | None, seq: int | None) -> None:
        """Take one message the world published (`_world_message`'s marks)."""
        self.start = min(self.start, tick)
        self.entries.append((index, e))
        self.epoch = epoch if epoch is not None else self.epoch
        if agent is not None:
            self._newest[agent] = max(self._newest.get(agent, -1), tick)
            self.frames.add((tick, agent))
        self._seq = max(self._seq, seq or 0)


def _world_message(leaf: str, data: bytes) -> tuple[int, int | None, str | None, int | None]:
    """(tick, epoch, agent of a frame, status count) of a message the world published."""
    if leaf == "sensors":
        f = _decode(data, SensorFrame)
        return f.tick, f.epoch, f.agent_id, None
    if leaf == "welcome":
        w = _decode(data, Welcome)
        return w.tick, w.epoch, None, None
    if leaf == "status":
        st = _decode(data, WorldStatus)
        return st.tick, None, None, st.seq or None
    if leaf == "perturbed":
        return _decode(data, Perturbed).tick, None, None, None
    return _decode(data, LockstepTimeout).tick, None, None, None


def world_runs(entries: Iterable[Entry]) -> list[LockstepScript]:
    """The scripts of a recording's runs of the world (see the module): one for a world that
    never died; else one per run whose ticks were not all undone by the next restart, in
    order, each from the tick it started at to the tick the next one was resumed from.
    ValueError if a run was resumed from a tick no run before it reaches."""
    entries = list(entries)
    runs = [WorldRun()]
    for i, e in enumerate(entries):
        leaf = e.key.rsplit("/", 1)[-1]
        if leaf not in _WORLD_LEAVES:
            continue
        try:
            marks = _world_message(leaf, e.data)
        except ProtocolError:
            continue
        if runs[-1].starts_anew(leaf, *marks):
            runs.append(WorldRun(start=marks[0]))  # from the first tick it was heard at, or earlier
        runs[-1].add(i, e, *marks)
    if len(runs) == 1:
        return [LockstepScript.from_entries(entries)]
    return _scripts(entries, runs)


def _scripts(entries: list[Entry], runs: list[WorldRun]) -> list[LockstepScript]:
    """One script per run that counts (see `world_runs`), each with the commands it took."""
    commands = [(i, e, _decode_or_none(e.data, AgentCommand)) for i, e in enumerate(entries)
                if e.key.endswith("/command")]
    scripts: list[LockstepScript] = []
    reached: set[tuple[int, str]] = set()  # (tick, agent) of the frames of the runs before
    welcomed: dict[str, Welcome] = {}       # each agent's newest Welcome of the runs before
    for k, run in enumerate(runs):
        end = min((r.start for r in runs[k + 1:]), default=None)
        if end is None or end > run.start:
            if scripts and run.start not in (0, scripts[-1].end):
                raise ValueError(f"the world was resumed at tick {run.start}, which the replay of its run before "
                                 f"does not reach (it ends at tick {scripts[-1].end})")
            mine = _commands_of(commands, run.start, end, reached)
            chosen = sorted(run.entries + mine, key=lambda pair: pair[0])
            scripts.append(LockstepScript.from_entries([e for _, e in chosen], run.start, end))
            if scripts[-1].resumed:
                _add_lost_reattaches(scripts[-1], welcomed)
        reached |= run.frames
        for _, e in run.entries:
            if e.key.endswith("/welcome") and (w := _decode_or_none(e.data, Welcome)) is not None:
                welcomed[w.agent_id] = w
    return scripts


def _add_lost_reattaches(script: LockstepScript, welcomed: dict[str, Welcome]) -> None:
    """A resumed run's agents attached again at its first tick. A Welcome the recording lacks
    there (a recorder that linked to the new world after the agent did; `conag run --record`
    has the world wait for it) is taken as given, before those recorded: an agent whose
    frames in the run come before any Welcome of it in the run attached then."""
    first = script.first_tick
    first_frame: dict[str, int] = {}
    for t, a in script.frames:
        first_frame[a] = min(first_frame.get(a, t), t)
    first_welcome = {w.agent_id: t for t in sorted(script.attaches, reverse=True) for w in script.attaches[t]}
    lost = sorted((a for a, t in first_frame.items() if t < first_welcome.get(a, t + 1) and a in welcomed),
                  key=lambda a: welcomed[a].body)
    if lost:
        script.attaches[first][:0] = [replace(welcomed[a], tick=first, epoch=script.epoch or welcomed[a].epoch)
                                      for a in lost]
        script.limits.append(f"the recording lacks the Welcome of {', '.join(lost)} at tick {first}, when the "
                             "world was resumed (its recorder linked to it late): taken as attached again then")


def _commands_of(commands: list[tuple[int, Entry, AgentCommand | None]], start: int, end: int | None,
                 reached: set[tuple[int, str]]) -> list[tuple[int, Entry]]:
    """The (recorded index, entry) of the commands of a run from `start` to `end`: those of
    its ticks, and for a tick an earlier run reached too, the agent's last one only (the
    earlier run's came before it, over the agent's one link to the recorder)."""
    within = _window(start, end)
    last: dict[tuple[int, str], int] = {}
    for i, _, c in commands:
        if c is not None and (c.tick, c.agent_id) in reached:
            last[c.tick, c.agent_id] = i
    return [(i, e) for i, e, c in commands if c is not None and within(c.tick)
            and last.get((c.tick, c.agent_id), i) == i]


def _decode_or_none(data: bytes, cls: type[T]) -> T | None:
    try:
        return _decode(data, cls)
    except ProtocolError:
        return None


def _order_welcomes(welcomes: list[Welcome]) -> None:
    """Put one tick's Welcomes in the order the world gave them, in place. The world numbers
    bodies in the order it attached them, but the recorder may hear the Welcomes of one
    tick in another order (they are published on different keys), and an agent attached
    later sees the bodies attached before it: so first attaches go in body order. A repeated
    Welcome of the same incarnation (a Hello the agent sent again on a busy machine, answered
    twice) keeps its recorded place among them: its body number says nothing of when it came."""
    seen: set[tuple[str, int]] = set()
    firsts = []
    for i, w in enumerate(welcomes):
        if (w.agent_id, w.restarts) not in seen:
            seen.add((w.agent_id, w.restarts))
            firsts.append(i)
    for i, w in zip(firsts, sorted((welcomes[i] for i in firsts), key=lambda w: w.body), strict=True):
        welcomes[i] = w


@dataclass
class Comparison:
    """Frames a replayed world sent against the recorded ones: how many matched, and the
    first that did not (tick, agent, what differs)."""

    matched: int = 0
    missing: int = 0          # frames the world sent that the recording lacks (its recorder missed them)
    dropped: int = 0          # frames the world sent that the bus dropped on the way to the replay
    first_difference: str = ""
    _left: dict[tuple[int, str], list[bytes]] = field(default_factory=dict)    # recorded, not matched yet
    _unmatched: dict[tuple[int, str], bytes] = field(default_factory=dict)     # sent, matching none

    @property
    def identical(self) -> bool:
        """Every frame compared was the same, and at least one was compared."""
        return self.matched > 0 and not self.first_difference

    def check(self, tick: int, agent: str, got: bytes, recorded: list[bytes]) -> bool:
        """Compare one frame the world sent with those recorded for (tick, agent): an agent
        that attaches gets a frame of the tick it attached at besides the step's, and the
        recorder may have missed either (frames are latest-wins). A frame equal to one not
        matched yet matches it; one equal to none is put aside as one the recording lacks,
        and is a difference only if a recorded frame of the same tick and agent is still
        unmatched when the replay ends (`settle`)."""
        left = self._left.setdefault((tick, agent), list(recorded))
        if got in left:
            left.remove(got)
            self.matched += 1
        else:
            self.missing += 1
            self._unmatched.setdefault((tick, agent), got)
        return True

    def settle(self) -> bool:
        """After the last frame: a frame the world sent that matched nothing, where a recorded
        frame of the same tick and agent matched nothing either, is a difference (the first,
        by tick, is reported). False if there is one."""
        for (tick, agent), got in sorted(self._unmatched.items()):
            if self._left.get((tick, agent)) and not self.first_difference:
                self.first_difference = f"tick {tick}, agent {agent}: {_difference(got, self._left[tick, agent][0])}"
        return not self.first_difference


def _difference(got: bytes, want: bytes) -> str:
    try:
        a, b = _decode(got, SensorFrame), _decode(want, SensorFrame)
    except ProtocolError as exc:
        return f"undecodable frame ({exc})"
    names = [n for n in SensorFrame.__dataclass_fields__ if getattr(a, n) != getattr(b, n)]
    return "fields " + ", ".join(names) + " differ" if names else "same fields, different bytes"
