"""Teams that use their numbers (issue 36): agents leave a goal to another agent in sight
that is nearer to it (`yield_goals`), and an agent with nothing to fetch waits near the
supply, off the sites, instead of wandering (`idle_wait`)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from agent_runtime.claims import claimed_by_others
from agent_runtime.config import AgentConfig
from conag import sim
from tests.conftest import scenario


def grid(cells: list[tuple[int, int]], n: int = 9) -> np.ndarray:
    g = np.zeros((n, n), bool)
    for r, c in cells:
        g[r, c] = True
    return g


def test_a_goal_another_agent_is_nearer_to_is_left_to_it():
    goals = grid([(4, 0), (4, 8)])
    others = grid([(4, 1)])
    assert claimed_by_others(goals, others, 4.0, 3.0).tolist() == grid([(4, 0)]).tolist()
    # Nearer than the other agent, this one keeps it; the other is guessed to take the far one.
    assert claimed_by_others(goals, others, 4.0, 0.5).tolist() == grid([(4, 8)]).tolist()


def test_with_more_agents_than_goals_only_the_nearest_agents_take_them():
    goals = grid([(0, 0)])
    assert claimed_by_others(goals, grid([(0, 2), (8, 8)]), 0.0, 5.0).tolist() == goals.tolist()
    assert not claimed_by_others(goals, grid([(0, 6), (8, 8)]), 0.0, 5.0).any()


def test_on_a_tie_this_agent_goes_first():
    assert not claimed_by_others(grid([(4, 4)]), grid([(4, 6)]), 4.0, 2.0).any()


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.tuples(st.integers(0, 8), st.integers(0, 8)), min_size=1, max_size=12),
       st.lists(st.tuples(st.integers(0, 8), st.integers(0, 8)), max_size=6),
       st.floats(0, 8), st.floats(0, 8))
def test_each_other_agent_takes_at_most_one_goal_and_the_pair_nearest_of_all_is_kept(goal_cells, agent_cells,
                                                                                         row, col):
    goals, others = grid(goal_cells), grid(agent_cells)
    taken = claimed_by_others(goals, others, row, col)
    assert not (taken & ~goals).any()
    assert taken.sum() <= others.sum()
    g = np.argwhere(goals)
    mine = np.hypot(g[:, 0] - row, g[:, 1] - col)
    theirs = min((np.hypot(*(g - a).T).min() for a in np.argwhere(others)), default=np.inf)
    if mine.min() <= theirs:   # this agent is in the nearest pair of all: its goal is its own
        assert not taken[tuple(g[np.argmin(mine)])]


# a1 stands beside the west brick, a2 three cells east of it; the east brick is a2's by a cell.
TWO_BRICKS = scenario("""
..........
bA..A....b
..........
....++....
""", agents=2)


def test_an_agent_heads_for_the_brick_no_nearer_agent_takes():
    for on, east in ((False, False), (True, True)):
        run = sim.start(TWO_BRICKS, cfg=AgentConfig(yield_goals=on, goal_sequencing=False))
        run.step()
        near = run.brains["a2"].plans.nearest_brick
        assert near is not None and (near[0] > 0) == east, (on, near)
        # a1 is nearest its brick either way and keeps it.
        assert run.brains["a1"].plans.nearest_brick[0] < 0


def test_the_last_goal_is_kept_even_when_another_agent_is_nearer():
    one = scenario("""
..........
bA..A.....
..........
....+.....
""", agents=2)
    run = sim.start(one, cfg=AgentConfig(yield_goals=True, goal_sequencing=False))
    run.step()
    assert run.brains["a2"].plans.brick_goals.any()


# No site to fill, so the agent has nothing to do. (A site walled in is the same once the
# agent has seen all its walls; a walk that takes a brick before it has, holds it for good.)
NOTHING_TO_DO = scenario("""
bb...........
bb.....###...
.......###...
.......###..A
""")


def _idle_run(on: bool, ticks: int) -> tuple[sim.SimRun, float]:
    run = sim.start(NOTHING_TO_DO, cfg=AgentConfig(idle_wait=on))
    run.run(ticks, until_complete=False)
    walked = float(run.world.distance[0])
    run.run(300, until_complete=False)
    return run, float(run.world.distance[0]) - walked


def test_an_idle_agent_waits_near_the_supply_instead_of_wandering():
    run, later = _idle_run(True, 300)
    assert later < 0.5, later             # standing still, and unstick leaves it so
    x, y = run.world.agent_poses()[0, :2] / run.world.scenario.world.cell_size
    bricks = np.array([(0.5, 3.5), (1.5, 3.5), (0.5, 2.5), (1.5, 2.5)])
    assert np.hypot(*(bricks - (x, y)).T).min() <= AgentConfig().idle_near + 1.0
    _, wandering = _idle_run(False, 300)
    assert wandering > 5.0, wandering     # left alone, it walks on


def test_an_idle_agent_looks_around_again_after_its_patience():
    run = sim.start(NOTHING_TO_DO, cfg=AgentConfig(idle_wait=True, idle_patience=200))
    run.run(300, until_complete=False)
    before = float(run.world.distance[0])
    run.run(400, until_complete=False)
    assert float(run.world.distance[0]) - before > 2.0


def test_a_searching_agent_leaves_unseen_ground_nearer_another_agent_to_it():
    from agent_runtime.far_memory import FarMemory

    for seed in range(20):
        far = FarMemory(21, np.zeros((0, 2)), (-20, -5, 20, 5))
        target = far.unseen_target(np.random.default_rng(seed), others=np.array([[-4, 0]]))
        assert target[1] > far.centre, (seed, target)       # east, away from the other agent
    picks = {int(FarMemory(21, np.zeros((0, 2)), (-20, -5, 20, 5)).unseen_target(np.random.default_rng(s))[1]
                 > 10) for s in range(40)}
    assert picks == {0, 1}     # alone, it goes either way


def test_the_waste_watcher_names_the_goal_a_gradient_ends_at():
    from agent_runtime.spreading import distance_field
    from experiments.team_waste import _goal_at_end

    goals = grid([(0, 0), (8, 7)])
    walls = grid([(5, 5), (5, 6), (5, 7), (5, 8), (6, 5)])
    field = distance_field(goals, walls)
    assert _goal_at_end(field, 4) == (0, 0)            # from the centre, the nearer goal
    assert _goal_at_end(field[2:, 2:], 4) == (6, 5)    # from (6, 6), below the wall: (8, 7)
    assert _goal_at_end(distance_field(np.zeros((9, 9), bool), walls), 4) is None
