"""The cheaper decision step's pieces give what the plain code gave: the field cache, the
flood-fill reachability, and the compiled gradient and mouth-side rules, each against a
plain reference on random maps (issue 31: decisions may not change)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent_runtime import brain as brain_module
from agent_runtime.brain import _extent, _mouth_side, _nearest_cell, _nearest_reading
from agent_runtime.config import AgentConfig
from agent_runtime.esm import EDGE_RINGS, map_extent
from agent_runtime.far_memory import _age_sites, _observe_sites
from agent_runtime.field_cache import FieldCache
from agent_runtime.spreading import (
    _STEP,
    MOVES,
    FieldWork,
    distance_field,
    gradient_step,
    reachable,
    readonly,
    seeded_distance_field,
)
from conag import sim
from tests.test_spreading import grids
from world_server.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent


def _plain_gradient_step(dist: np.ndarray) -> tuple[int, int] | None:
    """gradient_step as it was written before it was compiled (the reference)."""
    n, m = dist.shape
    r, c = n // 2, m // 2
    here = float(dist[r, c])
    if not math.isfinite(here):
        return None
    if here == 0.0:
        return (0, 0)

    def passable(i, j):
        return 0 <= i < n and 0 <= j < m and math.isfinite(dist[i, j])

    costs = []
    for (dr, dc), step in zip(MOVES, _STEP.tolist()):
        ok = passable(r + dr, c + dc) and (dr == 0 or dc == 0 or (passable(r + dr, c) and passable(r, c + dc)))
        costs.append(step + float(dist[r + dr, c + dc]) if ok else math.inf)
    best = min(costs)
    return next(move for move, cost in zip(MOVES, costs) if cost <= best + 1e-9)


def _plain_mouth_side(held, sites, depth):
    """_mouth_side as it was written with numpy slices (the reference)."""
    out = np.zeros_like(sites)
    n, m = sites.shape
    for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        src = (slice(max(-dr, 0), n - max(dr, 0)), slice(max(-dc, 0), m - max(dc, 0)))
        dst = (slice(max(dr, 0), n - max(-dr, 0)), slice(max(dc, 0), m - max(-dc, 0)))
        out[dst] |= held[src] & (depth[dst] <= depth[src] + 1e-9) & np.isfinite(depth[dst])
    return out & sites


@settings(max_examples=150, deadline=None)
@given(grids())
def test_reachable_is_exactly_where_a_distance_field_is_finite(grid):
    goals, obstacles = grid
    assert np.array_equal(reachable(goals, ~obstacles), np.isfinite(distance_field(goals, obstacles)))


@settings(max_examples=150, deadline=None)
@given(grids(min_size=3))
def test_the_compiled_gradient_step_moves_as_the_plain_one(grid):
    goals, obstacles = grid
    dist = distance_field(goals, obstacles)
    assert gradient_step(dist) == _plain_gradient_step(dist)


@settings(max_examples=100, deadline=None)
@given(grids(), st.integers(0, 2**32 - 1))
def test_the_compiled_mouth_side_marks_what_the_plain_one_marks(grid, seed):
    goals, obstacles = grid
    rng = np.random.default_rng(seed)
    depth = distance_field(goals, obstacles)
    sites = rng.random(goals.shape) < 0.4
    held = sites & (rng.random(goals.shape) < 0.3)
    assert np.array_equal(_mouth_side(held, sites, depth), _plain_mouth_side(held, sites, depth))


def _plain_nearest_cell(cells, centre, fx, fy):
    """_nearest_cell as a scan of every cell in row order (the reference)."""
    best, found = np.inf, (False, -1, -1)
    for r, c in zip(*np.nonzero(cells)):
        d = np.hypot(c - centre - fx, centre - r - fy)
        if d < best:
            best, found = d, (True, int(r), int(c))
    return found


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), size=st.sampled_from([1, 3, 5, 11, 41]),
       density=st.sampled_from([0.0, 0.002, 0.02, 0.3]), frac=st.sampled_from([0.0, 0.5, -0.5, None]))
def test_the_ring_search_for_the_nearest_cell_finds_what_a_whole_scan_finds(seed, size, density, frac):
    # Ties are common (whole-cell offsets: frac 0 or a half), and the first in row order wins.
    rng = np.random.default_rng(seed)
    cells = rng.random((size, size)) < density
    fx, fy = (float(v) for v in rng.uniform(-0.5, 0.5, 2)) if frac is None else (frac, -frac)
    got = _nearest_cell(readonly(cells), size // 2, fx, fy)   # as the brain passes it: one signature
    assert (bool(got[0]), int(got[1]), int(got[2])) == _plain_nearest_cell(cells, size // 2, fx, fy)


def test_a_cached_field_is_the_kernels_read_only_and_computed_once_per_input():
    goals = np.zeros((9, 9), bool)
    goals[1, 1] = True
    obstacles = np.zeros((9, 9), bool)
    obstacles[4, :7] = True
    cache = FieldCache(capacity=4)
    first = cache.distance(goals, obstacles)
    assert np.array_equal(first, distance_field(goals, obstacles))
    assert cache.distance(goals.copy(), obstacles.copy()) is first and (cache.hits, cache.misses) == (1, 1)
    with pytest.raises(ValueError):
        first[0, 0] = 0.0   # shared: nobody may write into it
    obstacles[4, 7] = True  # another input, another field
    assert not np.array_equal(cache.distance(goals, obstacles), first) and cache.misses == 2


def test_inputs_whose_digests_collide_still_get_each_its_own_field(monkeypatch):
    # The dictionary files keys by a 64-bit digest; two inputs under one digest must cost
    # a computation, never hand one the other's field. Every digest the same here:
    from agent_runtime import field_cache
    monkeypatch.setattr(field_cache, "_digest", lambda key: np.uint64(7))
    cache = FieldCache()
    obstacles = np.zeros((7, 7), bool)
    a, b = np.zeros((7, 7), bool), np.zeros((7, 7), bool)
    a[0, 0], b[6, 6] = True, True
    for goals in (a, b, a, b):
        assert np.array_equal(cache.distance(goals, obstacles), distance_field(goals, obstacles))
    assert cache.misses == 4


def test_the_digest_tells_apart_inputs_one_cell_apart():
    from agent_runtime.field_cache import _digest
    rng = np.random.default_rng(5)
    goals, obstacles = rng.random((41, 41)) < 0.1, rng.random((41, 41)) < 0.3
    seen = set()
    for k in range(goals.size):
        g = goals.copy()
        g.flat[k] ^= True
        seen.add(int(_digest(np.frombuffer(g.tobytes() + obstacles.tobytes(), np.uint8))))
    assert len(seen) == goals.size


def test_a_field_with_no_goal_is_all_inf_without_the_kernel():
    cache = FieldCache()
    field = cache.distance(np.zeros((5, 5), bool), np.zeros((5, 5), bool))
    assert np.isinf(field).all() and cache.misses == 0


def test_the_cache_keeps_at_most_its_capacity_oldest_out_first():
    cache = FieldCache(capacity=2)
    grids_ = []
    for k in range(3):
        goals = np.zeros((5, 5), bool)
        goals[k, k] = True
        grids_.append(goals)
        cache.distance(goals, np.zeros((5, 5), bool))
    assert len(cache._fields) == 2
    cache.distance(grids_[0], np.zeros((5, 5), bool))   # evicted: computed again
    assert cache.misses == 4
    with pytest.raises(ValueError):
        FieldCache(capacity=0)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(5, 30))
def test_kept_buffers_give_every_field_as_fresh_ones_do(seed, size):
    """One FieldWork through a run of different maps, plain and seeded fields in turn:
    each field equals the one made with buffers of its own (the buffers are left clean)."""
    rng = np.random.default_rng(seed)
    work = FieldWork((size, size))
    for _ in range(6):
        obstacles = rng.random((size, size)) < rng.uniform(0.0, 0.5)
        goals = rng.random((size, size)) < 0.02
        costs = np.where(rng.random((size, size)) < 0.03, rng.uniform(0.0, 9.0, (size, size)), np.inf)
        assert np.array_equal(distance_field(goals, obstacles, work), distance_field(goals, obstacles))
        assert np.array_equal(seeded_distance_field(costs, obstacles, work), seeded_distance_field(costs, obstacles))
    assert np.all(np.isinf(work.dist)) and np.all(work.bucket_of == -1)


def test_a_cached_seeded_field_is_the_seeded_kernels():
    seed = np.full((7, 7), np.inf)
    seed[0, 3], seed[6, 0] = 2.5, 0.0
    obstacles = np.zeros((7, 7), bool)
    obstacles[3, 1:6] = True
    cache = FieldCache()
    assert np.array_equal(cache.seeded(seed, obstacles), seeded_distance_field(seed, obstacles))
    assert cache.seeded(seed, obstacles) is cache.seeded(seed, obstacles) and cache.misses == 1


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), size=st.sampled_from([5, 9, 12]), site_memory=st.sampled_from([0, 3, 300]),
       agents_block=st.booleans(), closed_sites=st.booleans())
def test_the_navigation_inputs_are_the_numpy_expressions(seed, size, site_memory, agents_block, closed_sites):
    # The masks nav_masks once made with numpy, written out here as the reference.
    from agent_runtime.esm import AGENT, BRICK, CONFIG, FOOD, OBSTACLE, WATER
    from agent_runtime.nav_inputs import nav_inputs, nm_obstacles
    rng = np.random.default_rng(seed)
    marks = rng.random((7, size, size)) < 0.3
    recalled, extra = rng.random((2, size, size)) < 0.1
    clear_age = rng.integers(0, 6, (size, size)).astype(np.float32)
    centre = size // 2
    got = nav_inputs(marks, recalled, extra, clear_age, site_memory, agents_block, closed_sites, centre)
    food = marks[FOOD] | marks[OBSTACLE] | recalled
    water, brick, config = marks[WATER], marks[BRICK], marks[CONFIG]
    agents = marks[AGENT] if agents_block else np.zeros_like(marks[AGENT])
    config_goals, brick_goals = config & ~brick, brick & ~config
    obstacles = food | water | (brick & config)
    closed = config_goals & (clear_age > site_memory) if closed_sites else np.zeros_like(config_goals)
    closed[centre - 1:centre + 2, centre - 1:centre + 2] = False
    assert np.array_equal(got.config_goals, config_goals) and np.array_equal(got.brick_goals, brick_goals)
    assert np.array_equal(got.obstacles, obstacles) and np.array_equal(got.closed, closed)
    # The extra supply where nothing is in the way; where its border cell is taken (in
    # the way, or a site), the nearest free border cells instead (`_enter_where_free`).
    base = brick_goals | (extra & ~obstacles & ~config)
    assert np.array_equal(got.supply_bricks & base, base)
    border = np.ones((size, size), bool)
    border[1:-1, 1:-1] = False
    free = border & ~obstacles & ~config
    taken = np.argwhere(extra & border & (obstacles | config))
    moved = got.supply_bricks & ~base
    near = np.zeros_like(free)
    for r, c in taken:
        d = np.maximum(*np.abs(np.indices((size, size)) - np.array([r, c])[:, None, None]))
        if free.any():
            near |= free & (d == d[free].min())
            assert (got.supply_bricks & free & (d == d[free].min())).any()   # each enters somewhere nearest
    assert not (moved & ~near).any()                              # and nowhere else
    assert got.any_open == bool(config_goals.any())
    goals = brick_goals & (rng.random((size, size)) < 0.5)           # what the matching left as goals
    config_obstacles, brick_obstacles = nm_obstacles(got.in_the_way, brick, goals, centre)
    want_config, want_brick = food | water | brick | agents, food | water | agents | (brick & ~goals)
    want_config[centre, centre] = want_brick[centre, centre] = False
    assert np.array_equal(config_obstacles, want_config) and np.array_equal(brick_obstacles, want_brick)
    with pytest.raises(ValueError):
        got.config_goals[0, 0] = True                                # shared by the step's readers: read-only


@settings(max_examples=100, deadline=None)
@given(st.lists(st.sampled_from([-1.0, 0.0, 0.25, 1.5, 3.0, 5.75]), min_size=1, max_size=16))
def test_the_compiled_nearest_reading_is_the_least_real_reading(values):
    readings = np.array(values)
    hits = readings[readings != -1.0]
    expected = float(hits.min()) if hits.size else math.inf
    assert _nearest_reading(readings) == expected


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 40))
def test_the_compiled_extent_is_the_diagonal_of_the_bounding_box(seed, k):
    points = np.random.default_rng(seed).normal(0.0, 3.0, (k, 2))
    assert _extent(points) == float(np.hypot(*(points.max(axis=0) - points.min(axis=0))))


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_the_compiled_site_beliefs_are_the_numpy_expressions(seed):
    rng = np.random.default_rng(seed)
    n, k = 9, 12
    bricks = (rng.random((n, n)) < 0.4).astype(np.float32)      # as the maps and their ages are
    clear_age = rng.integers(0, 3, (n, n)).astype(np.float32)
    on = np.sort(rng.choice(k, size=rng.integers(0, k + 1), replace=False))
    rows, cols = rng.integers(0, n, on.size), rng.integers(0, n, on.size)
    site_open = rng.random(k) < 0.5
    ages = np.where(rng.random(k) < 0.3, np.inf, rng.integers(0, 50, k).astype(np.float64))
    expected_open, expected_ages = site_open.copy(), ages.copy()
    seen = bricks[rows, cols]                                  # far_memory's numpy code before it was compiled
    expected_open[on[seen > 0.5]] = False
    expected_open[on[(clear_age[rows, cols] == 0) & (seen <= 0.5)]] = True
    expected_ages += 1.0
    expected_ages[on] = np.minimum(expected_ages[on], clear_age[rows, cols])
    _observe_sites(on, rows, cols, bricks, clear_age, site_open)
    _age_sites(on, rows, cols, clear_age, ages)
    assert np.array_equal(site_open, expected_open)
    assert np.array_equal(ages, expected_ages)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), size=st.sampled_from([5, 9, 12]), bounded=st.booleans())
def test_the_step_marks_are_the_numpy_expressions(seed, size, bounded):
    # What Brain.perceive once did with numpy after sensing, written out as the reference.
    from agent_runtime.esm import BRICK, CONFIG, FOOD, OBSTACLE, WATER
    from agent_runtime.nav_inputs import step_marks
    rng = np.random.default_rng(seed)
    maps = np.where(rng.random((6, size, size)) < 0.3, 1.0, rng.random((6, size, size)) * 0.5).astype(np.float32)
    outside = rng.random((size, size)) < 0.2 if bounded else None
    recalled, known = rng.random((2, size, size)) < 0.4
    want_maps, want_recalled = maps.copy(), recalled & ~known
    if outside is not None:
        want_maps[OBSTACLE][outside] = 1.0
    marks = want_maps > 0.5
    got = step_marks(maps, outside, recalled, known)
    assert np.array_equal(maps, want_maps) and np.array_equal(recalled, want_recalled)   # both in place
    assert np.array_equal(got.marks, marks)
    assert np.array_equal(got.open_sites, marks[CONFIG] & ~marks[BRICK])
    assert np.array_equal(got.walls, marks[OBSTACLE] | marks[FOOD] | marks[WATER] | (marks[BRICK] & marks[CONFIG]))
    # Handed the last step's marks: they come back, the very object, exactly when nothing
    # crossed 0.5; else new marks, as without them.
    again = step_marks(maps, outside, recalled, known, got.marks)
    assert again.marks is got.marks
    layer, r, c = rng.integers(0, 6), rng.integers(0, size), rng.integers(0, size)
    maps[layer, r, c] = 0.0 if marks[layer, r, c] else 1.0
    if layer == OBSTACLE and outside is not None and outside[r, c]:
        return   # marked beyond the world's edge again: unchanged
    changed = step_marks(maps, outside, recalled, known, got.marks)
    assert changed.marks is not got.marks and changed.marks[layer, r, c] != marks[layer, r, c]


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), size=st.sampled_from([5, 7, 11, 41]))
def test_the_map_window_on_the_world_is_the_index_meshes(seed, size):
    # far memory's window as it was written with np.ix_ index meshes (the reference), on
    # worlds the map covers, overlaps on any side, or misses.
    from agent_runtime.far_memory import FarMemory
    rng = np.random.default_rng(seed)
    x0, y0 = (int(v) for v in rng.integers(-30, 1, 2))
    w, h = (int(v) for v in rng.integers(1, 40, 2))
    far = FarMemory(size, np.zeros((0, 2), np.int64), (x0, y0, x0 + w, y0 + h))
    far.move(*(int(v) for v in rng.integers(-45, 45, 2)), np.zeros((size, size), bool))
    idx = np.arange(size)
    gx, gy = far.pos[0] + idx - far.centre - x0, far.pos[1] + far.centre - idx - y0
    cols, rows = np.flatnonzero((gx >= 0) & (gx < w)), np.flatnonzero((gy >= 0) & (gy < h))
    layer, world = rng.random((size, size)) < 0.5, rng.random((w, h)) < 0.5
    want_world = world.copy()
    want_world[np.ix_(gx[cols], gy[rows])] = layer[np.ix_(rows, cols)].T
    want_map = np.zeros((size, size), bool)
    want_map[np.ix_(rows, cols)] = world[np.ix_(gx[cols], gy[rows])].T
    assert np.array_equal(far.on_world(world, layer), want_world)
    assert np.array_equal(far.on_map(world), want_map)


# ------------------------------------------------------------------ maps cut to the world

def test_a_map_larger_than_the_world_needs_is_cut_to_the_world():
    # Twice the longer side, plus the edge rings on each side: the whole world from any
    # cell of it. Never larger than asked, and as asked when the world's size is unknown.
    assert map_extent(121, (-5, -5, 16, 16)) == 2 * (21 + EDGE_RINGS) + 1
    assert map_extent(121, (0, 0, 51, 50)) == 2 * (51 + EDGE_RINGS) + 1
    assert map_extent(41, (0, 0, 51, 50)) == 41
    assert map_extent(121, None) == 121
    for w in range(1, 70):
        side = map_extent(121, (-w // 2, 0, w - w // 2, 3))
        assert side % 2 == 1 and side <= 121   # odd: the agent's cell is the centre
        assert side == 121 or (side - 1) // 2 >= w + EDGE_RINGS - 1


def _decisions(scenario, map_size: int, ticks: int) -> tuple[list[tuple], int]:
    """Every decision of a lockstep run of `ticks` ticks (agent, tick, command, behaviour,
    state nodes) and the side of the agents' maps."""
    run = sim.start(scenario, cfg=AgentConfig(map_size=map_size))
    out = []
    for _ in range(ticks):
        for frame in run.world.frames():
            s = run.brains[frame.agent_id].step(frame)
            out.append((frame.agent_id, frame.tick, s.speed, s.turn, s.action, s.behaviour, s.decision.state))
            run.world.set_command(frame.agent_id, s.speed, s.turn, s.action)
        run.world.step()
    return out, next(iter(run.brains.values())).maps.size


