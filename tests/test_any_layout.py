"""Issue 10's failure classes, each on a layout written for it (tests/layouts/), plus the
core pieces behind the fixes: the far memory, the seeded field, the obstacle channel,
Explore as the default and backing off when stuck."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent_runtime.brain import Brain, _mouth_side
from agent_runtime.config import AgentConfig
from agent_runtime.esm import BRICK, CONFIG, FOOD, OBSTACLE, WATER
from agent_runtime.far_memory import FarMemory, border_seed
from agent_runtime.sealing import FRESH_SITE, SEAL_MEMORY, enclosed_sites, pocket_beside
from agent_runtime.spreading import distance_field, seeded_distance_field
from conag import sim
from protocol.messages import BEHAVIOURS, CHANNELS, NO_READING, SensorFrame, Welcome
from world_server.discs import BRICK_DISC
from world_server.scenario import load_scenario, parse_scenario
from world_server.world import World

LAYOUTS = Path(__file__).resolve().parent / "layouts"
OBST = CHANNELS.index("obstacle")


def _build(name: str, ticks: int, **cfg) -> sim.SimRun:
    run = sim.start(load_scenario(LAYOUTS / f"{name}.toml"), cfg=AgentConfig(**cfg))
    run.run(ticks)
    return run


def _status(run: sim.SimRun):
    return run.world.status()


def _assert_builds(name: str, ticks: int, **cfg) -> sim.SimRun:
    """Build tests/layouts/NAME.toml in process for up to `ticks`; it must complete."""
    run = _build(name, ticks, **cfg)
    st = _status(run)
    assert st.completed, f"{st.sites_filled}/{st.sites_total} at tick {st.tick}"
    return run


# ------------------------------------------------------------------ the failure classes, end to end

@pytest.mark.slow
@pytest.mark.parametrize("sequencing", [True, False], ids=["goal-sequencing", "nearest-first"])
def test_a_blueprint_beyond_the_map_at_attach_is_built(sequencing):
    # Before: the agents never learned the blueprint and stood still (distance 0) to the limit.
    _assert_builds("far_blueprint", 12000, goal_sequencing=sequencing)


@pytest.mark.slow
def test_the_far_side_of_a_ring_is_not_forgotten_while_fetching_bricks():
    # Before: 18 of 25 sites after 60,000 ticks, one agent idle and two wandering.
    _assert_builds("ring_pillar", 12000)


@pytest.mark.slow
def test_agents_route_through_the_gaps_of_a_wall_they_sense():
    # Before: an agent carrying a brick pushed against a `#` wall it could not see.
    _assert_builds("hash_walls", 20000)


@pytest.mark.slow
def test_two_agents_at_the_end_of_an_edge_wall_do_not_livelock():
    # Before: two agents spent thousands of ticks avoiding each other at the wall's end.
    run = _assert_builds("edge_wall_livelock", 15000)
    for brain in run.brains.values():
        assert brain.behaviour_ticks["avoid"] < 1000


@pytest.mark.slow
def test_a_food_corridor_is_filled_from_its_far_end_and_never_sealed():
    # Before: 3 of 11 sites. The agent at the mouth saw ways out sideways where the walls'
    # far discs hide behind the near ones, filled the mouth and sealed the rest.
    _assert_builds("food_corridor", 8000)


@pytest.mark.slow
def test_pockets_beside_structure_bricks_are_not_sealed_over_a_ghost():
    # Before: 24 of 25 sites. A ghost brick on a deep open site (a structure brick beside it
    # seen at the same distance) was never cleared, and the mouth was filled over it.
    _assert_builds("twin_pockets", 8000)


@pytest.mark.slow
def test_one_cell_slots_between_water_walls_are_not_shut_by_far_wall_discs():
    # Before: 32 of 36 sites at tick 20,000, 1,552 ticks in avoid_red (holding a brick, no
    # open site reachable): far wall discs mapped a cell to the side closed slots for good.
    run = _assert_builds("water_slots", 20000)
    assert run.brains["a1"].behaviour_ticks["avoid_red"] < 300


def test_a_mouth_site_waits_while_the_site_behind_it_is_open_on_seen_ground():
    # A corridor of food one cell wide, its far walls unseen: filling the mouth would cut
    # the deeper sites off on the ground the agent has seen, so it is no goal; the deepest is.
    brain = Brain(_welcome(), AgentConfig(), np.random.default_rng(0))
    n, c = brain.cfg.map_size, brain.centre
    goals = np.zeros((n, n), bool)
    open_sites = goals.copy()
    open_sites[c, c:c + 4] = True                       # the agent stands at the mouth
    brain.maps.clear_age[open_sites] = 0.0              # and sees the corridor empty
    goals[c, c] = goals[c, c + 3] = True
    blocked = np.zeros((n, n), bool)
    blocked[[c - 1, c + 1], c:c + 2] = True             # the walls it has seen
    blocked[c, c + 4] = True                            # the corridor's end
    brain.maps.known[:, :c + 1] = True                  # seen ground: west of the agent only
    supply = np.zeros((n, n), bool)
    supply[c, c - 8] = True
    unsafe = brain.seals.judge(goals, open_sites, blocked, supply)
    assert unsafe[c, c] and not unsafe[c, c + 3]        # the far end is not near: not checked
    brain.maps.known[:] = True                          # seen open all round: no seal
    assert not brain.seals.judge(goals, open_sites, blocked, supply).any()


def _corridor_with_a_far_way_out() -> tuple[Brain, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The agent at the mouth of a one-cell corridor of five open sites between walls; the
    last site opens onto ground that leads round to the supply. All ground seen; no site
    seen empty yet. Returns the brain and the sealing inputs (goals, open, blocked, supply)."""
    brain = Brain(_welcome(), AgentConfig(), np.random.default_rng(0))
    n, c = brain.cfg.map_size, brain.centre
    open_sites = np.zeros((n, n), bool)
    open_sites[c, c:c + 5] = True
    goals = np.zeros((n, n), bool)
    goals[c, c] = True                                  # the mouth, where the agent stands
    blocked = np.zeros((n, n), bool)
    blocked[[c - 1, c + 1], c:c + 5] = True             # the corridor's walls
    brain.maps.known[:] = ~blocked
    supply = np.zeros((n, n), bool)
    supply[c, c - 8] = True
    return brain, goals, open_sites, blocked, supply


