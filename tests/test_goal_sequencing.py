"""ConAg-TS agents (paper §6.2; G2-G3): the Brain's Matching grid shapes its goals,
and agents build the paper's layouts that nearest-first cannot, in the order that keeps
every site reachable. Builds run the real World and Brain code in one process (sim).
"""

from __future__ import annotations

import numpy as np
import pytest

from agent_runtime.config import AgentConfig
from conag import sim
from tests.conftest import SCENARIOS
from world_server.scenario import load_scenario

NEAREST_FIRST = AgentConfig(goal_sequencing=False)


def build(name: str, agents: int = 1, ticks: int | None = None, cfg: AgentConfig | None = None, seed=None):
    sc = load_scenario(SCENARIOS / f"{name}.toml")
    run = sim.start(sc, agents=agents, seed=seed, cfg=cfg)
    run.run(ticks or sc.max_ticks)
    return sc, run


def test_the_switch_gives_the_plain_agent_and_sequencing_is_the_default():
    _, ts = build("fig18", ticks=5)
    _, nf = build("fig18", ticks=5, cfg=NEAREST_FIRST)
    assert ts.brains["a1"].plans.matching is not None
    assert nf.brains["a1"].plans.matching is None


def test_the_matching_is_recomputed_only_when_the_maps_change():
    _, run = build("fig18", ticks=3)
    brain = run.brains["a1"]
    n = brain.cfg.map_size
    bricks, sites, obstacles = (np.zeros((n, n), bool) for _ in range(3))
    bricks[5, 5], sites[10, 10] = True, True
    first = brain.matching(bricks, sites, obstacles)
    assert first.pairs == (((10, 10), (5, 5)),)
    assert brain.matching(bricks.copy(), sites.copy(), obstacles.copy()) is first
    bricks[10, 12] = True  # a brick appears nearer the site
    again = brain.matching(bricks, sites, obstacles)
    assert again is not first and again.pairs == (((10, 10), (10, 12)),)


def test_fig17_completes():
    _, run = build("fig17")
    assert run.world.status().completed


@pytest.mark.parametrize("agents", [1, 3])
def test_fig18_d2_is_filled_before_d1(agents):
    _, run = build("fig18", agents=agents, ticks=6000)
    assert run.world.status().completed
    filled = run.fill_ticks()
    assert filled[(8, 8)] < filled[(7, 8)]          # D2 (the pocket's end), then D1 (its mouth)


@pytest.mark.slow
def test_fig18_nearest_first_fills_d1_first_and_never_finishes():
    _, run = build("fig18", ticks=3000, cfg=NEAREST_FIRST)
    filled = run.fill_ticks()
    assert filled[(7, 8)] >= 0 and filled[(8, 8)] == -1 and not run.world.status().completed


@pytest.mark.slow
def test_fig19_completes_and_the_farthest_wall_is_finished_first():
    _, run = build("fig19")
    assert run.world.status().completed
    filled = run.fill_ticks()
    done = {row: max(t for (r, _), t in filled.items() if r == row) for row in (8, 11, 14)}
    assert done[14] < done[8] and done[14] < done[11]


@pytest.mark.slow
@pytest.mark.parametrize("agents", [1, 3])
def test_fig20_completes(agents):
    _, run = build("fig20", agents=agents)
    assert run.world.status().completed


@pytest.mark.slow
@pytest.mark.parametrize("agents", [1, 3])
def test_nested_squares_the_inner_square_is_built_before_the_outer_ring_closes(agents):
    _, run = build("nested_squares", agents=agents)
    assert run.world.status().completed
    filled = run.fill_ticks()
    inner = [t for (r, c), t in filled.items() if 7 <= r <= 9 and 9 <= c <= 11]
    outer = [t for (r, c), t in filled.items() if not (7 <= r <= 9 and 9 <= c <= 11)]
    assert len(inner) == 8 and max(inner) < max(outer)


@pytest.mark.slow
def test_nested_squares_nearest_first_closes_the_ring_first_and_stalls():
    _, run = build("nested_squares", ticks=6000, cfg=NEAREST_FIRST)
    filled = run.fill_ticks()
    inner = [t for (r, c), t in filled.items() if 7 <= r <= 9 and 9 <= c <= 11]
    assert not run.world.status().completed and -1 in inner


@pytest.mark.slow
def test_the_fig13_experiment_quick_run_writes_its_table_chart_and_section(tmp_path):
    import subprocess
    import sys

    from tests.conftest import ROOT

    doc = tmp_path / "EXPERIMENTS.md"
    r = subprocess.run([sys.executable, "-m", "experiments.goal_sequencing", "--quick", "--out", str(tmp_path),
                        "--doc", str(doc)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "[4/4]" in r.stderr                                   # progress per run
    rows = [line for line in r.stdout.splitlines() if line.startswith("| fig18 | 1 |")]
    assert len(rows) == 2
    nearest, sequencing = (row.split("|")[4].strip() for row in rows)
    assert nearest == "0/1" and sequencing == "1/1"
    assert (tmp_path / "goal_sequencing.png").stat().st_size > 10_000
    assert "<!-- section:G3 -->" in doc.read_text()
