"""The world core (paper §3; W1-W7 in docs/design.md) driven directly, without a bus.

Small worlds come from inline scenario strings. World coordinates: x east, y north,
one unit = one cell; cell (col, row) has its centre at (col + 0.5, rows - 1 - row + 0.5).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from protocol.codec import encode
from protocol.messages import CHANNELS, NO_READING, Perturbation
from tests.conftest import make, scenario
from world_server.config import WorldConfig
from world_server.scenario import ScenarioError
from world_server.sensors import sense
from world_server.world import World

FOOD, WATER, BRICK, OBSTACLE, AGENT = (CHANNELS.index(c) for c in ("food", "water", "brick", "obstacle", "agent"))
NCH = len(CHANNELS)
TOL = 0.03  # how far a resting body may sink into a disc or a wall (pymunk contact slop)
# There is no continuous collision detection: on the tick of impact a body can sink up to
# one tick's travel (max_speed * dt) into what it hits, before it is pushed back out.
STEP = 0.3


# ---------------------------------------------------------------- helpers


def ranges(w: World, agent_id: str) -> np.ndarray:
    return np.array(w.frame(agent_id).ranges).reshape(len(CHANNELS), w.cfg.sensor_sectors)


def pose(w: World, agent_id: str) -> np.ndarray:
    return w.agent_poses()[w.agents[agent_id].index]


def tick(w: World, commands: dict | None = None, n: int = 1) -> None:
    """Send the same commands (id -> (speed, turn, action)) and step, n times."""
    for _ in range(n):
        for a, (speed, turn, action) in (commands or {}).items():
            w.set_command(a, speed, turn, action)
        w.step()



def face_nearest_brick(w, agent: str = "a") -> None:
    """Turn the body to the nearest brick: the gripper takes bricks in front of it."""
    i = w.agents[agent].index
    x, y, _ = w.agent_poses()[i]
    lying = (w.discs.kind == 2) & (w.discs.state == 0)
    if lying.any():
        bricks = w.discs.xy[lying]
        bx, by = bricks[np.argmin(np.hypot(bricks[:, 0] - x, bricks[:, 1] - y))]
        w.heading[i] = math.atan2(by - y, bx - x)


def test_the_gripper_takes_the_brick_in_front_not_a_nearer_one_behind():
    w = make("\n".join(["......", ".bAb..", "......"]), grab_reach=1.5)
    w.attach("a")
    x, _, _ = w.agent_poses()[0]
    w.heading[0] = 0.0                       # facing east, a brick 1.0 away on each side
    tick(w, {"a": (0.0, 0.0, "grab")})
    held = w.agents["a"].holding
    assert held >= 0 and w.discs.xy[held][0] > x   # the east one, in front
    w2 = make("\n".join(["......", ".bA...", "......"]))
    w2.attach("a")
    w2.heading[0] = 0.0                      # the only brick is behind
    tick(w2, {"a": (0.0, 0.0, "grab")})
    assert w2.agents["a"].holding == -1 and not w2.frames()[0].grabbed

def face(w: World, agent_id: str, angle: float) -> None:
    """Turn in place until the heading is `angle`."""
    for _ in range(10):
        err = (angle - pose(w, agent_id)[2] + math.pi) % (2 * math.pi) - math.pi
        if abs(err) < 1e-9:
            return
        tick(w, {agent_id: (0.0, err, "none")})
    raise AssertionError("could not turn")


def drive_to(w: World, agent_id: str, target, ticks: int = 200, tol: float = 0.05) -> None:
    """A simple controller: turn towards the target, go slower when close, stop there."""
    target = np.asarray(target, float)
    for _ in range(ticks):
        x, y, h = pose(w, agent_id)
        d = target - (x, y)
        dist = float(np.hypot(*d))
        if dist < tol:
            tick(w, {agent_id: (0.0, 0.0, "none")}, 10)  # let inertia die out
            return
        err = (math.atan2(d[1], d[0]) - h + math.pi) % (2 * math.pi) - math.pi
        speed = min(w.cfg.max_speed, 1.5 * dist) if abs(err) < 0.3 else 0.0
        tick(w, {agent_id: (speed, err, "none")})
    raise AssertionError(f"{agent_id} did not reach {target}, at {pose(w, agent_id)}")


def at_angle(xy, angle: float, dist: float) -> tuple[float, float]:
    return float(xy[0] + dist * math.cos(angle)), float(xy[1] + dist * math.sin(angle))


def add(w: World, kind: str, xy) -> None:
    assert w.perturb(Perturbation("add", float(xy[0]), float(xy[1]), kind=kind)).ok


def sector_of(dx: float, dy: float, sectors: int) -> int:
    return int(math.atan2(dy, dx) % (2 * math.pi) // (2 * math.pi / sectors)) % sectors


# ---------------------------------------------------------------- sensors (W2)

BIG = "\n".join(["." * 15] * 7 + ["." * 7 + "A" + "." * 7] + ["." * 15] * 7)  # agent at (7.5, 7.5)
SENSE_LAYOUT = """
.W.....
.......
.....F.
...A...
b......
....A..
.......
"""


def test_each_colour_is_reported_in_its_channel_sector_and_distance():
    w = make(SENSE_LAYOUT, agents=2, sensor_noise=0.0)
    me = w.attach("me")  # first A in reading order: the centre cell (3, 3)
    assert (me.x, me.y) == (3.5, 3.5)
    w.attach("other")  # the A at (4, 5): offset (+1, -2)
    w.step()
    got = ranges(w, "me")
    expected = np.full_like(got, NO_READING)
    for channel, (dx, dy) in ((FOOD, (2, 1)), (WATER, (-2, 3)), (BRICK, (-3, -1)), (AGENT, (1, -2))):
        expected[channel, sector_of(dx, dy, 16)] = math.hypot(dx, dy)
    # The world's edge is on the obstacle channel (its own test below); the rest exactly.
    discs = [FOOD, WATER, BRICK, AGENT]
    np.testing.assert_allclose(got[discs], expected[discs], atol=1e-9)
    # The concrete sectors, so the convention (CCW from east, 16 sectors of 22.5°) is pinned.
    assert [int(np.flatnonzero(got[c] >= 0)[0]) for c in discs] == [1, 5, 8, 13]
    # The other agent sees "me" on its agent channel, north-west of it.
    theirs = ranges(w, "other")
    assert np.flatnonzero(theirs[AGENT] >= 0).tolist() == [5]
    assert theirs[AGENT, 5] == pytest.approx(math.hypot(1, 2))


@pytest.mark.parametrize("sectors", [1, 6, 16, 64])
def test_sector_k_covers_angles_k_to_k_plus_1_counter_clockwise_from_east(sectors):
    w = make(BIG, sensor_noise=0.0,
             sensor_sectors=sectors, sensor_range=7.0)
    w.attach("a")
    centre = pose(w, "a")[:2]
    width = 2 * math.pi / sectors
    for k in range(sectors):
        # just inside the start of sector k, at a distance that encodes k
        add(w, "brick", at_angle(centre, (k + 0.02) * width, 1.0 + 5.0 * k / sectors))
    tick(w)
    got = ranges(w, "a")[BRICK]
    if sectors == 1:
        assert got[0] == pytest.approx(1.0)
    else:
        np.testing.assert_allclose(got, 1.0 + 5.0 * np.arange(sectors) / sectors, atol=1e-9)


def test_nothing_beyond_sensor_range_is_seen():
    w = make("." * 10 + "A" + "." * 10, sensor_noise=0.0, sensor_range=4.0)
    w.attach("a")
    x, y, _ = pose(w, "a")
    add(w, "food", (x + 4.05, y))
    add(w, "water", (x - 3.95, y))
    tick(w)
    r = ranges(w, "a")
    assert np.all(r[FOOD] == NO_READING)
    assert r[WATER, 8] == pytest.approx(3.95)


def test_two_discs_in_one_sector_report_only_the_nearest():
    w = make(BIG, sensor_noise=0.0)
    w.attach("a")
    c = pose(w, "a")[:2]
    add(w, "brick", at_angle(c, 0.25, 4.0))
    add(w, "brick", at_angle(c, 0.15, 2.5))  # same sector 0 (22.5° wide), nearer
    add(w, "food", at_angle(c, 0.2, 1.5))  # another colour does not mask the bricks
    tick(w)
    r = ranges(w, "a")
    assert r[BRICK, 0] == pytest.approx(2.5)
    assert np.count_nonzero(r[BRICK] >= 0) == 1
    assert r[FOOD, 0] == pytest.approx(1.5)


def test_an_agent_does_not_sense_itself():
    w = make("...\n.A.\n...", sensor_noise=0.0)
    w.attach("a")
    tick(w)
    r = ranges(w, "a")
    assert np.all(np.delete(r, OBSTACLE, axis=0) == NO_READING)


def test_a_carried_brick_is_invisible_to_everyone_until_dropped():
    w = make(".....\n.bA.A\n.....", agents=2, sensor_noise=0.0)
    w.attach("a")
    w.attach("b")
    tick(w)
    assert np.count_nonzero(ranges(w, "a")[BRICK] >= 0) == 1
    assert ranges(w, "b")[BRICK].max() == pytest.approx(3.0)
    face_nearest_brick(w)
    tick(w, {"a": (0.0, 0.0, "grab")})
    assert w.frame("a").grabbed
    assert np.all(ranges(w, "a")[BRICK] == NO_READING)
    assert np.all(ranges(w, "b")[BRICK] == NO_READING)
    tick(w, {"a": (0.0, 0.0, "drop")})
    assert w.frame("a").dropped
    # The brick lies under a: a reads it at ~0, b at the a-b distance, west of it.
    assert ranges(w, "a")[BRICK].max() == pytest.approx(0.0, abs=1e-6)
    assert ranges(w, "b")[BRICK, 8] == pytest.approx(2.0, abs=1e-6)


def test_noise_grows_with_distance_and_readings_stay_within_range():
    w = make(BIG, seed=5, sensor_noise=0.05)
    w.attach("a")
    c = pose(w, "a")[:2]
    add(w, "food", at_angle(c, 0.2, 1.0))
    add(w, "water", at_angle(c, 2.0, 5.0))
    near, far = [], []
    for _ in range(300):
        tick(w)
        r = ranges(w, "a")
        near.append(r[FOOD, sector_of(math.cos(0.2), math.sin(0.2), 16)])
        far.append(r[WATER, sector_of(math.cos(2.0), math.sin(2.0), 16)])
    near, far = np.array(near), np.array(far)
    assert np.all(near >= 0) and np.all(far >= 0)
    assert far.std() > 3 * near.std() > 0
    assert near.std() == pytest.approx(0.05 * 1.0, rel=0.25)
    assert far.std() == pytest.approx(0.05 * 5.0, rel=0.25)
    assert near.mean() == pytest.approx(1.0, abs=0.02) and far.mean() == pytest.approx(5.0, abs=0.1)


def test_noisy_readings_are_clipped_to_zero_and_the_sensor_range():
    w = make(BIG, seed=9, sensor_noise=0.6)
    w.attach("a")
    c = pose(w, "a")[:2]
    add(w, "brick", at_angle(c, 0.2, 5.5))
    seen = []
    for _ in range(300):
        tick(w)
        r = ranges(w, "a")
        hits = r[r != NO_READING]
        assert np.all((hits >= 0) & (hits <= w.cfg.sensor_range))
        seen.append(r[BRICK, 0])
    seen = np.array(seen)
    # With a std of 3.3 around 5.5 both clips are hit; no reading is lost to them.
    assert np.any(seen == w.cfg.sensor_range) and np.any(seen == 0.0)
    assert np.all(seen != NO_READING)


def _reference_sense(agent_xy, sensing, disc_xy, disc_ch, sectors, radius, eps=1e-3):
    """Brute force: for every (agent, channel, sector), the nearest object within range.

    Returns (strict, loose): nearest distance over objects surely in the sector, and over
    objects possibly in it (within eps rad of a border either sector is right).
    """
    n = len(agent_xy)
    obj_xy = np.concatenate([disc_xy, agent_xy])
    obj_ch = np.concatenate([disc_ch, np.full(n, AGENT)])
    owner = np.concatenate([np.full(len(disc_xy), -1), np.arange(n)])
    width = 2 * np.pi / sectors
    strict = np.full((n, NCH, sectors), np.inf)
    loose = np.full((n, NCH, sectors), np.inf)
    candidates = [[[set() for _ in range(sectors)] for _ in range(NCH)] for _ in range(n)]
    for a in range(n):
        if not sensing[a]:
            continue
        d = obj_xy - agent_xy[a]
        dist = np.hypot(d[:, 0], d[:, 1])
        ang = np.arctan2(d[:, 1], d[:, 0]) % (2 * np.pi)
        for j in np.flatnonzero((dist <= radius) & (owner != a)):
            ch = obj_ch[j]
            near = {int((ang[j] + e) % (2 * np.pi) // width) % sectors for e in (-eps, 0.0, eps)}
            if len(near) == 1:  # clear of the sector borders
                k = near.pop()
                strict[a, ch, k] = min(strict[a, ch, k], dist[j])
                near = {k}
            for kk in near:
                loose[a, ch, kk] = min(loose[a, ch, kk], dist[j])
                candidates[a][ch][kk].add(round(float(dist[j]), 9))
    return strict, loose, candidates


@pytest.mark.parametrize("case", range(30))
def test_compiled_sweep_agrees_with_a_brute_force_reference(case):
    rng = np.random.default_rng(1000 + case)
    width, height = rng.uniform(3, 40, size=2)
    n, m = int(rng.integers(1, 25)), int(rng.integers(0, 120))
    sectors = int(rng.integers(1, 33))
    radius = float(rng.uniform(0.5, 12))
    agent_xy = rng.uniform((0, 0), (width, height), size=(n, 2))
    disc_xy = rng.uniform((0, 0), (width, height), size=(m, 2))
    disc_ch = rng.integers(0, 4, size=m)   # food, water, brick, obstacle points
    sensing = rng.random(n) < 0.8
    got = sense(agent_xy, sensing, disc_xy, disc_ch, sectors, radius, (width, height))
    assert got.shape == (n, NCH, sectors)
    strict, loose, candidates = _reference_sense(agent_xy, sensing, disc_xy, disc_ch, sectors, radius)
    assert np.all(got[~sensing] == NO_READING)
    for a, ch, k in np.ndindex(got.shape):
        v = got[a, ch, k]
        if v == NO_READING:
            assert strict[a, ch, k] == np.inf, (a, ch, k)
        else:
            assert round(float(v), 9) in candidates[a][ch][k], (a, ch, k, v)
            assert loose[a, ch, k] - 1e-12 <= v <= strict[a, ch, k] + 1e-12, (a, ch, k, v)


# ---------------------------------------------------------------- motion (W3)

ROOM = "\n".join(["." * 12] * 5)


def test_heading_turns_by_at_most_max_turn_per_tick():
    w = make(ROOM.replace(".", "A", 1), max_turn=0.5)
    w.attach("a")
    h0 = pose(w, "a")[2]
    tick(w, {"a": (0.0, 3.0, "none")})
    assert pose(w, "a")[2] - h0 == pytest.approx(0.5)
    assert w.frame("a").heading == pytest.approx(h0 + 0.5)
    tick(w, {"a": (0.0, -0.2, "none")})
    assert pose(w, "a")[2] - h0 == pytest.approx(0.3)
    tick(w, {"a": (0.0, -9.0, "none")})
    assert pose(w, "a")[2] - h0 == pytest.approx(-0.2)
    # a turn is one-shot: without a new turn command the heading stays
    tick(w, n=3)
    assert pose(w, "a")[2] - h0 == pytest.approx(-0.2)
    # the compass wraps into [-pi, pi)
    for _ in range(20):
        tick(w, {"a": (0.0, 0.5, "none")})
        assert -math.pi <= w.frame("a").heading < math.pi


def _speeds(w: World, agent_id: str, speed: float, ticks: int) -> np.ndarray:
    steps = []
    for _ in range(ticks):
        before = pose(w, agent_id)[:2]
        tick(w, {agent_id: (speed, 0.0, "none")})
        steps.append(np.hypot(*(pose(w, agent_id)[:2] - before)))
    return np.array(steps) / w.cfg.dt


def test_inertia_ramps_speed_up_gradually_to_max_speed():
    w = make("A" + "." * 39, inertia=0.3)
    w.attach("a")
    v = _speeds(w, "a", 3.0, 30)
    assert v[:3].max() < 0.6 * 3.0  # not full speed at once
    assert np.all(np.diff(v[:10]) > 0)  # speeds up tick by tick
    assert v[-5:] == pytest.approx(3.0, rel=0.01)  # and gets there
    # without inertia the set point is reached almost at once
    w1 = make("A" + "." * 39, inertia=1.0)
    w1.attach("a")
    assert _speeds(w1, "a", 3.0, 3)[-1] == pytest.approx(3.0, rel=0.01)


def test_speed_is_clipped_to_max_speed_and_cannot_be_negative():
    w = make("A" + "." * 39, max_speed=2.0)
    w.attach("a")
    v = _speeds(w, "a", 50.0, 25)
    assert v.max() <= 2.0 + 1e-9 and v[-1] == pytest.approx(2.0, rel=0.01)
    w = make("." * 20 + "A" + "." * 19)
    w.attach("a")
    x0 = pose(w, "a")[0]
    tick(w, {"a": (-3.0, 0.0, "none")}, 10)
    assert pose(w, "a")[0] == pytest.approx(x0)


def test_an_agent_driving_into_a_disc_stops_at_contact_and_never_passes():
    w = make(".A....b...\n.A....F...\n.A....W...", agents=3)
    for a in "xyz":
        w.attach(a)
    contact = w.cfg.agent_radius + w.cfg.disc_radius
    for _ in range(60):
        tick(w, dict.fromkeys("xyz", (3.0, 0.0, "none")))
        xs = w.agent_poses()[:, 0]
        assert np.all(6.5 - xs >= contact - STEP)
    np.testing.assert_allclose(w.agent_poses()[:, 0], 6.5 - contact, atol=TOL)
    # pushing on does not shift the disc either
    assert ranges(w, "x")[BRICK, 0] == pytest.approx(contact, abs=TOL)


def test_an_agent_stops_at_an_obstacle_and_at_the_world_edge():
    w = make(".A..#.\n......")
    w.attach("a")
    for _ in range(40):
        tick(w, {"a": (3.0, 0.0, "none")})
        assert pose(w, "a")[0] <= 4.0 - w.cfg.agent_radius + STEP
    assert pose(w, "a")[0] == pytest.approx(4.0 - w.cfg.agent_radius, abs=TOL)
    face(w, "a", math.pi / 2)
    for _ in range(30):
        tick(w, {"a": (3.0, 0.0, "none")})
        assert pose(w, "a")[1] <= 2.0 - w.cfg.agent_radius + STEP
    assert pose(w, "a")[1] == pytest.approx(2.0 - w.cfg.agent_radius, abs=0.06)


def test_a_crowd_of_wandering_agents_stays_inside_the_world():
    w = make("AAAAAA\nAAAAAA\nAAAAAA\nAAAAAA", agents=24)
    ids = [f"a{i}" for i in range(24)]
    for a in ids:
        w.attach(a)
    rng = np.random.default_rng(3)
    for t in range(300):
        for a in ids:
            w.set_command(a, 3.0, float(rng.uniform(-1.5, 1.5)) if t % 15 == 0 else 0.0, "none")
        w.step()
        xy = w.agent_poses()[:, :2]
        assert np.all((xy > 0) & (xy < w.size)), t


def test_a_speed_that_could_tunnel_through_walls_is_rejected():
    # One tick may move a body at most its radius (max_speed * dt <= agent_radius); faster
    # bodies pass through the world's edge, so such a world is refused up front.
    with pytest.raises(ScenarioError, match="max_speed"):
        scenario(".A.", max_speed=4.0)
    with pytest.raises(ValueError):
        WorldConfig(agent_radius=0.2)
    WorldConfig(max_speed=6.0, dt=0.05)  # the same speed in smaller steps is fine


def test_odometry_equals_the_displacement_without_noise():
    w = make(".........\n....A....\n.........\n....b....\n.........")
    w.attach("a")
    rng = np.random.default_rng(4)
    moved = 0.0
    for _ in range(150):
        before = pose(w, "a")[:2]
        tick(w, {"a": (float(rng.uniform(0, 3)), float(rng.uniform(-1, 1)), "none")})
        f = w.frame("a")
        step = pose(w, "a")[:2] - before
        assert (f.odom_dx, f.odom_dy) == pytest.approx(tuple(step), abs=1e-12)
        moved += float(np.hypot(*step))
    assert moved > 5  # it went somewhere, bumping into walls and the brick on the way
    # `distance` in the status is the path length, not the net displacement
    assert w.status().agent_distance[0] == pytest.approx(moved, rel=1e-9)


def test_odometry_noise_only_while_moving():
    w = make("A" + "." * 29, seed=2, odometry_noise=0.1)
    w.attach("a")
    tick(w, n=3)
    f = w.frame("a")
    assert (f.odom_dx, f.odom_dy) == (0.0, 0.0)
    errors = []
    for _ in range(30):
        before = pose(w, "a")[:2]
        tick(w, {"a": (3.0, 0.0, "none")})
        f = w.frame("a")
        errors.append(np.hypot(f.odom_dx - (pose(w, "a")[0] - before[0]), f.odom_dy))
    assert max(errors) > 0.001


# ---------------------------------------------------------------- gripper (W4)


def test_grab_only_within_reach():
    # bricks 1 (east) and sqrt(2) (north-west) cells away; grab_reach is 1.2
    w = make(".b...\n..Ab.\n.....", sensor_noise=0.0)
    w.attach("a")
    face_nearest_brick(w)
    tick(w, {"a": (0.0, 0.0, "grab")})
    f = w.frame("a")
    assert f.grabbed and f.holding
    assert np.flatnonzero(ranges(w, "a")[BRICK] >= 0).tolist() == [6]  # the east one is gone
    w2 = make("b....\n.....\nA.b..")
    w2.attach("a")
    face_nearest_brick(w2)
    tick(w2, {"a": (0.0, 0.0, "grab")})
    f = w2.frame("a")
    assert not f.grabbed and not f.holding
    assert w2.status().agent_grabs == (0,)
    w3 = make(".b...\n.....\n..A..", grab_reach=2.5)
    w3.attach("a")
    face_nearest_brick(w3)
    tick(w3, {"a": (0.0, 0.0, "grab")})
    assert w3.frame("a").grabbed


def test_an_agent_carries_at_most_one_brick():
    w = make(".....\n.bAb.\n.....")
    w.attach("a")
    face_nearest_brick(w)
    tick(w, {"a": (0.0, 0.0, "grab")})
    assert w.frame("a").grabbed
    face_nearest_brick(w)
    tick(w, {"a": (0.0, 0.0, "grab")})
    f = w.frame("a")
    assert not f.grabbed and f.holding
    assert np.count_nonzero(ranges(w, "a")[BRICK] >= 0) == 1  # the other one stays put
    assert w.status().agent_grabs == (1,)
    assert w.status().bricks_total == 2


def test_drop_puts_the_brick_where_the_agent_stands():
    w = make("........\n.bA.....\n........\n......A.", agents=2, sensor_noise=0.0)
    w.attach("a")
    w.attach("obs")
    face_nearest_brick(w)
    tick(w, {"a": (0.0, 0.0, "grab")})
    drive_to(w, "a", (4.5, 1.7))
    where = pose(w, "a")[:2]
    tick(w, {"a": (0.0, 0.0, "drop")})
    f = w.frame("a")
    assert f.dropped and not f.holding
    assert w.status().agent_drops == (1, 0) and w.status().bricks_total == 1
    obs = pose(w, "obs")[:2]
    d = where - obs
    assert ranges(w, "obs")[BRICK, sector_of(*d, 16)] == pytest.approx(np.hypot(*d), abs=1e-6)
    # the brick can be picked up again from there
    face_nearest_brick(w)
    tick(w, {"a": (0.0, 0.0, "grab")})
    assert w.frame("a").grabbed


def test_drop_without_a_brick_does_nothing():
    w = make(".....\n.bA..\n.....", sensor_noise=0.0)
    w.attach("a")
    tick(w, {"a": (0.0, 0.0, "drop")})
    f = w.frame("a")
    assert not f.dropped and not f.holding
    s = w.status()
    assert s.agent_drops == (0,) and s.bricks_total == 1
    assert ranges(w, "a")[BRICK, 8] == pytest.approx(1.0, abs=1e-6)


def test_a_brick_dropped_on_a_drop_site_fills_it():
    w = make(".b..\n.A+.\n....")
    w.attach("a")
    s = w.status()
    assert (s.sites_total, s.sites_filled, s.completed) == (1, 0, False)
    face_nearest_brick(w)
    tick(w, {"a": (0.0, 0.0, "grab")})
    assert w.frame("a").grabbed
    drive_to(w, "a", (2.5, 1.5))
    tick(w, {"a": (0.0, 0.0, "drop")})
    assert w.frame("a").dropped
    s = w.status()
    assert (s.sites_total, s.sites_filled, s.completed) == (1, 1, True)
    # and picking it up again empties the site
    face_nearest_brick(w)
    tick(w, {"a": (0.0, 0.0, "grab")})
    assert w.frame("a").grabbed and w.status().sites_filled == 0


def test_a_brick_dropped_off_centre_in_an_empty_drop_site_settles_on_its_centre():
    # Off-centre site bricks narrow the one-cell gaps between sites below a body's width.
    w = make(".b...\n.A+..\n.....", sensor_noise=0.0)
    w.attach("a")
    face_nearest_brick(w)
    tick(w, {"a": (0.0, 0.0, "grab")})
    brick = w.agents["a"].holding
    drive_to(w, "a", (2.8, 1.25))
    tick(w, {"a": (0.0, 0.0, "drop")})
    assert w.frame("a").dropped and w.status().sites_filled == 1
    assert w.discs.xy[brick] == pytest.approx((2.5, 1.5))
    # off every site, a brick stays where it fell
    face_nearest_brick(w)
    tick(w, {"a": (0.0, 0.0, "grab")})
    drive_to(w, "a", (3.7, 0.8))
    tick(w, {"a": (0.0, 0.0, "drop")})
    assert w.discs.xy[brick] == pytest.approx(pose(w, "a")[:2], abs=0.05)
    assert w.status().sites_filled == 0


def test_a_dropped_brick_does_not_kick_the_agent_and_is_solid_once_left():
    w = make(".b........\n.A........\n..........")
    w.attach("a")
    face_nearest_brick(w)
    tick(w, {"a": (0.0, 0.0, "grab")})
    w.heading[w.agents["a"].index] = 0.0  # face east again: the drive below goes east
    tick(w, n=5)
    start = pose(w, "a")[:2].copy()
    tick(w, {"a": (0.0, 0.0, "drop")})
    assert w.frame("a").dropped
    for _ in range(5):
        tick(w)
        assert np.hypot(*(pose(w, "a")[:2] - start)) < 0.2
    # drive away, turn round and drive back into the brick: it is an obstacle again
    tick(w, {"a": (3.0, 0.0, "none")}, 15)
    face(w, "a", math.pi)
    contact = w.cfg.agent_radius + w.cfg.disc_radius
    for _ in range(40):
        tick(w, {"a": (3.0, 0.0, "none")})
        assert pose(w, "a")[0] - start[0] >= contact - STEP
    assert pose(w, "a")[0] - start[0] == pytest.approx(contact, abs=TOL)


# ---------------------------------------------------------------- eat and drink (W5)


@pytest.mark.parametrize("kind,action,flag,other", [("F", "eat", "ate", "W"), ("W", "drink", "drank", "F")])
def test_eat_and_drink_need_touching_the_right_disc(kind, action, flag, other):
    w = make(f"{other}.......\n{kind}..A....\n........")
    w.attach("a")
    tick(w, {"a": (0.0, 0.0, action)})
    assert not getattr(w.frame("a"), flag)  # 3 cells away
    face(w, "a", math.pi)
    tick(w, {"a": (3.0, 0.0, "none")}, 30)  # drive west until blocked by the disc
    assert pose(w, "a")[0] == pytest.approx(0.5 + w.cfg.agent_radius + w.cfg.disc_radius, abs=TOL)
    tick(w, {"a": (0.0, 0.0, action)})
    assert getattr(w.frame("a"), flag)
    tick(w)
    assert not getattr(w.frame("a"), flag)  # a flag reports one action, not a state
    tick(w, {"a": (0.0, 0.0, action)})
    assert getattr(w.frame("a"), flag)  # the disc was not used up
    ch = FOOD if kind == "F" else WATER
    assert ranges(w, "a")[ch].max() == pytest.approx(0.8, abs=0.05)
    # the other kind of disc does not satisfy this need, even when touching
    w2 = make(f"........\n{other}A......\n........")
    w2.attach("a")
    face(w2, "a", math.pi)
    tick(w2, {"a": (3.0, 0.0, "none")}, 10)
    tick(w2, {"a": (0.0, 0.0, action)})
    assert not getattr(w2.frame("a"), flag)


# ---------------------------------------------------------------- agents come and go (S2)


def test_new_agents_get_free_starts_and_never_overlap():
    w = make("A..\n.#.\n..A", agents=3)
    a = w.attach("a")
    b = w.attach("b")
    assert (a.x, a.y, a.body) == (0.5, 2.5, 0)
    assert (b.x, b.y, b.body) == (2.5, 0.5, 1)
    c = w.attach("c")  # no A left: an empty cell one step from a start (the first in reading order)
    assert (c.x, c.y) == (1.5, 2.5)
    # a leaves its start for an empty cell; a newcomer gets the freed A, not a's cell
    drive_to(w, "a", (0.5, 1.5))
    d = w.attach("d")
    assert (d.x, d.y) == (0.5, 2.5)
    e = w.attach("e")  # (1, 0) holds c, (0, 1) holds a: the next cell one step from a start
    assert (e.x, e.y) == (2.5, 1.5)
    xy = w.agent_poses()[:, :2]
    dist = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1))
    assert dist[np.triu_indices(len(xy), 1)].min() >= 2 * w.cfg.agent_radius
    assert w.status().agents_alive == 5


def test_agents_beyond_the_starts_gather_round_them_on_their_side_of_a_wall():
    w = make("""
