"""Maps that stay true (issue 37 item 3): `anchor_maps` moves an agent's belief of where it
is by what landmarks it knows say, structure bricks and the world's edge, so a known shift
of the belief is recovered and a noisy run's map error stays bounded."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agent_runtime.anchoring import (
    BRICK_CHANNEL,
    OBSTACLE_CHANNEL,
    Anchor,
    AnchorConfig,
    Landmarks,
    Relocaliser,
    edge_ring,
)
from agent_runtime.config import ADDITIONS, CORRECTIONS, AgentConfig
from conag import sim
from protocol.messages import CHANNELS
from tests.conftest import scenario
from world_server.noise import NoiseSettings

SECTORS = 16
RANGE = 6.0
NONE = np.zeros((0, 2))


def readings(position, channels: dict[int, np.ndarray], sectors: int = SECTORS) -> np.ndarray:
    """Noise-free sector readings from the true `position`, as the world makes them: per
    channel and sector, the distance to the nearest point in range (cells; -1: none)."""
    out = np.full((len(CHANNELS), sectors), -1.0)
    for ch, points in channels.items():
        rel = np.asarray(points, float) - position
        d = np.hypot(rel[:, 0], rel[:, 1])
        s = (np.mod(np.arctan2(rel[:, 1], rel[:, 0]), 2 * math.pi) // (2 * math.pi / sectors)).astype(int)
        for k, dist in sorted(zip(s, d), key=lambda p: -p[1]):
            if dist <= RANGE:
                out[ch, k] = dist
    return out


def anchored(truth, believed, landmarks: Landmarks, channels: dict[int, np.ndarray], ticks: int = 30,
             moved: float = 0.0) -> np.ndarray:
    """The belief after `ticks` frames seen from `truth`, each correction added to it."""
    anchor = Anchor()
    anchor.predict(3.0)       # three cells walked since the belief was last sure
    believed = np.array(believed, float)
    for _ in range(ticks):
        believed += anchor.correct(readings(truth, channels), believed, landmarks)
        anchor.predict(moved)
    return believed


# A ring of structure bricks round the agent (sites at whole cells: their centres).
RING = np.array([(x, y) for x in range(-3, 4) for y in range(-3, 4) if max(abs(x), abs(y)) == 3], float)
FILLED = np.ones(len(RING), bool)
ONE, NOTHING = np.ones(1, bool), np.zeros(0, bool)


@pytest.mark.parametrize("shift", [(0.3, -0.25), (-0.4, 0.1), (0.0, 0.45)])
def test_a_known_shift_of_the_belief_is_recovered_from_structure_bricks(shift):
    truth = np.array([0.2, -0.1])
    believed = anchored(truth, truth - shift, Landmarks(RING, FILLED, NONE), {BRICK_CHANNEL: RING})
    assert np.hypot(*(believed - truth)) < 0.05


def test_the_worlds_edge_anchors_the_axis_it_faces():
    bounds = (-2, -10, 20, 10)                 # the west edge two cells away, the others out of range
    edge = edge_ring(bounds)
    truth = np.array([0.1, 0.3])
    believed = anchored(truth, truth - (0.35, 0.0), Landmarks(NONE, NOTHING, edge), {OBSTACLE_CHANNEL: edge})
    assert abs(believed[0] - truth[0]) < 0.05


def test_the_edge_ring_is_where_the_world_puts_its_edge():
    ring = edge_ring((0, 0, 3, 2))
    assert len(ring) == 2 * 5 + 2 * 2 and {(-1.0, -1.0), (3.0, 2.0), (-1.0, 1.0), (1.0, 2.0)} <= set(map(tuple, ring))
    assert edge_ring(None).shape == (0, 2)


def test_a_reading_of_something_nearer_than_the_landmark_is_not_used():
    # A free brick two cells east, in front of the structure brick five cells east: the
    # east sector reads 2, which is not the landmark, and no equation comes of it.
    site = np.array([[5.0, 0.2]])
    seen = readings(np.zeros(2), {BRICK_CHANNEL: np.vstack([site, [[2.0, 0.1]]])})
    anchor = Anchor()
    anchor.predict(2.0)
    u, _, _ = anchor.equations(seen, np.zeros(2), Landmarks(site, ONE, NONE))
    assert len(u) == 0
    assert not anchor.correct(seen, np.zeros(2), Landmarks(site, ONE, NONE)).any()
    # Without the free brick the same sector gives one.
    alone = readings(np.zeros(2), {BRICK_CHANNEL: site})
    assert len(anchor.equations(alone, np.zeros(2), Landmarks(site, ONE, NONE))[0]) == 1


def test_with_nothing_known_in_sight_the_belief_is_left_alone_and_grows_less_sure():
    anchor = Anchor()
    free = readings(np.zeros(2), {BRICK_CHANNEL: np.array([[2.0, 1.0], [-3.0, 0.5]])})
    assert not anchor.correct(free, np.zeros(2), Landmarks(NONE, NOTHING, NONE)).any()
    before = np.trace(anchor.cov)
    anchor.predict(4.0)
    assert np.trace(anchor.cov) > before


def test_a_correction_is_at_most_a_quarter_cell_a_tick():
    truth = np.zeros(2)
    anchor = Anchor()
    anchor.predict(10.0)
    step = anchor.correct(readings(truth, {BRICK_CHANNEL: RING}), truth - (0.4, 0.4), Landmarks(RING, FILLED, NONE))
    assert np.all(np.abs(step) <= anchor.cfg.max_step + 1e-12) and np.all(step > 0)


def test_the_correction_is_a_named_switch_off_by_default():
    assert CORRECTIONS == ("anchor_maps", "occlusion_clearing") and not set(CORRECTIONS) & set(ADDITIONS)
    assert AgentConfig().anchor_maps is False
    assert AgentConfig.from_mapping({"anchor_maps": True}).anchor_maps is True
    with pytest.raises(ValueError, match="anchor_maps must be true or false"):
        AgentConfig(anchor_maps=1)  # type: ignore[arg-type]
    assert AgentConfig(anchor_maps=True).describe() == {"preset": "default", "without": [],
                                                       "changed": {"anchor_maps": True}}


# A small walled yard: wherever the agent goes, the world's edge is in sight.
YARD = """
bb..........
bb..........
............
....++++....
....+..+....
....++++....
............
A..........A
"""


def map_errors(cfg: AgentConfig, ticks: int) -> list[float]:
    """Each agent's belief error (cells) every 10 ticks of a noisy run on the yard."""
    run = sim.start(scenario(YARD, agents=2, seed=5), cfg=cfg,
                    noise=NoiseSettings(odometry_distance_slip=0.3, odometry_heading_slip=0.3))
    out = []
    for tick in range(ticks):
        then = {a: run.world.agent_poses()[run.world.agents[a].index, :2] for a in run.brains}
        run.step()
        if tick % 10 == 9:
            for a, brain in run.brains.items():
                true = then[a] / run.world.cfg.cell_size - brain._origin - 0.5
                out.append(float(np.hypot(*(true - brain.far.pos - brain.maps.frac))))
    return out


