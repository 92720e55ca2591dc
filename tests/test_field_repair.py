"""A repaired distance field is the field computed afresh, bit for bit (issue 31): through
chains of random small changes of goals and obstacles, on open maps (many ties), mazes
and the world-in-a-map shapes an agent's maps have."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent_runtime import field_repair
from agent_runtime.field_repair import MAX_CHANGED, MAX_QUEUED, repair_distance_field
from agent_runtime.spreading import distance_field


@pytest.fixture
def unbounded(monkeypatch):
    """Repairs never given up for their size: the algorithm itself, on any change."""
    monkeypatch.setattr(field_repair, "MAX_QUEUED", 10**9)


def _grids(rng: np.random.Generator, size: int, density: float, walled: bool) -> tuple[np.ndarray, np.ndarray]:
    obstacles = rng.random((size, size)) < density
    if walled:   # a world smaller than the map: all obstacle round it
        h, w = (int(v) for v in rng.integers(1, size + 1, 2))
        r0, c0 = int(rng.integers(0, size - h + 1)), int(rng.integers(0, size - w + 1))
        inside = np.zeros((size, size), bool)
        inside[r0:r0 + h, c0:c0 + w] = True
        obstacles |= ~inside
    goals = rng.random((size, size)) < rng.choice([0.005, 0.02, 0.1])
    return goals, obstacles


def _change(rng: np.random.Generator, goals: np.ndarray, obstacles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A few cells toggled: obstacles (as agents move), goals, or both, often clustered."""
    goals, obstacles = goals.copy(), obstacles.copy()
    size = goals.shape[0]
    r, c = (int(v) for v in rng.integers(0, size, 2))
    for _ in range(int(rng.integers(1, 6))):
        rr = int(np.clip(r + rng.integers(-2, 3), 0, size - 1))
        cc = int(np.clip(c + rng.integers(-2, 3), 0, size - 1))
        which = rng.integers(0, 3)
        if which == 0:
            obstacles[rr, cc] ^= True
        elif which == 1:
            goals[rr, cc] ^= True
        else:
            r, c = (int(v) for v in rng.integers(0, size, 2))   # somewhere else
            obstacles[r, c] ^= True
    return goals, obstacles


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), size=st.sampled_from([1, 2, 5, 12, 31]),
       density=st.sampled_from([0.0, 0.1, 0.3, 0.45]), walled=st.booleans())
def test_a_repaired_field_is_the_field_computed_afresh_through_a_chain_of_changes(seed, size, density, walled):
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(field_repair, "MAX_QUEUED", 10**9)   # the algorithm itself, on any change
        _chain(seed, size, density, walled)


def _chain(seed: int, size: int, density: float, walled: bool) -> None:
    rng = np.random.default_rng(seed)
    goals, obstacles = _grids(rng, size, density, walled)
    field = distance_field(goals, obstacles)
    for _ in range(12):
        new_goals, new_obstacles = _change(rng, goals, obstacles)
        repaired = repair_distance_field(field, goals, obstacles, new_goals, new_obstacles)
        fresh = distance_field(new_goals, new_obstacles)
        assert repaired is not None
        assert np.array_equal(repaired, fresh)   # inf where inf, every value to the bit
        goals, obstacles, field = new_goals, new_obstacles, repaired


def test_an_agent_stepping_across_the_only_corridor_cuts_the_far_side_off_and_back():
    obstacles = np.zeros((7, 15), bool)
    obstacles[:, 7] = True
    obstacles[3, 7] = False            # the one gap
    goals = np.zeros((7, 15), bool)
    goals[3, 0] = True
    field = distance_field(goals, obstacles)
    blocked = obstacles.copy()
    blocked[3, 7] = True               # an agent stands in the gap
    cut = repair_distance_field(field, goals, obstacles, goals, blocked)
    assert cut is not None and np.isinf(cut[:, 8:]).all() and np.array_equal(cut, distance_field(goals, blocked))
    back = repair_distance_field(cut, goals, blocked, goals, obstacles)
    assert back is not None and np.array_equal(back, field)


def test_a_change_of_more_than_max_changed_cells_is_left_to_the_kernel(unbounded):
    goals = np.zeros((20, 20), bool)
    goals[0, 0] = True
    obstacles = np.zeros((20, 20), bool)
    field = distance_field(goals, obstacles)
    more = obstacles.copy()
    more.flat[5:6 + MAX_CHANGED] = True
    assert repair_distance_field(field, goals, obstacles, goals, more) is None
    fewer = obstacles.copy()
    fewer.flat[5:5 + MAX_CHANGED] = True
    assert np.array_equal(repair_distance_field(field, goals, obstacles, goals, fewer), distance_field(goals, fewer))