............
............
#########...
A...........
............""", agents=1)
    cells = w.scenario.to_cell([(m.x, m.y) for m in (w.attach(f"a{i}") for i in range(7))])
    # nearest the start by walking, ties in reading order: not the top-left corner, which is
    # two cells away in a straight line but beyond the wall
    assert [tuple(c) for c in cells] == [(0, 3), (1, 3), (0, 4), (2, 3), (1, 4), (3, 3), (2, 4)]


def test_reattach_returns_the_same_body_and_pose():
    w = make("A....\n.....\n...A.", agents=2)
    first = w.attach("a")
    w.attach("b")
    drive_to(w, "a", (2.5, 1.5))
    tick(w, {"a": (0.0, 0.7, "none")})
    w.detach("a")
    tick(w, n=3)
    before = pose(w, "a").copy()
    again = w.attach("a")
    assert again.body == first.body
    assert (again.x, again.y, again.heading) == pytest.approx(tuple(before), abs=1e-6)
    assert again.restarts == 1 and first.restarts == 0
    assert w.attach("a").restarts == 2
    s = w.status()
    assert s.agent_ids == ("a", "b") and s.agent_restarts == (2, 0)
    assert w.set_command("a", 1.0, 0.0, "none")


def test_a_repeated_attach_from_the_same_live_process_is_not_a_restart():
    w = make("A....\n.....\n...A.", agents=2)
    first = w.attach("a", pid=100)
    assert w.attach("a", pid=100).restarts == 0        # a retry, answered again
    assert w.attach("a", pid=100).body == first.body
    assert w.attach("a", pid=200).restarts == 1        # another process took the id over
    w.detach("a")
    assert w.attach("a", pid=200).restarts == 2        # the same pid after a detach: back again


def test_detach_puts_the_brick_down_stops_the_body_and_refuses_commands():
    w = make(".........\n.........\n.bA...A..\n.........\n.........", agents=2, sensor_noise=0.0)
    w.attach("a")
    w.attach("b")
    face_nearest_brick(w)
    tick(w, {"a": (0.0, 0.0, "grab")})
    assert w.frame("a").holding
    tick(w, {"a": (3.0, 0.0, "none")}, 4)  # moving east
    w.detach("a")
    assert w.status().bricks_total == 1 and w.agents["a"].holding == -1
    assert w.status().agent_alive == (False, True) and w.live_agents() == ["b"]
    tick(w)
    _, vel = w.physics.state()
    assert np.hypot(*vel[0]) < 1e-6
    stopped = pose(w, "a")[:2].copy()
    tick(w, n=5)
    assert pose(w, "a")[:2] == pytest.approx(stopped)
    assert not w.set_command("a", 3.0, 0.0, "grab")
    assert not w.set_command("nobody", 3.0, 0.0, "none")
    tick(w, n=2)
    assert pose(w, "a")[:2] == pytest.approx(stopped)
    assert [f.agent_id for f in w.frames()] == ["b"]
    # the brick lies on a cell centre clear of both bodies; b sees it, and a's body as an agent
    brick = w.discs.xy[np.flatnonzero(w.discs.kind == 2)[0]]
    assert (brick % 1.0) == pytest.approx((0.5, 0.5))
    for body in (stopped, pose(w, "b")[:2]):
        assert np.hypot(*(brick - body)) >= w.cfg.disc_radius + w.cfg.agent_radius
    r = ranges(w, "b")
    bxy = pose(w, "b")[:2]
    assert r[BRICK].max() == pytest.approx(np.hypot(*(brick - bxy)), abs=1e-6)
    assert r[AGENT, sector_of(*(stopped - bxy), 16)] == pytest.approx(np.hypot(*(stopped - bxy)), abs=1e-6)
    # the world keeps running for the others
    tick(w, {"b": (0.0, 1.0, "none")})
    assert w.tick > 0 and w.frame("b").heading == pytest.approx(1.0)


def test_a_dead_body_leaves_the_world_after_its_grace_period():
    w = make("A.....A", agents=2, sensor_noise=0.0, body_grace_ticks=5)
    w.attach("a")
    w.attach("b")
    w.detach("a")
    tick(w, n=4)
    assert (ranges(w, "b")[AGENT] != NO_READING).any()   # still there, and solid
    assert w.status().agent_present == (True, True) and w.status().agent_alive == (False, True)
    tick(w)
    assert (ranges(w, "b")[AGENT] == NO_READING).all()   # gone: no sensor sees it
    assert w.status().agent_present == (False, True)     # and the status says so
    # b drives through where a's body lies: nothing stops it
    tick(w, {"b": (0.0, math.pi / 2, "none")}, 2)  # face west
    tick(w, {"b": (3.0, 0.0, "none")}, 40)
    assert pose(w, "b")[0] < 0.5
    assert w.status().agents_alive == 1
    # a newcomer may start where a dead body lies, once it has left
    w = make("A.....A", agents=2, body_grace_ticks=0)
    w.attach("a")
    w.detach("a")
    assert w.attach("c").x == 0.5


def test_a_restarted_agent_gets_its_body_back_at_the_free_cell_nearest_where_it_left():
    w = make("......\n.A....\n......\n....A.", agents=2, sensor_noise=0.0, body_grace_ticks=0)
    w.attach("a")
    w.attach("b")
    left = pose(w, "a")[:2].copy()
    w.detach("a")
    # b comes to stand where a's body was (it no longer collides), and a brick lands beside
    w.physics.place_body(w.agents["b"].index, left)
    w.perturb(Perturbation("add", left[0] + 1, left[1], "brick", 0.0, 0.0, False))
    tick(w)
    assert w.status().agent_present == (False, True)
    back = w.attach("a")
    assert back.restarts == 1 and w.status().agent_present == (True, True)
    xy = np.array([back.x, back.y])
    assert np.hypot(*(xy - left)) == pytest.approx(1.0)          # a neighbouring cell
    assert (xy % 1.0) == pytest.approx((0.5, 0.5))
    assert np.hypot(*(xy - pose(w, "b")[:2])) >= 2 * w.cfg.agent_radius
    present = w.discs.xy[w.discs.state == 0]
    assert np.hypot(*(present - xy).T).min() >= w.cfg.disc_radius + w.cfg.agent_radius
    assert (ranges(w, "b")[AGENT] != NO_READING).any()             # solid and sensed again
    tick(w, {"a": (3.0, 0.0, "none")}, 3)
    assert pose(w, "a")[:2] != pytest.approx(xy)                    # and it moves


POCKET = """
A........
.........
...bbb...
...b.b...
...b.b...
.........
"""


@pytest.mark.parametrize("sealed", [True, False])
def test_a_body_never_comes_back_inside_a_pocket_sealed_while_it_was_away(sealed):
    from world_server.buildability import reachable

    w = make(POCKET, agents=1, sensor_noise=0.0, body_grace_ticks=0)
    w.attach("a")
    inside = w.scenario.to_world([(4, 3)])[0]   # in the horseshoe of bricks, open to the south
    w.physics.place_body(w.agents["a"].index, inside)
    tick(w)
    w.detach("a")                               # grace 0: the body leaves the world at once
    if sealed:  # a brick closes the horseshoe's mouth while the body is away
        assert w.perturb(Perturbation("add", *w.scenario.to_world([(4, 4)])[0], "brick", 0.0, 0.0, False)).ok
    back = w.attach("a")
    cell = tuple(int(v) for v in w.scenario.to_cell([(back.x, back.y)])[0])
    if not sealed:
        assert cell == (4, 3)                   # the pocket is open: back where it was
        return
    layout = [row[:4] + "b" + row[5:] if r == 4 else row for r, row in enumerate(w.scenario.layout)]
    assert cell in reachable(layout)            # the open world, not the sealed pocket
    assert np.hypot(cell[0] - 4, cell[1] - 3) == pytest.approx(2.0)  # and the nearest such cell


def test_a_dead_agents_brick_never_fills_a_site_and_bricks_are_conserved():
    # The body dies standing on a site, holding a brick: the brick goes elsewhere.
    w = make(".......\n.......\n..b+...\n.......\n.......", agents=1, sensor_noise=0.0)
    w.attach("a", )
    face_nearest_brick(w)  # the body starts at the first empty cell (0, 0)
    w.physics.place_body(0, (3.5, 2.5))
    w.heading[0] = math.pi
    tick(w, {"a": (0.0, 0.0, "grab")})
    assert w.agents["a"].holding >= 0
    filled, total = w.status().sites_filled, w.status().bricks_total
    w.detach("a")
    assert (w.status().sites_filled, w.status().bricks_total) == (filled, total) == (0, 1)
    brick = w.discs.xy[np.flatnonzero(w.discs.kind == 2)[0]]
    site = w.sites_xy[0]
    assert np.abs(brick - site).max() >= 2.0  # not on the site, not beside it


# ---------------------------------------------------------------- perturbation (W6)


def test_remove_takes_the_nearest_disc_within_three_quarters_of_a_cell():
    w = make("......\n.A.bb.\n......", sensor_noise=0.0)
    w.attach("a")
    tick(w)
    assert w.status().bricks_total == 2
    miss = w.perturb(Perturbation("remove", 3.5, 2.3))  # 0.8 from the nearest disc
    assert not miss.ok and w.status().bricks_total == 2
    res = w.perturb(Perturbation("remove", 3.9, 1.3))  # nearer the west brick (3.5, 1.5)
    assert res.ok and res.tick == w.tick
    tick(w)
    assert w.status().bricks_total == 1
    assert ranges(w, "a")[BRICK, 0] == pytest.approx(3.0)
    assert not w.perturb(Perturbation("remove", 3.5, 1.5)).ok  # nothing left there


def test_add_and_move_discs_and_refuse_points_outside():
    w = make("......\n.A....\n......", sensor_noise=0.0)
    w.attach("a")
    assert w.perturb(Perturbation("add", 4.5, 1.5, kind="brick")).ok
    assert w.perturb(Perturbation("add", 1.5, 0.5, kind="food")).ok
    assert w.status().bricks_total == 1
    tick(w)
    r = ranges(w, "a")
    assert r[BRICK, 0] == pytest.approx(3.0) and r[FOOD, 12] == pytest.approx(1.0)
    assert w.perturb(Perturbation("move", 4.4, 1.6, to_x=1.5, to_y=2.5)).ok
    tick(w)
    r = ranges(w, "a")
    assert r[BRICK, 4] == pytest.approx(1.0) and np.count_nonzero(r[BRICK] >= 0) == 1
    assert w.status().bricks_total == 1
    for p in (Perturbation("add", -0.5, 1.0), Perturbation("add", 3.0, 3.5, kind="water"),
              Perturbation("move", 1.5, 2.5, to_x=6.5, to_y=1.0)):
        assert not w.perturb(p).ok
    tick(w)
    r = ranges(w, "a")
    assert r[BRICK, 4] == pytest.approx(1.0) and np.all(r[WATER] == NO_READING)
    assert w.status().bricks_total == 1


def test_removing_a_brick_from_a_site_unfills_it_and_adding_one_fills_it():
    w = make("BB+\n...", agents=0)
    s = w.status()
    assert (s.sites_total, s.sites_filled, s.completed) == (3, 2, False)
    assert w.perturb(Perturbation("remove", 0.5, 1.5)).ok
    assert w.status().sites_filled == 1 and w.status().bricks_total == 1
    refused = w.perturb(Perturbation("add", 0.4, 1.6))  # a brick here would fill the site: only when forced
    assert not refused.ok and "drop site" in refused.message and "force" in refused.message
    assert w.status().sites_filled == 1 and w.status().bricks_total == 1
    assert w.perturb(Perturbation("add", 0.4, 1.6, force=True)).ok
    assert w.perturb(Perturbation("add", 2.5, 1.5, force=True)).ok
    s = w.status()
    assert (s.sites_filled, s.completed, s.bricks_total) == (3, True, 3)
    assert w.perturb(Perturbation("move", 1.5, 1.5, to_x=1.5, to_y=0.5)).ok
    s = w.status()
    assert (s.sites_filled, s.completed) == (2, False)


def test_add_refuses_a_disc_on_an_agent_body_unless_forced():
    w = make("......\n.A....\n......", sensor_noise=0.0)
    w.attach("a")
    x, y, _ = pose(w, "a")
    near = x + w.cfg.disc_radius + w.cfg.agent_radius - 0.05  # would overlap the body
    refused = w.perturb(Perturbation("add", near, y, kind="food"))
    assert not refused.ok and "agent a" in refused.message and w.discs.present().size == 0
    assert w.perturb(Perturbation("add", x + 1.0, y, kind="food")).ok  # next cell: clear of the body
    assert w.perturb(Perturbation("add", near, y, kind="food", force=True)).ok


# ---------------------------------------------------------------- status


@pytest.mark.parametrize("layout,total,filled,completed", [
    ("+.+\nb.b", 2, 0, False),
    ("+B.\nb..", 2, 1, False),
    ("BB.\n...", 2, 2, True),
    ("b..\n...", 0, 0, False),  # no blueprint: nothing to complete
])
def test_status_counts_sites(layout, total, filled, completed):
    s = make(layout, agents=0).status()
    assert (s.sites_total, s.sites_filled, s.completed) == (total, filled, completed)
    assert s.bricks_total == layout.count("b") + layout.count("B")


# ---------------------------------------------------------------- determinism (W7)

DET_LAYOUT = """
F.....b...
..A...+...
....b.+.W.
..b...A...
.....b....
"""


def _run(seed: int, ticks: int = 200) -> list[bytes]:
    w = make(DET_LAYOUT, seed=seed, agents=2, sensor_noise=0.05, odometry_noise=0.05)
    w.attach("a")
    w.attach("b")
    cmd = np.random.default_rng(77)  # the command sequence is the same for every run
    actions = ("none", "none", "none", "grab", "drop", "eat", "drink")
    out = []
    for _ in range(ticks):
        for a in ("a", "b"):
            w.set_command(a, float(cmd.uniform(0, 3)), float(cmd.uniform(-0.8, 0.8)),
                          actions[int(cmd.integers(len(actions)))])
        w.step()
        out.extend(encode(f) for f in w.frames())
        out.append(encode(w.status()))
    return out


def test_same_seed_and_commands_give_identical_frames():
    first, second = _run(11), _run(11)
    assert len(first) == 600
    assert first == second


def test_a_different_seed_gives_different_noisy_frames():
    assert _run(11, 30) != _run(12, 30)


def _encoded_frames_match(w: World) -> None:
    assert w.encoded_frames() == [(f.agent_id, encode(f)) for f in w.frames()]


@pytest.mark.parametrize("cue_reach", [0.0, 6.0])
def test_the_frames_the_server_sends_are_the_encoded_frames_byte_for_byte(cue_reach):
    # The world server publishes World.encoded_frames, built from the arrays without a
    # SensorFrame each: an agent must get the bytes encode(frame) gives, through grabs,
    # drops, eating, noise, cues marked, and an agent that left (no frame of its own).
    w = make(DET_LAYOUT, seed=5, agents=3, sensor_noise=0.05, odometry_noise=0.05, cue_reach=cue_reach)
    for a in ("a", "b", "c"):
        w.attach(a)
    cmd = np.random.default_rng(78)
    actions = ("none", "none", "grab", "drop", "eat", "drink", "mark", "unmark")
    for tick in range(150):
        if tick == 60:
            w.detach("b")
        for a in w.live_agents():
            w.set_command(a, float(cmd.uniform(0, 3)), float(cmd.uniform(-0.8, 0.8)),
                          actions[int(cmd.integers(len(actions)))], (float(cmd.uniform(-2, 2)), 0.5, "site"))
        w.step()
        _encoded_frames_match(w)
    assert [a for a, _ in w.encoded_frames()] == ["a", "c"]


def test_a_world_reading_no_frame_may_carry_is_refused_as_a_sensor_frame_refuses_it():
    # The one check of the arrays stands for SensorFrame's own: a NaN or a negative range
    # other than NO_READING gets SensorFrame's error, not bytes that every agent would drop.
    w = make(DET_LAYOUT, agents=2)
    w.attach("a")
    w.attach("b")
    for bad in (np.nan, -0.5):
        w._ranges[1, 0, 3] = bad
        with pytest.raises(ValueError, match="SensorFrame"):
            w.encoded_frames()
    w._ranges[1, 0, 3] = 1.0
    w.heading[0] = np.inf
    with pytest.raises(ValueError, match="not finite"):
        w.encoded_frames()


# ---------------------------------------------------------------- what the Welcome tells an agent


def test_the_welcome_states_the_constants_of_the_world_config_in_use():
    from protocol.messages import WELCOME_CONSTANTS

    w = make("A....\n.....", max_speed=2.0, dt=0.125, max_turn=0.4, inertia=0.7, grab_reach=1.1,
             grab_cone=0.9, sensor_range=4.5, sensor_noise=0.05, odometry_noise=0.01, touch_margin=0.2)
    welcome = w.attach("a")
    for name in WELCOME_CONSTANTS:
        assert getattr(welcome, name) == pytest.approx(getattr(w.cfg, name)), name
    assert (welcome.max_speed, welcome.dt, welcome.max_turn, welcome.grab_cone) == (2.0, 0.125, 0.4, 0.9)
    assert welcome.sensor_range == 4.5 and welcome.drop_tolerance == 0.5 * welcome.cell_size
    d = make("A.\n..").attach("a")  # the defaults come from WorldConfig, not from the message
    assert (d.max_speed, d.dt, d.agent_radius, d.disc_radius) == (3.0, 0.1, 0.3, 0.5)


@pytest.mark.parametrize("speed", [1.0, 2.0, 5.0])
def test_speed_moves_speed_times_dt_per_tick_up_to_max_speed(speed):
    # What an external agent works out from the Welcome: speed 1.0 moves 0.1 units per
    # tick once inertia has caught up, and 5.0 is clipped to max_speed (0.3 per tick).
    w = make("A" + "." * 59)
    welcome = w.attach("a")
    tick(w, {"a": (speed, 0.0, "none")}, 20)
    x0 = pose(w, "a")[0]
    tick(w, {"a": (speed, 0.0, "none")})
    per_tick = min(speed, welcome.max_speed) * welcome.dt
    assert pose(w, "a")[0] - x0 == pytest.approx(per_tick, rel=1e-3)
    assert w.frame("a").odom_dx == pytest.approx(per_tick, rel=1e-3)  # odometry: world axes, no noise here


def test_heading_zero_is_east_a_positive_turn_is_counter_clockwise_and_motion_follows_a_tick_later():
    w = make("." * 9 + "\n" + "....A...." + "\n" + "." * 9, inertia=1.0)
    welcome = w.attach("a")
    assert welcome.heading == 0.0
    tick(w, {"a": (1.0, 0.0, "none")})  # command for tick 0: frame 1 shows no motion yet ...
    assert (w.frame("a").odom_dx, w.frame("a").odom_dy) == (0.0, 0.0)
    tick(w, {"a": (1.0, 0.0, "none")})  # ... frame 2 does: east
    f = w.frame("a")
    assert f.odom_dx == pytest.approx(0.1) and f.odom_dy == pytest.approx(0.0, abs=1e-9)
    tick(w, {"a": (1.0, math.pi / 2, "none")})  # the turn shows at once, the motion along it a tick later
    f = w.frame("a")
    assert f.heading == pytest.approx(math.pi / 2) and f.odom_dx == pytest.approx(0.1)
    tick(w, {"a": (1.0, 0.0, "none")})
    f = w.frame("a")
    assert f.odom_dy == pytest.approx(0.1) and abs(f.odom_dx) < 1e-6  # north


def test_lockstep_waits_for_responsive_agents_and_takes_a_silent_one_back_when_it_answers():
    from world_server.lockstep import LockstepWaits

    waits = LockstepWaits(miss_limit=2)
    assert waits.awaited(["a", "b"]) == ["a", "b"]
    assert waits.deadline_passed(["b"]) == []
    assert waits.awaited(["a", "b"]) == ["a", "b"]       # one miss is not enough
    assert waits.deadline_passed(["b"]) == ["b"]         # two in a row: unresponsive
    assert waits.awaited(["a", "b"]) == ["a"]
    assert waits.awaited(["b"]) == ["b"]                 # alone, it is still waited for
    assert waits.heard("b") and not waits.unresponsive("b")
    assert waits.awaited(["a", "b"]) == ["a", "b"]
    waits.deadline_passed(["b"])
    waits.heard("b")                                     # an answer in between resets the count
    assert waits.deadline_passed(["b"]) == [] and not waits.unresponsive("b")
    waits.forget("b")
    assert waits.missed == {}
