"""The learning student (§5.1, L2) and the Q-learner (L4): pure rules, no bus, no world."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from agent_runtime.learning import MARGIN, Student, WeightsFileError
from agent_runtime.network import NONE, OUTPUTS, STATE_NODES, THRESHOLD, engineered
from agent_runtime.qlearning import ARM_ACTIONS, MOTOR_ACTIONS, QLearner, state_index
from protocol.messages import Decision
from teacher.core import signals

ENG = engineered()
ALL_STATES = [np.array(s, dtype=float) for s in itertools.product((0, 1), repeat=len(STATE_NODES))]
# The state node patterns a building agent meets (Fig. 7's sequence, seen on Fig. 6).
BUILDING_STATES = [np.array(s, dtype=float) for s in (
    (1, 0, 0, 0, 1, 1), (0, 0, 0, 0, 1, 1), (0, 0, 0, 0, 1, 0), (1, 0, 0, 0, 0, 1), (0, 0, 1, 1, 1, 1),
    (0, 0, 0, 1, 1, 1), (1, 0, 0, 1, 1, 1), (1, 1, 0, 0, 1, 1), (0, 0, 0, 0, 0, 1), (1, 1, 0, 0, 0, 1))]


def col(name):
    return OUTPUTS.index(name)


def teach(learner, states, eta, rng, passes):
    """Present the states in random order, `passes` times; errors per pass."""
    per_pass = []
    for _ in range(passes):
        errors = 0
        for i in rng.permutation(len(states)):
            s = states[i]
            c = learner.choose(s)
            arm, motor = signals(Decision("a1", 0, tuple(s), c.outputs, c.arm, c.motor), ENG)
            errors += arm < 0 or motor < 0
            learner.learn(s, c.arm, c.motor, arm, motor, eta)
        per_pass.append(errors)
    return per_pass


def test_initial_weights_are_uniform_in_the_papers_ranges_and_follow_the_seed():
    a = Student.random(np.random.default_rng(3))
    b = Student.random(np.random.default_rng(3))
    c = Student.random(np.random.default_rng(4))
    assert a.excite.shape == a.inhibit.shape == (6, 7)
    assert np.array_equal(a.excite, b.excite) and np.array_equal(a.inhibit, b.inhibit)
    assert not np.array_equal(a.excite, c.excite)
    many = np.stack([Student.random(np.random.default_rng(s)).excite for s in range(200)])
    inh = np.stack([Student.random(np.random.default_rng(s)).inhibit for s in range(200)])
    assert 0 <= many.min() < 0.01 and 0.49 < many.max() <= 0.5
    assert -0.5 <= inh.min() < -0.49 and -0.01 < inh.max() <= 0
    assert many.mean() == pytest.approx(0.25, abs=0.01) and inh.mean() == pytest.approx(-0.25, abs=0.01)


def test_a_student_with_the_engineered_weights_chooses_as_the_engineered_network_on_every_state():
    student = Student(ENG.excite, ENG.inhibit)
    for s in ALL_STATES:
        assert student.choose(s) == ENG.choose(s)


def test_plus_one_raises_only_the_chosen_output_on_the_active_inputs():
    student = Student(np.full((6, 7), 0.1), np.full((6, 7), -0.1))  # every input 0: nothing fires
    state = np.array([0, 0, 1, 0, 1, 0.0])
    before_e, before_i = student.excite.copy(), student.inhibit.copy()
    student.learn(state, "grab", "brick_nav", 1, 1, eta=0.05)
    changed = (student.excite != before_e) | (student.inhibit != before_i)
    assert set(zip(*np.nonzero(changed))) == {(2, col("grab")), (4, col("grab")), (2, col("brick_nav")),
                                               (4, col("brick_nav"))}
    # Both weights move by +eta * a_i (the inhibitory one towards 0): the input rises by 2 * eta per active input.
    assert student.excite[2, col("grab")] == pytest.approx(0.15)
    assert student.inhibit[2, col("grab")] == pytest.approx(-0.05)
    net = student.choose(state).outputs
    assert net[col("grab")] == pytest.approx(0.2) and net[col("brick_nav")] == pytest.approx(0.2)


def test_the_summed_input_of_the_output_moves_in_the_direction_of_the_signal():
    """The paper's literal signs (w_exc += eta R a, w_inh -= eta R a) would leave w_exc + w_inh
    unchanged: no learning at all. Our reading weakens inhibition on +1 and strengthens it on -1."""
    state = np.array([1, 0, 0, 0, 1, 1.0])
    for signal in (1, -1):
        student = Student(np.full((6, 7), 0.2), np.full((6, 7), -0.2))
        before = student.choose(state).outputs[col("config_nav")]
        student.learn(state, NONE, "config_nav", 1, signal, eta=0.1)
        after = student.choose(state).outputs[col("config_nav")]
        assert np.sign(after - before) == signal


def test_minus_one_lowers_the_wrong_output_and_weights_keep_their_signs():
    student = Student(np.full((6, 7), 0.3), np.full((6, 7), -0.05))
    state = np.array([1, 1, 1, 1, 1, 1.0])
    for _ in range(50):
        student.learn(state, "drop", "explore", -1, -1, eta=0.1)
    for j in (col("drop"), col("explore")):
        assert np.all(student.excite[:, j] == 0.0)      # clipped at 0, not negative
        assert np.all(student.inhibit[:, j] < -4.0)     # inhibition grows without bound
    assert student.choose(state).arm != "drop" and student.choose(state).motor != "explore"
    for _ in range(200):
        student.learn(state, "grab", "avoid_red", 1, 1, eta=0.1, margin=1e9)
    assert np.all(student.inhibit[:, col("grab")] == 0.0)  # clipped at 0, not positive
    assert (student.excite >= 0).all() and (student.inhibit <= 0).all()


def test_a_plus_one_on_a_clearly_firing_output_changes_nothing():
    student = Student(ENG.excite, ENG.inhibit)
    state = np.array([1, 0, 0, 0, 1, 1.0])      # holding: config_nav at 1.0 >= T + margin
    assert student.choose(state).outputs[col("config_nav")] >= THRESHOLD + MARGIN
    before = student.excite.copy(), student.inhibit.copy()
    student.learn(state, NONE, "config_nav", 1, 1, eta=0.2)
    assert np.array_equal(student.excite, before[0]) and np.array_equal(student.inhibit, before[1])
    barely = Student(np.where(ENG.excite > 0, 0.36, 0.0), ENG.inhibit)  # config_nav at 0.72: right but barely
    barely.learn(state, NONE, "config_nav", 1, 1, eta=0.01)
    assert barely.choose(state).outputs[col("config_nav")] > 0.72


def test_choosing_nothing_when_the_teacher_wanted_something_raises_the_whole_group():
    student = Student(np.zeros((6, 7)), np.full((6, 7), -0.2))
    state = np.array([0, 0, 0, 0, 1, 1.0])
    assert np.allclose(student.choose(state).outputs, -0.4)
    student.learn(state, NONE, NONE, 1, -1, eta=0.1)   # arm right (nothing), motor wrong (teacher: brick_nav)
    net = np.array(student.choose(state).outputs)
    assert np.allclose(net[:2], -0.4)                   # arm group untouched
    assert np.allclose(net[2:], 0.0)                    # every motor output raised by 2 * eta * 2 inputs


def test_bad_signals_and_outputs_are_rejected():
    student = Student.random(np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"\+1 or -1"):
        student.learn(np.ones(6), "grab", NONE, 0, 1, eta=0.1)
    with pytest.raises(ValueError, match="not an output of the group"):
        student.learn(np.ones(6), "explore", NONE, 1, 1, eta=0.1)
    with pytest.raises(ValueError, match="shape"):
        Student(np.zeros((7, 6)), np.zeros((7, 6)))
    with pytest.raises(ValueError, match=">= 0"):
        Student(-np.ones((6, 7)), np.zeros((6, 7)))


@pytest.mark.parametrize("eta", [0.01, 0.05, 0.2])
def test_the_student_learns_the_building_states_to_zero_errors(eta):
    student = Student.random(np.random.default_rng(1))
    errors = teach(student, BUILDING_STATES, eta, np.random.default_rng(2), passes=400)
    assert errors[0] >= 5                       # random weights: most states wrong at first
    assert errors[-50:] == [0] * 50              # and then none, for good
    for s in BUILDING_STATES:
        assert (student.choose(s).arm, student.choose(s).motor) == (ENG.choose(s).arm, ENG.choose(s).motor)


def test_save_and_load_round_trip(tmp_path):
    student = Student.random(np.random.default_rng(5))
    teach(student, BUILDING_STATES, 0.05, np.random.default_rng(6), passes=3)
    path = tmp_path / "w.json"
    student.save(path)
    assert path.stat().st_size < 8000 and not list(tmp_path.glob(".*.tmp"))
    back = Student.load(path)
    assert np.allclose(back.excite, student.excite, atol=1e-11) and np.allclose(back.inhibit, student.inhibit,
                                                                                atol=1e-11)
    for s in ALL_STATES:
        assert (back.choose(s).arm, back.choose(s).motor) == (student.choose(s).arm, student.choose(s).motor)


def _valid_doc(tmp_path):
    path = tmp_path / "w.json"
    Student.random(np.random.default_rng(0)).save(path)
    return json.loads(path.read_text())


@pytest.mark.parametrize("change, message", [
    (lambda d: d.update(format="something-else"), "not a student weights file"),
    (lambda d: d.update(version=99), "unsupported version 99"),
    (lambda d: d.update(outputs=["grab"]), "outputs must be"),
    (lambda d: d.update(state_nodes=list(reversed(d["state_nodes"]))), "state nodes must be"),
    (lambda d: d.update(threshold="high"), "threshold"),
    (lambda d: d.update(excite=[[0.1] * 7] * 5), "shape"),
    (lambda d: d.update(excite=[[0.1] * 7] * 5 + [[0.1] * 6]), "bad weights"),
    (lambda d: d.update(inhibit=[[0.1] * 7] * 6), "inhibitory weights <= 0"),
    (lambda d: d.update(excite=[["x"] * 7] * 6), "list of numbers"),
])
def test_a_bad_weights_file_is_a_clear_error_naming_the_file(tmp_path, change, message):
    doc = _valid_doc(tmp_path)
    change(doc)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(WeightsFileError, match=message) as e:
        Student.load(bad)
    assert str(bad) in str(e.value)


def test_a_missing_or_garbled_weights_file_is_a_clear_error(tmp_path):
    with pytest.raises(WeightsFileError, match="cannot read"):
        Student.load(tmp_path / "none.json")
    garbled = tmp_path / "g.json"
    garbled.write_bytes(b"\x00\xff{not json")
    with pytest.raises(WeightsFileError, match="cannot read"):
        Student.load(garbled)


# Q-learning (L4) -------------------------------------------------------------------------
def test_state_index_covers_the_64_patterns_once():
    assert sorted(state_index(s) for s in ALL_STATES) == list(range(64))


def test_q_learning_from_the_teachers_signals_reaches_zero_errors():
    q = QLearner(np.random.default_rng(0), gamma=0.5)
    errors = teach(q, BUILDING_STATES, 0.5, np.random.default_rng(1), passes=60)
    assert errors[0] >= 5 and errors[-20:] == [0] * 20
    for s in BUILDING_STATES:
        c = q.choose(s)
        assert (c.arm, c.motor) == (ENG.choose(s).arm, ENG.choose(s).motor)
        assert len(c.outputs) == 7


def test_q_update_uses_the_next_state_and_end_episode_closes_the_last_step():
    q = QLearner(np.random.default_rng(0), gamma=0.5)
    s0, s1 = BUILDING_STATES[0], BUILDING_STATES[1]
    q.motor_q[state_index(s1), MOTOR_ACTIONS.index("brick_nav")] = 2.0
    q.learn(s0, NONE, "config_nav", 1, 1, eta=0.5)
    assert q.motor_q[state_index(s0)].max() == 0.0          # not yet: s' unknown
    q.learn(s1, NONE, "brick_nav", 1, -1, eta=0.5)
    # 0 + 0.5 * (1 + 0.5 * 2.0 - 0)
    assert q.motor_q[state_index(s0), MOTOR_ACTIONS.index("config_nav")] == pytest.approx(1.0)
    assert q.arm_q[state_index(s0), ARM_ACTIONS.index(NONE)] == pytest.approx(0.5)
    q.end_episode()                                          # s1's step, no successor: 2 + 0.5 * (-1 - 2)
    assert q.motor_q[state_index(s1), MOTOR_ACTIONS.index("brick_nav")] == pytest.approx(0.5)
    with pytest.raises(ValueError):
        QLearner(np.random.default_rng(0), gamma=1.0)
