"""The one simulation loop: stop conditions, per-tick observers, the first completion, and
the stall watch `conag run` shares with it."""

from __future__ import annotations

from pathlib import Path

import pytest

from agent_runtime.network import engineered
from conag import sim
from conag.sim.restarts import RestartAtDrop
from conag.sim.trials import run_trial
from protocol.messages import SensorFrame, WorldStatus
from teacher.core import Teacher
from world_server.scenario import load_scenario
from world_server.stall import StallWatch

QUICK_WALL = Path(__file__).resolve().parent.parent / "scenarios" / "quick_wall.toml"


def test_a_stop_condition_ends_the_run_before_the_tick_it_first_holds_on():
    run = sim.start(load_scenario(QUICK_WALL))
    seen: list[int] = []
    result = run.run(1000, stop=[lambda r: r.world.tick >= 40], observers=[lambda r: seen.append(r.world.tick)])
    assert result == sim.SimResult(completed=False, stalled=False, ticks=40, stopped=True)
    assert seen == list(range(1, 41))                     # once after every tick


def test_first_completion_sees_the_tick_a_run_until_complete_stops_at():
    scenario = load_scenario(QUICK_WALL)
    until_complete = sim.start(scenario).run(scenario.max_ticks)
    assert until_complete.completed and not until_complete.stopped
    first = sim.FirstCompletion()
    run = sim.start(scenario)
    result = run.run(until_complete.ticks + 50, until_complete=False, observers=[first])
    assert first.tick == until_complete.ticks and result.ticks == until_complete.ticks + 50
    run = sim.start(scenario)
    first = sim.FirstCompletion()
    stopped = run.run(scenario.max_ticks, until_complete=False, stop=[first.seen], observers=[first])
    assert stopped.stopped and stopped.completed and stopped.ticks == until_complete.ticks


def test_a_trial_until_complete_ends_at_its_completion_tick():
    r = run_trial(load_scenario(QUICK_WALL), engineered(), Teacher(), ticks=5000, eta=0.0, seed=1, learn=False,
                  until_complete=True)
    assert r.completed_at is not None and r.ticks == r.completed_at and r.sites_filled == r.sites_total


def _status(tick: int, filled: int, total: int = 2) -> WorldStatus:
    return WorldStatus(world_id="w0", scenario="s", seed=1, mode="lockstep", tick=tick, sites_filled=filled,
                       sites_total=total, bricks_total=3, agents_alive=1, bad_messages=0, completed=filled == total,
                       agent_ids=("a1",), agent_alive=(True,), agent_distance=(0.0,), agent_grabs=(0,),
                       agent_drops=(0,), agent_restarts=(0,), agent_x=(1.0,), agent_y=(2.0,),
                       agent_present=(True,))


def test_the_stall_watch_keeps_the_report_once_no_site_was_filled_for_its_limit():
    watch = StallWatch(100)
    assert not watch.observe(_status(0, 0)) and not watch.observe(_status(60, 1))
    assert not watch.observe(_status(159, 1)) and watch.report == []
    assert watch.observe(_status(160, 1)) and watch.stalled
    assert watch.report[0] == "STALLED at tick 160: no site filled for 100 ticks (1/2 sites)"
    assert watch.report[1].startswith("  a1: alive at (1.00, 2.00): no AgentState received")
    assert watch.observe(_status(170, 2))                 # stalled stays stalled, the report stays
    assert watch.report[0].startswith("STALLED at tick 160")


def test_a_stall_watch_with_limit_zero_never_stalls():
    watch = StallWatch(0)
    assert not any(watch.observe(_status(t, 0)) for t in range(0, 100000, 5000))


def test_a_brain_started_again_at_a_drop_never_hears_of_it_and_the_build_goes_on():
    run = sim.start(load_scenario(QUICK_WALL))
    restart = RestartAtDrop(1.0, seed=3)
    handed: list[bool] = []   # the dropped flag of each frame a new brain first steps on

    def watched(r: sim.SimRun, frame: SensorFrame) -> SensorFrame:
        before = r.brains[frame.agent_id]
        out = restart(r, frame)
        if r.brains[frame.agent_id] is not before:
            handed.append(out.dropped)
        return out

    run.before_step = watched
    assert run.run(run.world.scenario.max_ticks).completed
    drops = int(run.world.sites_filled().sum())
    # every drop started its brain again but the last, which completed the run before any frame
    assert len(handed) == restart.restarts >= drops - 1 > 0
    assert not any(handed)
    assert sum(r.restarts for r in run.world.agents.values()) == restart.restarts   # the world counts them too


def test_a_withheld_frame_leaves_the_brain_unstepped_and_the_last_command_standing():
    run = sim.start(load_scenario(QUICK_WALL))
    run.run(20)                                  # the agent is under way
    agent = next(iter(run.brains))
    index = run.world.agents[agent].index
    speed, ticks = float(run.world.speed[index]), run.behaviour_ticks[agent].total()
    assert speed > 0
    run.before_step = lambda r, frame: None      # cut off: no frame reaches the brain
    start = run.world.agent_poses()[index, :2].copy()
    run.run(5)
    assert run.behaviour_ticks[agent].total() == ticks            # the brain did not step
    assert float(run.world.speed[index]) == speed                 # the world kept its command
    assert (run.world.agent_poses()[index, :2] != start).any()    # and drove the body on


def test_a_restart_share_outside_zero_to_one_is_refused():
    with pytest.raises(ValueError, match=r"in \[0, 1\]"):
        RestartAtDrop(1.5, seed=0)
