"""Telling a stalled build from a slow one, and saying why it stalled.

`StallClock` counts the ticks since a drop site was last filled; `conag run` (through a
`StallWatch` on the world's statuses) and `conag.sim.SimRun.run` (every tick) both stop a run
once that reaches the limit. `stall_report` is the text both print then: one line for
the run, one per agent from the world's view of its body and the agent's own last
`AgentState`. No bus and no agent code here, so both sides import it freely.
"""

from __future__ import annotations

from collections.abc import Mapping

from protocol.messages import AgentState, WorldStatus

DEFAULT_STALL_TICKS = 3000


class StallClock:
    """Ticks since the last site was filled; `observe` says when that reaches `limit`.

    Progress is the filled count beating its best since the blueprint last changed. Not
    merely the open count falling: agents that lift a brick off the structure and put it
    back (a nearest-first agent walled out of the rest does) would otherwise look busy for
    ever. A site added or removed by a perturbation starts the count again (new work,
    which the agents have not had a chance at). A build with nothing left to do never
    stalls. Where the agents say how much of the world they have first seen while
    searching for bricks (`searched`), more of it is progress too: on a large world the
    supply may lie far from everyone, and a team still sweeping for it is not stuck. A
    repair after a brick was knocked off counts once the count is back above its best, so
    a repair slower than `limit` ticks is reported as a stall.
    """

    def __init__(self, limit: int):
        if limit <= 0:
            raise ValueError("the stall limit must be > 0 ticks")
        self.limit = limit
        self.since: int | None = None   # the tick of the last progress
        self._best = -1
        self._total = -1
        self._searched = 0

    def observe(self, tick: int, sites_filled: int, sites_total: int, searched: int = 0) -> bool:
        """Record the state at `tick`; True once no site has been filled (and, with
        `searched`, no new part of the world seen by a searching agent) for `limit` ticks."""
        if self.since is None or sites_total != self._total:
            self.since, self._best = tick, sites_filled
        elif sites_filled > self._best or searched > self._searched:
            self.since, self._best = tick, max(sites_filled, self._best)
        self._searched = max(self._searched, searched)
        self._total = sites_total
        return sites_filled < sites_total and self.idle(tick) >= self.limit

    def idle(self, tick: int) -> int:
        """Ticks since the last progress (0 before the first observation)."""
        return 0 if self.since is None else tick - self.since


class StallWatch:
    """A run watched from outside: the world's statuses, and the agents' last AgentStates
    in `states` (kept by the caller). Once no site has been filled for `limit` ticks (0:
    never), `observe` keeps the stall report in `report` and sets `stalled`."""

    def __init__(self, limit: int, unbuildable: str = ""):
        self.clock = StallClock(limit) if limit > 0 else None
        self.unbuildable = unbuildable  # why the start-up check found the structure cannot be built ("": it can)
        self.states: dict[str, AgentState] = {}
        self.stalled = False
        self.report: list[str] = []

    def observe(self, status: WorldStatus) -> bool:
        """See one status; True once the run has stalled (and from then on)."""
        if self.clock is None or self.stalled:
            return self.stalled
        if self.clock.observe(status.tick, status.sites_filled, status.sites_total):
            self.report = stall_report(status, self.clock.idle(status.tick), dict(self.states), self.unbuildable)
            self.stalled = True
        return self.stalled


def stall_report(status: WorldStatus, idle_ticks: int, states: Mapping[str, AgentState],
                 unbuildable: str = "") -> list[str]:
    """The stall report: a headline and one line per agent (see `agent_lines`). `unbuildable`:
    why the start-up check (`world_server.buildability`) found the structure cannot be built."""
    head = (f"STALLED at tick {status.tick}: no site filled for {idle_ticks} ticks "
            f"({status.sites_filled}/{status.sites_total} sites)")
    return [head, *agent_lines(status, states, unbuildable)]


def blocker(status: WorldStatus, state: AgentState, unbuildable: str = "") -> str:
    """What keeps an agent from building, for the report: what it says, unless it believes
    nothing is left to do (no site open, or nothing blocks it) while the world counts open
    sites. Then the agent is wrong about the world, and the truth is what the start-up
    check found (`unbuildable`: sites no agent can reach, too few bricks), or else the
    world's count; the agent's own word follows in brackets."""
    left = status.sites_total - status.sites_filled
    own = state.blocker or "none"
    if left <= 0 or (state.sites_open > 0 and state.blocker):
        return own
    if unbuildable:
        return f"{unbuildable} (found at start-up; the agent: {own})"
    if state.sites_open == 0:
        return f"{own}, but the world counts {left} open"
    return own


def agent_lines(status: WorldStatus, states: Mapping[str, AgentState], unbuildable: str = "") -> list[str]:
    """One line per agent of `status`, by id: where its body is and what it last said it does
    (its blocker as `blocker` gives it)."""
    lines = []
    for i, agent in sorted(enumerate(status.agent_ids), key=lambda item: item[1]):
        where = ""
        if i < len(status.agent_x):  # a status from an older world has no positions
            where = f" at ({status.agent_x[i]:.2f}, {status.agent_y[i]:.2f})"
        alive = "alive" if status.agent_alive[i] else "GONE"
        state = states.get(agent)
        if state is None:
            doing = "no AgentState received"
        else:
            doing = (f"{state.behaviour} (tick {state.tick}), holding {'a brick' if state.holding else 'nothing'}, "
                     f"{state.sites_open} sites open, blocker: {blocker(status, state, unbuildable)}")
        lines.append(f"  {agent}: {alive}{where}: {doing}")
    return lines