@pytest.mark.parametrize("far_end_seen_ago, mouth_seals", [(5, False), (FRESH_SITE + 50, True)])
def test_an_open_site_not_seen_lately_is_no_way_through(far_end_seen_ago, mouth_seals):
    # The corridor's far-end site was the other way in. Seen empty lately, it is, and the
    # mouth may be filled. Not seen for a while, another agent (or the world before a
    # restart) may have filled it: the mouth would seal the corridor, so it waits. Before,
    # a stale belief let an agent fill a ring's last gap with a site inside still open
    # (nested_squares, two agents cut off for ten seconds and back with new brains).
    brain, goals, open_sites, blocked, supply = _corridor_with_a_far_way_out()
    c = brain.centre
    brain.maps.clear_age[open_sites] = 0.0
    brain.maps.clear_age[c, c + 4] = far_end_seen_ago
    assert brain.seals.judge(goals, open_sites, blocked, supply)[c, c] == mouth_seals


def test_inside_a_corridor_whose_exit_was_not_seen_lately_the_deeper_sites_still_count():
    # The agent stands inside a one-cell corridor of sites, its deep end shut, its exit (a
    # site) out of sight behind it for a while: judged strictly, the inside reaches nothing.
    # Judged on every cell not known blocked, the unseen ground beside the deep end let the
    # deeper sites out, and the agent filled its site, sealing them (gen-pocket 031, nine
    # agents: stalled at 11/15). With the open sites passable first, its site waits.
    brain = Brain(_welcome(), AgentConfig(), np.random.default_rng(0))
    n, c = brain.cfg.map_size, brain.centre
    open_sites = np.zeros((n, n), bool)
    open_sites[c, c - 4:c + 5] = True
    brain.maps.clear_age[open_sites] = 0.0
    brain.maps.clear_age[c, c + 4] = FRESH_SITE + 10     # the exit: behind the agent
    goals = np.zeros((n, n), bool)
    goals[c, c] = True
    blocked = np.zeros((n, n), bool)
    blocked[[c - 1, c + 1], c - 5:c + 5] = True
    blocked[c, c - 5] = True                            # the deep end
    brain.maps.known[:] = ~blocked
    brain.maps.known[c - 3:c - 1, c - 6:c] = False       # beside the deep end: never seen
    blocked[c - 1, c - 5:c] = False                     # ... nor the wall there
    brain.maps.known[c - 1, c - 5:c] = False
    supply = np.zeros((n, n), bool)
    supply[c, c + 10] = True
    assert brain.seals.judge(goals, open_sites, blocked, supply)[c, c]


def test_a_brain_that_knows_nothing_beyond_the_sites_fills_none_near_it():
    # A brain made on re-attaching (its world restored from a checkpoint) stands on a site
    # with a brick in its gripper and has seen nothing but the cells round it: no supply, no
    # ground beyond the checked square. It cannot tell a ring's last gap from any site, so
    # none near is filled until it has seen more. Before, it dropped at once and walled
    # itself inside a ring with a site still open (nested_squares under `python3 -m faults.chaos`).
    brain, goals, open_sites, blocked, _ = _corridor_with_a_far_way_out()
    c = brain.centre
    brain.maps.clear_age[open_sites] = 0.0
    nothing = np.zeros_like(goals)
    brain.maps.known[:] = False
    brain.maps.known[c - 2:c + 3, c - 2:c + 3] = ~blocked[c - 2:c + 3, c - 2:c + 3]
    assert brain.seals.judge(goals, open_sites, blocked, nothing)[c, c]
    brain.maps.known[:] = ~blocked                      # it has looked round: a way out at the far end
    assert not brain.seals.judge(goals, open_sites, blocked, nothing).any()


def test_a_site_walled_in_by_a_ghost_keeps_the_way_it_would_have():
    # A ring of sites in the world's corner; the agent stands on its last gap (south middle).
    # Its map shows the north-west corner open but walled in by structure bricks, one of them
    # a ghost: the site is a contradiction, so the gap waits until the agent has seen which.
    brain = Brain(_welcome(), AgentConfig(), np.random.default_rng(0))
    n, c = brain.cfg.map_size, brain.centre
    m = brain.maps.maps
    ring = [(r, k) for r in range(c - 2, c + 1) for k in range(c - 1, c + 2) if (r, k) != (c - 1, c)]
    for r, k in ring:
        m[CONFIG, r, k] = 1.0
        m[BRICK, r, k] = float((r, k) not in ((c - 2, c - 1), (c, c)))
    m[OBSTACLE, c - 3, c - 2:c + 3] = m[OBSTACLE, c - 3:c + 2, c - 2] = 1.0   # the world's corner
    brain.maps.known[:] = True
    brain.maps.clear_age[(m[CONFIG] > 0.5) & (m[BRICK] <= 0.5)] = 0.0   # the open sites, seen empty
    goals = np.zeros((n, n), bool)
    goals[c, c] = True
    supply = np.zeros((n, n), bool)
    supply[c + 8, c] = True

    def unsafe():
        layers = m > 0.5
        blocked = layers[OBSTACLE] | (layers[BRICK] & layers[CONFIG])
        return brain.seals.judge(goals, layers[CONFIG] & ~layers[BRICK], blocked, supply)[c, c]

    assert unsafe()
    m[BRICK, c - 2, c - 1] = 1.0        # seen filled after all: the gap may close
    assert not unsafe()


def test_a_site_no_path_reaches_is_not_beside_a_mouth():
    held = np.zeros((5, 5), bool)
    held[2, 2] = True
    sites = np.zeros((5, 5), bool)
    sites[2, 1] = sites[2, 3] = True
    depth = np.full((5, 5), 3.0)
    depth[2, 3] = 4.0                                   # deeper: stays a goal
    assert _mouth_side(held, sites, depth).tolist() == (np.arange(25).reshape(5, 5) == 11).tolist()
    depth[2, 1] = np.inf                                # behind closed sites: no depth
    assert not _mouth_side(held, sites, depth).any()


# ------------------------------------------------------------------ obstacles are sensed and mapped

WALLED = """
.......
...#...
.A.#.+.
...#...
.b.....
"""


def _scenario(layout: str, agents: int = 1, **world):
    extra = "".join(f"{k} = {v}\n" for k, v in world.items())
    return parse_scenario(f'name = "t"\nseed = 1\nagents = {agents}\nlayout = """{layout}"""\n[world]\n{extra}')


def test_fixed_walls_and_the_world_edge_are_on_the_obstacle_channel():
    w = World(_scenario(WALLED, sensor_noise=0.0), np.random.default_rng(0))
    w.attach("a")
    r = np.array(w.frame("a").ranges).reshape(len(CHANNELS), -1)
    # The wall's nearest cell is 2 cells east (sector 0 or 15 by the border), the west edge
    # ring cell is 2 cells west (sector 7 or 8).
    def nearest(sectors):
        return min(v for v in r[OBST][sectors] if v >= 0)
    assert nearest([0, 15]) == pytest.approx(2.0)
    assert nearest([7, 8]) == pytest.approx(2.0)
    # Nothing else reports them.
    assert np.all(r[CHANNELS.index("food")] == NO_READING)


