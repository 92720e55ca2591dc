"""Rules of the agent's decision step (agent_runtime/brain.py), each on a small situation
built for it: the principle a rule serves, asserted apart from the layout that first
showed the need for it. Each test fails with its rule switched off (its `AgentConfig`
flag), so a rule that stops doing its job is seen here first."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from agent_runtime.brain import Brain
from agent_runtime.config import AgentConfig
from agent_runtime.esm import BRICK, CONFIG
from protocol.messages import CHANNELS, NO_READING, SensorFrame, Welcome
from tests.conftest import make
from world_server.discs import BRICK_DISC

SECTORS = 16
EAST, WEST = 0, 8   # sectors whose centre angles (11.25 and 191.25 degrees) lie half a sector off due east and west


def _welcome(site_xs=(), site_ys=(), x: float = 50.5, y: float = 50.5) -> Welcome:
    return Welcome(world_id="w", agent_id="a1", body=0, tick=0, x=x, y=y, heading=0.0, holding=False,
                   restarts=0, sectors=SECTORS, sensor_range=6.0, cell_size=1.0,
                   site_xs=tuple(site_xs), site_ys=tuple(site_ys))


def _frame(tick: int, holding: bool = False, dx: float = 0.0, **readings: dict[int, float]) -> SensorFrame:
    """A frame with the given readings per channel ({sector: distance in cells}), else none."""
    ranges = [NO_READING] * (SECTORS * len(CHANNELS))
    for channel, by_sector in readings.items():
        for sector, distance in by_sector.items():
            ranges[CHANNELS.index(channel) * SECTORS + sector] = distance
    return SensorFrame(agent_id="a1", tick=tick, heading=0.0, odom_dx=dx, odom_dy=0.0, sectors=SECTORS,
                       ranges=tuple(ranges), holding=holding)


def _free_bricks(brain: Brain) -> np.ndarray:
    m = brain.maps.maps > 0.5
    return m[BRICK] & ~m[CONFIG]


# ------------------------------------------------------------------ the supply beyond what is in view

def _two_sites_in_a_row(brain: Brain, mouth: tuple[int, int], deep: tuple[int, int], supply: tuple[int, int]):
    """What the matching promises for a site between the supply and a deeper site in line
    with it: both are paired with `supply`, the nearer one is held open and the deeper
    one is the only drop site (Fig. 18: filled first, the nearer one would wall it off)."""
    plans = brain.plans
    assert plans is not None and plans.matching is not None
    assert {site for site, _ in plans.matching.pairs} == {mouth, deep}
    assert {brick for _, brick in plans.matching.pairs} == {supply}
    assert plans.matching.match[mouth] and not plans.config_goals[mouth]
    assert plans.config_goals[deep] and np.count_nonzero(plans.config_goals) == 1


@pytest.mark.parametrize("walked", [0, 8])
def test_the_held_bricks_source_stands_for_the_supply_when_no_free_brick_is_in_view(walked):
    # The agent takes the only brick in view, a cell west of it, and carries it `walked`
    # cells east (8: its source is then beyond the 11-cell map), to two open sites in a
    # row due east. It knows no free brick now, yet where its brick came from is where
    # the supply is: the matching keeps the way from there to the deeper site open.
    x = 50.5 + walked
    brain = Brain(_welcome((x + 1, x + 2), (50.5, 50.5)), AgentConfig(map_size=11), np.random.default_rng(0))
    c = brain.centre
    brain.step(_frame(1, brick={WEST: 1.0}))            # at the brick
    assert brain.plans is not None and brain.plans.nearest_brick is not None
    brain.step(_frame(2, holding=True))                 # grabbed: nothing else in view
    for t in range(3, 3 + 5 * walked):
        brain.step(_frame(t, holding=True, dx=0.2))
    assert not _free_bricks(brain).any() and len(brain.far.bricks) == 0
    _two_sites_in_a_row(brain, mouth=(c, c + 1), deep=(c, c + 2), supply=(c, max(c - 1 - walked, 0)))


def test_free_bricks_remembered_beyond_the_map_stand_for_the_supply_on_its_border():
    # None in view, but bricks are remembered 20 cells west, beyond the map: the matching
    # holds the map only, so they stand in it at the border cell towards them.
    brain = Brain(_welcome((51.5, 52.5), (50.5, 50.5)), AgentConfig(map_size=11), np.random.default_rng(0))
    c = brain.centre
    brain.far.bricks = np.array([[-20, 0]])             # (x east, y north) cells from the attach cell
    brain.step(_frame(1))
    assert not _free_bricks(brain).any()
    _two_sites_in_a_row(brain, mouth=(c, c + 1), deep=(c, c + 2), supply=(c, 0))


# ------------------------------------------------------------------ other agents in the way

def test_paths_go_round_other_agents_in_sight_on_both_navigation_maps():
    # A site 8 cells east and a free brick 8 cells west (beyond sensor range, so this
    # frame clears neither), another agent 2 cells along each straight way. Both ways go
    # round the agents, not through them.
    brain = Brain(_welcome((58.5,), (50.5,)), AgentConfig(map_size=21), np.random.default_rng(0))
    c = brain.centre
    brain.maps.maps[BRICK, c, c - 8] = 1.0
    brain.step(_frame(1, agent={EAST: 2.0, WEST: 2.0}))
    plans = brain.plans
    assert plans is not None and plans.config_goals[c, c + 8] and plans.brick_goals[c, c - 8]
    for field, other in ((plans.config, (c, c + 2)), (plans.brick, (c, c - 2))):
        assert math.isinf(field[other])                 # no way through the agent's cell ...
        assert 8.5 < field[c, c] < math.inf             # ... but one round it, longer than straight on


CORRIDOR = """
b..####
...A.A+
"""  # a dead end one cell wide along the world's south edge; its only site at the far end


@pytest.mark.parametrize("layout, backs_away", [
    (CORRIDOR, True),
    (CORRIDOR.replace("A.A+", "A#A+"), False),          # a wall shuts the site off too: no use backing away
], ids=["only agents in the way", "a wall too"])
def test_an_agent_whose_site_only_other_agents_keep_out_of_reach_backs_away_from_them(layout, backs_away):
    # a1 holds a brick at the corridor's mouth, a2 stands inside, between it and the site.
    # Neither can pass the other; a queue in a dead end clears only from its mouth, so a1
    # turns away from a2 and makes room. Where a wall keeps the site out of reach as well,
    # backing away would free nothing: it does not.
    world = make(layout, agents=2, sensor_noise=0.0)
    welcome = world.attach("a1")
    world.attach("a2")
    brick = int(np.flatnonzero(world.discs.kind == BRICK_DISC)[0])
    world.discs.carry(brick)
    world.physics.remove_disc(brick)
    world.agents["a1"].holding = brick
    world.step()
    brain = Brain(welcome, AgentConfig(), np.random.default_rng(0))
    for _ in range(3):
        frame = world.frame("a1")
        step = brain.step(frame)
        pos = world.physics.state()[0]
        towards_a2 = math.atan2(pos[1, 1] - pos[0, 1], pos[1, 0] - pos[0, 0])
        away = math.cos(frame.heading + step.turn - towards_a2) < -0.9   # the way it now wants to go
        assert step.behaviour == "avoid_red" and away == backs_away
        world.set_command("a1", step.speed, step.turn, step.action)
        world.set_command("a2", 0.0, 0.0, "none")
        world.step()


# ------------------------------------------------------------------ what is remembered, what is seen

def test_a_thirsty_agent_never_heads_for_water_it_only_remembers():
    # Water remembered beyond the map comes back onto it 8 cells east, out of sensor range:
    # it may be gone (drunk, moved), and a sector sees only the nearest disc of a wall, so
    # a need acts only on water seen. Until seen gone it is in the way of every path.
    welcome = replace(_welcome(x=10.5, y=20.5), world_width=60.0, world_height=40.0)
    brain = Brain(welcome, AgentConfig(map_size=21), np.random.default_rng(0))
    c = brain.centre
    x0, y0 = brain.far.bounds[:2]
    brain.far.discs[14 - x0, -y0] = True               # 14 cells east, beyond the map's border (10)
    for t in range(1, 31):                              # 6 cells east: back on the map, 8 cells off
        brain.perceive(_frame(t, dx=0.2))
    (_, config_obstacles), (_, brick_obstacles) = brain.nav_masks()
    assert config_obstacles[c, c + 8] and brick_obstacles[c, c + 8]
    brain.motivations.thirst, brain.motivations.seeking_water = 1.0, True
    assert brain.step(_frame(31)).behaviour != "approach_water"
