"""Where the world puts a dead agent's brick and a returning body: the pure rules of
`world_server.placement` on small grids ([row, col], row 0 north)."""

from __future__ import annotations

import numpy as np
import pytest

from world_server.placement import body_cell, brick_drop_cell, extra_start_cells, reachable_cells, spread_cells


def grid(text: str) -> tuple[np.ndarray, np.ndarray]:
    """(free, site) from a picture: `#` not free (wall, disc, body), `+` a drop site, `.` free."""
    cells = np.array([list(line) for line in text.strip().splitlines()])
    return cells != "#", cells == "+"


def test_the_brick_goes_to_the_nearest_open_cell_away_from_the_structure():
    free, site = grid("""
.......
.......
..+++..
.......
.......
.......
""")
    # dying on the middle site: not on a site, not next to one, all eight neighbours free
    assert brick_drop_cell(free, site, (3.5, 2.5)) == (3, 4)


def test_the_brick_never_closes_a_one_cell_gap():
    free, site = grid("""
...#....
...#....
........
...#....
...#....
""")
    # standing in the only gap of the wall: the brick goes to an open cell beside it
    col, row = brick_drop_cell(free, site, (3.5, 2.5))
    assert free[row, col] and not site[row, col]
    ring = np.pad(free, 1, constant_values=False)[row:row + 3, col:col + 3]
    assert ring.all()
    assert (col, row) != (3, 2)


def test_with_no_open_cell_it_falls_back_to_cells_that_are_merely_free_and_not_sites():
    free, site = grid("""
#.#
+.+
""")
    # (1, 0) has walls around it and sites beside it; (1, 1) lies between two sites
    assert brick_drop_cell(free, site, (1.5, 1.5)) == (1, 1)
    free, site = grid("""
#+#
+++
""")
    assert brick_drop_cell(free, site, (1.5, 1.5)) is None


def test_ties_are_broken_in_reading_order_and_the_choice_is_deterministic():
    free, site = grid("""
.....
.....
.....
.....
.....
""")
    # equidistant from the centre: the first in reading order wins
    assert brick_drop_cell(free, site, (2.5, 2.5)) == (2, 2)
    free[2, 2] = False
    assert body_cell(free, (2.5, 2.5)) == (2, 1)


def test_a_body_comes_back_at_the_nearest_free_cell():
    free, _ = grid("""
####
#..#
####
""")
    assert body_cell(free, (0.2, 0.2)) == (1, 1)
    assert body_cell(np.zeros((2, 2), bool), (0.0, 0.0)) is None


def test_a_body_comes_back_only_where_the_open_world_reaches():
    free, _ = grid("""
.......
..###..
..#.#..
..###..
.......
""")
    reach = reachable_cells(free, np.array([(0, 0)]))
    assert not reach[2, 3] and reach[0, 3] and reach[4, 6]          # the walled-in cell is cut off
    assert body_cell(free, (3.5, 2.5)) == (3, 2)                     # nearest free: inside
    assert body_cell(free, (3.5, 2.5), reach) == (3, 0)              # nearest reachable: outside
    # no reachable cell free (every seed walled in): any free cell rather than none
    assert body_cell(free, (3.5, 2.5), reachable_cells(free, np.array([(3, 1)]))) == (3, 2)


def test_extra_starts_grow_from_the_starts_by_walking_distance():
    cells = np.array([list(line) for line in """
A....
####.
.....
....A""".strip().splitlines()])
    empty, passable = cells == ".", cells != "#"
    order = [tuple(int(v) for v in c) for c in extra_start_cells(empty, passable, np.argwhere(cells == "A")[:, ::-1])]
    assert sorted(order) == sorted(tuple(int(v) for v in c) for c in np.argwhere(empty)[:, ::-1])
    # one step from either start first (reading order), then two steps; (0, 2) is one row
    # below the first start but seven steps round the wall, so it comes last
    assert order[:4] == [(1, 0), (4, 2), (3, 3), (2, 0)]
    assert order[-1] == (0, 2)


def test_extra_starts_without_a_start_are_in_reading_order_and_walled_off_cells_come_last():
    cells = np.array([list(line) for line in ["..#.", "..#A"]])
    order = extra_start_cells(cells == ".", cells != "#", np.zeros((0, 2), np.int64))
    assert [tuple(c) for c in order.tolist()] == [(0, 0), (1, 0), (3, 0), (0, 1), (1, 1)]
    order = extra_start_cells(cells == ".", cells != "#", np.array([[3, 1]]))
    assert [tuple(c) for c in order.tolist()] == [(3, 0), (0, 0), (1, 0), (0, 1), (1, 1)]


def test_spread_cells_go_into_the_largest_gap_first():
    free = np.ones((10, 10), bool)
    cells = [tuple(c) for c in spread_cells(free, 4, (0, 0)).tolist()]
    # the far corner, then the two others (equally far from both: reading order)
    assert cells == [(0, 0), (9, 9), (9, 0), (0, 9)]


def test_spread_cells_cover_the_floor_evenly_and_only_free_cells():
    rng = np.random.default_rng(5)
    free = rng.random((40, 50)) > 0.3
    free[:, 20] = False  # a wall
    first = tuple(int(v) for v in np.argwhere(free)[0][::-1])
    cells = spread_cells(free, 120, first)
    assert cells.shape == (120, 2) and tuple(cells[0]) == first
    assert free[cells[:, 1], cells[:, 0]].all() and len({tuple(c) for c in cells.tolist()}) == 120
    # even: no free cell is farther from its nearest start than the closest two starts are
    # from each other (each start went where the gap was widest, and gaps only shrink)
    apart = np.hypot(*(cells[:, None, :] - cells[None, :, :]).transpose(2, 0, 1)).astype(float)
    np.fill_diagonal(apart, np.inf)
    floor = np.argwhere(free)[:, ::-1]
    gap = np.hypot(*(floor[:, None, :] - cells[None, :, :]).transpose(2, 0, 1)).min(axis=1)
    assert gap.max() <= apart.min()
    assert apart.min() >= 3.0  # 120 starts on about 1,400 free cells: 3-4 cells apart


def test_spread_cells_stop_when_the_floor_is_full_and_refuse_a_blocked_first_cell():
    free = np.array([[True, False, True]])
    assert [tuple(c) for c in spread_cells(free, 5, (0, 0)).tolist()] == [(0, 0), (2, 0)]
    with pytest.raises(ValueError, match="not free"):
        spread_cells(free, 1, (1, 0))
