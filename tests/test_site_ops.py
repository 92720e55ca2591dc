"""Blueprint changes at run time (issue #10, part 3): add_site / remove_site.

The world core directly (counts, completion, refusals, the Blueprint and its version) and
the in-process simulator (`SimRun.perturb` hands the new blueprint to every brain).
World coordinates: cell (col, row) has its centre at (col + 0.5, rows - 1 - row + 0.5).
"""

from __future__ import annotations

import numpy as np
import pytest

from conag import sim
from protocol.codec import decode, encode
from protocol.messages import Blueprint, Perturbation
from tests.conftest import make


def site(op: str, x: float, y: float) -> Perturbation:
    return Perturbation(op, x, y)


def counts(w) -> tuple[int, int, int, bool]:
    s = w.status()
    return s.sites_total, s.sites_filled, s.bricks_total, s.completed


def test_add_site_extends_the_blueprint_and_never_adds_a_brick():
    w = make("+..\nb.#", agents=0)
    assert counts(w) == (1, 0, 1, False) and w.blueprint_version == 0
    res = w.perturb(site("add_site", 1.3, 0.9))  # any point of cell (1, 1): its centre is the site
    assert res.ok and "blueprint version 1" in res.message and res.tick == w.tick
    assert counts(w) == (2, 0, 1, False) and w.blueprint_version == 1
    assert w.sites_xy.tolist() == [[0.5, 1.5], [1.5, 0.5]]
    bp = w.blueprint()
    assert (bp.version, bp.site_xs, bp.site_ys) == (1, (0.5, 1.5), (1.5, 0.5))
    assert decode(encode(bp), Blueprint) == bp


def test_a_brick_already_in_an_added_site_fills_it_and_completion_follows_the_blueprint():
    w = make("B..\nb..", agents=0)
    assert counts(w)[3] and w.completed()
    assert w.perturb(site("add_site", 2.5, 1.5)).ok      # an empty cell: no longer complete
    assert counts(w) == (2, 1, 2, False) and not w.completed()
    assert w.perturb(site("add_site", 0.5, 0.5)).ok      # the free brick's cell: filled at once
    assert counts(w) == (3, 2, 2, False)
    assert w.perturb(site("remove_site", 2.5, 1.5)).ok   # the only open site goes: complete
    assert counts(w) == (2, 2, 2, True) and w.completed()
    assert w.blueprint_version == 3


def test_removing_a_filled_site_leaves_its_brick_as_a_free_brick():
    w = make("B+\n..", agents=0)
    res = w.perturb(site("remove_site", 0.5, 1.5))
    assert res.ok and "removed" in res.message
    assert counts(w) == (1, 0, 1, False)                   # still one brick, now a free one
    assert w.discs.nearest((0.5, 1.5), 0.1) >= 0           # the brick has not moved
    assert w.sites_xy.tolist() == [[1.5, 1.5]]


@pytest.mark.parametrize("op, x, y, why", [
    ("add_site", -0.5, 0.5, "outside the world"),
    ("add_site", 3.0, 0.5, "outside the world"),           # x == width: the edge, no cell
    ("add_site", 1.5, 2.5, "outside the world"),
    ("add_site", 2.5, 0.5, "fixed obstacle"),
    ("add_site", 0.9, 1.1, "already a drop site"),
    ("remove_site", 1.5, 1.5, "no drop site"),
    ("remove_site", -1.0, 0.0, "outside the world"),
])
def test_site_ops_are_refused_with_a_reason_and_change_nothing(op, x, y, why):
    w = make("+..\nb.#", agents=0)
    res = w.perturb(site(op, x, y))
    assert not res.ok and why in res.message
    assert counts(w) == (1, 0, 1, False) and w.blueprint_version == 0


@pytest.mark.parametrize("x, y, held", [(0.5, 1.5, "food"), (1.5, 1.5, "water")])
def test_no_site_is_added_where_food_or_water_lies(x, y, held):
    w = make("FW+\nb..", agents=0)
    res = w.perturb(site("add_site", x, y))
    assert not res.ok and f"holds {held}" in res.message
    assert counts(w) == (1, 0, 1, False) and w.blueprint_version == 0
    assert w.perturb(site("add_site", 2.5, 0.5)).ok   # beside them, on open ground: fine


def test_welcome_carries_the_blueprint_version_and_the_sites_now():
    w = make("+..\n.A.", agents=1)
    assert w.attach("a").blueprint_version == 0
    assert w.perturb(site("add_site", 2.5, 1.5)).ok
    welcome = w.attach("b")
    assert welcome.blueprint_version == 1 and welcome.site_xs == (0.5, 2.5)


def test_status_reports_every_body_position():
    w = make("....\n.A.A", agents=2)
    w.attach("a")
    w.attach("b")
    s = w.status()
    assert s.agent_x == pytest.approx((1.5, 3.5)) and s.agent_y == pytest.approx((0.5, 0.5))


# ---------------------------------------------------------------- in-process (sim)

OPEN = """
name = "open"
seed = 3
agents = 1
layout = \"\"\"
..........
.b..A..b..
..........
...+......
..........
\"\"\"
"""


def test_simrun_perturb_hands_the_new_blueprint_to_every_brain(monkeypatch):
    from world_server.scenario import parse_scenario

    seen = []
    real = sim.loop.Brain.set_blueprint

    def spy(self, version, xs, ys):
        seen.append((self.agent_id, version, xs, ys))
        return real(self, version, xs, ys)

    monkeypatch.setattr(sim.loop.Brain, "set_blueprint", spy)
    run = sim.start(parse_scenario(OPEN), agents=2)
    assert run.perturb(Perturbation("remove", 1.5, 3.5)).ok   # a disc op: no blueprint
    assert seen == []
    assert run.perturb(site("add_site", 6.5, 1.5)).ok
    assert not run.perturb(site("add_site", 6.5, 1.5)).ok     # refused: nothing handed out
    assert sorted(a for a, *_ in seen) == ["a1", "a2"]
    assert {(v, xs, ys) for _, v, xs, ys in seen} == {(1, (3.5, 6.5), (1.5, 1.5))}
    assert all(b.blueprint_version == 1 for b in run.brains.values())
    run.step()
    assert run.fill_ticks() == {(3, 3): -1, (3, 6): -1}


def test_an_agent_fills_a_site_added_mid_run_in_process():
    from world_server.scenario import parse_scenario

    run = sim.start(parse_scenario(OPEN), agents=1)
    assert run.run(3000).completed
    assert run.perturb(site("add_site", 6.5, 1.5)).ok
    assert not run.world.completed()
    result = run.run(3000)
    assert result.completed and not result.stalled
    assert counts(run.world) == (2, 2, 2, True)
    assert np.all(run.filled_at > 0)
