"""The teacher (paper §5.1, L1) and learning students over the bus.

The bus tests run a real `conag teacher` process; students are a real `conag agent
--learn` process or `run_agent` in a thread, against a world server in this process.
"""

from __future__ import annotations

import itertools
import json
import signal
import threading
from collections import Counter

import numpy as np
import pytest
import zenoh

from agent_runtime.config import AgentConfig
from agent_runtime.learning import Student
from agent_runtime.network import ARM_OUTPUTS, MOTOR_OUTPUTS, NONE, engineered
from agent_runtime.node import AgentOptions, AgentReport, Learning, run_agent
from conag.agent_settings import AgentSettings
from protocol import keys
from protocol.codec import decode, encode
from protocol.messages import Decision, Reinforcement
from teacher.core import Teacher, is_error, signals
from tests.conftest import LONG_WALL, SCENARIOS, Process, conag, free_port, wait_until
from world_server.scenario import load_scenario, parse_scenario

ENG = engineered()
STATES = [tuple(float(v) for v in s) for s in itertools.product((0, 1), repeat=6)]


def decision(agent, tick, state, arm, motor):
    return Decision(agent, tick, state, (0.0,) * 7, arm, motor)


# the core --------------------------------------------------------------------------------
def test_signals_compare_each_group_with_the_engineered_network():
    at_brick = (0.0, 0.0, 1.0, 1.0, 1.0, 1.0)   # Fig. 7 step 3: grab, no motor output
    assert ENG.choose(np.array(at_brick)).arm == "grab"
    assert signals(decision("a1", 0, at_brick, "grab", NONE), ENG) == (1, 1)
    assert signals(decision("a1", 0, at_brick, "drop", NONE), ENG) == (-1, 1)
    assert signals(decision("a1", 0, at_brick, "grab", "approach_red"), ENG) == (1, -1)
    assert signals(decision("a1", 0, at_brick, NONE, "explore"), ENG) == (-1, -1)
    for state in STATES:  # the engineered network's own choices are always right
        c = ENG.choose(np.array(state))
        assert signals(decision("a1", 0, state, c.arm, c.motor), ENG) == (1, 1)


def test_the_teacher_numbers_reinforcements_per_student_and_counts_errors():
    t = Teacher()
    s = STATES[0b110000]
    right = ENG.choose(np.array(s))
    rs = [t.reinforce(decision("a1", 10 + i, s, right.arm, right.motor)) for i in range(3)]
    wrong = t.reinforce(decision("a1", 13, s, "drop", "explore"))
    other = t.reinforce(decision("a2", 5, s, right.arm, right.motor))
    assert [r.seq for r in rs] + [wrong.seq] == [0, 1, 2, 3] and other.seq == 0
    assert [r.tick for r in rs] == [10, 11, 12] and other.agent_id == "a2"
    assert not any(is_error(r) for r in rs) and is_error(wrong)
    assert t.students["a1"].errors == 1 and t.students["a1"].decisions == 4
    assert "a1: tick 13 decisions 4 errors 1" in t.progress()
    t.forget("a1")
    assert t.reinforce(decision("a1", 14, s, right.arm, right.motor)).seq == 0


# over the bus ---------------------------------------------------------------------------------
def teacher_process(endpoint, *extra):
    proc = Process("teacher", "--connect", endpoint, *extra)
    proc.wait_for("reinforcing students")
    return proc


def wait_for_teacher(session, world="w0", timeout=15.0):
    wait_until(lambda: any(r.ok is not None for r in session.liveliness().get(keys.all_teacher_tokens(world),
                                                                               timeout=1.0)),
               timeout, interval=0.05, what="a teacher's liveliness token")


class Collector:
    """Every reinforcement (or decision) published for one student, in arrival order (a FIFO: none dropped)."""

    def __init__(self, session, agent, world="w0", key=keys.reinforcement, kind=Reinforcement):
        self.items, self.kind = [], kind
        self._sub = session.declare_subscriber(key(world, agent), zenoh.handlers.FifoChannel(16384))

    def drain(self) -> list:
        while (s := self._sub.try_recv()) is not None:
            self.items.append(decode(s.payload.to_bytes(), self.kind))
        return self.items

    def wait(self, n, timeout=20.0) -> list:
        """All items so far, once there are at least `n` (AssertionError after `timeout` s)."""
        wait_until(lambda: len(self.drain()) >= n, timeout, interval=0.01, what=f"{n} {self.kind.__name__}s")
        return self.items


