"""Intrusions on a secure bus, refused: a zenoh router with the deployment's ACL on loopback
(`protocol.bus.deployment`, opened in this process), a world and a rightful agent `a1` as clients
with their own credentials, and intruders holding no credential, a wrong password, or the
credential of another identity (another agent, the teacher, the observer, the operator, the
world). Every attack is checked on what the world or the victim did (the body did not move,
no brick went, no frame or reinforcement arrived, the RunControl handler was not called),
and next to it the rightful identity does the same thing and it works, so a test whose
attack "failed" only because nothing reached anybody cannot pass.

`INTRUSIONS` counts the attempts; docs/results/reliability.md reports the figures.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import replace

import numpy as np
import pytest
import zenoh

from agent_runtime.world_link import AttachError, WorldLink
from conag.run import _on_control, control
from protocol import keys
from protocol.bus import BusOptions, open_session
from protocol.bus.acl import OBSERVER, OPERATOR, TEACHER, WORLD, agent_user
from protocol.bus.deployment import ROUTER_FILE, DeploymentSpec, client_file, write_deployment
from protocol.codec import decode, encode
from protocol.messages import AgentCommand, Hello, Perturbation, PerturbResult, Reinforcement, SensorFrame
from tests.conftest import SCENARIOS, RunningWorld, free_port, wait_until
from world_server.scenario import load_scenario
from world_server.world import World

# One worker runs the whole module (pyproject's `--dist loadgroup`): its tests share one
# deployment, and `test_the_figures` tallies every kind of attempt the module makes.
pytestmark = pytest.mark.xdist_group("secure_bus")

W = "w0"
A1, A2 = agent_user("a1"), agent_user("a2")
QUIET = 0.5  # seconds an attack is given to have an effect (the rightful control shows one in far less)


class SecureBus:
    """A deployment for agents a1 and a2, its router open in this process, and sessions by user."""

    def __init__(self, tmp):
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.dir = tmp
        write_deployment(tmp, DeploymentSpec(("a1", "a2"), W, self.endpoint))
        self.passwords = dict(line.split(":", 1) for line in (tmp / "credentials.txt").read_text().split())
        self._sessions: list = []
        self.router = self._keep(open_session(BusOptions(zenoh_config=str(tmp / ROUTER_FILE))))

    def _keep(self, session):
        self._sessions.append(session)
        return session

    def session(self, user: str):
        return self._keep(open_session(BusOptions(zenoh_config=str(self.dir / client_file(user)))))

    def raw(self, mode: str = "client", user: str | None = None, password: str | None = None):
        """A session of one's own making: no credential, or a guessed one."""
        config = zenoh.Config()
        config.insert_json5("mode", json.dumps(mode))
        config.insert_json5("connect/endpoints", json.dumps([self.endpoint]))
        config.insert_json5("scouting/multicast/enabled", "false")
        if user is not None:
            config.insert_json5("transport/auth/usrpwd", json.dumps({"user": user, "password": password}))
        return self._keep(zenoh.open(config))

    def close(self):
        for s in reversed(self._sessions):
            try:
                s.close()
            except Exception:  # noqa: BLE001 -- teardown: one session failing to close must not stop the rest
                pass


class Recorded:
    """What the attacks tried, for the figures: kind -> the identities that tried it."""

    def __init__(self):
        self.attempts: dict[str, list[str]] = {}

    def add(self, kind: str, who: str) -> None:
        self.attempts.setdefault(kind, []).append(who)


INTRUSIONS = Recorded()


@pytest.fixture(scope="module")
def secure(tmp_path_factory):
    bus = SecureBus(tmp_path_factory.mktemp("deploy"))
    scenario = load_scenario(SCENARIOS / "quick_wall.toml")
    # The world steps only when a1's command for the tick arrives: no clock in the way.
    scenario = replace(scenario, world=replace(scenario.world, lockstep_timeout=60.0))
    world = World(scenario, np.random.default_rng(scenario.seed), world_id=W)
    rw = RunningWorld(world, bus.session(WORLD))
    a1 = bus.session(A1)
    link = WorldLink(a1, W, "a1")
    welcome = link.attach(timeout=20.0)
    intruders = {u: bus.session(u) for u in (A2, TEACHER, OBSERVER, OPERATOR, WORLD)}
    intruders[A1] = a1  # the rightful agent, as an intruder where it has no right (perturb, kill)
    state = {"bus": bus, "rw": rw, "world": world, "a1": a1, "link": link, "welcome": welcome,
             "intruders": intruders, "tick": welcome.tick}
    try:
        yield state
    finally:
        state["link"].close()
        rw.close()
        bus.close()


