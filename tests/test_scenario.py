"""Scenario files: the shipped ones are valid and buildable, bad ones are rejected precisely."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from world_server.buildability import check_buildable, reachable
from world_server.scenario import ScenarioError, load_scenario, parse_scenario

SCENARIO_DIR = Path(__file__).resolve().parent.parent / "scenarios"
SCENARIOS = sorted(SCENARIO_DIR.glob("*.toml"))
EXPECTED = {"quick_wall", "fig6", "fig17", "fig18", "fig19", "fig20", "nested_squares"}
MAP_CELLS = 41  # an agent's egocentric map is 41 x 41 cells

GOOD = '''name = "tiny"
seed = 3
agents = 1
layout = """
..A..
.b+b.
"""
'''


# ---------------------------------------------------------------- shipped scenarios


def test_the_paper_scenarios_are_all_there():
    assert {p.stem for p in SCENARIOS} >= EXPECTED


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_scenario_file_loads_and_is_sane(path):
    s = load_scenario(path)
    assert s.name == path.stem
    assert s.description.strip()
    assert s.tick_mode == "lockstep"
    assert s.max_ticks >= 20000
    assert 1 <= s.agents <= len(s.cells_col_row("A")), "every agent needs an A start cell"
    assert len(s.cells_col_row("b")) >= len(s.cells_col_row("+")), "fewer free bricks than empty drop sites"
    assert len(s.cells_col_row("+")) > 0
    assert s.cols <= MAP_CELLS and s.rows <= MAP_CELLS


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_scenario_structure_can_be_built_in_some_order(path):
    verdict = check_buildable(load_scenario(path))  # the grid model: world_server/buildability.py
    assert verdict.ok, verdict.reason


def test_fig18_filling_d1_first_walls_d2_off():
    s = load_scenario(SCENARIO_DIR / "fig18.toml")
    start = tuple(s.cells_col_row("A")[0].tolist())
    d1 = min(map(tuple, s.cells_col_row("+").tolist()), key=lambda c: abs(c[0] - start[0]) + abs(c[1] - start[1]))
    grid = [list(row) for row in s.layout]
    grid[d1[1]][d1[0]] = "B"
    others = [tuple(c) for c in s.cells_col_row("+").tolist() if tuple(c) != d1]
    assert len(others) == 1 and others[0] not in reachable(grid, [start])


def test_nested_squares_closing_the_outer_ring_first_walls_the_inner_ring_off():
    s = load_scenario(SCENARIO_DIR / "nested_squares.toml")
    sites = s.cells_col_row("+")
    (c0, r0), (c1, r1) = sites.min(axis=0), sites.max(axis=0)
    outer = [tuple(c) for c in sites.tolist() if c[0] in (c0, c1) or c[1] in (r0, r1)]
    grid = [list(row) for row in s.layout]
    for c, r in outer:
        grid[r][c] = "B"
    reach = reachable(grid, [tuple(s.cells_col_row("A")[0].tolist())])
    inner = [tuple(c) for c in sites.tolist() if tuple(c) not in outer]
    assert inner and not any(cell in reach for cell in inner)


# ---------------------------------------------------------------- bad files


def _replace(old, new):
    assert old in GOOD
    return GOOD.replace(old, new)


BAD_FILES = [
    # (id, file text, line, column, text the `expected` part must contain)
    ("unknown layout char", _replace(".b+b.", ".bX+."), 6, 3, "'b' (free brick)"),
    ("ragged row", _replace(".b+b.", ".b+"), 6, 4, "row of 5 cells"),
    ("toml syntax", _replace("seed = 3", "seed = = 3"), 2, 8, "valid TOML"),
    ("unterminated layout", GOOD.rsplit('"""', 1)[0], 6, 6, "valid TOML"),
    ("missing required key", _replace("seed = 3\n", ""), 1, 1, "'seed'"),
    ("wrong type for seed", _replace("seed = 3", 'seed = "3"'), 2, 1, "integer seed"),
    ("bool seed", _replace("seed = 3", "seed = true"), 2, 1, "integer seed"),
    ("bad tick_mode", GOOD + 'tick_mode = "fast"\n', 8, 1, "lockstep"),
    ("unknown key", GOOD + "colour = 2\n", 8, 1, "one of the keys"),
    ("unknown world setting", GOOD + "[world]\nsensor_range = 5.0\nsensor_rnage = 4.0\n", 10, 1,
     "[world] settings"),
    ("bad world value", GOOD + "[world]\ndt = 0.1\nsensor_range = -1.0\n", 10, 1, "[world] settings"),
    ("too many agents", _replace("agents = 1", "agents = 9"), 3, 1, "at most 7 agents"),
    ("negative max_ticks", GOOD + "max_ticks = 0\n", 8, 1, "positive integer max_ticks"),
    ("indented layout", _replace("..A..\n.b+b.", "    ..A..\n    .bX+."), 6, 7, "'+' (drop site)"),
    ("over-indented row", _replace("..A..\n.b+b.", "  ..A..\n    .b+b."), 6, 3, "'.' (empty)"),
    ("blank line in layout", _replace("..A..\n", "..A..\n\n"), 6, 1, "no blank lines"),
]


