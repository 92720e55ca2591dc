"""Issue 36's solid shapes and corridors: the generator's new families are buildable (the
check proves each one), the suite and an unset family still make version 1's files, and
the two layouts the issue found the agent losing on are built (slow tier)."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from conag import sim
from world_server.buildability import check_buildable
from world_server.generator import MAX_BLOCK_SIDE, generate, spiral_cells, suite_plan
from world_server.layout_options import SOLID_FAMILIES, SUITE_FAMILIES
from world_server.scenario import load_scenario

LAYOUTS = Path(__file__).resolve().parent / "layouts"
STALL = 3000  # the default stall rule of the experiments (experiments.generalisation.DEFAULT_STALL)


def _sites(g) -> np.ndarray:
    return g.scenario().grid("+B")


@pytest.mark.parametrize("family", SOLID_FAMILIES)
@pytest.mark.parametrize("seed", range(6))
def test_every_new_family_is_buildable_with_what_was_asked(family, seed):
    size = (15, 30, 60)[seed % 3]
    g = generate(seed, family, size, 1 + seed, max_sites=(40, 80, 120)[seed % 3])
    s = g.scenario()
    assert g.family == family and s.agents == 1 + seed and (s.cols, s.rows) == (size, size)
    verdict = check_buildable(s)
    assert verdict.ok, verdict.reason
    assert verdict.spare >= 2 and len(verdict.order) == g.sites


def test_blocks_are_solid_and_at_most_ten_a_side():
    solid = 0
    for seed in range(20):
        g = generate(seed, "block", 40, 2, max_sites=120)
        rows, cols = np.nonzero(_sites(g))
        h, w = np.ptp(rows) + 1, np.ptp(cols) + 1
        assert max(h, w) <= MAX_BLOCK_SIDE
        solid += len(rows) == h * w  # a full rectangle (the others are compact blobs)
    assert solid >= 5


def test_a_large_block_fills_its_core_before_its_rim_closes():
    g = generate(3, "block", 40, 4, max_sites=120)
    order = check_buildable(g.scenario()).order
    assert len(order) >= 9  # every site in an order that never seals one in


@pytest.mark.parametrize("n", [5, 7, 9, 11])
def test_a_spiral_is_one_cell_wide_with_a_free_cell_between_its_arms(n):
    cells = spiral_cells(n)
    assert len(set(cells)) == len(cells)
    assert all(abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1 for a, b in itertools.pairwise(cells))  # one path
    grid = np.zeros((n, n), bool)
    for r, c in cells:
        grid[r, c] = True
    assert not (grid[:-1, :-1] & grid[1:, :-1] & grid[:-1, 1:] & grid[1:, 1:]).any()  # never 2 cells wide
    assert not grid[n - 1, 1]  # the corridor opens at the south-west corner


def test_corridors_are_one_cell_wide_paths():
    for seed in range(10):
        sites = _sites(generate(seed, "corridor", 30, 2, max_sites=40))
        assert not (sites[:-1, :-1] & sites[1:, :-1] & sites[:-1, 1:] & sites[1:, 1:]).any()
        assert sites.sum() >= 6


def test_solid_hollow_shapes_hold_a_solid_part_and_an_empty_inside():
    for seed in range(10):
        g = generate(seed, "solid_hollow", 30, 2, max_sites=40)
        sites = _sites(g)
        assert (sites[:-1, :-1] & sites[1:, :-1] & sites[:-1, 1:] & sites[1:, 1:]).any()  # a 2 x 2 solid part


def test_the_suite_and_an_unset_family_make_version_one_files():
    # The committed suite manifest (experiments/generalisation/layouts.json) names files
    # by checksum: the new families must not change them.
    assert {p["family"] for p in suite_plan(40, 2026)} == set(SUITE_FAMILIES)
    assert {generate(seed).family for seed in range(60)} <= set(SUITE_FAMILIES)


def _build(name: str) -> sim.SimResult:
    sc = load_scenario(LAYOUTS / f"{name}.toml")
    assert check_buildable(sc).ok
    return sim.start(sc).run(sc.max_ticks, stall_ticks=STALL)


@pytest.mark.slow
def test_the_solid_six_by_six_block_is_built():
    # Issue 36: four agents stalled at 34/36, two inner sites sealed in.
    result = _build("solid_block")
    assert result.completed, result


@pytest.mark.slow
def test_the_nine_by_nine_spiral_is_built():
    # Issue 36: three agents stalled at 45/50, one agent making 44 of the fills.
    result = _build("spiral")
    assert result.completed, result


def test_the_candidate_suite_manifest_makes_its_files_again(tmp_path):
    from experiments.generalisation import FAMILIES_MANIFEST
    from world_server import suite

    m = suite.read_manifest(FAMILIES_MANIFEST)
    assert len(m.layouts) == 200 and {e.mix for e in m.layouts} == {"solid"}
    new = [e for e in m.layouts if any(f"-{f}-" in e.file for f in SOLID_FAMILIES)]
    assert 0.2 <= len(new) / len(m.layouts) <= 0.3  # about a quarter
    some = suite.Manifest(m.generator, tuple(new[:4]))
    assert suite.Manifest.from_json(some.to_json()) == some
    paths = suite.materialise(some, tmp_path)  # refuses if the generator made other files
    assert all(check_buildable(load_scenario(p)).ok for p in paths)