@pytest.mark.slow
def test_a_burst_of_2000_decisions_gets_2000_reinforcements_in_order(bus):
    session = bus.server_session()
    got = Collector(session, "s1")
    teacher = teacher_process(bus.endpoint, "--quiet")
    try:
        wait_for_teacher(session)
        pub = session.declare_publisher(keys.decision("w0", "s1"), reliability=zenoh.Reliability.RELIABLE,
                                        congestion_control=zenoh.CongestionControl.BLOCK)
        pub.put(b"\x00garbage")                      # ignored and counted, nothing sent back
        rng = np.random.default_rng(0)
        sent = []
        for tick in range(2000):
            d = decision("s1", tick, STATES[tick % 64], str(rng.choice((NONE, *ARM_OUTPUTS))),
                         str(rng.choice((NONE, *MOTOR_OUTPUTS))))
            sent.append(d)
            pub.put(encode(d))
        items = got.wait(2000)
        assert len(items) == 2000
        assert [r.seq for r in items] == list(range(2000))
        assert [r.tick for r in items] == list(range(2000))
        assert [(r.arm, r.motor) for r in items] == [signals(d, ENG) for d in sent]
        assert any(is_error(r) for r in items) and not all(is_error(r) for r in items)
        # Nothing for the garbage: it went first on the same ordered publisher, so an answer
        # to it would have come before the answer to tick 0.
        assert teacher.stop(signal.SIGTERM) == 0, teacher.err
        assert len(got.drain()) == 2000
        assert "final: s1: tick 1999 decisions 2000" in teacher.out and "bad 1" in teacher.out
        assert "Traceback" not in teacher.err
    finally:
        teacher.kill()


def test_a_recorded_teacher_teaches_only_once_it_hears_the_recorder(bus):
    # Peers do not forward for each other: the recorder gets the teacher's reinforcements only
    # over its own link to the teacher. A recorded teacher shows its token (students then
    # decide aloud) once the recorder's token has come over that link.
    from teacher.node import run_teacher

    session, watcher = bus.server_session(), bus.client_session()
    stop = threading.Event()
    thread = threading.Thread(target=run_teacher, args=(session, "w0", stop), kwargs=dict(recorded=30.0), daemon=True)
    thread.start()

    def teachers():
        return [r for r in watcher.liveliness().get(keys.all_teacher_tokens("w0"), timeout=0.5) if r.ok is not None]

    try:
        assert teachers() == [] and teachers() == []   # a second and more in: still waiting
        token = bus.client_session().liveliness().declare_token(keys.recorder_token("w0", "recorder"))
        wait_until(teachers, 20, what="the teacher's token once the recorder is up")
        token.undeclare()
    finally:
        stop.set()
        thread.join(10)


