"""Tests for imitation learning of the transition rule set (R3, Fig. 11)."""
import numpy as np
import pytest

from conag.baselines.lattice import BLANK, SEEN_EDGE, SEEN_FREE, SEEN_WALL, simulate
from conag.baselines.learned import (
    EXPLORE,
    ImitationNet,
    NetPolicy,
    RecordingTeacher,
    collect,
    encode,
    from_class,
    input_size,
    learn,
    n_classes,
    n_states_of,
    simulate_policy,
    to_class,
)
from conag.baselines.rules import square_rules

N = 6


@pytest.fixture(scope="module")
def corner_run():
    rule_set, seeds, shape = square_rules(N, "corners")
    errors, net, policy, n_decisions = learn(rule_set, seeds, shape, np.random.default_rng(0),
                                             epochs=20, episodes=5, return_net=True)
    return rule_set, seeds, shape, errors, net, policy, n_decisions


def test_encode_layout():
    n_states = 5
    pattern = ((SEEN_WALL, 3),) + ((SEEN_FREE, BLANK),) * 6 + ((SEEN_EDGE, BLANK),)
    x = encode(BLANK, pattern, n_states)
    assert x.shape == (input_size(n_states),)
    width = 4 + n_states
    assert x[BLANK] == 1 and x[:n_states].sum() == 1
    first = x[n_states:n_states + width]
    assert first[SEEN_WALL] == 1 and first[4 + 3] == 1 and first.sum() == 2
    last = x[n_states + 7 * width:]
    assert last[SEEN_EDGE] == 1 and last.sum() == 1
    assert x.sum() == 1 + 2 + 6 + 1


def test_classes_round_trip():
    n_states = 7
    assert from_class(EXPLORE, n_states) is None
    seen = {EXPLORE}
    for action in ("brick", "wait"):
        for k in range(n_states):
            cls = to_class(action, k, n_states)
            assert from_class(cls, n_states) == (action, k)
            seen.add(cls)
    assert seen == set(range(n_classes(n_states)))


@pytest.mark.parametrize("seeding", ["corners", "sides"])
def test_teacher_policy_reproduces_lattice_simulate(seeding):
    """The adapter is a faithful stand-in for `conag.simulate` (same random stream)."""
    rule_set, seeds, shape = square_rules(N, seeding)
    ref = simulate(rule_set, seeds, shape, 8, 20000, np.random.default_rng(3))
    teacher = RecordingTeacher(rule_set, n_states_of(rule_set, seeds))
    got = simulate_policy(teacher, seeds, shape, 8, 20000, np.random.default_rng(3),
                          rule_set.target)
    assert got.built and ref.built and got.steps == ref.steps
    assert np.array_equal(got.brick_state, ref.brick_state)
    bricks_laid = int(rule_set.target.sum()) - len(seeds)
    assert sum(t != EXPLORE for t in teacher.targets) == bricks_laid


def test_collect_records_every_decision():
    rule_set, seeds, shape = square_rules(N, "corners")
    x, y = collect(rule_set, seeds, shape, np.random.default_rng(1), 2)
    assert len(x) == len(y) > 100
    assert x.shape[1] == input_size(n_states_of(rule_set, seeds))
    bricks_laid = int(rule_set.target.sum()) - len(seeds)
    assert (y != EXPLORE).sum() == 2 * bricks_laid


def test_train_step_reduces_loss_on_a_batch():
    rng = np.random.default_rng(0)
    x = rng.integers(0, 2, (40, 12)).astype(float)
    y = rng.integers(0, 3, 40)
    net = ImitationNet(12, 16, 3, rng, lr=0.5)
    first = net.train_step(x, y)
    for _ in range(500):
        last = net.train_step(x, y)
    assert last < first and last <= 2


def test_corner_errors_fall_to_near_zero(corner_run):
    *_, errors, _, _, n_decisions = corner_run
    assert errors[0] > 0
    assert errors[-1] <= 0.01 * n_decisions
    assert errors[-1] == 0  # for this seed it is exactly zero
    assert errors[-3:].sum() < errors[:3].sum()


def test_trained_network_builds_the_square(corner_run):
    rule_set, seeds, shape, _, _, policy, _ = corner_run
    assert isinstance(policy, NetPolicy)
    for seed in (100, 101, 102):
        result = simulate_policy(policy, seeds, shape, 8, 20000,
                                 np.random.default_rng(seed), rule_set.target)
        assert result.built
        assert np.array_equal(result.grid, rule_set.target)


def test_same_seed_same_learning_curve():
    rule_set, seeds, shape = square_rules(N, "corners")

    def run(seed):
        return learn(rule_set, seeds, shape, np.random.default_rng(seed), epochs=4,
                     episodes=1, return_net=True)

    (ea, na, _, da), (eb, nb, _, db), (_, nc, _, dc) = run(7), run(7), run(8)
    assert np.array_equal(ea, eb) and da == db
    assert np.array_equal(na.w1, nb.w1) and np.array_equal(na.w2, nb.w2)
    assert da != dc or not np.array_equal(na.w1, nc.w1)
