"""Cues in the world (issue 37 item 4; world_server/cues.py): marked and unmarked by command,
sensed on their own channel where they lie, covered by a disc, kept by checkpoints, sent
over the wire, and shown to observers: the world's WorldView carries them (every cue, covered
or not) to the viewer's picture and the recorder."""

from __future__ import annotations

import math

import numpy as np
import pytest

from protocol.codec import decode, encode
from protocol.messages import CUE_KINDS, NO_READING, AgentCommand, Perturbation, SensorFrame, WorldView
from tests.conftest import make, scenario, wait_until
from world_server.checkpoint import restore_world, world_state
from world_server.cues import sense_cues

SITE, SUPPLY = (CUE_KINDS.index(k) for k in CUE_KINDS)
# 9 x 5 cells; the agent starts at cell (1, 2), centre (1.5, 2.5); a brick at cell (7, 2).
LAYOUT = """
.........
.........
.A.....b.
.........
.........
"""


def cues(w, agent="a") -> np.ndarray:
    f = w.frame(agent)
    return np.array(f.cues).reshape(len(CUE_KINDS), f.sectors)


def mark(w, dx: float, dy: float, kind: str = "site", action: str = "mark", agent: str = "a") -> None:
    assert w.set_command(agent, 0.0, 0.0, action, (dx, dy, kind))
    w.step()


def test_a_world_without_cues_sends_no_cue_channel_and_ignores_marks():
    w = make(LAYOUT, sensor_noise=0.0)
    w.attach("a")
    mark(w, 2.0, 0.0)
    assert len(w.cues) == 0
    assert w.frame("a").cues == () and w.frame("a").cue_under == ""


def test_a_cue_is_sensed_where_it_lies_and_under_the_body():
    w = make(LAYOUT, sensor_noise=0.0, cue_reach=6.0)
    w.attach("a")
    assert (cues(w) == NO_READING).all()
    mark(w, 3.0, 1.0)                       # the cell (4, 1): centre (4.5, 3.5)
    assert w.cues.kind_at((4, 1)) == "site"
    x, y, _ = w.agent_poses()[0]
    d, bearing = math.hypot(4.5 - x, 3.5 - y), math.atan2(3.5 - y, 4.5 - x) % (2 * math.pi)
    reading = cues(w)
    sector = int(bearing * w.cfg.sensor_sectors / (2 * math.pi))
    assert reading[SITE, sector] == pytest.approx(d)
    assert (np.delete(reading[SITE], sector) == NO_READING).all() and (reading[SUPPLY] == NO_READING).all()
    assert w.frame("a").cue_under == ""
    mark(w, 0.0, 0.0, "supply")             # under the body itself
    assert w.frame("a").cue_under == "supply"
    assert cues(w)[SUPPLY].max() == pytest.approx(math.hypot(1.5 - x, 2.5 - y))


def test_unmark_takes_the_cue_off_and_marks_beyond_reach_or_on_walls_do_nothing():
    w = make("#" + LAYOUT.strip()[1:], sensor_noise=0.0, cue_reach=3.0)
    w.attach("a")
    mark(w, 2.0, 0.0)
    assert len(w.cues) == 1
    mark(w, 2.2, 0.1, action="unmark")      # the same cell
    assert len(w.cues) == 0
    mark(w, 4.0, 0.0)                       # beyond cue_reach
    mark(w, -1.0, 2.0)                      # the `#` cell (0, 0)
    mark(w, -2.0, 0.0)                      # outside the world
    assert len(w.cues) == 0


def test_a_cue_under_a_brick_is_covered():
    w = make(LAYOUT, sensor_noise=0.0, cue_reach=7.0)
    w.attach("a")
    mark(w, 6.0, 0.0)                       # the brick's cell (7, 2)
    assert len(w.cues) == 1
    assert (cues(w) == NO_READING).all()
    brick = int(np.flatnonzero(w.discs.kind == 2)[0])
    assert w.perturb(Perturbation("move", *w.discs.xy[brick], to_x=7.5, to_y=0.5)).ok
    w.step()
    assert cues(w)[SITE].max() == pytest.approx(6.0)


def test_cues_do_not_change_the_other_readings_nor_the_noise():
    plain = make(LAYOUT, sensor_noise=0.05, seed=3)
    cued = make(LAYOUT, sensor_noise=0.05, seed=3, cue_reach=6.0)
    for w in (plain, cued):
        w.attach("a")
    mark(cued, 2.0, 1.0)
    plain.set_command("a", 0.0, 0.0, "mark", (2.0, 1.0, "site"))
    plain.step()
    for _ in range(5):
        for w in (plain, cued):
            w.set_command("a", 2.0, 0.3, "none")
            w.step()
    assert plain.frame("a").ranges == cued.frame("a").ranges
    assert (cues(cued) >= 0).any()


def test_checkpoints_keep_the_cues():
    w = make(LAYOUT, sensor_noise=0.0, cue_reach=6.0)
    w.attach("a")
    mark(w, 2.0, 0.0)
    mark(w, 0.0, 2.0, "supply")
    back = restore_world(world_state(w))
    assert back.cues.items() == w.cues.items() and back.cfg.cue_reach == 6.0