def _step(s, speed: float = 0.0, turn: float = 0.0) -> SensorFrame:
    """The rightful a1 answers the current frame; returns the next one."""
    link, tick = s["link"], s["world"].tick
    link.send(tick, speed=speed, turn=turn)
    frame = link.next_frame(tick, timeout=20.0)
    assert frame is not None and frame.tick == tick + 1, "the rightful agent's command did not step the world"
    return frame


def _counter(session, key: str) -> list:
    got: list = []
    session.declare_subscriber(key, lambda sample: got.append(sample.payload.to_bytes()))
    return got


def _at_once(calls: list[tuple]) -> None:
    """Run each (function, *args) in its own thread, all together, and wait for them all."""
    threads = [threading.Thread(target=fn, args=args) for fn, *args in calls]
    for t in threads:
        t.start()
    for t in threads:
        t.join()


def _others(*rightful: str) -> list[str]:
    return [u for u in (A1, A2, TEACHER, OBSERVER, OPERATOR, WORLD) if u not in rightful]


# --- no credential at all -------------------------------------------------------------------

@pytest.mark.parametrize("how", ["client without credentials", "peer without credentials",
                                 "a1 with a wrong password", "an unknown user"])
def test_a_process_without_a_valid_credential_cannot_join_the_bus(secure, how):
    bus = secure["bus"]
    args = {"client without credentials": ("client",), "peer without credentials": ("peer",),
            "a1 with a wrong password": ("client", A1, bus.passwords[A1] + "x"),
            "an unknown user": ("client", "mallory", "guess")}[how]
    INTRUSIONS.add("join the bus", how)
    if args[0] == "client":
        with pytest.raises(zenoh.ZError):  # a client must reach its router to open at all
            bus.raw(*args)
        return
    peer = bus.raw(*args)  # a peer opens alone: the router refused its connection
    assert list(peer.info.routers_zid()) == [] and list(peer.info.peers_zid()) == []
    assert list(peer.get(keys.status(W), timeout=QUIET)) == []


# --- the agent's body and id -----------------------------------------------------------------

def test_nobody_but_a1_drives_a1s_body(secure):
    world, rw = secure["world"], secure["rw"]
    tick, pose = world.tick, world.agent_poses()[0].copy()
    bad = world.bad_messages
    intruders = _others(A1)
    for user in intruders:
        INTRUSIONS.add("drive a1's body", user)
        s = secure["intruders"][user]
        for _ in range(5):
            s.put(keys.command(W, "a1"), encode(AgentCommand("a1", tick, 1.0, 0.5, "grab")))
    time.sleep(QUIET)
    assert world.tick == tick, "an intruder's command stepped the lockstep world"
    np.testing.assert_array_equal(world.agent_poses()[0], pose)
    assert world.bad_messages == bad, "an intruder's command even reached the world"
    # The rightful agent drives it.
    for _ in range(5):
        _step(secure, speed=1.0)
    assert float(np.hypot(*(world.agent_poses()[0][:2] - pose[:2]))) > 0.05
    assert rw.thread.is_alive()


def test_nobody_else_can_take_over_the_id_a1_but_a1s_own_credential_can(secure):
    world, bus = secure["world"], secure["bus"]
    restarts = world.agents["a1"].restarts
    links, refused = [], []

    def attempt(link):
        try:
            link.attach(timeout=QUIET)
        except AttachError:
            refused.append(link)

    for user in _others(A1):
        INTRUSIONS.add("attach as a1 while a1 runs", user)
        links.append(WorldLink(secure["intruders"][user], W, "a1"))  # a1's token, a1's frames, a1's Hello
    _at_once([(attempt, link) for link in links])
    assert len(refused) == len(links), "an intruder attached as a1"
    assert world.agents["a1"].restarts == restarts
    _step(secure)  # the rightful a1 still drives its body

    # The intruders' a1 tokens never reached the world: when the rightful a1 leaves, the world
    # sees a1 gone although every intruder still declares a1's token.
    secure["link"].close()
    wait_until(lambda: not world.agents["a1"].alive, timeout=15.0, what="the world to see a1 gone")
    # a1's own credential claims the id again (a restart), and the world answers it.
    again = WorldLink(bus.session(A1), W, "a1")
    secure["link"] = again
    welcome = again.attach(timeout=20.0)
    assert welcome.restarts == restarts + 1 and welcome.epoch == secure["welcome"].epoch
    assert world.agents["a1"].alive
    for link in links:
        link.close()
    _step(secure)


