"""Tests for the Jones & Mataric-style reactive construction baseline (R1, R2, R4)."""
from itertools import pairwise

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conag.baselines.lattice import (
    BLANK,
    LATTICE_BRICK,
    NO_BRICK,
    Rule,
    RuleSet,
    decide,
    make_world,
    sense,
    simulate,
)
from conag.baselines.perturb import nested_squares, run_perturbed
from conag.baselines.rules import (
    CORNER_GROWTH,
    corner_seeds,
    side_seeded,
    square_rules,
    square_target,
)

SIDES = range(4, 9)


def build(n, seeding, seed, n_agents=8, max_steps=20000):
    rule_set, seeds, shape = square_rules(n, seeding)
    return rule_set, simulate(rule_set, seeds, shape, n_agents, max_steps,
                              np.random.default_rng(seed))


def test_corner_rule_set_has_four_states_and_eight_rules():
    for n in SIDES:
        rule_set, _, _ = square_rules(n, "corners")
        assert len(rule_set.states) == 4
        assert len(rule_set.rules) == 8


@pytest.mark.parametrize("n", SIDES)
# The other seeds add little but time: the slow tier runs them.
@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)])
@pytest.mark.parametrize("seeding", ["corners", "sides"])
def test_rule_set_builds_exact_square(n, seed, seeding):
    rule_set, result = build(n, seeding, seed)
    assert result.built
    assert np.array_equal(result.grid, rule_set.target)


def test_side_seeded_rule_count_grows_with_side():
    counts = [len(square_rules(n, "sides")[0].rules) for n in SIDES]
    states = [len(square_rules(n, "sides")[0].states) for n in SIDES]
    assert all(a < b for a, b in pairwise(counts))
    assert all(a < b for a, b in pairwise(states))
    assert counts[0] > 8  # side seeds need more rules than corner seeds


def test_corner_guard_is_needed():
    """Interior cell east of a left-wall TL brick: only the guard stops it."""
    n, shape, origin = 6, (12, 12), (3, 3)
    guarded = square_rules(n, "corners")[0]
    unguarded = RuleSet(tuple(Rule(BLANK, ((behind, s),), "brick", s)
                              for s, behind, _ in CORNER_GROWTH))
    world = make_world(shape, {**corner_seeds(n, origin), (4, 3): 1})  # TL = 1
    probe = (4, 4)  # interior, its west neighbour is the left wall
    world.agents[probe] = BLANK
    pattern = sense(world, probe)
    assert decide(unguarded, BLANK, pattern, np.random.default_rng(0))[0] == "brick"
    assert decide(guarded, BLANK, pattern, np.random.default_rng(0))[0] == "move"
    wall = (3, 4)  # the true top-wall cell next to the TL seed
    world.agents[wall] = BLANK
    assert decide(guarded, BLANK, sense(world, wall), np.random.default_rng(0)) == ("brick", 1)


@pytest.mark.parametrize("seeding", ["corners", "sides"])
def test_same_seed_same_result(seeding):
    _, a = build(7, seeding, 42)
    _, b = build(7, seeding, 42)
    _, c = build(7, seeding, 43)
    assert a.steps == b.steps
    assert np.array_equal(a.brick_state, b.brick_state)
    assert (a.steps, a.brick_state.tobytes()) != (c.steps, c.brick_state.tobytes())


RULE_SETS = [square_rules(6, "corners")[0], side_seeded(6, (3, 3), (12, 12))[0]]


@settings(max_examples=150, deadline=None)
@given(data=st.data(), which=st.sampled_from([0, 1]))
def test_decision_depends_only_on_neighbourhood(data, which):
    rule_set = RULE_SETS[which]
    states = sorted(rule_set.states)
    shape = (9, 9)
    cells = st.lists(st.sampled_from([0, 0] + states), min_size=81, max_size=81)

    def world_from(values):
        grid = np.array(values).reshape(shape)
        return make_world(shape, {tuple(map(int, p)): int(grid[tuple(p)])
                                  for p in np.argwhere(grid > 0)})

    world = world_from(data.draw(cells))
    pos = (data.draw(st.integers(1, 7)), data.draw(st.integers(1, 7)))
    world.grid[pos] = 0
    world.agents[pos] = BLANK
    other = world_from(data.draw(cells))  # far cells replaced wholesale
    r, c = pos
    window = (slice(r - 1, r + 2), slice(c - 1, c + 2))
    other.grid[window] = world.grid[window]
    other.brick_state[window] = world.brick_state[window]
    other.agents[pos] = BLANK
    assert sense(world, pos) == sense(other, pos)
    first = decide(rule_set, BLANK, sense(world, pos), np.random.default_rng(5))
    second = decide(rule_set, BLANK, sense(other, pos), np.random.default_rng(5))
    assert first == second


def test_rules_only_read_the_neighbourhood():
    for rule_set in RULE_SETS:
        for rule in rule_set.rules:
            assert all(0 <= i < 8 for i, _ in rule.require)
            assert any(c != NO_BRICK for _, c in rule.require)


@pytest.mark.parametrize("seeding", ["corners", "sides"])
@pytest.mark.parametrize("direction", ["out", "in"])
@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)])
def test_moved_brick_gives_wrong_structure(seeding, direction, seed):
    n = 8
    rule_set, seeds, shape = square_rules(n, seeding)
    result, moved = run_perturbed(rule_set, seeds, shape, n, (3, 3), 20, direction,
                                  8, 3000, np.random.default_rng(seed))
    assert moved is not None
    assert not result.built
    assert not np.array_equal(result.grid, rule_set.target)
    assert result.grid[moved[1]] == LATTICE_BRICK  # the displaced brick stays a stray


def test_moved_brick_outward_grows_a_spurious_wall():
    rule_set, seeds, shape = square_rules(8, "corners")
    result, _ = run_perturbed(rule_set, seeds, shape, 8, (3, 3), 20, "out",
                              8, 3000, np.random.default_rng(0))
    stray = (result.grid == LATTICE_BRICK) & (rule_set.target == 0)
    assert stray.sum() > 1  # more than the moved brick: the rules extended it


@pytest.mark.parametrize("seed", [0] + [pytest.param(s, marks=pytest.mark.slow) for s in (1, 2, 3)])
def test_nested_inner_square_is_never_finished(seed):
    out = nested_squares(12, 4, 8, 4000, np.random.default_rng(seed))
    assert out.outer is not None
    assert out.inner is None
    assert out.enclosed == 0


def test_inner_square_alone_is_buildable():
    """Control for the nested case: the same rules build the inner ring alone."""
    n, origin, shape = 4, (7, 7), (18, 18)
    rule_set, _, _ = square_rules(4, "corners")
    rule_set.target = square_target(n, origin, shape)
    result = simulate(rule_set, corner_seeds(n, origin), shape, 8, 20000,
                      np.random.default_rng(0))
    assert result.built