@pytest.mark.slow
def test_with_the_correction_a_noisy_runs_map_error_stays_bounded_where_it_grows_without():
    ticks = 1500
    plain, anchored_ = map_errors(AgentConfig(), ticks), map_errors(AgentConfig(anchor_maps=True), ticks)
    late = slice(len(plain) // 2, None)
    assert max(plain[late]) > 1.0                       # dead reckoning alone: over a cell off
    assert max(anchored_) < 0.5                        # anchored: never half a cell off
    assert np.mean(anchored_[late]) < np.mean(plain[late]) / 4


def test_a_reading_that_fits_an_open_site_as_well_as_a_filled_one_is_not_used():
    # Two sites side by side, the east one believed filled: seen end on, one sector holds
    # both at about the same distance, and the reading cannot say which holds the brick.
    sites = np.array([[4.0, 0.0], [4.0, 1.0]])
    seen = readings(np.zeros(2), {BRICK_CHANNEL: sites[1:]})
    anchor = Anchor()
    anchor.predict(1.0)
    assert len(anchor.equations(seen, np.zeros(2), Landmarks(sites, np.array([False, True]), NONE))[0]) == 0
    assert len(anchor.equations(seen, np.zeros(2), Landmarks(sites[1:], ONE, NONE))[0]) == 1


# A straight wall of structure bricks two cells east of the agent, ending two cells north
# of it: seen from its side, the readings fit a belief a cell off along it about as well.
WALL = np.array([(2.0, float(y)) for y in range(-8, 3)])


def relocalised(truth, believed, ticks: int = 40, noise: float = 0.0, seed: int = 0) -> tuple[np.ndarray, int]:
    """The belief after `ticks` frames from `truth` (each reading off by a uniform error of
    std `noise` per cell of its distance), moved by every jump; and how many jumps."""
    rng = np.random.default_rng(seed)
    relocaliser = Relocaliser(AnchorConfig(), SECTORS, RANGE, occluding=False)
    believed = np.array(believed, float)
    marks = Landmarks(WALL, np.ones(len(WALL), bool), NONE)
    for _ in range(ticks):
        r = readings(truth, {BRICK_CHANNEL: WALL})
        r = np.where(r >= 0, r * (1 + noise * math.sqrt(3) * rng.uniform(-1, 1, r.shape)), r)
        believed += relocaliser.update(r, believed, marks)
    return believed, relocaliser.jumps


@pytest.mark.parametrize("off", [(0.0, 1.0), (0.0, -1.0)])
def test_a_belief_a_cell_off_along_a_wall_comes_back_where_the_wall_ends(off):
    # Beside the wall's end: a cell north, the belief puts a brick where the sensors see
    # none and misses the last one they see; a cell south, the same the other way round.
    truth = np.array([0.3, 2.5])
    believed, jumps = relocalised(truth, truth + off)
    assert jumps == 1 and np.allclose(believed, truth)


@pytest.mark.parametrize("seed", range(5))
def test_a_true_belief_is_never_moved_a_cell(seed):
    truth = np.array([0.1, -0.2])
    believed, jumps = relocalised(truth, truth, ticks=200, noise=0.04, seed=seed)
    assert jumps == 0 and np.allclose(believed, truth)


@pytest.mark.parametrize("counts, moved", [
    ([9, 9, 9, 9, 9, 9, 2, 9, 9], (1.0, -1.0)),    # one neighbour clearly best: the belief moves there
    ([9, 9, 9, 2, 9, 2, 9, 9, 9], (0.0, 0.0)),     # two alike (a wall seen from its middle): it stays
    ([9, 9, 9, 9, 7, 9, 2, 9, 9], (0.0, 0.0)),     # the belief only 5 worse: not enough
])
def test_the_belief_moves_a_cell_only_to_one_neighbour_clearly_better(counts, moved, monkeypatch):
    relocaliser = Relocaliser(AnchorConfig(decay=0.0), SECTORS, RANGE, occluding=False)
    monkeypatch.setattr(relocaliser, "contradictions", lambda *_: np.asarray(counts, float))
    step = relocaliser.update(np.full((len(CHANNELS), SECTORS), -1.0), np.zeros(2), Landmarks(NONE, NOTHING, NONE))
    assert tuple(step) == moved and relocaliser.jumps == (1 if any(moved) else 0)