def test_the_agent_maps_walls_and_plans_around_them():
    run = sim.start(_scenario(WALLED, sensor_noise=0.0))
    run.step()
    brain = run.brains["a1"]
    c = brain.centre
    walls = {(int(r) - c, int(col) - c) for r, col in zip(*np.nonzero(brain.maps.maps[OBSTACLE] > 0.5))}
    assert {(-1, 2), (0, 2), (1, 2)} <= walls   # the three `#` cells east of the agent
    plans = brain.plan()
    assert np.all(np.isinf(plans.config[brain.maps.maps[OBSTACLE] > 0.5]))


# ------------------------------------------------------------------ Explore is the default

def _welcome(sites=((),()), x=50.5, y=50.5) -> Welcome:
    return Welcome(world_id="w", agent_id="a1", body=0, tick=0, x=x, y=y, heading=0.0, holding=False,
                   restarts=0, sectors=16, sensor_range=6.0, cell_size=1.0,
                   site_xs=tuple(sites[0]), site_ys=tuple(sites[1]))


def _frame(tick: int, dx: float = 0.0, dy: float = 0.0, holding: bool = False) -> SensorFrame:
    return SensorFrame(agent_id="a1", tick=tick, heading=0.0, odom_dx=dx, odom_dy=dy, sectors=16,
                       ranges=(NO_READING,) * (16 * len(CHANNELS)), holding=holding)


def test_an_agent_with_nothing_on_its_maps_explores():
    brain = Brain(_welcome(([80.5], [50.5])), AgentConfig(), np.random.default_rng(0))
    step = brain.step(_frame(1))
    assert step.behaviour == "explore" and step.speed > 0


def _bricks(frame: SensorFrame) -> np.ndarray:
    """The frame's brick readings, one per sector, in cells (the test worlds' cells are 1.0)."""
    return np.asarray(frame.ranges).reshape(len(CHANNELS), frame.sectors)[CHANNELS.index("brick")]


def _ring_gap_welcome() -> Welcome:
    """An agent of radius 0.3 among discs of radius 0.5 (a body and a brick touch 0.8 apart),
    one site 10 cells east: the agent of the ring's-last-gap tests."""
    return replace(_welcome(([60.5], [50.5])), agent_radius=0.3, disc_radius=0.5)


def _ring_pocket_south(brain: Brain, closed: bool = True) -> tuple[int, int]:
    """Bricks on the brain's map round the cell south of it, open only through the agent's
    own cell (the centre of a ring whose last gap the agent stands in); `closed=False`
    leaves a second way in from the south. Returns the pocket cell."""
    c = brain.centre
    brick = brain.maps.maps[BRICK]
    for r, col in ((c, c - 1), (c, c + 1), (c + 1, c - 1), (c + 1, c + 1), (c + 2, c - 1), (c + 2, c + 1)):
        brick[r, col] = 1.0
    if closed:
        brick[c + 2, c] = 1.0
    return c + 1, c


def test_pocket_beside_is_what_a_brick_on_the_cell_would_close():
    blocked = np.zeros((9, 9), bool)
    blocked[5, 3] = blocked[5, 5] = blocked[6, 3] = blocked[6, 5] = blocked[7, 4] = True
    blocked[4, 3] = blocked[4, 5] = True
    pocket = pocket_beside(blocked, (4, 4))
    assert pocket[5, 4] and pocket[6, 4] and pocket.sum() == 2
    blocked[7, 4] = False                                 # a second way in: no pocket
    assert not pocket_beside(blocked, (4, 4)).any()
    blocked[7, 4] = True
    assert not pocket_beside(blocked, (0, 0)).any()       # nothing walled in beside that cell
    # A map that holds the whole world: its border lies beyond the world's edge, blocked, so
    # no cell reaches it. The pocket is still only the ring's inside, not the world round it
    # (nested_squares on a 41-cell map: the guard found everything a pocket and did nothing).
    walled = np.pad(blocked, 2, constant_values=True)
    pocket = pocket_beside(walled, (6, 6))
    assert pocket[7, 6] and pocket[8, 6] and pocket.sum() == 2
    walled[9, 6] = False                                  # a second way in: no pocket
    assert not pocket_beside(walled, (6, 6)).any()


def test_an_agent_leaves_a_brick_it_dropped_on_the_side_away_from_the_pocket_it_closes():
    # It stands on the brick it just dropped in a ring's last gap, the ring's inside to the
    # south. Whatever its behaviour asks (here: due south, into the ring), it heads north:
    # once off the brick, the brick holds, and inside it would be shut in for good
    # (nested_squares, its world killed and restored, stalled at 31/32 in CI).
    welcome = _ring_gap_welcome()
    brain = Brain(welcome, AgentConfig(), np.random.default_rng(0))
    brain.step(_frame(1))
    south = (1.0, -math.pi / 2)          # (speed, turn) as steering gives them: heading east, turn right
    _ring_pocket_south(brain)
    dropped = SensorFrame(**{**_brick_north(2, 0.1).__dict__, "dropped": True})   # on its brick
    speed, turn = brain._off_own_brick(dropped, _bricks(dropped), *south)
    assert turn > 0 and speed >= 0         # turns left, to the north
    # With a second way into the ring there is no pocket: the behaviour's move stands.
    brain = Brain(welcome, AgentConfig(), np.random.default_rng(0))
    brain.step(_frame(1))
    _ring_pocket_south(brain, closed=False)
    assert brain._off_own_brick(dropped, _bricks(dropped), *south) == south
    # Off the brick (more than a body and a brick's radius away), nothing is overridden.
    brain = Brain(welcome, AgentConfig(), np.random.default_rng(0))
    brain.step(_frame(1))
    brain._dropped_at = np.array([0.0, 3.0]) + brain._odo
    _ring_pocket_south(brain)
    assert brain._off_own_brick(_frame(2), _bricks(_frame(2)), *south) == south and brain._dropped_at is None


def _brick_north(tick: int, distance: float) -> SensorFrame:
    """A frame whose one brick reading is `distance` cells due north (sector 4 of 16)."""
    ranges = [NO_READING] * (16 * len(CHANNELS))
    ranges[CHANNELS.index("brick") * 16 + 4] = distance
    return SensorFrame(**{**_frame(tick).__dict__, "ranges": tuple(ranges)})


