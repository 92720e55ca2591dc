"""The world's ticks a recording lacks: found as the recorder writes, kept in its metadata.

A recorder that gets no CPU for long (an idle-priority process on a machine whose cores
other work keeps busy) has its link to the world closed: the world waits at most 5 s
(zenoh's `wait_before_close`) on a full queue towards it. zenoh then connects the
recorder again by itself, and what the world published in between is not in the file.
`TickGaps` finds those ticks from what the recorder heard, so that a recording never
lacks ticks silently:

* in lockstep the world publishes frames (congestion control BLOCK) at every tick it
  steps, so the newest tick of its messages never jumps by more than one: a jump is a gap;
* in any mode, when the world's liveliness token went and came back, the ticks between
  the newest heard before and the first heard after were not recorded (a world that died
  and was resumed from a checkpoint comes back at a tick already heard: nothing lost).

Ticks going back (a world resumed from an older checkpoint) are no gap: the newest tick
stays the highest heard, and the resumed world's ticks count again once past it.
The gaps go into the recording's closing metadata (`end_metadata`, read by `lost_ticks`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

# The messages the world publishes that carry its tick (peek's type names).
WORLD_TYPES = frozenset({"SensorFrame", "WorldStatus", "Welcome", "WorldView", "Perturbed", "LockstepTimeout"})


@dataclass
class TickGaps:
    """The world's ticks a recorder did not hear (see the module), fed as it goes."""

    lockstep: bool = False      # every tick brings world messages: a jump of the newest tick is a gap
    newest: int = -1            # the highest tick of a world message heard
    gaps: list[tuple[int, int]] = field(default_factory=list)  # (first, last) tick not recorded
    _gone: bool = False         # the world's token went and has not come back
    _check_next: bool = False   # the next world message after the token came back closes a gap

    def token(self, alive: bool) -> None:
        """The world's liveliness token came (`alive`) or went, as the recorder saw it."""
        if not alive:
            self._gone = True
        elif self._gone:
            self._gone, self._check_next = False, True

    def heard(self, tick: int) -> tuple[int, int] | None:
        """A world message of `tick` was recorded; returns the gap it closes (first, last), if any."""
        jump = self.newest >= 0 and tick > self.newest + 1 and (self.lockstep or self._check_next)
        gap = (self.newest + 1, tick - 1) if jump else None
        if not self._gone:
            self._check_next = False
        if gap is not None:
            self.gaps.append(gap)
        self.newest = max(self.newest, tick)
        return gap

    @property
    def lost(self) -> int:
        """How many ticks the recording lacks."""
        return sum(last - first + 1 for first, last in self.gaps)

    def end_metadata(self) -> dict[str, str]:
        """What the recording's closing metadata says of its gaps."""
        return {"ticks_lost": str(self.lost), "lost_ticks": format_gaps(self.gaps)}


def format_gaps(gaps: list[tuple[int, int]]) -> str:
    """'562-563,700' for the gaps (562, 563) and (700, 700)."""
    return ",".join(str(a) if a == b else f"{a}-{b}" for a, b in gaps)


def lost_ticks(end: Mapping[str, str]) -> list[tuple[int, int]]:
    """The gaps a recording's closing metadata names ([] for none, or a recording older than
    the field, or one cut short: it has no closing metadata)."""
    gaps = []
    for part in end.get("lost_ticks", "").split(","):
        first, _, last = part.strip().partition("-")
        if first.isdecimal() and (not last or last.isdecimal()):
            gaps.append((int(first), int(last or first)))
    return gaps


def describe_lost(gaps: list[tuple[int, int]]) -> str:
    """One sentence naming a recording's gaps ('' for none)."""
    if not gaps:
        return ""
    n = sum(b - a + 1 for a, b in gaps)
    return (f"lacks the world's ticks {format_gaps(gaps)} ({n} tick{'s' if n != 1 else ''}): its recorder fell "
            "behind and the world's link to it was closed for a while")
