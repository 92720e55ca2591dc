"""The reactive worker (agent_runtime/worker.py): its rules on hand-made frames, and a worker
in a world that fills a site a cue marks, taking bricks only by a supply cue."""

from __future__ import annotations

import math

import numpy as np

from agent_runtime.worker import Worker, WorkerConfig
from protocol.messages import CHANNELS, CUE_KINDS, NO_READING, SensorFrame
from tests.conftest import make

S = 16
BRICK, WALL = CHANNELS.index("brick"), CHANNELS.index("obstacle")
SITE, SUPPLY = CUE_KINDS.index("site"), CUE_KINDS.index("supply")


def sector(angle: float) -> int:
    return int((angle % (2 * math.pi)) / (2 * math.pi / S))


def frame(heading=0.0, holding=False, under="", bricks=(), sites=(), supplies=(), walls=()) -> SensorFrame:
    """A frame with bricks / walls / cues at (angle, distance)."""
    ranges = np.full((len(CHANNELS), S), NO_READING)
    cues = np.full((len(CUE_KINDS), S), NO_READING)
    for grid, ch, items in ((ranges, BRICK, bricks), (ranges, WALL, walls), (cues, SITE, sites),
                            (cues, SUPPLY, supplies)):
        for angle, d in items:
            grid[ch, sector(angle)] = d
    return SensorFrame("w1", 5, heading, 0.0, 0.0, S, tuple(ranges.ravel()), holding,
                       cues=tuple(cues.ravel()), cue_under=under)


def worker() -> Worker:
    w = make("....\n.A..\n....", cue_reach=5.0)
    return Worker(w.attach("w1"), rng=np.random.default_rng(0))


def test_it_drops_a_held_brick_on_a_site_cue_and_then_backs_off():
    w = worker()
    assert w.step(frame(holding=True, under="site")).action == "drop"
    after = w.step(frame(holding=False))
    assert after.action == "none" and after.behaviour == "avoid"
    assert w.step(frame(holding=True, under="supply")).action != "drop"


WANTED = [(math.pi, 5.0)]   # a site cue in sight, behind: some site wants a brick


def test_it_grabs_only_a_brick_by_a_supply_cue():
    w = worker()
    near_supply = frame(bricks=[(0.1, 1.0)], supplies=[(0.1, 2.0)], sites=WANTED)
    assert w.step(near_supply).action == "grab"
    nowhere = frame(bricks=[(0.1, 1.0)], sites=WANTED)
    far_from_supply = frame(bricks=[(0.1, 1.0)], supplies=[(math.pi, 4.0)], sites=WANTED)
    for f in (nowhere, far_from_supply):
        assert worker().step(f).action != "grab"


def test_it_takes_no_brick_unless_it_saw_a_site_cue_lately():
    # Thirty idle workers each holding a brick can hold every brick the foremen need.
    by_supply = frame(bricks=[(0.1, 1.0)], supplies=[(0.1, 2.0)])
    assert worker().step(by_supply).action == "grab"           # a new worker takes one
    w = worker()
    for _ in range(w.cfg.demand_ticks):
        w.step(frame())
    assert w.step(by_supply).action != "grab"                  # no site cue for too long
    w.step(frame(sites=WANTED))
    assert w.step(by_supply).action == "grab"                  # one was in sight a step ago


def test_a_brick_no_site_wants_goes_back_beside_a_supply_cue_not_on_it():
    w = worker()
    for _ in range(w.cfg.return_ticks - 1):
        assert w.step(frame(holding=True)).action != "drop"      # wanders with it a while
    far = w.step(frame(holding=True, supplies=[(0.1, 3.0)]))
    assert far.action == "none" and far.behaviour == "config_nav" and far.speed > 0
    assert w.step(frame(holding=True, supplies=[(0.1, 0.3)])).action != "drop"   # on the cue
    assert w.step(frame(holding=True, supplies=[(0.1, 1.0)])).action == "drop"  # beside it
    assert w.returns == 1 and w.drops == 0
    loaded = worker()
    loaded.step(frame(holding=True, sites=WANTED))
    for _ in range(50):   # a site cue seen lately: it keeps the brick and looks for the site
        assert loaded.step(frame(holding=True, supplies=[(0.1, 1.0)])).action != "drop"