def test_a_brain_started_on_a_brick_its_body_dropped_leaves_it_away_from_the_pocket():
    # A process started again (or a world resumed) while the body still stood on the brick
    # it had dropped in a ring's last gap: the new brain never saw the drop. A brick nearer
    # than touching can only be that one, so it heads north, out of the ring, all the same
    # (a lone agent restarted in that moment under `python3 -m faults.chaos` was shut in at 30/32).
    south = (1.0, -math.pi / 2)
    welcome = _ring_gap_welcome()   # touching: 0.8 apart
    brain = Brain(welcome, AgentConfig(), np.random.default_rng(0))
    brain.step(_frame(1))
    _ring_pocket_south(brain)
    on = _brick_north(2, 0.3)
    speed, turn = brain._off_own_brick(on, _bricks(on), *south)
    assert turn > 0 and speed >= 0
    # A brick that only touches the body (or further off) is not underfoot: nothing changes.
    brain = Brain(welcome, AgentConfig(), np.random.default_rng(0))
    brain.step(_frame(1))
    _ring_pocket_south(brain)
    touching = _brick_north(2, 0.8)
    assert brain._off_own_brick(touching, _bricks(touching), *south) == south and brain._dropped_at is None


def test_a_body_off_its_dropped_brick_is_not_steered_back_through_it():
    # It dropped a brick in a ring's last gap and stepped into the ring, 1.1 cells past the
    # brick: no brick overlaps the body, so the world has made that brick solid again, and
    # heading out through it would press into it for good (with brains restarted at every
    # drop, a lone agent in nested_squares did that from tick 380 on, at 6/32). The
    # behaviour's move stands, there and when the body comes back against the brick.
    south = (1.0, -math.pi / 2)
    welcome = _ring_gap_welcome()   # off it: 0.8 apart
    brain = Brain(welcome, AgentConfig(), np.random.default_rng(0))
    brain.step(_frame(1))
    _ring_pocket_south(brain)
    dropped = SensorFrame(**{**_brick_north(2, 0.1).__dict__, "dropped": True})
    speed, turn = brain._off_own_brick(dropped, _bricks(dropped), *south)
    assert turn > 0 and speed >= 0 and brain._dropped_at is not None     # still on it: out of the ring, north
    off = _brick_north(3, 1.1)
    assert brain._off_own_brick(off, _bricks(off), *south) == south and brain._dropped_at is None
    pressing = _brick_north(4, 0.79)
    assert brain._off_own_brick(pressing, _bricks(pressing), *south) == south and brain._dropped_at is None


RING_GAP = """
.............
.b.b.....b.b.
.............
....BBB......
....B.B......
....B+B......
.............
.A...........
.b.b.....b.b.
.............
"""


@pytest.mark.parametrize("new_brain_after", [0, 1, 3])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_an_agent_restarted_on_the_brick_that_closed_a_ring_ends_outside_it(seed, new_brain_after):
    # The ring's last gap is site (5, 5), its inside cell (5, 4) to the north. The agent
    # drops its brick there, 0.2 cells in from the site's centre, and its process is started
    # again 0..3 ticks later, the body still on the brick (the world lets it pass until it is
    # off). The new brain steps off on the outside: with the old code it walked into the
    # ring in 3 of these 9 cases (all of seed 2) and was shut in for good.
    run = sim.start(_scenario(RING_GAP), seed=seed)
    w = run.world
    rec, sc = w.agents["a1"], w.scenario
    brick = int(np.flatnonzero(w.discs.kind == BRICK_DISC)[0])  # a free brick (top left)
    w.discs.carry(brick)
    w.physics.remove_disc(brick)
    rec.holding = brick
    w.physics.place_body(rec.index, sc.to_world([(5, 5)])[0] + (0.0, 0.2))
    w.set_command("a1", 0.0, 0.0, "drop")
    w.step()
    assert w.sites_filled().all()
    for _ in range(new_brain_after):
        run.step()
    w.detach("a1")
    run.brains["a1"] = Brain(w.attach("a1"), None, np.random.default_rng([seed, 1]))
    for _ in range(200):
        run.step()
    cell = sc.to_cell(w.physics.state()[0][rec.index][None])[0]
    assert (int(cell[0]), int(cell[1])) != (5, 4), "the agent is shut inside the ring"


# ------------------------------------------------------------------ stuck agents back off

def test_an_agent_without_headway_backs_off_for_a_bounded_while():
    cfg = AgentConfig(stuck_ticks=40)
    brain = Brain(_welcome(([60.5], [50.5])), cfg, np.random.default_rng(3))
    behaviours = [brain.step(_frame(t, holding=True)).behaviour for t in range(1, 200)]
    # Pinned in place (odometry 0) while it wants to move: it backs off, and not for ever.
    first = behaviours.index("unstick")
    assert first == cfg.stuck_ticks   # the window is full after stuck_ticks steps
    run = next(i for i in range(first, len(behaviours)) if behaviours[i] != "unstick") - first
    assert cfg.stuck_ticks // 4 <= run <= cfg.stuck_ticks // 2
    assert brain.unsticks >= 2   # still pinned afterwards: it tries again


