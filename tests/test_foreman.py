"""The foreman's marking (agent_runtime/foreman.py): which sites are safe to mark for workers,
where the supply cue goes, and when a cue comes off. Grids are drawn as text: `#` blocked,
`+` open site, `B` filled site, `b` free brick, `.` open ground; the foreman stands in the
centre of a 9 x 9 map."""

from __future__ import annotations

import numpy as np
import pytest

from agent_runtime.esm import BRICK, CONFIG, LAYERS, OBSTACLE
from agent_runtime.foreman import Foreman, ForemanConfig, MapView, marking_is_safe, site_candidates, supply_cell


def grids(text: str) -> np.ndarray:
    rows = text.strip().split()
    marks = np.zeros((LAYERS, len(rows), len(rows[0])), bool)
    for r, line in enumerate(rows):
        for c, ch in enumerate(line):
            marks[OBSTACLE, r, c] = ch == "#"
            marks[CONFIG, r, c] = ch in "+B"
            marks[BRICK, r, c] = ch in "Bb"
    return marks


def view(text: str) -> MapView:
    marks = grids(text)
    return MapView.of(marks, np.zeros(marks.shape[1:], np.float32), fresh=5.0)


def cells(v: MapView, *where: tuple[int, int]) -> np.ndarray:
    out = np.zeros_like(v.open_sites)
    for rc in where:
        out[rc] = True
    return out


POCKET = """
.........
.........
..#####..
..#+..#..
..#...#..
..###+#..
.........
.........
.........
"""


def test_marking_the_mouth_of_a_pocket_is_unsafe_while_its_inside_is_open():
    v = view(POCKET)
    assert not marking_is_safe(v, cells(v, (5, 5)))     # the mouth: the site (3, 3) inside is cut off
    assert marking_is_safe(v, cells(v, (3, 3)))         # the inside first is fine
    # Both together: the mouth filled before the inside would shut it: unsafe as a set.
    assert not marking_is_safe(v, cells(v, (3, 3), (5, 5)))


WALL = """
.........
.........
.........
..+++++..
.........
.........
.........
.........
.........
"""


def test_a_straight_wall_in_open_ground_is_safe_whole():
    v = view(WALL)
    assert marking_is_safe(v, v.open_sites)


def test_two_marks_that_close_a_gap_together_are_unsafe():
    # A room whose door is two sites wide: either alone leaves a way in, both shut it.
    v = view("""
    .........
    .#######.
    .#.....#.
    .#.....#.
    .#.....#.
    .###++##.
    .........
    .........
    .........
    """)
    assert marking_is_safe(v, cells(v, (5, 4)))
    assert marking_is_safe(v, cells(v, (5, 5)))
    assert not marking_is_safe(v, cells(v, (5, 4), (5, 5)))


def test_candidates_are_fresh_unmarked_sites_within_reach_nearest_first():
    v = view(WALL)
    assert site_candidates(v, cells(v), 1.5) == [(3, 4), (3, 3), (3, 5)]
    assert site_candidates(v, cells(v, (3, 4)), 1.5) == [(3, 3), (3, 5)]
    stale = MapView.of(grids(WALL), np.full((9, 9), 50, np.float32), fresh=5.0)
    assert site_candidates(stale, cells(v), 9.0) == []


def test_the_supply_cue_lies_beside_free_bricks_and_clear_of_every_site():
    v = view("""
    .........
    .bbb.....
    .bbb.....
    .........
    .........
    .........
    ...+B....
    .........
    .........
    """)
    cell = supply_cell(v, reach=9.0, clearance=2)
    assert cell is not None
    r, c = cell
    assert not v.blocked[r, c] and v.free_bricks[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2].any()
    assert abs(r - 6) > 2 or min(abs(c - 3), abs(c - 4)) > 2
    assert supply_cell(v, reach=0.5, clearance=2) is None          # none so near the foreman


def test_a_foreman_marks_then_unmarks_a_site_once_it_is_filled():
    f = Foreman(ForemanConfig(every=1, reach=3.0, max_site_cues=1))
    centre = 4

    def offset_of(r, c):
        return float(c - centre), float(centre - r)

    def cell_of(dx, dy):
        return centre - int(np.floor(dy + 0.5)), centre + int(np.floor(dx + 0.5))

    marks = grids(WALL)
    age = np.zeros((9, 9), np.float32)
    odo = np.zeros(2)
    first = f.decide(marks, age, odo, offset_of, cell_of)
    assert first is not None and first.action == "mark" and first.kind == "site"
    assert (first.dx, first.dy) == pytest.approx((0.0, 1.0))    # the site (3, 4), one cell north
    assert f.decide(marks, age, odo, offset_of, cell_of) is None  # one site cue at most
    marks[BRICK, 3, 4] = True                                     # seen filled
    off = f.decide(marks, age, odo, offset_of, cell_of)
    assert off is not None and off.action == "unmark" and (off.dx, off.dy) == pytest.approx((0.0, 1.0))
    assert f.cues == []
