"""The buildability check: refuses what cannot be built, and proves the rest with a fill
order that an independent replay (scipy's labelling, not the module's kernels) accepts."""

from __future__ import annotations

from collections import deque
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import ndimage

from world_server.buildability import Buildability, check_buildable, check_layout, reachable
from world_server.scenario import load_scenario, parse_scenario

SCENARIOS = sorted((Path(__file__).resolve().parent.parent / "scenarios").glob("*.toml"))


# ---------------------------------------------------------------- independent references


def replay(layout, order, bricks, agents=None) -> str:
    """Play a fill order on the grid model; '' if every step is legal and every site ends
    filled, else what went wrong. A step needs one agent that can grab the brick and then
    walk to the site; reachability from scipy.ndimage.label (4-connected)."""
    g = np.array([list(row) for row in layout])
    starts = [tuple(c) for c in np.argwhere(g == "A")]  # (row, col), reading order
    starts = starts if agents is None else starts[:agents]
    if len(order) != len(bricks) or len(set(bricks)) != len(bricks):
        return "one distinct brick per fill"
    for (sc, sr), (bc, br) in zip(order, bricks):
        if g[br, bc] != "b":
            return f"no free brick at {(bc, br)}"
        before = ndimage.label(np.isin(g, list(".A+")))[0]
        near = {before[br + dr, bc + dc] for dr, dc in ((0, 1), (1, 0), (0, -1), (-1, 0))
                if 0 <= br + dr < g.shape[0] and 0 <= bc + dc < g.shape[1]} - {0}
        grabbers = [a for a in starts if before[a] in near]
        if not grabbers:
            return f"brick {(bc, br)} cannot be grabbed"
        g[br, bc] = "."
        after = ndimage.label(np.isin(g, list(".A+")))[0]
        if g[sr, sc] != "+" or not any(after[a] == after[sr, sc] for a in grabbers):
            return f"site {(sc, sr)} cannot be reached"
        g[sr, sc] = "B"
    return "" if not (g == "+").any() else "sites left open"


def brute_force(layout) -> bool:
    """Exhaustive search over every (brick, site) move: is there any way to fill all sites?
    A move needs one agent that can grab the brick and then walk to the site."""
    starts = [(c, r) for r, row in enumerate(layout) for c, ch in enumerate(row) if ch == "A"]
    rows, cols = len(layout), len(layout[0])

    def walk(grid, start):
        seen, todo = {start}, deque([start])
        while todo:
            c, r = todo.popleft()
            for n in ((c + 1, r), (c - 1, r), (c, r + 1), (c, r - 1)):
                if n not in seen and 0 <= n[0] < cols and 0 <= n[1] < rows and grid[n[1]][n[0]] in ".A+":
                    seen.add(n)
                    todo.append(n)
        return seen

    @cache
    def solve(state: tuple[str, ...]) -> bool:
        grid = [list(row) for row in state]
        sites = [(c, r) for r, row in enumerate(grid) for c, ch in enumerate(row) if ch == "+"]
        if not sites:
            return True
        for start in starts:
            area = walk(grid, start)
            for r, row in enumerate(state):
                for c, ch in enumerate(row):
                    if ch != "b" or not any(n in area for n in ((c + 1, r), (c - 1, r), (c, r + 1), (c, r - 1))):
                        continue
                    grid[r][c] = "."
                    after = walk(grid, start)
                    for sc, sr in sites:
                        if (sc, sr) in after:
                            grid[sr][sc] = "B"
                            if solve(tuple("".join(x) for x in grid)):
                                return True
                            grid[sr][sc] = "+"
                    grid[r][c] = "b"
        return False

    return bool(starts) and solve(tuple(layout))


def assert_proven(layout, result: Buildability, agents=None):
    assert result.ok, result.reason
    assert result.reason == ""
    assert replay(layout, result.order, result.bricks, agents) == ""


# ---------------------------------------------------------------- the shipped scenarios


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_every_shipped_scenario_is_buildable_and_the_order_replays(path):
    s = load_scenario(path)
    result = check_buildable(s)
    assert_proven(s.layout, result, s.agents)
    assert sorted(result.order) == sorted(map(tuple, s.cells_col_row("+").tolist()))


def test_fig18_the_pocket_end_is_filled_before_its_mouth():
    s = load_scenario(SCENARIOS[0].parent / "fig18.toml")
    assert check_buildable(s).order == ((8, 8), (8, 7))  # D2 (the end) first, then D1
    assert replay(s.layout, ((8, 7), (8, 8)), ((2, 1), (2, 5))) == "site (8, 8) cannot be reached"


def test_nested_squares_inner_ring_is_finished_before_the_outer_ring_closes():
    s = load_scenario(SCENARIOS[0].parent / "nested_squares.toml")
    order = check_buildable(s).order
    sites = s.cells_col_row("+")
    (c0, r0), (c1, r1) = sites.min(axis=0), sites.max(axis=0)
    outer = [i for i, (c, r) in enumerate(order) if c in (c0, c1) or r in (r0, r1)]
    inner = [i for i in range(len(order)) if i not in outer]
    assert len(inner) == 8 and max(inner) < max(outer)