def test_an_agent_that_moves_never_backs_off():
    brain = Brain(_welcome(([60.5], [50.5])), AgentConfig(stuck_ticks=40), np.random.default_rng(3))
    for t in range(1, 200):
        assert brain.step(_frame(t, dx=0.2 if (t // 60) % 2 == 0 else -0.2)).behaviour != "unstick"


# ------------------------------------------------------------------ the far memory

def test_sites_beyond_the_map_stay_known_and_pull_the_agent_towards_them():
    brain = Brain(_welcome(([90.5, 91.5], [50.5, 50.5])), AgentConfig(map_size=21), np.random.default_rng(0))
    assert brain.maps.maps[CONFIG].sum() == 0          # 40 cells east: not on a 21-cell map
    brain.step(_frame(1, holding=True))
    plans = brain.plans
    c = brain.centre
    assert np.isfinite(plans.config[c, c])             # a drop site is available ...
    assert plans.config[c, c] == pytest.approx(40.0)   # ... 40 cells away, through the border
    assert plans.config[c, c + 1] < plans.config[c, c]  # and the way is east


def test_a_site_that_scrolls_off_the_map_comes_back_in_its_cell():
    brain = Brain(_welcome(([52.5], [50.5])), AgentConfig(map_size=11), np.random.default_rng(0))
    for t in range(1, 41):                              # 8 cells west
        brain.perceive(_frame(t, dx=-0.2))
    assert brain.maps.maps[CONFIG].sum() == 0           # 10 cells east of a radius-5 map
    brain.far.site_open[:] = False                      # believed filled (say, seen so)
    brain.perceive(_frame(41))
    assert brain.far.open_sites() == 0                  # out of sight: the belief stands
    for t in range(42, 82):                             # 8 cells east, back where it started
        brain.perceive(_frame(t, dx=0.2))
    r, col = np.argwhere(brain.maps.maps[CONFIG] > 0.5)[0]
    assert (r - brain.centre, col - brain.centre) == (0, 2)
    assert brain.far.open_sites() == 1                  # in sensor range and seen empty: open again


def test_bricks_that_leave_the_map_are_remembered_and_come_back():
    mem = FarMemory(5, np.zeros((0, 2)))
    free = np.zeros((5, 5), bool)
    free[2, 4] = True                       # a brick 2 cells east of the centre
    for _ in range(3):                      # walk 3 cells west: it leaves on the east side
        back = mem.move(-1, 0, free)
        free = np.zeros((5, 5), bool)
        assert not back.any()
    assert mem.bricks.tolist() == [[2, 0]]
    assert mem.far_bricks().tolist() == [[2, 7]]   # row 2, col 7: beyond the east border
    back = mem.move(1, 0, free)                    # one step east: col 6, still off
    back = mem.move(1, 0, free)                    # col 5 -> still off (cols 0-4)
    back = mem.move(1, 0, free)                    # col 4: on the map again
    assert back[2, 4] and len(mem.bricks) == 0


def test_without_far_memory_a_site_that_scrolls_off_the_map_is_forgotten():
    # The paper's maps (far_memory off): what shifts off them is gone, and nothing beyond
    # them pulls the agent; with far memory the same walk brings the site back (above).
    for far_memory in (True, False):
        brain = Brain(_welcome(([52.5], [50.5])), AgentConfig(map_size=11, far_memory=far_memory),
                      np.random.default_rng(0))
        assert brain.maps.maps[CONFIG][brain.centre, brain.centre + 2] == 1.0
        for t in range(1, 41):                              # 8 cells west: the site leaves
            brain.perceive(_frame(t, dx=-0.2))
        brain.step(_frame(41, holding=True))
        c = brain.centre
        assert np.isfinite(brain.plans.config[c, c]) == far_memory   # beyond the border: a goal, or nothing
        for t in range(42, 82):                             # 8 cells east, back where it started
            brain.perceive(_frame(t, dx=0.2))
        assert brain.maps.maps[CONFIG].sum() == (1 if far_memory else 0)
        assert tuple(brain.far.pos) == (0, 0)               # the agent's own cell is still kept


def test_without_the_obstacle_layer_neither_a_wall_nor_the_worlds_edge_is_mapped():
    # An agent 2 cells from the west edge of a 10 x 10 world, a wall reading 2 cells east.
    welcome = dataclasses.replace(_welcome(x=2.5, y=5.5), world_width=10.0, world_height=10.0)
    ranges = np.full((len(CHANNELS), 16), NO_READING)
    ranges[OBST, 0] = 2.0                               # sector 0: just north of east
    frame = dataclasses.replace(_frame(1), ranges=tuple(ranges.ravel()))
    for layer in (True, False):
        brain = Brain(welcome, AgentConfig(obstacle_layer=layer), np.random.default_rng(0))
        brain.perceive(frame)
        m, c = brain.layers()[OBSTACLE], brain.centre
        assert m[c, c + 2] == layer                     # the wall
        assert m[c, c - 3] == layer                     # beyond the west edge (x < 0)
        assert not m[c, c + 1] and not m[c, c - 1]      # the ground between is free either way


def test_a_memory_that_forgets_gives_back_no_brick_and_no_far_goal():
    mem = FarMemory(5, np.array([[9, 0]]), remember=False)   # a site 9 cells east: off the map
    free = np.zeros((5, 5), bool)
    free[2, 4] = True                                   # a brick 2 cells east of the centre
    for _ in range(3):                                  # 3 cells west: it leaves the map ...
        assert not mem.move(-1, 0, free).any()
    assert len(mem.bricks) == 0 and len(mem.far_bricks()) == 0   # ... and is not kept
    assert mem.far_open_sites().shape == (0, 2)         # nor is the site beyond the map a goal
    for _ in range(3):
        assert not mem.move(1, 0, free).any()           # coming back brings nothing back
    assert mem.cell == (0, 0)


def test_a_brick_mapped_beyond_the_world_edge_is_remembered_on_the_edge():
    # Seen from afar, a brick by the edge was mapped a cell beyond it: back on the map it lay
    # in the edge's wall (no goal), off the map it was one, and the agent walked to and fro
    # across one cell's edge for 50,000 ticks (gen-nested_rings 11230026).
    mem = FarMemory(5, np.zeros((0, 2)), bounds=(-10, -10, 2, 10))   # the east edge: x < 2
    free = np.zeros((5, 5), bool)
    free[2, 4] = True                       # 2 cells east of the centre: x = 2, outside
    none = np.zeros((5, 5), bool)
    for _ in range(3):                      # 3 cells west: it leaves on the east side
        free = mem.move(-1, 0, free)        # (what comes back is on the map's brick layer)
    assert mem.bricks.tolist() == [[1, 0]]  # kept on the world's last column, x = 1
    mem.move(1, 0, none)
    back = mem.move(1, 0, none)             # x = 1 comes onto the map's east column
    assert back[2, 4] and not mem.outside_world()[2, 4]   # back on a cell inside the world


def test_blueprint_changes_keep_beliefs_of_sites_that_stay():
    mem = FarMemory(9, np.array([[1, 0], [2, 0]]))
    mem.site_open[:] = (False, True)
    mem.set_sites(np.array([[1, 0], [3, 0]]))
    assert mem.site_open.tolist() == [False, True]


def test_set_blueprint_ignores_older_versions_and_replans():
    brain = Brain(_welcome(([52.5], [50.5])), AgentConfig(), np.random.default_rng(0))
    assert brain.set_blueprint(2, [48.5], [50.5])
    assert not brain.set_blueprint(1, [60.5], [50.5])
    r, col = np.argwhere(brain.maps.maps[CONFIG] > 0.5)[0]
    assert (r - brain.centre, col - brain.centre) == (0, -2)


def test_border_seed_is_the_octile_distance_that_remains():
    seed = border_seed(np.array([[2, 10]]), 5, np.zeros((5, 5), bool))
    assert seed[2, 4] == pytest.approx(6.0)                       # straight east
    assert seed[0, 4] == pytest.approx(6 + 2 * (math.sqrt(2) - 1))  # two rows off: two diagonals
    blocked = np.zeros((5, 5), bool)
    blocked[:, 4] = True
    assert np.isinf(border_seed(np.array([[2, 10]]), 5, blocked)[:, 4]).all()
    assert border_seed(np.zeros((0, 2)), 5, blocked) is None


@settings(max_examples=60, deadline=None)
@given(st.integers(3, 14), st.integers(0, 2**32 - 1))
def test_seeded_field_is_the_cheapest_goal_plus_its_cost(n, seed):
    rng = np.random.default_rng(seed)
    obstacles = rng.random((n, n)) < 0.25
    goals = rng.random((n, n)) < 0.1
    cost = rng.uniform(0, 15, (n, n))
    got = seeded_distance_field(np.where(goals, cost, np.inf), obstacles)
    expected = np.full((n, n), np.inf)
    for r, c in zip(*np.nonzero(goals & ~obstacles)):
        one = np.zeros((n, n), bool)
        one[r, c] = True
        expected = np.minimum(expected, distance_field(one, obstacles) + cost[r, c])
    np.testing.assert_allclose(np.where(np.isinf(got), -1, got), np.where(np.isinf(expected), -1, expected))
    zero = seeded_distance_field(np.where(goals, 0.0, np.inf), obstacles)
    np.testing.assert_array_equal(zero, distance_field(goals, obstacles))


def test_seeded_field_rejects_negative_costs():
    with pytest.raises(ValueError):
        seeded_distance_field(np.full((3, 3), -1.0), np.zeros((3, 3), bool))


# ------------------------------------------------------------------ what the agent reports

def test_the_state_report_names_what_blocks_the_agent():
    brain = Brain(_welcome(([52.5], [50.5])), AgentConfig(), np.random.default_rng(0))
    brain.step(_frame(1))
    report = brain.state_report(1)
    assert report.behaviour == "explore" and report.sites_open == 1
    assert "no free brick" in report.blocker
    assert sum(report.behaviour_ticks) == 1 and report.behaviour_ticks[BEHAVIOURS.index("explore")] == 1


def _walk_beside_a_gap(path, seed):
    """An agent walks `path` (offsets from x = 7.3, y = 10.5, x kept in [5, 9.6]) west of a
    wall at x = 10 with a one-cell gap at (10, 10), sensing it with noise after each step.
    After each step the gap must be open on the map; returns the maps and the final pose."""
    from agent_runtime.esm import EgocentricMaps
    from world_server.sensors import sense

    wall = np.array([(10.5, y + 0.5) for y in range(21) if y != 10])      # x = 10, gap at (10, 10)
    sectors, reach = 16, 6.0
    maps = EgocentricMaps(41)
    rng = np.random.default_rng(seed)
    here = np.array([7.3, 10.5])
    maps.seed_blueprint(*here, [], [])
    for dx, dy in path:
        step = np.array([min(max(7.3 + dx, 5.0), 9.6), 10.5 + dy]) - here
        maps.move(*step)
        here = here + step
        ranges = sense(here[None], np.array([True]), wall, np.full(len(wall), OBST), sectors, reach, (30.0, 30.0),
                       noise=0.02, seed=int(rng.integers(2**62)))[0]
        maps.sense(ranges, reach)
        gap = maps.cell_of(10.5 - here[0], 10.5 - here[1])
        assert maps.maps[OBSTACLE][gap] == 0.0
    return maps, here


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-5.0, 5.0), st.floats(-5.0, 5.0)), min_size=1, max_size=30),
       st.integers(0, 2**32 - 1))