def test_sense_cues_reports_the_nearest_per_kind_and_sector():
    agents = np.array([[0.0, 0.0], [50.0, 50.0]])
    cue_xy = np.array([[2.0, 0.1], [1.0, 0.05], [0.0, 3.0], [9.0, 0.0]])
    kinds = np.array([SITE, SITE, SUPPLY, SITE])
    out = sense_cues(agents, np.array([True, True]), cue_xy, kinds, 4, 6.0)
    assert out[0, SITE, 0] == pytest.approx(math.hypot(1.0, 0.05))
    assert out[0, SUPPLY, 1] == pytest.approx(3.0)
    assert (out[1] == NO_READING).all()


def test_the_cue_fields_cross_the_wire():
    frame = SensorFrame("a1", 3, 0.0, 0.0, 0.0, 2, (-1.0,) * 10, False, cues=(1.5, -1.0, -1.0, 0.5),
                        cue_under="supply")
    assert decode(encode(frame)) == frame
    cmd = AgentCommand("a1", 3, 1.0, 0.0, "mark", mark_dx=2.0, mark_dy=-1.0, mark_kind="supply")
    assert decode(encode(cmd)) == cmd
    with pytest.raises(ValueError, match="cues"):
        SensorFrame("a1", 3, 0.0, 0.0, 0.0, 2, (-1.0,) * 10, False, cues=(1.0,))
    with pytest.raises(ValueError, match="mark_kind"):
        AgentCommand("a1", 3, 1.0, 0.0, "mark", mark_kind="paint")


# --- what observers see (WorldView, issue 37 items 5-6) ------------------------------------------

def test_the_view_carries_every_cue_where_and_of_the_kind_it_lies_covered_ones_too():
    w = make(LAYOUT, sensor_noise=0.0, cue_reach=7.0)
    w.attach("a")
    mark(w, 3.0, 1.0)                       # the cell (4, 1): centre (4.5, 3.5)
    mark(w, 0.0, -2.0, "supply")            # the cell (1, 4): centre (1.5, 0.5)
    mark(w, 6.0, 0.0)                       # the brick's cell (7, 2): covered, not sensed, still drawn
    v = w.view()
    assert sorted(zip(v.cue_xs, v.cue_ys, v.cue_kinds)) == [(1.5, 0.5, "supply"), (4.5, 3.5, "site"),
                                                            (7.5, 2.5, "site")]
    assert decode(encode(v)) == v
    mark(w, 3.0, 1.0, action="unmark")
    assert (4.5, 3.5) not in set(zip(w.view().cue_xs, w.view().cue_ys))


def test_a_world_without_cues_shows_none_and_builds_none(monkeypatch):
    w = make(LAYOUT, sensor_noise=0.0)
    w.attach("a")
    mark(w, 2.0, 0.0)
    monkeypatch.setattr(type(w.cues), "arrays", lambda _self: pytest.fail("a world without cues built a cue list"))
    v = w.view()
    assert v.cue_xs == v.cue_ys == v.cue_kinds == ()


def test_the_view_message_round_trips_its_cues_and_refuses_bad_ones():
    v = WorldView("w0", 10, 9.0, 5.0, (), (), (), (), (), (), (), (), (), (), (), (), (), (),
                  cue_xs=(4.5, 1.5), cue_ys=(3.5, 0.5), cue_kinds=("site", "supply"))
    assert decode(encode(v)) == v
    with pytest.raises(ValueError, match="cue_kinds"):
        WorldView("w0", 10, 9.0, 5.0, (), (), (), (), (), (), (), (), (), (), (), (), (), (),
                  cue_xs=(4.5,), cue_ys=(3.5,), cue_kinds=("paint",))
    with pytest.raises(ValueError, match="cue_ys"):
        WorldView("w0", 10, 9.0, 5.0, (), (), (), (), (), (), (), (), (), (), (), (), (), (),
                  cue_xs=(4.5,), cue_ys=(), cue_kinds=("site",))


def test_a_world_with_cues_publishes_them_to_a_viewer_on_the_bus(bus, start_world):
    from agent_runtime.world_link import WorldLink
    from conag.viewer.server import LiveFeed

    start_world(scenario(LAYOUT, sensor_noise=0.0, cue_reach=6.0), view_every=5)
    feed = LiveFeed(bus.client_session(), "w0").start()
    link = WorldLink(bus.client_session(), "w0", "a")
    try:
        frame = link.next_frame(link.attach(timeout=10.0).tick - 1, timeout=10.0)
        marks = [(3.0, 1.0, "site"), (0.0, -2.0, "supply")] + [None] * 10
        for m in marks:
            link.send(frame.tick, 0.0, 0.0, "mark" if m else "none", m)
            frame = link.next_frame(frame.tick, timeout=10.0)
            assert frame is not None
        view = wait_until(lambda: feed.scene.view if feed.scene.view and feed.scene.view.tick >= 10 else None,
                          what="a view after the marks")
        assert sorted(zip(view.cue_xs, view.cue_ys, view.cue_kinds)) == [(1.5, 0.5, "supply"), (4.5, 3.5, "site")]
        assert sorted(feed.scene.picture()["cues"]) == [[1.5, 0.5, "supply"], [4.5, 3.5, "site"]]
    finally:
        link.close()
        feed.close()
