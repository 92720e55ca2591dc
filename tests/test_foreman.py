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


def _coordinates(centre: int = 4):
    def offset_of(r, c):
        return float(c - centre), float(centre - r)

    def cell_of(dx, dy):
        return centre - int(np.floor(dy + 0.5)), centre + int(np.floor(dx + 0.5))
    return offset_of, cell_of


# The whole world on the map (its edge, `#`, all round): a corridor of sites along the east
# edge, shut at the top, whose mouth is the site (4, 7).
CORRIDOR = """
#########
#.....#+#
#.....#+#
#.....#+#
#......+#
#.......#
#.......#
#.......#
#########
"""


def test_on_a_map_holding_the_whole_world_the_mouth_of_a_corridor_is_unsafe_first():
    # With no open border the largest open region stood for the outside, and a cut-off cell
    # is in that region itself: every marking passed. A wall of sites along the world's edge
    # was sealed so (gen-wall 20 with a foreman and four workers: 14 of 18 sites).
    v = view(CORRIDOR)
    assert not marking_is_safe(v, cells(v, (4, 7)))       # the mouth: the corridor's inside cut off
    assert marking_is_safe(v, cells(v, (1, 7)))           # the far end first is fine
    assert not marking_is_safe(v, cells(v, (1, 7), (4, 7)))


def test_a_cue_that_a_fill_since_made_unsafe_is_taken_off():
    # The corridor opens at its top too (the site (1, 6)): the mouth is safe to mark. Then
    # (1, 6) is filled (by the foreman's own building, or anyone): the mouth's cue now
    # shuts the inside if a worker fills it first, so it comes off.
    open_top = CORRIDOR.replace("#.....#+#\n#.....#+#\n#.....#+#", "#.....++#\n#.....#+#\n#.....#+#", 1)
    marks = grids(open_top)
    f = Foreman(ForemanConfig(every=1, reach=3.0))
    offset_of, cell_of = _coordinates()
    f.cues = [(*offset_of(4, 7), "site")]
    age, odo = np.zeros((9, 9), np.float32), np.zeros(2)
    assert marking_is_safe(view(open_top), cells(view(open_top), (4, 7)))
    nxt = f.decide(marks, age, odo, offset_of, cell_of)
    assert nxt is None or nxt.action == "mark"              # safe: it keeps the cue
    assert (*offset_of(4, 7), "site") in f.cues
    marks[BRICK, 1, 6] = True                                 # the top filled
    off = f.decide(marks, age, odo, offset_of, cell_of)
    assert off is not None and off.action == "unmark" and (off.dx, off.dy) == pytest.approx(offset_of(4, 7))
    assert (*offset_of(4, 7), "site") not in f.cues


DOORS = """
.........
.........
.........
.....#...
....+++..
.....#...
.........
.........
.........
"""


def test_before_its_own_drop_shuts_a_site_behind_a_cue_the_foreman_takes_the_cue_off():
    # The site (4, 5) has two doors, the foreman's own cell (4, 4) and the marked (4, 6).
    # Its brick going down on its cell leaves the cue the only way in: the cue comes off
    # first. Nothing else marked, nothing to take off.
    f = Foreman(ForemanConfig(every=1, reach=3.0))
    offset_of, cell_of = _coordinates()
    marks, age, odo = grids(DOORS), np.zeros((9, 9), np.float32), np.zeros(2)
    f.cues = [(*offset_of(4, 6), "site")]
    off = f.before_drop(marks, age, odo, cell_of)
    assert off is not None and off.action == "unmark" and (off.dx, off.dy) == pytest.approx(offset_of(4, 6))
    assert f.cues == [] and f.before_drop(marks, age, odo, cell_of) is None
    f.cues = [(*offset_of(2, 2), "site")]                     # a cue elsewhere: the drop is harmless
    assert f.before_drop(marks, age, odo, cell_of) is None


def test_a_cue_beyond_reach_is_not_taken_off_the_world_would_not_take_it():
    open_top = CORRIDOR.replace("#.....#+#\n#.....#+#\n#.....#+#", "#.....B+#\n#.....#+#\n#.....#+#", 1)
    f = Foreman(ForemanConfig(every=1, reach=2.0))            # the mouth is 3 cells off
    offset_of, cell_of = _coordinates()
    f.cues = [(*offset_of(4, 7), "site")]
    assert f.decide(grids(open_top), np.zeros((9, 9), np.float32), np.zeros(2), offset_of, cell_of) is None
    assert len(f.cues) == 1


def test_a_dry_supply_stays_while_sites_are_open_and_moves_to_bricks_seen_elsewhere():
    # Workers bring the bricks no site wants back to the supply cue: while a site is open a
    # dry supply stays, else the last bricks ride round with idle workers and the build
    # stalls (gen-ring 15, two foremen and ten workers: 29 of 30, four workers loaded).
    offset_of, cell_of = _coordinates()
    age, odo = np.zeros((9, 9), np.float32), np.zeros(2)
    f = Foreman(ForemanConfig(every=1, reach=3.0, max_site_cues=0))
    f.cues = [(*offset_of(4, 2), "supply")]
    dry_open = grids("""
    .........
    .........
    .........
    .........
    .........
    .........
    .........
    .......+.
    .........
    """)
    assert f.decide(dry_open, age, odo, offset_of, cell_of) is None and len(f.cues) == 1
    done = dry_open.copy()
    done[BRICK, 7, 7] = True                                   # the last site filled
    off = f.decide(done, age, odo, offset_of, cell_of)
    assert off is not None and off.action == "unmark" and off.kind == "supply" and f.cues == []
    f.cues = [(*offset_of(4, 2), "supply")]
    bricks_east = dry_open.copy()
    bricks_east[BRICK, 3:6, 6] = True                          # free bricks beyond, east
    move = f.decide(bricks_east, age, odo, offset_of, cell_of)
    assert move is not None and move.action == "unmark" and (move.dx, move.dy) == pytest.approx(offset_of(4, 2))
    new = f.decide(bricks_east, age, odo, offset_of, cell_of)
    assert new is not None and new.action == "mark" and new.kind == "supply" and new.dx > 0


RING = """
.........
.BBB+BBB.
.B.....B.
.BBBBBBB.
.........
.........
.........
.........
.........
"""


def test_closing_a_ring_on_empty_ground_is_safe_but_not_on_a_site_or_a_brick_inside():
    # Ground cut off with nothing the build needs on it is no loss: a ring's last site may
    # go to the workers. Not with an open site or a free brick inside, nor with the foreman.
    v = view(RING)
    assert marking_is_safe(v, cells(v, (1, 4)))
    for inside in ("+", "b"):
        w = view(RING.replace(".B.....B.", f".B.{inside}...B.", 1))
        assert not marking_is_safe(w, cells(w, (1, 4)))
    around_foreman = view(RING.replace(".BBB+BBB.\n.B.....B.\n.BBBBBBB.", ".........\n.........\n.BBBBBBB.")
                          .replace(".........\n.........\n.........\n.........\n.........\n",
                                   ".B.....B.\n.B.....B.\n.BBB+BBB.\n.........\n.........\n", 1))
    assert around_foreman.centre == (4, 4) and not around_foreman.blocked[4, 4]
    assert not marking_is_safe(around_foreman, cells(around_foreman, (5, 4)))