def test_a_one_cell_gap_in_a_wall_is_never_sealed_by_the_map(path, seed):
    """Seen from anywhere around it, with noise, a wall's one-cell gap stays open on the map
    (a mark written beside the true cell would close the only way through for good)."""
    maps, here = _walk_beside_a_gap(path, seed)
    # And the wall beside it is mapped once the agent has been near it. (Two cells off, the
    # sector that sees it may also cover a wall cell mapped from an earlier place, and the
    # reading goes to that one, by the rule against ghosts: hypothesis found such a path.)
    near = maps.cell_of(10.5 - here[0], 11.5 - here[1])
    if np.hypot(10.5 - here[0], 11.5 - here[1]) < 1.5:
        assert maps.maps[OBSTACLE][near] == 1.0


def test_a_wall_cell_beside_the_agent_is_mapped_though_its_neighbour_is_marked():
    # Hypothesis found it (issue 35): at (9.3, 13.5) the agent maps the wall cells (10, 12-14);
    # two cells south, at (9.3, 11.5), wall cell (10, 11) is 1.2 cells due east, read by
    # sector 0 (0-22.5 degrees). The marked cell (10, 12), at 40 degrees, is within half a
    # cell of that sector's wedge, and the rule against ghosts gave it the reading: (10, 11)
    # stayed off the map, and the gap looked two cells wide for as long as the agent stood there.
    maps, here = _walk_beside_a_gap([(2.0, 3.0), (2.0, 1.0)], seed=0)
    assert tuple(here) == pytest.approx((9.3, 11.5))
    assert maps.maps[OBSTACLE][maps.cell_of(10.5 - here[0], 12.5 - here[1])] == 1.0
    assert maps.maps[OBSTACLE][maps.cell_of(10.5 - here[0], 11.5 - here[1])] == 1.0


# ------------------------------------------------------------------ the world's extent, exploring, the supply beyond

def _sized_welcome(x: float, y: float, w: float, h: float, sites=((), ())) -> Welcome:
    return Welcome(world_id="w", agent_id="a1", body=0, tick=0, x=x, y=y, heading=0.0, holding=False,
                   restarts=0, sectors=16, sensor_range=6.0, cell_size=1.0, site_xs=tuple(sites[0]),
                   site_ys=tuple(sites[1]), world_width=w, world_height=h)


def _corridor_beyond_the_map(end_shut: bool) -> tuple[Brain, np.ndarray, np.ndarray, np.ndarray]:
    """An agent (map 11 x 11) at the mouth of a one-cell corridor of 29 sites running 24
    cells beyond its map's east border; the corridor's walls and the ground round it are
    remembered, and its far end was seen shut by a wall, or open. Returns the brain and the
    sealing check's map inputs (goals, open sites, blocked)."""
    brain = Brain(_sized_welcome(2.5, 10.5, 40.0, 20.0, sites=([x + 2.5 for x in range(1, 30)], [10.5] * 29)),
                  AgentConfig(map_size=11), np.random.default_rng(0))
    far, c = brain.far, brain.centre
    assert far.walls is not None and far.ground is not None
    x0, y0 = -2, -10                                  # the world's first cell, from the attach cell
    far.ground[:] = True
    for y in (-1, 0, 1):
        far.ground[1 - x0:31 - x0, y - y0] = False     # the corridor and its walls are no ground
    far.walls[1 - x0:31 - x0, [-1 - y0, 1 - y0]] = True
    far.walls[30 - x0, -y0] = end_shut                 # the far end: a wall, or open ground
    far.ground[30 - x0, -y0] = not end_shut
    open_sites = brain.maps.maps[CONFIG] > 0.5         # sites 1-5 are on the map
    far.site_clear_age[:] = 10.0                       # all seen empty lately, walking along
    brain.maps.clear_age[open_sites] = 0.0
    blocked = far.on_map(far.walls)
    brain.maps.known[:] = ~blocked & ~open_sites
    goals = open_sites & (np.abs(np.arange(11) - c) <= 2)[None, :]
    return brain, goals, open_sites, blocked