# ---------------------------------------------------------------- refusals, with reasons


RING_WITH_A_SITE_INSIDE = [
    "A.........",
    "..FFFFF...",
    "..F...F.b.",
    "..F.+.F.b.",
    "..F...F...",
    "..FFFFF...",
]


def test_a_site_inside_a_closed_ring_with_no_brick_is_refused():
    result = check_layout(RING_WITH_A_SITE_INSIDE)
    assert not result.ok and not result
    assert result.reason == "site (4,3) is inside a closed ring with no brick and no way in"
    assert result.order == ()


def test_every_site_no_agent_can_reach_is_named():
    layout = ["A.b.b.b.b.b.b.b.b", "..+..............", "#####.###.###.###", "#+++#.#+#.#+#.#+#",
              "#####.###.###.###"]
    assert check_layout(layout).reason == (
        "site (1,3) is inside a closed ring with no brick and no way in (and 5 more sites no agent can reach: "
        "(2,3), (3,3), (7,3), (11,3), (15,3))")
    layout[3] += "#+#"
    layout[2] += "###"
    layout[4] += "###"
    layout[0] += "..."
    layout[1] += "..."
    assert check_layout(layout).reason.endswith("(and 6 more sites no agent can reach: (2,3), (3,3), (7,3), (11,3), "
                                                "(15,3), ...)")


def test_a_closed_ring_with_bricks_inside_but_no_agent_is_walled_off():
    layout = [row.replace("F.+.F", "F.+bF") for row in RING_WITH_A_SITE_INSIDE]
    assert check_layout(layout).reason == "site (4,3) is walled off from every agent start (with 1 brick)"


def test_a_ring_with_a_gap_is_buildable():
    layout = [row.replace("FFFFF", "FF.FF") if i == 1 else row for i, row in enumerate(RING_WITH_A_SITE_INSIDE)]
    assert_proven(layout, check_layout(layout))


def test_too_few_bricks_is_refused_with_the_counts():
    assert check_layout(["A.+++.", "..b.b."]).reason == "3 open sites but only 2 free bricks can be reached"
    assert check_layout(["A.+...", "......"]).reason == "1 open site but only 0 free bricks can be reached"


def test_bricks_behind_a_wall_do_not_count():
    layout = ["A.++..#bb", "......#bb", "......#.."]
    assert check_layout(layout).reason == "2 open sites but only 0 free bricks can be reached"


def test_no_start_and_no_site():
    assert check_layout(["..+b."]).reason == "no agent start"
    assert check_layout(["A.+b."], agents=0).reason == "no agent start (the scenario has 0 agents)"
    assert check_layout(["A..b."]).reason == "no drop site"
    assert check_layout(["A.Bb."]).reason == "no open drop site: every site already holds a brick"


def test_sites_holding_bricks_are_obstacles():
    # the B closes the corridor to the site: walled off
    assert "inside a closed ring" in check_layout(["A.b.#+#", "....#B#", "......."]).reason
    assert check_layout(["A.b.#+#", "....#.#", "......."]).ok


def test_the_scenario_agent_count_limits_the_starts():
    # the second A is the only one next to the bricks' room
    layout = ["A#...", "##...", "..+bA"]
    assert check_layout(layout).ok
    assert check_layout(layout, agents=2).ok
    assert "walled off" in check_layout(layout, agents=1).reason


def test_agents_in_separate_areas_each_serve_their_own_area():
    layout = ["A.+.b.#.b.+.A", "......#......"]
    result = check_layout(layout)
    assert_proven(layout, result)
    one_short = ["A.+.b.#...+.A", "......#....b."]
    assert check_layout(one_short).ok
    starved = ["A.+.bb#...+.A", "......#......"]
    assert check_layout(starved).reason == "the agent start at (12,0) can reach 1 open site but only 0 free bricks"


def test_a_pile_is_dug_into_from_its_face():
    # the site behind a one-brick wall: take that brick for the near site, walk through
    layout = ["A.+.b+", "....b#", "....b#"]
    result = check_layout(layout)
    assert_proven(layout, result)
    assert result.order[0] == (2, 0)
    # three bricks deep with one near site: the first brick has nowhere to go
    assert not check_layout(["A.+bbb+", "#######"]).ok


def test_a_deep_pocket_is_filled_from_its_end_outwards():
    layout = [
        "A.bbbbbb.",
        ".........",
        "###+#####",
        "###+#####",
        "###+#####",
        "###+#####",
        "###+#####",
    ]
    result = check_layout(layout)
    assert_proven(layout, result)
    assert result.order == ((3, 6), (3, 5), (3, 4), (3, 3), (3, 2))
    assert replay(layout, result.order[::-1], result.bricks) != ""  # mouth first blocks the rest


