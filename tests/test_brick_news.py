"""Brick news between agents (`AgentConfig.share_bricks`, issue 36): an agent tells the
others the free bricks in its sight, in world cells; a listener remembers those beyond its
own map and forgets those taken or claimed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agent_runtime.brick_news import NEWS_EVERY, cells, report
from agent_runtime.config import AgentConfig
from agent_runtime.far_memory import FarMemory
from conag import sim
from protocol import keys
from protocol.codec import encode
from tests.conftest import SCENARIOS, conag, scenario, wait_until
from world_server.discs import BRICK_DISC

NO_SITES = np.zeros((0, 2), np.int64)


def test_reported_bricks_beyond_the_map_are_remembered_and_taken_ones_forgotten():
    far = FarMemory(11, NO_SITES)   # the map reaches 5 cells each way from the attach cell
    far.hear(cells([(20, 0), (2, 1)]), cells([]))
    assert far.bricks.tolist() == [[20, 0]]   # on the map, the agent's own sight holds
    kept = far.bricks
    far.hear(cells([(20, 0)]), cells([]))
    assert far.bricks is kept                 # old news changes nothing
    far.hear(cells([(30, 0)]), cells([(20, 0), (30, 0)]))
    assert far.bricks.tolist() == []          # taken (or claimed by the teller): forgotten, not learned


def test_maps_that_forget_learn_nothing_from_news():
    far = FarMemory(11, NO_SITES, remember=False)
    far.hear(cells([(20, 0)]), cells([]))
    assert far.bricks.tolist() == []


# Two agents 36 cells apart, bricks beside the first only; maps of 11 cells.
APART = """
A.b.b...............................A.
......................................
..................+...................
"""


def brick_cells(run: sim.SimRun, cell: float) -> set[tuple[int, int]]:
    _, xy, kinds = run.world.discs.present_arrays()
    return set(map(tuple, np.floor(xy[kinds == BRICK_DISC] / cell).astype(int).tolist()))


def near_bricks(reported: set[tuple[int, int]], run: sim.SimRun, cell: float) -> bool:
    """Every reported cell within a cell of a brick in the world (a map marks a brick in the
    cell its readings put it, sometimes the next one: the maps' own resolution)."""
    truth = np.array(sorted(brick_cells(run, cell)))
    return all(np.abs(truth - r).max(axis=1).min() <= 1 for r in reported)


def remembered(run: sim.SimRun, agent: str) -> set[tuple[int, int]]:
    brain = run.brains[agent]
    return set(map(tuple, (brain.far.bricks + brain._origin).tolist()))


def test_an_agent_learns_the_bricks_another_sees_far_beyond_its_own_map():
    sc = scenario(APART, agents=2)
    run = sim.start(sc, cfg=AgentConfig(map_size=11, share_bricks=True))
    for _ in range(NEWS_EVERY + 1):
        run.step()
    heard = remembered(run, "a2")
    assert heard and near_bricks(heard, run, run.brains["a2"].cell)
    alone = sim.start(sc, cfg=AgentConfig(map_size=11))
    for _ in range(NEWS_EVERY + 1):
        alone.step()
    assert remembered(alone, "a2") == set()


def test_news_is_of_bricks_in_sight_only_and_in_world_cells():
    run = sim.start(scenario(APART, agents=2), cfg=AgentConfig(map_size=11, share_bricks=True))
    for _ in range(NEWS_EVERY + 1):   # frames of ticks 0 to NEWS_EVERY
        run.step()
    a1, a2 = run.brains["a1"], run.brains["a2"]
    news = a1.brick_news()
    assert news is not None and news.agent_id == "a1"
    seen = set(zip(news.seen_xs, news.seen_ys))
    assert seen and near_bricks(seen, run, a1.cell)
    assert a2.brick_news() is not None and a2.brick_news().seen_xs == ()   # none in a2's sight
    run.step()
    assert a1.brick_news() is None   # one report every NEWS_EVERY ticks


def test_agent_processes_hear_each_others_news_over_the_bus(bus):
    from agent_runtime.feeds import AgentFeeds
    from protocol.messages import BEHAVIOURS, AgentState

    class Teller:
        def brick_news(self):
            return report("a1", 10, cells([(3, 4), (9, 1)]), cells([(5, 5)]), cells([]))

        def state_report(self, tick):
            return AgentState("a1", tick, "explore", False, 0, "", (0,) * len(BEHAVIOURS))

    class Listener:
        set_blueprint = staticmethod(lambda *_: False)

        def __init__(self):
            self.heard = []

        def hear_bricks(self, news):
            self.heard.append(news)

    teller = AgentFeeds(bus.server_session(), "w0", "a1", news=True)
    listener = AgentFeeds(bus.client_session(), "w0", "a2", news=True)
    ear = Listener()
    try:
        def heard() -> bool:
            teller.after_step(Teller(), 10)   # best effort: sent again until the link is up
            listener.before_step(ear)
            return bool(ear.heard)
        wait_until(heard, what="a1's brick news at a2")
        news = ear.heard[0]
        assert (news.agent_id, news.seen_xs, news.seen_ys, news.taken_xs) == ("a1", (3, 9), (4, 1), (5,))
        # News in another agent's name, on a1's key, is refused and counted.
        forger = bus.client_session().declare_publisher(keys.bricks("w0", "a1"))
        forged = encode(report("a3", 20, cells([(1, 1)]), cells([]), cells([])))

        def refused() -> bool:
            forger.put(forged)
            return not listener.brick_news() and listener.bad > 0
        wait_until(refused, what="the forged news counted as bad")
    finally:
        for feeds in (teller, listener):
            feeds.close()


def test_the_env_refuses_brick_news_rather_than_drop_it():
    # The env's agents meet only in its world: switched on there, the addition would
    # silently do nothing.
    from conag.env import ConAgParallelEnv
    with pytest.raises(ValueError, match="share_bricks"):
        ConAgParallelEnv("scenarios/fig6.toml", cfg=AgentConfig(share_bricks=True))


@pytest.mark.slow
def test_conag_run_builds_fig6_with_agent_processes_sharing_bricks(tmp_path):
    summary = tmp_path / "summary.json"
    done = conag("run", str(SCENARIOS / "fig6.toml"), "--with", "share_bricks", "--headless", "--summary",
                 str(summary), timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    record = json.loads(summary.read_text())
    assert record["completed"] and record["agent"]["changed"] == {"share_bricks": True}