@pytest.mark.parametrize("end_shut", [True, False])
def test_a_corridor_longer_than_the_map_is_judged_on_what_lies_beyond_it(end_shut):
    # Judged on the map alone, a corridor running past the border was cut off from
    # everything (nothing checked: a site filled with open sites deeper in, gen-pocket 153),
    # or, with the border counted open, open at a far end that was a wall (its mouth filled
    # first, gen-pocket 117). The far memory knows the walls and the ground seen beyond.
    brain, goals, open_sites, blocked = _corridor_beyond_the_map(end_shut)
    c = brain.centre
    unsafe = brain.seals.judge(goals, open_sites, blocked, np.zeros_like(goals))
    assert goals[c, c + 1] and goals[c, c + 2]
    assert unsafe[c, c + 1] == end_shut and unsafe[c, c + 2] == end_shut


def test_ground_once_seen_free_is_remembered_beyond_what_the_map_sees_now():
    # The maps forget what shifts off them and see little beside a wall: the mouth of a
    # corridor by the world's edge, walked through on the way in, was unknown on coming back.
    mem = FarMemory(5, np.zeros((0, 2)), bounds=(-10, -10, 10, 10))
    seen = np.zeros((5, 5), bool)
    seen[2, 2] = True                                  # the agent's own cell
    mem.save_walls(np.zeros((5, 5), bool), np.zeros((5, 5), bool), seen)
    mem.save_walls(np.zeros((5, 5), bool), np.zeros((5, 5), bool), np.zeros((5, 5), bool))
    assert mem.ground is not None and mem.ground[10, 10]          # still known, at x = 0, y = 0


def test_an_open_site_no_way_reaches_is_believed_filled():
    # A brick deep in a one-cell slot hides behind the one in front: its site, seen empty
    # long ago, stayed open, walled in, and loaded agents wandered for it (gen-pocket 153).
    open_sites = np.zeros((9, 9), bool)
    walls = np.zeros((9, 9), bool)
    walls[3, 1:8] = walls[5, 1:8] = walls[4, 1] = True   # a slot, shut at its west end
    walls[4, 4] = True                                   # a structure brick across it
    open_sites[4, 2] = open_sites[4, 6] = True           # one behind the brick, one before it
    enclosed = enclosed_sites(open_sites, walls, centre=(7, 7))
    assert enclosed[4, 2] and not enclosed[4, 6]          # the east one opens onto the border
    assert not enclosed_sites(open_sites, walls, centre=(4, 3))[4, 2]   # an agent inside reaches it


def test_the_world_edge_is_a_wall_on_the_map_wherever_the_agent_is():
    brain = Brain(_sized_welcome(2.5, 3.5, 30.0, 20.0), AgentConfig(map_size=11), np.random.default_rng(0))
    brain.perceive(_frame(1))
    walls = brain.maps.maps[OBSTACLE] > 0.5
    c = brain.centre
    # Two cells of the world lie west of the agent (x = 0.5, 1.5), three south (y = 0.5 .. 2.5).
    assert walls[:, :c - 2].all() and not walls[c, c - 2:].any()
    assert walls[c + 4:, :].all() and not walls[:c + 4, c - 2:].any()
    for t in range(2, 42):                      # 8 cells east: the west edge scrolls off
        brain.perceive(_frame(t, dx=0.2))
    walls = brain.maps.maps[OBSTACLE] > 0.5
    assert not walls[:c + 4, :].any() and walls[c + 4:, :].all()


def test_explore_heads_for_squares_of_the_world_not_yet_seen():
    # A 40 x 10 world, the agent at its west end, nothing to see: it sweeps east.
    brain = Brain(_sized_welcome(2.5, 5.5, 40.0, 10.0, ([38.5], [5.5])), AgentConfig(), np.random.default_rng(1))
    step = brain.step(_frame(1))
    assert step.behaviour == "explore" and step.speed > 0
    target = brain.far.unseen_target(brain.rng)
    assert target[1] > brain.centre                          # east of the agent
    seen_before = int(brain.far.seen.sum())
    for t in range(2, 200):                                  # walking east marks squares seen
        brain.perceive(_frame(t, dx=0.2))
    assert brain.far.seen.sum() > seen_before


def test_bricks_beyond_the_map_stand_in_the_matching_at_the_border():
    brain = Brain(_welcome(([50.5], [52.5])), AgentConfig(map_size=11), np.random.default_rng(0))
    brain.far.bricks = np.array([[30, 0]])                   # a pile 30 cells east of the attach cell
    supply = brain._supply()                                  # not holding: the far bricks alone
    assert supply.sum() == 1 and supply[brain.centre, -1]    # the east border cell on the agent's row


def test_a_site_believed_filled_comes_back_onto_the_map_holding_its_brick():
    # A brick deep in a one-cell slot is hidden behind the one in front of it: shown open on
    # return, its site looked like a goal behind a filled one (gen-pocket 102).
    mem = FarMemory(5, np.array([[2, 0], [2, 1]]))
    mem.site_open[:] = (False, True)              # the first seen filled, the second open
    no_bricks = np.zeros((5, 5), bool)
    for _ in range(3):                            # 3 cells west: both leave on the east side
        assert not mem.move(-1, 0, no_bricks).any()
    for _ in range(2):
        assert not mem.move(1, 0, no_bricks).any()
    back = mem.move(1, 0, no_bricks)              # back on the map's east column
    assert back[2, 4] and back.sum() == 1         # the filled one's brick, not the open one's


def test_with_no_open_site_on_the_map_any_free_brick_is_a_brick_goal():
    # The Matching grid pairs nothing without a site on the map; following a remembered
    # brick beyond the border instead, the agent turned back each time the sites came into
    # view, a step either side of the map's edge (gen-polyomino 134).
    brain = Brain(_welcome(([50.5], [80.5])), AgentConfig(map_size=11), np.random.default_rng(0))
    c = brain.centre
    brain.far.bricks = np.array([[0, 20]])        # remembered 20 cells north, beyond the border
    brain.maps.maps[BRICK, c + 2, c - 2] = 1.0     # a free brick in view, south-west
    plans = brain.plan()
    assert plans.brick_goals[c + 2, c - 2]
    assert plans.brick[c, c] == pytest.approx(2 * math.sqrt(2))


