"""The one simulation loop: a world and one Brain per agent, in lockstep, no bus.

`start` makes the world and its brains; `SimRun.step` is one lockstep tick (every brain
answers its frame, then the world steps); `SimRun.run` steps until the structure is
complete, `max_ticks` pass, no site has been filled for `stall_ticks` ticks (as `conag
run --stall-ticks N` gives up; `stall_report()` then says what each agent was at) or one
of its `stop` conditions holds, calling its `observers` after every tick, and returns a
`SimResult`. `on_step` sees every decision (the teacher's view); `before_step` sees each
frame before its brain does, and may start that brain again (`SimRun.restart`, as
`conag.sim.restarts` does at the worst moment) or withhold the frame (None: the brain does
not step and the world keeps its last command, as from a process cut off, `faults.cutoff`). `SimRun.perturb`
changes the world as `conag perturb` does, handing a changed blueprint to every brain as
the Blueprint message does on the bus. `start(..., cfg="paper")` runs the agent of a
preset as `conag run --agent paper` does; `SimRun.agent` and `SimResult.agent` record
which agent ran, as the run summary does (`AgentConfig.describe`).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from agent_runtime.brain import Brain, Step
from agent_runtime.config import AgentConfig
from protocol.messages import SITE_OPS, Perturbation, PerturbResult, SensorFrame
from world_server.buildability import check_layout
from world_server.noise import NoiseSettings
from world_server.scenario import Scenario
from world_server.stall import StallClock, stall_report
from world_server.world import World

StopCondition = Callable[["SimRun"], bool]  # asked before every tick: True ends the run
Observer = Callable[["SimRun"], None]        # called after every tick


@dataclass(frozen=True)
class SimResult:
    """How `SimRun.run` ended; true when the structure is complete (as the old bool was)."""

    completed: bool
    stalled: bool
    ticks: int             # the world's tick at the end
    stopped: bool = False  # one of the run's stop conditions ended it
    # which agent ran: {"preset", "without", "changed"} (`AgentConfig.describe`, as in the run
    # summary); not compared, so a result still equals SimResult(completed, stalled, ticks, ...)
    agent: dict = field(default_factory=dict, compare=False)

    def __bool__(self) -> bool:
        return self.completed


@dataclass
class SimRun:
    """A world and its brains, stepped in lockstep (`step`, `run`)."""

    world: World
    brains: dict[str, Brain] = field(default_factory=dict)
    behaviours: dict[str, str] = field(default_factory=dict)
    behaviour_ticks: dict[str, Counter] = field(default_factory=dict)  # agent -> behaviour -> ticks
    filled_at: np.ndarray | None = None  # per site (world order), the tick it was last filled; -1: empty
    on_step: Callable[[str, Step], None] | None = None  # sees every decision (the teacher's view)
    # sees each frame before its brain steps on it, and returns the frame the brain gets
    # (None: none this tick; the world keeps the agent's last command)
    before_step: Callable[[SimRun, SensorFrame], SensorFrame | None] | None = None
    stall: StallClock | None = None  # the last run's, when it watched for stalls
    agent: dict = field(default_factory=dict)  # which agent runs (`AgentConfig.describe`), for SimResult
    # The brains that tell and hear brick news, kept per number of brains (`_pass_news`).
    _tellers: tuple[int, list[Brain]] = field(default=(-1, []), init=False, repr=False, compare=False)

    def step(self) -> None:
        """One lockstep tick: every brain answers its frame, then the world steps."""
        for sensed in self.world.frames():
            frame = sensed if self.before_step is None else self.before_step(self, sensed)
            if frame is None:
                continue
            s = self.brains[frame.agent_id].step(frame)
            self.behaviours[frame.agent_id] = s.behaviour
            self.behaviour_ticks.setdefault(frame.agent_id, Counter())[s.behaviour] += 1
            if self.on_step is not None:
                self.on_step(frame.agent_id, s)
            self.world.set_command(frame.agent_id, s.speed, s.turn, s.action, s.mark)
        self._pass_news()
        self.world.step()
        self._record_fills()

    def restart(self, agent_id: str, rng: np.random.Generator) -> None:
        """Start `agent_id`'s brain again, as a restarted agent process is: the world attaches
        it again (its body stays where it stands) and a new Brain of the same agent knows
        only what the Welcome tells it."""
        old = self.brains[agent_id]
        self.brains[agent_id] = Brain(self.world.attach(agent_id), old.cfg, rng, network=old.network)

    def _pass_news(self) -> None:
        """Each brain's brick news (`AgentConfig.share_bricks`) to every other brain: the
        loop stands in for a bus (agent_runtime.brick_news). A society's workers keep no maps:
        they neither tell nor hear."""
        if self._tellers[0] != len(self.brains):
            self._tellers = (len(self.brains), [b for b in self.brains.values()
                                                if isinstance(b, Brain) and b.cfg.share_bricks])
        tellers = self._tellers[1]
        for news in [b.brick_news() for b in tellers]:
            if news is not None:
                for brain in tellers:
                    brain.hear_bricks(news)

    def _record_fills(self) -> None:
        filled = self.world.sites_filled()
        if self.filled_at is None:
            self.filled_at = np.full(filled.shape, -1, np.int64)
        self.filled_at[filled & (self.filled_at < 0)] = self.world.tick
        self.filled_at[~filled] = -1  # emptied again (a perturbation): not filled any more

    def fill_ticks(self) -> dict[tuple[int, int], int]:
        """The tick each site, as (row, col) of the layout, was filled at (-1: empty)."""
        cells = self.world.scenario.to_cell(self.world.sites_xy)
        return {(int(r), int(c)): int(t) for (c, r), t in zip(cells, self.filled_at)}

    def perturb(self, p: Perturbation) -> PerturbResult:
        """Apply `p` to the world; a changed blueprint goes to every brain at once."""
        before = self.fill_ticks() if p.op in SITE_OPS else None
        result = self.world.perturb(p)
        if result.ok and before is not None:
            bp = self.world.blueprint()
            for brain in self.brains.values():
                brain.set_blueprint(bp.version, bp.site_xs, bp.site_ys)
            # Sites kept keep their fill tick; a new one is recorded at the next step.
            cells = self.world.scenario.to_cell(self.world.sites_xy)
            self.filled_at = np.array([before.get((int(r), int(c)), -1) for c, r in cells], np.int64)
        return result

    def run(self, max_ticks: int, until_complete: bool = True, stall_ticks: int | None = None, *,
            stop: Sequence[StopCondition] = (), observers: Sequence[Observer] = ()) -> SimResult:
        """Step at most `max_ticks` times; return how the run ended.

        Before each tick, in this order: the structure is complete (with
        `until_complete`), no site has been filled for `stall_ticks` ticks (counted from
        this call), or one of `stop` holds: the run ends there. After each tick every
        observer is called with the run.
        """
        self.stall = StallClock(stall_ticks) if stall_ticks else None
        for _ in range(max_ticks):
            if until_complete and self.world.completed():
                return SimResult(True, False, self.world.tick, agent=self.agent)
            if self._stalled():
                return SimResult(False, True, self.world.tick, agent=self.agent)
            if any(condition(self) for condition in stop):
                return SimResult(self.world.completed(), False, self.world.tick, stopped=True, agent=self.agent)
            self.step()
            for observe in observers:
                observe(self)
        return SimResult(self.world.completed(), self._stalled(), self.world.tick, agent=self.agent)

    def _stalled(self) -> bool:
        if self.stall is None:
            return False
        if self.filled_at is None:
            self._record_fills()
        filled = int(np.count_nonzero(self.filled_at >= 0))
        searched = sum(brain.searched for brain in self.brains.values())
        return self.stall.observe(self.world.tick, filled, len(self.filled_at), searched)

    def stall_report(self) -> list[str]:
        """The report `conag run` prints on a stall: a headline, then one line per agent
        (its body, and what its brain says it is doing and what blocks it)."""
        status = self.world.status()
        idle = self.stall.idle(status.tick) if self.stall is not None else 0
        states = {a: brain.state_report(status.tick) for a, brain in self.brains.items()}
        unbuildable = check_layout(self.world.scenario.layout, len(self.brains)).reason
        return stall_report(status, idle, states, unbuildable)


class FirstCompletion:
    """A loop observer: the tick after which the structure was first complete (None: not yet)."""

    def __init__(self) -> None:
        self.tick: int | None = None

    def __call__(self, run: SimRun) -> None:
        """Record the world's tick the first time the structure is complete."""
        if self.tick is None and run.world.completed():
            self.tick = run.world.tick

    def seen(self, _run: SimRun) -> bool:
        """A stop condition: the structure has been complete after some tick."""
        return self.tick is not None


def start(scenario: Scenario, agents: int | None = None, seed: int | None = None,
          cfg: AgentConfig | str | None = None, network=None, noise: NoiseSettings | None = None) -> SimRun:
    """A world and its brains; `cfg` is every agent's AgentConfig or a preset's name, as
    `conag run --agent` takes it ("default", "paper"; default the default agent);
    `network` (one for every agent) replaces the Fig. 8 network; `noise` overrides the
    scenario's noise settings (docs/noise.md)."""
    seed = scenario.seed if seed is None else seed
    preset = cfg if isinstance(cfg, str) else None
    cfg = AgentConfig.preset(cfg) if isinstance(cfg, str) else cfg or AgentConfig()
    if noise is not None:
        scenario = noise.apply(scenario)
    world = World(scenario, np.random.default_rng(seed))
    run = SimRun(world, agent=cfg.describe(preset))
    run._record_fills()  # sites filled from the start count as filled at tick 0
    for i in range(scenario.agents if agents is None else agents):
        agent_id = f"a{i + 1}"
        welcome = world.attach(agent_id)
        run.brains[agent_id] = Brain(welcome, cfg, np.random.default_rng([seed, i]), network=network)
    return run