@pytest.mark.slow
def test_a_learning_agent_process_learns_from_a_teacher_process_until_it_makes_no_errors(bus, start_world, tmp_path):
    """Random weights, a real teacher, a real `conag agent --learn` on the 30-site walls: errors per
    window fall to zero (whole windows without one while it is still building), the student finishes
    the structure, and its weights are saved. (One run's errors are not monotone: a state met for the
    first time late in the run is an error, and learning it can upset a state learned before.)"""
    world = start_world(parse_scenario(LONG_WALL), max_ticks=3200)
    session = bus.client_session()
    got, seen = Collector(session, "a1"), Collector(session, "a1", key=keys.decision, kind=Decision)
    teacher = teacher_process(bus.endpoint)
    weights = tmp_path / "a1.json"
    agent = Process("agent", "--id", "a1", "--learn", "--eta", "0.1", "--seed", "0", "--weights-out", str(weights),
                    "--connect", bus.endpoint)
    try:
        completed = []

        def world_done() -> bool:  # and note the tick at which the structure is first complete
            if not completed and world.world.status().completed:
                completed.append(world.world.tick)
            return not world.thread.is_alive()

        wait_until(world_done, 90, interval=0.01, what="the world to reach its last tick")
        completed_at = completed[0] if completed else None
        assert world.result.completed and world.result.sites_filled == 30 and completed_at is not None
        items = got.wait(world.result.tick - 5, timeout=10)
        assert [r.seq for r in items] == list(range(len(items)))          # none lost, none reordered
        errors = np.array([is_error(r) for r in items])
        per_window = np.add.reduceat(errors, np.arange(0, len(errors), 200))
        assert per_window[0] > 5, per_window                              # random weights: many errors
        building = np.add.reduceat(errors[:completed_at - completed_at % 200], np.arange(0, completed_at - 199, 200))
        assert (building == 0).sum() >= 2, (completed_at, per_window)     # error-free stretches while building
        # None at the end on what it has learned: the last 500 decisions hold no error on a
        # state met 20 times before, and only a few at all (after the build, a first meeting
        # with a free brick and no site left is new to it).
        decided = [d.state for d in seen.wait(len(items))][:len(items)]
        met = Counter(decided[:-500])
        late = [(i, decided[i]) for i in range(len(items) - 500, len(items)) if errors[i]]
        assert len(late) < 10 and all(met[state] < 20 for _, state in late), (completed_at, late)
        assert agent.stop(signal.SIGTERM) == 0, agent.err
        assert f"reinforcements, {errors.sum()} errors" in agent.out, agent.out
        assert "weights saved to" in agent.out and "Traceback" not in agent.err
        student = Student.load(weights)                                   # a trained student, reusable
        for state in {s for s in decided[-500:] if met[s] >= 20}:         # what it learned, it keeps
            c, want = student.choose(np.array(state)), ENG.choose(np.array(state))
            assert (c.arm, c.motor) == (want.arm, want.motor), state
        assert teacher.stop(signal.SIGTERM) == 0 and "a1: tick" in teacher.out
    finally:
        agent.kill()
        teacher.kill()


@pytest.mark.slow
def test_a_student_keeps_acting_without_its_teacher_and_learns_again_when_a_new_one_starts(bus, start_world):
    world = start_world(SCENARIOS / "fig6.toml", max_ticks=100000)
    got = Collector(bus.client_session(), "a1")
    teacher = teacher_process(bus.endpoint)
    stop, report = threading.Event(), AgentReport()
    student = threading.Thread(target=run_agent, daemon=True, kwargs=dict(
        session=bus.client_session(), opts=AgentOptions("w0", "a1", AgentConfig(), 3, learning=Learning(eta=0.1)),
        stop=stop, report=report))
    student.start()
    second = None
    try:
        assert len(got.wait(100)) >= 100
        assert report.link.teachers == {"teacher"}
        teacher.kill()                                                    # SIGKILL: no goodbye
        # Every decision the dead teacher answered is from this tick or before; answers to
        # them may still be on their way, so later ones are told apart by their tick.
        killed_at = world.world.tick
        wait_until(lambda: not report.link.teachers, 15, what="the student to see its teacher go")
        tick0 = world.world.tick
        wait_until(lambda: world.world.tick >= tick0 + 300, 15, what="the student to keep acting")  # lockstep
        assert student.is_alive()
        assert [r for r in got.drain() if r.tick > killed_at] == []       # nobody reinforced meanwhile
        learned = report.link.counts.reinforcements

        def resumed() -> list:
            return [r for r in got.drain() if r.tick > killed_at]

        second = teacher_process(bus.endpoint)
        wait_until(lambda: len(resumed()) >= 100, 20, interval=0.01, what="100 reinforcements from the new teacher")
        new = resumed()
        assert new[0].seq == 0 and new[0].tick > tick0 + 300
        assert [r.seq for r in new] == list(range(len(new)))
        wait_until(lambda: report.link.counts.teacher_restarts == 1, 15, what="the student to see a new teacher")
        assert report.link.counts.reinforcements > learned and report.link.counts.gaps == 0
        assert second.stop(signal.SIGTERM) == 0, second.err
        assert "final:" in second.out and "Traceback" not in second.err
    finally:
        stop.set()
        student.join(10)
        teacher.kill()
        if second is not None:
            second.kill()
    assert not student.is_alive()