def test_free_bricks_the_matching_cannot_pair_on_the_map_are_goals_before_bricks_beyond_it():
    # The way from the bricks here to the sites leads round a wall beyond the map, so the
    # Matching grid (the map only) pairs none of them. Following the remembered bricks far
    # off instead, the agent turned back each time a step brought one more site onto the
    # map and the bricks here were paired again (gen-nested_rings 11260025).
    brain = Brain(_welcome(([50.5], [47.5])), AgentConfig(map_size=11), np.random.default_rng(0))
    c = brain.centre
    assert brain.maps.maps[CONFIG, c + 3, c] == 1.0   # the site, three cells south
    brain.maps.maps[OBSTACLE, c + 2, :] = 1.0         # a wall right across the map between
    brain.maps.maps[BRICK, c - 2, c + 1] = 1.0        # a free brick in view, north
    brain.far.bricks = np.array([[0, 20]])            # remembered 20 cells north, beyond the border
    plans = brain.plan()
    assert plans.matching is not None and not plans.matching.pairs
    assert plans.brick_goals[c - 2, c + 1]
    assert plans.brick[c, c] == pytest.approx(1 + math.sqrt(2))


def test_water_remembered_beyond_the_map_blocks_paths_when_it_comes_back_until_seen_free():
    # Back on the map, remembered water was open ground: the agents planned through a
    # water wall longer than the map, walked to it, along it and back (gen-multi 025).
    brain = Brain(_sized_welcome(10.5, 20.5, 60.0, 40.0), AgentConfig(map_size=21), np.random.default_rng(0))
    c = brain.centre
    x0, y0 = brain.far.bounds[:2]
    brain.far.discs[14 - x0, -y0] = True               # water 14 cells east, beyond the border (10)
    for t in range(1, 31):                              # 6 cells east: it is 8 cells off, on the map
        brain.perceive(_frame(t, dx=0.2))
    assert brain._recalled[c, c + 8] and brain._recalled.sum() == 1
    assert brain.maps.maps[WATER, c, c + 8] == 0.0 and brain.maps.maps[FOOD, c, c + 8] == 0.0  # no need's goal
    (_, config_obstacles), (_, brick_obstacles) = brain.nav_masks()
    assert config_obstacles[c, c + 8] and brick_obstacles[c, c + 8]
    for t in range(31, 46):                             # 3 cells on: within sensor range, seen free
        brain.perceive(_frame(t, dx=0.2))
    assert not brain._recalled.any()
    for t in range(46, 96):                             # and it is not remembered once gone
        brain.perceive(_frame(t, dx=-0.2))
    assert not brain.far.discs.any()


def test_a_site_found_sealing_stays_no_goal_for_a_while_out_of_the_checks_reach():
    # The sealing check runs only within SEAL_RADIUS cells. A site it refused became a goal
    # again one cell farther off, and the agent turned back at that cell's edge, to and fro,
    # in a one-cell slot of water (gen-pocket 11230010).
    brain = Brain(_welcome(([52.5], [50.5])), AgentConfig(map_size=11), np.random.default_rng(0))
    c = brain.centre
    goals = np.zeros((11, 11), bool)
    goals[c, c + 2] = True                         # the site, 2 cells east: within the check
    assert brain.seals.remember(goals, goals.copy(), brain._tick)[c, c + 2]
    brain.far.move(-2, 0, np.zeros((11, 11), bool))    # 2 cells west: out of the check's reach
    goals = np.zeros((11, 11), bool)
    goals[c, c + 4] = True
    unsafe_now = np.zeros((11, 11), bool)          # the check no longer looks at it
    assert brain.seals.remember(goals, unsafe_now, brain._tick)[c, c + 4]       # still no goal
    brain._tick += SEAL_MEMORY + 1
    assert not brain.seals.remember(goals, unsafe_now, brain._tick).any()        # forgotten in time
    brain.far.move(2, 0, np.zeros((11, 11), bool))     # back within reach
    goals = np.zeros((11, 11), bool)
    goals[c, c + 2] = True
    brain.seals.remember(goals, goals.copy(), brain._tick)       # found sealing again ...
    brain._tick += 1
    assert not brain.seals.remember(goals, np.zeros((11, 11), bool), brain._tick).any()   # ... then safe: goal at once


def test_the_distance_beyond_the_map_goes_round_the_walls_remembered_there():
    # A wall longer than the map between the agent and its goal: the straight distance made
    # the border cell straight behind the wall the cheapest, and the agent walked into it.
    mem = FarMemory(5, np.zeros((0, 2)), bounds=(-20, -20, 20, 20))
    target = np.array([[2, 12]])                   # row 2 (the agent's), 10 cells east of the map's edge
    free = np.zeros((5, 5), bool)
    assert mem.border_costs(target, free)[2, 4] == pytest.approx(8.0)   # nothing known: straight on
    assert mem.walls is not None
    mem.walls[3 + 20, -15 + 20:16 + 20] = True     # a wall at x = 3 from y = -15 to 15
    mem._memory_version += 1
    round_it = mem.border_costs(target, free)
    assert np.isfinite(round_it[2, 4]) and round_it[2, 4] > 25          # round its end, 16 cells on
    assert round_it[0, 4] < round_it[2, 4] and round_it[4, 4] < round_it[2, 4]  # towards an end


def test_an_agent_pinned_while_it_heads_for_water_backs_off():
    # A source seen a cell off now and then flips the way to it: an agent turned back and
    # forth beside a gap in a wall for 9,000 ticks (gen-letter 109).
    cfg = AgentConfig(stuck_ticks=40)
    brain = Brain(_welcome(), cfg, np.random.default_rng(3))
    c = brain.centre
    brain.maps.maps[WATER, c, c + 9] = 1.0         # on the map, beyond sensor range
    brain.motivations.thirst, brain.motivations.seeking_water = 1.0, True
    behaviours = [brain.step(_frame(t)).behaviour for t in range(1, 120)]
    assert behaviours[0] == "approach_water"
    assert "unstick" in behaviours


@pytest.mark.parametrize("holding,gives_way", [(True, True), (False, False)])
def test_a_loaded_agent_gives_way_to_an_unloaded_one(holding, gives_way):
    # Both backing off at the same distance, two agents in a corridor one body wide met
    # again and again (generated pockets with 9-12 agents); the loaded one backs off first.
    brain = Brain(_welcome(([60.5], [50.5])), AgentConfig(), np.random.default_rng(0))
    ranges = [NO_READING] * (16 * len(CHANNELS))
    ranges[CHANNELS.index("agent") * 16 + 0] = 0.6     # another agent 0.6 cells away, east
    frame = SensorFrame(agent_id="a1", tick=1, heading=0.0, odom_dx=0.0, odom_dy=0.0, sectors=16,
                        ranges=tuple(ranges), holding=holding)
    assert (brain.step(frame).behaviour == "avoid") is gives_way
