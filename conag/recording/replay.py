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
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import TypeVar, cast

from conag.recording.mcap_log import Entry
from protocol.codec import ProtocolError, decode
from protocol.messages import AgentCommand, LockstepTimeout, Perturbation, Perturbed, SensorFrame, Welcome

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

    @classmethod
    def from_entries(cls, entries: Iterable[Entry]) -> LockstepScript:
        """Sort a recording's welcomes, commands, perturbations and frames by tick."""
        script = cls()
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
                missed.update((t.tick, a) for a in t.agent_ids)
        for e in entries:
            leaf = e.key.rsplit("/", 1)[-1]
            try:
                if leaf == "welcome":
                    w = _decode(e.data, Welcome)
                    if w.agent_id in welcomed and w.restarts > welcomed[w.agent_id].restarts:
                        script.limits.append(f"agent {w.agent_id} was restarted at tick {w.tick}")
                    welcomed[w.agent_id] = w
                    script.world_id = w.world_id
                    script.attaches[w.tick].append(w)
                elif leaf == "command":
                    c = _decode(e.data, AgentCommand)
                    at = max(c.tick + 1, world_tick) if (c.tick, c.agent_id) in missed else c.tick
                    script.commands[at].append(c)
                    script.last_tick = max(script.last_tick, at)
                elif leaf == "perturbed":
                    p = _decode(e.data, Perturbed)
                    if p.ok:
                        script.perturbations[p.tick].append(p.perturbation())
                elif leaf == "sensors":
                    f = _decode(e.data, SensorFrame)
                    script.frames[f.tick, f.agent_id].append(e.data)
                    world_tick = max(world_tick, f.tick)
            except ProtocolError:
                continue  # what the world did not understand either changed nothing
        for welcomes in script.attaches.values():
            _order_welcomes(welcomes)
        script._add_stand_ins()
        script._end_at_the_last_full_tick()
        return script

    def _add_stand_ins(self) -> None:
        """A command for each (tick, agent) the world stepped without (see the module)."""
        missed: dict[int, list[str]] = defaultdict(list)
        for t, a in sorted(self.missed):
            missed[t].append(a)
        speed: dict[str, float] = {}
        for tick in range(self.last_tick + 1):
            for w in self.attaches.get(tick, ()):
                speed[w.agent_id] = 0.0
            for c in self.commands.get(tick, ()):
                if c.tick == tick:  # taken; a late one naming an earlier tick was refused
                    speed[c.agent_id] = c.speed
            for a in missed.get(tick, ()):
                self.commands[tick].append(AgentCommand(a, tick, speed.get(a, 0.0), 0.0, "none"))

    def _end_at_the_last_full_tick(self) -> None:
        """End the script at the last tick that holds the command of every agent the world
        still sent frames to. A recorder stopped while some agent's last commands were still
        on their way (an idle-priority recorder on a busy machine reads its socket late)
        holds that agent's frames but not its commands: a world fed the script past that
        tick would wait for ever for a command the recording does not hold. So the script
        ends before the first tick at which an agent had a frame (it was attached) but the
        recording holds no command of it; the last tick of a run is often one (the world
        stopped there, and some answers to its last frames came too late to be recorded).
        An agent that went away has its frames end with its commands: it cuts nothing."""
        last_frame: dict[str, int] = {}
        for t, a in self.frames:
            last_frame[a] = max(last_frame.get(a, -1), t)
        last_command: dict[str, int] = dict.fromkeys(last_frame, -1)
        for t, cmds in self.commands.items():
            for c in cmds:
                if c.agent_id in last_command:
                    last_command[c.agent_id] = max(last_command[c.agent_id], t)
        short = [(last_command[a], a) for a in last_frame
                 if last_command[a] < min(last_frame[a], self.last_tick)]
        if short:
            tick, agent = min(short)
            self.cut_short = (f"the recording holds no command of {agent} after tick {tick}, though it holds its "
                              f"frames to tick {last_frame[agent]} (the recorder stopped before they reached it)")
            self.last_tick = max(tick, 0)
            if tick < 0:
                # Not one tick holds the command of every agent (cut short right after the
                # attaches): the replay compares the attaches' frames and takes no step (a
                # world fed some of tick 0's commands would wait for the others for ever).
                self.commands.pop(0, None)

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
