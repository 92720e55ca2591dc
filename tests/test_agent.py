"""The agent of paper §4: its network runs the construction sequence, and agents build.

Builds run the real World and Brain code in one process (sim, lockstep); the
process-level behaviour (separate agent processes, kill and restart) is in
tests/test_run.py.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from agent_runtime.config import AgentConfig
from agent_runtime.motivations import Motivations
from agent_runtime.network import STATE_NODES, engineered
from conag import sim
from protocol.messages import Perturbation
from tests.conftest import SCENARIOS
from world_server.scenario import load_scenario


def state(**on):
    return np.array([float(on.get(n, 0)) for n in STATE_NODES])


@pytest.mark.parametrize("nodes, arm, motor", [
    (dict(brick_available=1, drop_site_available=1), "none", "brick_nav"),          # 2b
    (dict(near_brick=1, brick_available=1, drop_site_available=1), "none", "approach_red"),  # 2a
    (dict(drop_site_available=1), "none", "explore"),                               # 2c
    (dict(at_brick=1, near_brick=1, brick_available=1, drop_site_available=1), "grab", "none"),  # 3
    (dict(holding_brick=1, drop_site_available=1, brick_available=1), "none", "config_nav"),   # 4a
    (dict(holding_brick=1, near_brick=1, drop_site_available=1), "none", "config_nav"),
    (dict(holding_brick=1, at_drop_site=1, drop_site_available=1), "drop", "none"),  # 5
    (dict(holding_brick=1, at_brick=1, drop_site_available=1), "none", "config_nav"),  # never a second brick
    (dict(), "none", "none"),                                                        # structure done
])
def test_engineered_network_runs_the_construction_sequence_of_fig7(nodes, arm, motor):
    choice = engineered().choose(state(**nodes))
    assert (choice.arm, choice.motor) == (arm, motor)


def test_grab_needs_both_at_brick_and_a_drop_site_to_pass_the_threshold():
    net = engineered()
    assert net.choose(state(at_brick=1)).arm == "none"           # 0.5 < T = 0.7
    assert net.choose(state(drop_site_available=1)).arm == "none"
    assert net.choose(state(at_brick=1, drop_site_available=1)).arm == "grab"


def test_hunger_and_thirst_grow_reset_and_latch():
    cfg = AgentConfig(hunger_rate=0.3, thirst_rate=0.0)
    m = Motivations()
    for _ in range(3):
        m.update(cfg, ate=False, drank=False)
    assert m.seeking_food and m.hunger >= cfg.need_threshold
    m.update(cfg, ate=False, drank=False)
    assert m.seeking_food                     # stays until it has eaten
    m.update(cfg, ate=True, drank=False)
    assert m.hunger == 0.0 and not m.seeking_food


@given(st.floats(0.001, 0.5), st.lists(st.booleans(), max_size=200))
def test_a_need_is_on_exactly_from_its_threshold_until_it_is_met(rate, ate):
    # The paper's rule, with nothing latched on top: on while hunger is at or above the
    # threshold, and since only eating lowers hunger, on from then until it has eaten.
    cfg = AgentConfig(hunger_rate=rate)
    m, was_on = Motivations(), False
    for a in ate:
        m.update(cfg, ate=a, drank=False)
        assert m.seeking_food == (m.hunger >= cfg.need_threshold)
        if was_on and not a:
            assert m.seeking_food
        was_on = m.seeking_food


def _run(name, agents, max_ticks, cfg=None, seed=None):
    run = sim.start(load_scenario(SCENARIOS / f"{name}.toml"), agents=agents, seed=seed, cfg=cfg)
    return run, run.run(max_ticks)


@pytest.mark.parametrize("name, agents, max_ticks", [
    ("quick_wall", 1, 2000), ("fig17", 1, 3000),
    pytest.param("fig6", 1, 5000, marks=pytest.mark.slow), pytest.param("fig6", 3, 3000, marks=pytest.mark.slow),
])
def test_agents_complete_the_structure_in_lockstep(name, agents, max_ticks):
    run, completed = _run(name, agents, max_ticks)
    status = run.world.status()
    assert completed, f"{name}: {status.sites_filled}/{status.sites_total} sites after {status.tick} ticks"
    sc = load_scenario(SCENARIOS / f"{name}.toml")
    assert status.bricks_total == sc.cells_col_row("bB").shape[0]
    assert sum(status.agent_drops) >= status.sites_total - len(sc.cells_col_row("B"))


@pytest.mark.slow
def test_the_same_seed_gives_the_same_build():
    a, _ = _run("fig6", 3, 400, seed=5)
    b, _ = _run("fig6", 3, 400, seed=5)
    assert a.world.status() == b.world.status()
    np.testing.assert_array_equal(a.world.agent_poses(), b.world.agent_poses())


@pytest.mark.slow
def test_repair_a_brick_removed_from_the_finished_part_is_replaced():
    """Paper Fig. 6b: remove a brick of the structure; an agent puts another one there."""
    run = sim.start(load_scenario(SCENARIOS / "fig6.toml"), agents=1)
    world = run.world
    for _ in range(5000):
        if world.sites_filled().sum() >= 2:
            break
        run.step()
    filled = np.flatnonzero(world.sites_filled())
    x, y = world.sites_xy[filled[0]]
    assert world.perturb(Perturbation("remove", float(x), float(y))).ok
    assert not world.sites_filled()[filled[0]]
    assert run.run(8000), "the structure was not repaired and completed"
    assert world.sites_filled()[filled[0]]


@pytest.mark.slow
def test_hunger_and_thirst_interrupt_construction_which_then_resumes():
    cfg = AgentConfig(hunger_rate=0.005, thirst_rate=0.006)   # a need every ~130-160 ticks
    run = sim.start(load_scenario(SCENARIOS / "fig6.toml"), agents=1, cfg=cfg)
    seen = []
    for _ in range(8000):
        if run.world.status().completed:
            break
        run.step()
        seen.append(run.behaviours["a1"])
    assert run.world.status().completed
    assert "eat" in seen and "drink" in seen
    first_meal = min(seen.index("eat"), seen.index("drink"))
    assert {"config_nav", "brick_nav"} & set(seen[first_meal:]), "construction never resumed"
    assert run.world.status().agent_drops[0] >= 4


@pytest.mark.slow
def test_a_restarted_agent_rebuilds_its_maps_and_the_structure_completes():
    """Paper S2: the process dies (maps lost) and comes back with the same id."""
    scenario = load_scenario(SCENARIOS / "fig6.toml")
    run = sim.start(scenario, agents=3)
    for _ in range(120):
        run.step()
    run.world.detach("a2")
    for _ in range(30):
        run.step()
    welcome = run.world.attach("a2")
    assert welcome.restarts == 1
    from agent_runtime.brain import Brain
    run.brains["a2"] = Brain(welcome, None, np.random.default_rng(99))
    assert run.run(4000)
    assert run.world.status().bricks_total == 5


def test_agent_config_rejects_bad_values():
    with pytest.raises(ValueError):
        AgentConfig(map_size=40)
    with pytest.raises(ValueError):
        AgentConfig.from_mapping({"map_sise": 41})
    assert dataclasses.replace(AgentConfig(), map_size=101).map_size == 101


def _carry_trip(open_gap: bool) -> float:
    """Distance the agent travels from its first grab to its first drop in fig6."""
    run = sim.start(load_scenario(SCENARIOS / "fig6.toml"), agents=1)
    world = run.world
    while world.agents["a1"].holding < 0:
        run.step()
    if open_gap:  # two discs of the wall, straight between the agent and the diamond
        for x in (6.5, 7.5):
            assert world.perturb(Perturbation("remove", x, 8.5)).ok
    start = world.distance[0]
    while world.agents["a1"].drops == 0:
        assert world.tick < 3000, "the brick was never dropped"
        run.step()
    return float(world.distance[0] - start)


def test_a_gap_opened_in_the_wall_is_used_as_a_shorter_path():
    """Paper Fig. 6c: when a gap appears, the plan goes through it instead of around."""
    around, through = _carry_trip(False), _carry_trip(True)
    assert through < 0.6 * around, (through, around)


def test_other_agents_in_sight_are_obstacles_on_both_navigation_maps():
    from agent_runtime.esm import AGENT

    run = sim.start(load_scenario(SCENARIOS / "fig6.toml"))   # three agents start side by side
    run.step()
    brain = run.brains["a2"]
    seen = brain.maps.maps[AGENT] > 0.5
    seen[brain.centre, brain.centre] = False
    assert seen.sum() >= 1
    for _, obstacles in brain.nav_masks():
        assert obstacles[seen].all()