@pytest.mark.parametrize("layout", ["scenarios/fig6.toml", "tests/layouts/twin_pockets.toml"])
def test_maps_cut_to_the_world_make_the_decisions_of_the_whole_map(layout, monkeypatch):
    # What a map larger than the world adds lies outside it, where nothing is: the cut
    # maps (a fraction of the work per step) must choose as the whole 121-cell map does,
    # step for step, through walls, pockets and other agents.
    scenario = load_scenario(ROOT / layout)
    cut, cut_side = _decisions(scenario, 121, 250)
    monkeypatch.setattr(brain_module, "map_extent", lambda size, world: size)
    whole, whole_side = _decisions(scenario, 121, 250)
    assert cut_side < 121 and whole_side == 121
    assert cut == whole


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), sectors=st.sampled_from([4, 16, 33]), room=st.sampled_from([0, 3, 10_000]))
def test_the_sector_pairs_are_written_whole_or_not_at_all(seed, sectors, room):
    """`_pairs_into` into arrays that may be too small: it then writes nothing and says how
    many pairs it needs, and with room it gives the pairs of a plain loop."""
    from agent_runtime.esm import _pairs_into
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    angle, half = rng.uniform(-math.pi, math.pi, n), rng.uniform(0.0, math.pi / 2, n)
    per = sectors / (2 * math.pi)
    plain = []
    for i in range(n):
        lo = math.floor((angle[i] - half[i]) * per)
        span = min(math.floor((angle[i] + half[i]) * per) - lo + 1, sectors)
        plain += [(i, (lo + j) % sectors) for j in range(span)]
    cell_of_pair, sector, starts = (np.full(room, -7, np.int64), np.full(room, -7, np.int64),
                                    np.full(n, -7, np.int64))
    total = _pairs_into(angle, half, per, sectors, cell_of_pair, sector, starts)
    if room < len(plain):
        assert total == -len(plain) and (cell_of_pair == -7).all() and (starts == -7).all()
    else:
        assert total == len(plain)
        assert list(zip(cell_of_pair[:total].tolist(), sector[:total].tolist())) == plain
        assert starts.tolist() == [next(p for p, (i, _) in enumerate(plain) if i == c) for c in range(n)]


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), size=st.sampled_from([1, 4, 9, 41]), radius=st.integers(0, 6),
       density=st.sampled_from([0.0, 0.01, 0.2]))