def test_a_second_live_claim_with_the_same_credential_is_answered(secure):
    """The same credential may claim a1 while a1 runs (a restart whose old process is not
    seen gone yet): the world answers it."""
    bus = secure["bus"]
    second = WorldLink(bus.session(A1), W, "a1")
    try:
        welcome = second.attach(timeout=20.0)
        assert (welcome.agent_id, welcome.body, welcome.epoch) == ("a1", 0, secure["welcome"].epoch)
    finally:
        second.close()
    _step(secure)


def test_nobody_but_a1_and_the_readers_sees_a1s_frames(secure):
    got = {u: _counter(secure["intruders"][u], keys.sensors(W, "a1")) for u in (A2, TEACHER, WORLD)}
    for user in got:
        INTRUSIONS.add("read a1's frames", user)
    mine = _counter(secure["a1"], keys.sensors(W, "a1"))
    time.sleep(0.3)  # the subscriptions travel to the router
    for _ in range(5):
        _step(secure)
    wait_until(lambda: len(mine) >= 5, what="a1's own subscriber to see its frames")
    assert {u: len(v) for u, v in got.items()} == dict.fromkeys(got, 0)


def test_only_the_world_publishes_frames(secure):
    mine = _counter(secure["a1"], keys.sensors(W, "a1"))
    time.sleep(0.3)
    frame = _step(secure)
    # A frame a1 would take: its own id, the world's epoch, the next tick; from anyone else.
    payload = encode(replace(frame, tick=frame.tick + 1, odom_dx=0.5))
    for user in _others(WORLD, A1):
        INTRUSIONS.add("publish a1's frames", user)
        secure["intruders"][user].put(keys.sensors(W, "a1"), payload)
    time.sleep(QUIET)
    assert payload not in mine, "a forged frame reached a1"
    assert secure["world"].tick == frame.tick
    nxt = _step(secure)
    wait_until(lambda: any(decode(m, SensorFrame).tick == nxt.tick for m in mine), what="the world's frame")
    assert payload not in mine


def test_only_a_teacher_reinforces(secure):
    got = _counter(secure["a1"], keys.reinforcement(W, "a1"))
    time.sleep(0.3)
    r = encode(Reinforcement("a1", secure["world"].tick, 0, 1, 1))
    for user in _others(TEACHER, A1):
        INTRUSIONS.add("reinforce a1", user)
        secure["intruders"][user].put(keys.reinforcement(W, "a1"), r)
    time.sleep(QUIET)
    assert got == []
    secure["intruders"][TEACHER].put(keys.reinforcement(W, "a1"), r)
    wait_until(lambda: got, what="the teacher's reinforcement")


# --- the operator's powers -------------------------------------------------------------------

def _perturb(session, p: Perturbation, timeout: float) -> PerturbResult | None:
    for reply in session.get(keys.perturb(W), payload=encode(p), timeout=timeout):
        if reply.ok is not None:
            return decode(reply.ok.payload.to_bytes(), PerturbResult)
    return None


def test_only_the_operator_perturbs(secure):
    world = secure["world"]
    bricks = world.discs.bricks_total()
    remove = Perturbation("remove", 2.5, 3.5)  # quick_wall's free brick in column 2, row 4
    add = Perturbation("add", 9.5, 6.5, "brick")
    results = {}

    def attempt(user, p):
        results[(user, p.op)] = _perturb(secure["intruders"][user], p, QUIET)

    calls = []
    for user in _others(OPERATOR):
        for p in (remove, add):
            INTRUSIONS.add(f"perturb ({p.op} a brick)", user)
            calls.append((attempt, user, p))
    _at_once(calls)
    assert results == dict.fromkeys(results), "an intruder's perturbation was answered"
    assert world.discs.bricks_total() == bricks
    result = _perturb(secure["intruders"][OPERATOR], remove, 10.0)
    assert result is not None and result.ok, result
    assert world.discs.bricks_total() == bricks - 1