def test_holding_it_heads_for_the_nearest_site_cue():
    w = worker()
    s = w.step(frame(heading=0.0, holding=True, sites=[(math.pi / 2 + 0.1, 3.0), (math.pi + 0.1, 5.0)]))
    assert s.behaviour == "config_nav" and s.turn > 0.5     # turning north, to the nearer cue


def test_in_a_world_a_worker_fills_the_marked_site_from_the_supply():
    # Bricks west, a site east; cues put as a foreman would: supply beside the bricks, site on the site.
    w = make("""
..........
.bb.......
.bb...A.+.
..........
..........
""", sensor_noise=0.02, cue_reach=9.0)
    welcome = w.attach("w1")
    mind = Worker(welcome, rng=np.random.default_rng(3))
    w.cues.place((3, 2), "supply")
    w.cues.place((8, 2), "site")
    w.step()
    for _ in range(1500):
        if w.completed():
            break
        s = mind.step(w.frame("w1"))
        w.set_command("w1", s.speed, s.turn, s.action)
        w.step()
    assert w.completed()
    assert w.status().agent_grabs == (1,)   # one brick taken, the one that filled the site


def test_in_a_world_a_worker_brings_a_brick_nobody_wants_back_to_the_supply():
    # No site cue anywhere: the brick it holds must end beside the supply cue, which stays
    # uncovered (a covered cue is seen by nobody), and not where the worker happened to be.
    w = make("""
............
............
..Ab........
............
............
............
""", sensor_noise=0.02, cue_reach=9.0)
    welcome = w.attach("w1")
    w.set_command("w1", 0.0, 0.0, "grab")
    w.step()
    assert w.agents["w1"].holding >= 0
    brick = w.agents["w1"].holding
    mind = Worker(welcome, rng=np.random.default_rng(5))
    w.cues.place((8, 3), "supply")
    for _ in range(2000):
        if w.agents["w1"].holding < 0:
            break
        s = mind.step(w.frame("w1"))
        w.set_command("w1", s.speed, s.turn, s.action)
        w.step()
    assert w.agents["w1"].holding < 0 and mind.returns == 1
    col, row = w.scenario.to_cell(w.discs.xy[brick][None])[0]   # the cue's cell is (col 8, row 3)
    assert max(abs(col - 8), abs(row - 3)) == 1                 # in a cell beside the cue's
    assert w.frame("w1").cues[SUPPLY * S:(SUPPLY + 1) * S] != (NO_READING,) * S   # still seen


def idle_worker() -> Worker:
    """A worker that has seen no site cue for demand_ticks (and, its frames carrying no
    odometry, is never stuck)."""
    w = make("....\n.A..\n....", cue_reach=5.0)
    idle = Worker(w.attach("w1"), WorkerConfig(stuck_ticks=100_000), rng=np.random.default_rng(0))
    for _ in range(idle.cfg.demand_ticks):
        idle.step(frame())
    return idle


def test_an_idle_worker_with_no_wall_in_sight_walks_until_it_sees_one():
    idle = idle_worker()
    steps = [idle.step(frame()) for _ in range(200)]
    assert all(s.behaviour == "explore" for s in steps) and sum(s.speed > 0 for s in steps) > 50

def test_an_idle_worker_parks_beside_a_wall_out_of_the_way():
    # Idle bodies in the open stand where foremen walk; along a wall nobody's way runs.
    idle = idle_worker()
    towards = idle.step(frame(walls=[(0.1, 4.0)]))
    assert towards.speed > 0 and abs(towards.turn) < 0.3          # walks to the wall ahead
    assert all(idle.step(frame(walls=[(0.1, 1.0)])).speed == 0 for _ in range(200))   # and stays by it
    busy = worker()
    busy.step(frame(sites=WANTED))
    moves = [busy.step(frame(walls=[(0.1, 1.0)])).speed > 0 for _ in range(100)]
    assert any(moves)                                              # a worker with work does not park