def test_a_ring_around_the_only_bricks_closes_last():
    # every brick inside the ring: the site outside must get its brick before the ring closes
    layout = [
        "A..........",
        "...........",
        ".+++++++...",
        ".+bbbbb+...",
        ".+bbbbb+...",
        ".+bbbbb+.+.",
        ".+bbbbb+...",
        ".+bbbbb+...",
        ".+++++++...",
    ]
    result = check_layout(layout)
    assert_proven(layout, result)
    assert result.order[-1] != (9, 5)
    late = result.order.index((9, 5))
    moved = result.order[:late] + result.order[late + 1:] + ((9, 5),)
    bricks = result.bricks[:late] + result.bricks[late + 1:] + (result.bricks[late],)
    assert "cannot be grabbed" in replay(layout, moved, bricks)


def test_an_impossible_order_is_refused_with_where_it_got_stuck():
    # the only agent sits inside the inner of two rings, every brick outside the outer
    layout = [
        "bbbbbbbbbbbbbbbbbbbbbbbbbbbbbbbb",
        "bbbbbbbbbbbbbbbbbbbbbbbbbbbbbbbb",
        "................................",
        "..+++++++.......................",
        "..+.....+.......................",
        "..+.+++.+.......................",
        "..+.+A+.+.......................",
        "..+.+++.+.......................",
        "..+.....+.......................",
        "..+++++++.......................",
    ]
    result = check_layout(layout)  # how long it takes: bench/bench_budgets.py
    assert not result.ok and result.reason.startswith("no fill order found")
    assert "stuck after" in result.reason


# ---------------------------------------------------------------- against exhaustive search

_cells = st.sampled_from(list("....++bbb#B"))


@st.composite
def small_layouts(draw):
    rows, cols = draw(st.integers(2, 5)), draw(st.integers(2, 5))
    grid = [[draw(_cells) for _ in range(cols)] for _ in range(rows)]
    grid[draw(st.integers(0, rows - 1))][draw(st.integers(0, cols - 1))] = "A"
    if draw(st.booleans()):  # sometimes a second agent
        grid[draw(st.integers(0, rows - 1))][draw(st.integers(0, cols - 1))] = "A"
    return ["".join(row) for row in grid]


@pytest.mark.slow   # 1,500 layouts, each searched exhaustively: about 2 s
@settings(max_examples=1500, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(layout=small_layouts())
def test_agrees_with_exhaustive_search_on_small_layouts(layout):
    n_sites = sum(row.count("+") for row in layout)
    if not 1 <= n_sites <= 4:
        return
    result = check_layout(layout)
    assert result.ok == brute_force(layout), (layout, result.reason)
    if result.ok:
        assert replay(layout, result.order, result.bricks) == ""
    else:
        assert result.reason and not result.order


# ---------------------------------------------------------------- a big layout and helpers


def _big_layout() -> list[str]:
    """120 x 120, 400 sites: a solid 8 x 8 blob (filled from its core), two nested rings
    and four dead-end pockets; bricks scattered in the south, a food wall with a gap."""
    g = np.full((120, 120), ".")
    g[10:18, 10:18] = "+"
    for lo, hi in ((60, 100), (63, 97)):
        g[lo, lo:hi] = g[hi - 1, lo:hi] = "+"
        g[lo:hi, lo] = g[lo:hi, hi - 1] = "+"
    g[60:100, 101:110] = "#"
    g[60:72, 102:110:2] = "+"  # the pockets open north, onto row 59
    g[35, :] = "F"
    g[35, 50:53] = "."
    rng = np.random.default_rng(0)
    free = np.argwhere(g[40:, :] == ".") + [40, 0]
    for r, c in free[rng.choice(len(free), int((g == "+").sum()) + 30, replace=False)]:
        g[r, c] = "b"
    g[119, 0] = "A"
    return ["".join(row) for row in g]


def test_a_120_by_120_layout_with_400_sites_is_proven_buildable():
    layout = _big_layout()
    assert sum(row.count("+") for row in layout) == 400
    assert_proven(layout, check_layout(layout))  # how long it takes: bench/bench_budgets.py


def test_reachable_walks_over_empty_start_and_open_site_cells():
    layout = ["A.+b.", "###..", "....."]
    assert reachable(layout) == {(0, 0), (1, 0), (2, 0)}
    assert (4, 2) in reachable(layout, [(4, 0)])
    assert reachable([list(row) for row in layout]) == reachable(layout)


def test_check_buildable_uses_the_scenario_agent_count():
    text = 'name = "t"\nseed = 1\nagents = 1\nlayout = """\nA#..\n##.A\n+b..\n"""\n'
    assert "walled off" in check_buildable(parse_scenario(text)).reason
    assert check_buildable(parse_scenario(text.replace("agents = 1", "agents = 2"))).ok