class FakeFleet:
    """What `conag run` kills and restarts, recorded instead."""

    def __init__(self):
        self.calls: list[tuple[str, str]] = []

    def kill(self, agent_id):
        self.calls.append(("kill", agent_id))
        return f"killed {agent_id}"

    def restart(self, agent_id):
        self.calls.append(("restart", agent_id))
        return f"restarted {agent_id}"


def test_only_the_operator_kills_or_restarts(secure):
    fleet = FakeFleet()
    operator = secure["intruders"][OPERATOR]
    run = operator.declare_queryable(keys.run_control(W), _on_control(fleet))
    try:
        time.sleep(0.3)
        answers = {}

        def attempt(user, op):
            answers[(user, op)] = control(secure["intruders"][user], W, op, "a1", timeout=QUIET)

        calls = []
        for user in _others(OPERATOR):
            for op in ("kill", "restart"):
                INTRUSIONS.add(f"{op} a1 (RunControl)", user)
                calls.append((attempt, user, op))
        _at_once(calls)
        assert len(answers) == len(calls)
        assert all(not r.ok and "answered" in r.message for r in answers.values()), answers
        assert fleet.calls == []
        result = control(operator, W, "restart", "a1", timeout=10.0)
        assert result.ok and fleet.calls == [("restart", "a1")]
    finally:
        run.undeclare()


def test_nobody_but_the_operator_serves_run_control(secure):
    """Every other identity poses as the run (a RunControl queryable answering by itself):
    the operator's `conag kill` reaches the real run only (a fake's reply would not decode)."""
    fleet = FakeFleet()
    operator = secure["intruders"][OPERATOR]
    fakes = []
    for user in _others(OPERATOR):
        INTRUSIONS.add("serve RunControl (pose as conag run)", user)
        fakes.append(secure["intruders"][user].declare_queryable(
            keys.run_control(W), lambda q: (q.reply(q.key_expr, b"\x00"), q.drop())))
    run = operator.declare_queryable(keys.run_control(W), _on_control(fleet))
    try:
        time.sleep(0.3)
        for _ in range(3):
            result = control(operator, W, "kill", "a1", timeout=10.0)
            assert result.ok, result
        assert fleet.calls == [("kill", "a1")] * 3
    finally:
        for q in (*fakes, run):
            q.undeclare()


def test_nobody_but_the_world_answers_an_attach(secure):
    """An intruder posing as the world (a queryable on a1's attach key, answering a Welcome of
    its own) is never asked: a1's restart is answered by the world."""
    asked = []
    fakes = []
    for user in _others(WORLD, A1):
        INTRUSIONS.add("serve a1's attach (pose as the world)", user)
        fakes.append(secure["intruders"][user].declare_queryable(
            keys.attach(W, "a1"), lambda q, u=user: (asked.append(u), q.reply_err(b"fake"), q.drop())))
    try:
        time.sleep(0.3)
        hello = encode(Hello("a1", 1))
        replies = list(secure["a1"].get(keys.attach(W, "a1"), payload=hello, timeout=10.0))
        assert [r.ok is not None for r in replies] == [True], "only the world's Welcome"
        assert asked == []
    finally:
        for q in fakes:
            q.undeclare()
    _step(secure)


KINDS = 12  # the kinds of attempt above (joining the bus counts as one kind, tried four ways)


def test_the_figures():
    """The tally docs/results/reliability.md reports (`pytest tests/test_secure_bus.py -s` prints it); only
    when the whole module ran."""
    if len(INTRUSIONS.attempts) < KINDS:
        pytest.skip(f"only part of the module ran: {sorted(INTRUSIONS.attempts)}")
    total = sum(map(len, INTRUSIONS.attempts.values()))
    print(f"\n{total} intrusion attempts of {len(INTRUSIONS.attempts)} kinds, all refused:")
    for kind, who in INTRUSIONS.attempts.items():
        print(f"  {kind}: {len(who)} ({', '.join(who)})")
    assert len(INTRUSIONS.attempts) == KINDS
