"""Blueprint changes over the bus (issue #10, part 3): a `conag world` process and one
`conag agent` process; `conag perturb add-site / remove-site` mid-run. The agent hears the
new Blueprint (published reliably, also answered by a queryable) and fills the new site;
removing a filled site leaves its brick. The agent reports its AgentState on the way."""

from __future__ import annotations

import json
import signal
import time

import pytest

from protocol import keys
from protocol.bus import Inbox
from protocol.codec import decode
from protocol.messages import AgentState, Blueprint, WorldStatus
from tests.conftest import Process, conag, wait_until

pytestmark = pytest.mark.slow

SMALL = '''
name = "small"
seed = 3
agents = 1
layout = """
..........
.b..A..b..
..........
...+......
..........
"""
'''
FIRST_SITE, NEW_SITE = (3.5, 1.5), (6.5, 1.5)


class Watch:
    """The newest WorldStatus, every Blueprint and AgentState, as they arrive."""

    def __init__(self, session, world: str = "w0"):
        self.status = None
        self.blueprints, self.states = Inbox().subscribe(session, keys.blueprint(world)), []
        self._statuses = Inbox().subscribe(session, keys.status(world))
        self._states = Inbox().subscribe(session, keys.agent_state(world, "a1"))
        self.session, self.world = session, world

    def until(self, predicate, what: str, timeout: float = 60.0) -> WorldStatus:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            while (sample := self._statuses.get(0.05)) is not None:
                self.status = decode(sample.payload.to_bytes(), WorldStatus)
            while (sample := self._states.get(0)) is not None:
                self.states.append(decode(sample.payload.to_bytes(), AgentState))
            if self.status is not None and predicate(self.status):
                return self.status
        raise AssertionError(f"timed out waiting for {what}; last status {self.status}")

    def next_blueprint(self, timeout: float = 10.0) -> Blueprint:
        sample = self.blueprints.get(timeout)
        assert sample is not None, "no Blueprint published"
        return decode(sample.payload.to_bytes(), Blueprint)

    def query_blueprint(self, timeout: float = 10.0) -> Blueprint:
        def answer():  # the world declares the queryable a moment after saying it is up
            return next((r.ok for r in self.session.get(keys.blueprint(self.world), timeout=1.0)
                         if r.ok is not None), None)

        ok = wait_until(answer, timeout, interval=0.05, what="the blueprint queryable to answer")
        return decode(ok.payload.to_bytes(), Blueprint)


def perturb(ep: str, op: str, at: tuple[float, float]) -> str:
    r = conag("perturb", op, "--at", f"{at[0]},{at[1]}", "--connect", ep, timeout=30)
    assert r.returncode == 0, r.stdout + r.stderr
    return r.stdout


def test_a_site_added_mid_run_is_filled_and_a_removed_site_keeps_its_brick(bus, tmp_path):
    scenario, summary = tmp_path / "small.toml", tmp_path / "world.json"
    scenario.write_text(SMALL)
    world = Process("world", str(scenario), "--listen", bus.endpoint, "--quiet", "--summary", str(summary))
    agent = None
    try:
        world.wait_for("lockstep: ticks start")
        watch = Watch(bus.client_session())
        assert watch.query_blueprint().version == 0
        agent = Process("agent", "--id", "a1", "--connect", bus.endpoint)
        watch.until(lambda st: st.tick > 0, "the agent to drive the world")
        assert "added a drop site" in perturb(bus.endpoint, "add-site", NEW_SITE)
        refused = conag("perturb", "remove-site", "--at", "0.5,0.5", "--connect", bus.endpoint, timeout=30)
        assert refused.returncode == 1 and "no drop site in cell (0, 4)" in refused.stdout, refused
        bp = watch.next_blueprint()
        assert (bp.version, list(zip(bp.site_xs, bp.site_ys))) == (1, [FIRST_SITE, NEW_SITE])
        st = watch.until(lambda st: st.completed and st.sites_total == 2, "the agent to fill both sites")
        assert (st.sites_total, st.sites_filled, st.bricks_total) == (2, 2, 2)

        assert "removed the drop site" in perturb(bus.endpoint, "remove-site", FIRST_SITE)
        assert watch.next_blueprint().version == 2 and watch.query_blueprint().site_xs == (NEW_SITE[0],)
        st = watch.until(lambda st: st.sites_total == 1, "the status to show one site")
        assert (st.sites_filled, st.bricks_total, st.completed) == (1, 2, True)
        assert st.agent_ids == ("a1",) and len(st.agent_x) == len(st.agent_y) == 1

        watch.until(lambda st: len(watch.states) >= 2, "state reports (every 100 ticks)")
        assert all(s.agent_id == "a1" for s in watch.states)
        assert sum(watch.states[-1].behaviour_ticks) > 0
        assert agent.stop(signal.SIGTERM, timeout=15) == 0, agent.err
        assert world.stop(signal.SIGTERM, timeout=15) == 0, world.err
    finally:
        for p in (agent, world):
            if p is not None and p.proc.poll() is None:
                p.proc.kill()
                p.proc.wait(10)
    s = json.loads(summary.read_text())
    assert (s["sites_total"], s["sites_filled"], s["bricks_total"], s["stalled"]) == (1, 1, 2, False)
    assert s["agents"][0]["behaviour_ticks"], s                       # the world kept the agent's reports