def test_the_seal_guards_goal_near_check_is_the_numpy_slice(seed, size, radius, density):
    from agent_runtime.seal_guard import _any_within
    goals = np.random.default_rng(seed).random((size, size)) < density
    c = size // 2
    expected = bool(np.count_nonzero(goals[max(c - radius, 0):c + radius + 1, max(c - radius, 0):c + radius + 1]))
    assert _any_within(readonly(goals), c, radius) == expected   # as the guard passes it


def test_a_slot_asked_with_a_few_cells_changed_gets_the_kernels_field_repaired():
    # As the NMs are asked step after step while other agents move: the field comes from
    # the slot's last one (`repairs` counts it), and is the kernel's, bit for bit.
    rng = np.random.default_rng(21)
    goals = rng.random((31, 31)) < 0.01
    obstacles = rng.random((31, 31)) < 0.15
    cache = FieldCache()
    cache.distance(goals, obstacles, "config")
    for _ in range(30):
        obstacles = obstacles.copy()
        obstacles.flat[rng.integers(0, obstacles.size, 2)] ^= True   # an agent's mark moves
        assert np.array_equal(cache.distance(goals, obstacles, "config"), distance_field(goals, obstacles))
    assert cache.repairs >= 20 and cache.misses <= 31


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), size=st.sampled_from([1, 2, 5, 41]),
       density=st.sampled_from([0.0, 0.05, 0.5]))
def test_the_seal_guards_fresh_uncontested_sites_are_the_numpy_expression(seed, size, density):
    from agent_runtime.seal_guard import _fresh_uncontested
    from agent_runtime.sealing import FRESH_SITE, dilate
    rng = np.random.default_rng(seed)
    open_sites = rng.random((size, size)) < 0.5
    clear_age = rng.choice(np.array([0, FRESH_SITE, FRESH_SITE + 1, np.inf], np.float32), (size, size))
    agents = np.where(rng.random((size, size)) < density, 1.0, rng.random((size, size)) * 0.5).astype(np.float32)
    expected = open_sites & (clear_age <= FRESH_SITE) & ~dilate(agents > 0.5)
    got = _fresh_uncontested(readonly(open_sites), readonly(clear_age), readonly(agents), FRESH_SITE)
    assert np.array_equal(got, expected)