@pytest.mark.parametrize("text,line,column,expected", [b[1:] for b in BAD_FILES],
                         ids=[b[0] for b in BAD_FILES])
def test_bad_file_is_rejected_with_line_column_and_expectation(tmp_path, text, line, column, expected):
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    err = info.value
    assert (err.path, err.line, err.column) == (str(path), line, column), str(err)
    assert expected in err.expected
    assert str(err).startswith(f"{path}:{line}:{column}: expected ")


def test_good_file_parses(tmp_path):
    path = tmp_path / "good.toml"
    path.write_text(GOOD + "[world]\nsensor_range = 5\n", encoding="utf-8")
    s = load_scenario(path)
    assert (s.name, s.seed, s.agents, s.tick_mode, s.max_ticks) == ("tiny", 3, 1, "lockstep", 20000)
    assert s.layout == ("..A..", ".b+b.")
    assert s.world.sensor_range == 5.0 and s.path == str(path)


def test_missing_file_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_scenario(tmp_path / "nope.toml")


# ---------------------------------------------------------------- coordinates


def test_north_row_first():
    s = parse_scenario(GOOD)
    (_, a_row), = s.cells_col_row("A")
    assert a_row == 0
    top, bottom = s.to_world([[0, 0], [0, s.rows - 1]])
    assert top[1] > bottom[1]
    assert top[1] == pytest.approx(s.size[1] - 0.5 * s.world.cell_size)
    assert bottom[1] == pytest.approx(0.5 * s.world.cell_size)
    assert s.to_world([[0, 0]])[0, 0] == pytest.approx(0.5 * s.world.cell_size)


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_every_cell_round_trips(path):
    s = load_scenario(path)
    cells = np.array([(c, r) for r in range(s.rows) for c in range(s.cols)])
    np.testing.assert_array_equal(s.to_cell(s.to_world(cells)), cells)


@settings(max_examples=60, deadline=None)
@given(col=st.integers(0, 4), row=st.integers(0, 1), fx=st.floats(0.01, 0.99), fy=st.floats(0.01, 0.99),
       size=st.sampled_from([0.5, 1.0, 2.0, 3.7]))
def test_any_point_in_a_cell_maps_to_that_cell(col, row, fx, fy, size):
    s = parse_scenario(GOOD + f"[world]\ncell_size = {size}\n")
    corner = s.to_world([[col, row]])[0] - size / 2  # south-west corner of the cell
    point = corner + np.array([fx, fy]) * size
    np.testing.assert_array_equal(s.to_cell(point), [[col, row]])