@pytest.mark.slow
def test_weights_options_are_checked_before_anything_starts(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "something"}')
    ep = f"tcp/127.0.0.1:{free_port()}"
    r = conag("agent", "--id", "a1", "--learn", "--weights-in", str(bad), "--connect", ep)
    assert r.returncode == 2 and "bad.json" in r.stderr and "not a student weights file" in r.stderr
    r = conag("agent", "--id", "a1", "--eta", "0.1", "--connect", ep)
    assert r.returncode == 2 and "need --learn" in r.stderr


@pytest.mark.slow
def test_conag_run_with_a_teacher_and_learning_agents_saves_their_weights(tmp_path):
    out, weights = tmp_path / "summary.json", tmp_path / "weights"
    r = conag("run", "scenarios/quick_wall.toml", "--headless", "--teacher", "--learn", "--eta", "0.2",
              "--weights-dir", weights, "--max-ticks", 2000, "--summary", out,
              "--listen", f"tcp/127.0.0.1:{free_port()}", timeout=120)
    assert r.returncode in (0, 3), r.stdout + r.stderr                 # 3: not complete within the ticks
    assert "quick_wall:" in r.stdout and "Traceback" not in r.stderr
    summary = json.loads(out.read_text())
    assert summary["ticks"] > 0 and [a["id"] for a in summary["agents"]] == ["a1"]
    student = Student.load(weights / "a1.json")                      # saved on the way out
    initial = Learning().student(load_scenario(SCENARIOS / "quick_wall.toml").seed)  # the agents' --seed
    assert not np.array_equal(student.excite, initial.excite)         # it learned from the teacher


@pytest.mark.slow
def test_an_agent_process_acts_on_saved_weights_without_learning(bus, start_world, tmp_path):
    path = tmp_path / "fig8.json"
    Student(ENG.excite, ENG.inhibit).save(path)                       # Fig. 8 as a weights file
    world = start_world(SCENARIOS / "quick_wall.toml", max_ticks=3000, stop_when_complete=True)
    seen = Collector(bus.client_session(), "a1", key=keys.decision, kind=Decision)
    agent = Process("agent", "--id", "a1", "--weights-in", str(path), "--connect", bus.endpoint)
    try:
        world.thread.join(60)
        assert not world.thread.is_alive() and world.result.completed, world.result
        assert len(seen.wait(50)) >= 50                                  # it still tells a teacher what it does
        assert agent.stop(signal.SIGTERM) == 0, agent.err
        assert "reinforcements" not in agent.out and "Traceback" not in agent.err  # not a learner
        assert Student.load(path).excite.tolist() == Student(ENG.excite, ENG.inhibit).excite.tolist()  # untouched
    finally:
        agent.kill()


def test_a_restarted_student_in_conag_run_starts_from_its_saved_weights(tmp_path, monkeypatch):
    import conag.run as run_mod

    started = []

    class FakeProcess:
        pid = 1

        def __init__(self, cmd, **_):
            started.append(cmd)

        def poll(self):
            return 0

    monkeypatch.setattr(run_mod.subprocess, "Popen", FakeProcess)
    opts = run_mod.RunOptions(scenario_path="x", scenario=load_scenario(SCENARIOS / "fig6.toml"),
                              endpoint="tcp/127.0.0.1:1", agent=AgentSettings(learn=True),
                              weights_dir=str(tmp_path))
    fleet = run_mod.Fleet(opts)
    (tmp_path / "a1.json").write_text("{}")      # left over from an earlier run: not loaded at first
    fleet.start("a1")
    assert "--weights-in" not in started[-1] and str(tmp_path / "a1.json") in started[-1]
    fleet.restart("a1")                           # a restart picks up what it had saved
    i = started[-1].index("--weights-in")
    assert started[-1][i + 1] == str(tmp_path / "a1.json")
