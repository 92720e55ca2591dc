"""Learning trials in one process (paper §5.1, Fig. 9; L3): world, student, teacher, no bus.

The same World, Brain, Student / QLearner and teacher core as the processes, stepped in
lockstep by the simulation loop (`conag.sim.loop`) for the many runs of the Fig. 9
experiment. One trial: the scenario's initial layout (every brick where the file puts
it), the student's body at its start with fresh maps (its configuration ESM seeded from
the blueprint), `ticks` steps; each step the teacher reinforces the student's decision
and the student learns from it before acting on the next frame. The learner's weights
carry over from trial to trial: that is what is learned.

Between trials the whole environment is reset, not only the agent: a fresh `World` from
the same scenario and a fresh Brain (why: docs/design.md, "Learning (§5.1)").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent_runtime.brain import Step
from agent_runtime.config import AgentConfig
from conag.sim.loop import FirstCompletion, start
from teacher.core import Teacher, is_error
from world_server.scenario import Scenario


@dataclass(frozen=True)
class TrialResult:
    """One learning trial: the student's errors against the teacher, and how far the build got."""

    errors: int            # steps where the student's (arm, motor) differs from the teacher's
    ticks: int             # steps taken
    sites_filled: int
    sites_total: int
    completed_at: int | None  # the tick the structure was first complete, if it was


def trial_seed(seed: int, run: int, trial: int) -> int:
    """A distinct world/agent seed for each (run, trial) of an experiment seeded with `seed`."""
    return int(np.random.SeedSequence([seed, run, trial]).generate_state(1)[0])


def run_trial(scenario: Scenario, learner, teacher: Teacher, *, ticks: int, eta: float, seed: int,
              learn: bool = True, cfg: AgentConfig | None = None, until_complete: bool = False) -> TrialResult:
    """One trial of `ticks` steps from the scenario's initial layout; `learner` learns if `learn`.

    With `until_complete` the trial ends early once every drop site holds a brick.
    """
    run = start(scenario, agents=1, seed=seed, cfg=cfg, network=learner)
    errors = 0

    def on_step(_agent: str, step: Step) -> None:
        nonlocal errors
        d = step.decision
        r = teacher.reinforce(d)
        errors += is_error(r)
        if learn:
            learner.learn(d.state, d.arm, d.motor, r.arm, r.motor, eta)

    run.on_step = on_step
    completion = FirstCompletion()
    run.run(ticks, until_complete=False, stop=[completion.seen] if until_complete else [], observers=[completion])
    if learn and hasattr(learner, "end_episode"):
        learner.end_episode()
    st = run.world.status()
    return TrialResult(errors, run.world.tick, st.sites_filled, st.sites_total, completion.tick)


def run_learning(scenario: Scenario, learner, *, trials: int, ticks: int, eta: float, seed: int, run: int = 0,
                 cfg: AgentConfig | None = None, on_trial=None) -> list[TrialResult]:
    """`trials` trials in a row with one learner; `on_trial(i, result)` after each."""
    teacher = Teacher()
    results = []
    for i in range(trials):
        r = run_trial(scenario, learner, teacher, ticks=ticks, eta=eta, seed=trial_seed(seed, run, i), cfg=cfg)
        results.append(r)
        if on_trial is not None:
            on_trial(i, r)
    return results