def test_the_old_field_is_left_as_it_was(unbounded):
    rng = np.random.default_rng(3)
    goals, obstacles = _grids(rng, 15, 0.2, False)
    field = distance_field(goals, obstacles)
    kept = field.copy()
    new_goals, new_obstacles = _change(rng, goals, obstacles)
    repair_distance_field(field, goals, obstacles, new_goals, new_obstacles)
    assert np.array_equal(field, kept)


@pytest.mark.parametrize("size", [9, 40])
def test_every_cell_toggled_in_turn_on_an_open_map(unbounded, size):
    # Open ground is where ties abound: values reached along different orders of 1s and
    # sqrt(2)s differ in their last bits, and a repair must land on the kernel's own.
    goals = np.zeros((size, size), bool)
    goals[1, 2] = goals[size - 2, size // 2] = True
    obstacles = np.zeros((size, size), bool)
    field = distance_field(goals, obstacles)
    for k in range(0, size * size, 7):
        new = obstacles.copy()
        new.flat[k] ^= True
        got = repair_distance_field(field, goals, obstacles, goals, new)
        assert np.array_equal(got, distance_field(goals, new))


def test_a_repair_that_would_move_much_of_the_field_is_left_to_the_kernel():
    # The one goal of an open map gone: every value goes. The budget gives the repair up
    # (None: the caller computes the field afresh) rather than redo it all on a heap.
    goals = np.zeros((30, 30), bool)
    goals[15, 15] = goals[2, 2] = True
    obstacles = np.zeros((30, 30), bool)
    field = distance_field(goals, obstacles)
    fewer = goals.copy()
    fewer[15, 15] = False
    assert repair_distance_field(field, goals, obstacles, fewer, obstacles) is None


def test_within_the_budget_the_repairs_of_random_small_changes_are_exact_and_most_are_made():
    rng = np.random.default_rng(11)
    made = 0
    for _ in range(60):
        goals, obstacles = _grids(rng, 31, 0.2, True)
        field = distance_field(goals, obstacles)
        new = obstacles.copy()
        new.flat[int(rng.integers(0, new.size))] ^= True   # one agent's mark, come or gone
        got = repair_distance_field(field, goals, obstacles, goals, new)
        if got is not None:
            made += 1
            assert np.array_equal(got, distance_field(goals, new))
    assert made >= 40, f"only {made} of 60 repaired within MAX_QUEUED={MAX_QUEUED}"


def _moved(grid: np.ndarray, dr: int, dc: int, fill: bool) -> np.ndarray:
    """The grid's contents moved by (dr, dc), `fill` on the cells that come onto it."""
    out = np.full(grid.shape, fill)
    n, m = grid.shape
    out[max(dr, 0):n + min(dr, 0), max(dc, 0):m + min(dc, 0)] = grid[max(-dr, 0):n - max(dr, 0),
                                                                     max(-dc, 0):m - max(dc, 0)]
    return out


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), size=st.sampled_from([5, 12, 31]), density=st.sampled_from([0.0, 0.2, 0.4]),
       move=st.sampled_from([(0, 1), (1, 0), (-1, 0), (0, -1), (1, 1), (-1, 1), (1, -1), (-1, -1)]))
def test_a_field_repaired_across_a_move_of_the_map_is_the_field_computed_afresh(seed, size, density, move):
    """The agent crossed into the next cell: the map's contents moved by one row or column
    or both. Where everything that left the map was an obstacle (a world smaller than the
    map), the old field moved and repaired is the new one, bit for bit; else no repair."""
    rng = np.random.default_rng(seed)
    goals, obstacles = _grids(rng, size, density, walled=True)
    field = distance_field(goals, obstacles)
    dr, dc = move
    new_goals, new_obstacles = _change(rng, _moved(goals, dr, dc, False), _moved(obstacles, dr, dc, True))
    inside = _moved(np.ones(goals.shape, bool), -dr, -dc, False)   # the cells that stay on the map
    leaving_free = bool((~obstacles & ~inside).any())
    before = np.frombuffer(goals.tobytes() + obstacles.tobytes(), np.uint8)
    after = np.frombuffer(new_goals.tobytes() + new_obstacles.tobytes(), np.uint8)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(field_repair, "MAX_QUEUED", 10**9)
        got = field_repair.repair_from_bytes(field, before, after, 0, move)
    if leaving_free:
        assert got is None
    else:
        assert got is not None and np.array_equal(got, distance_field(new_goals, new_obstacles))
