"""experiments/team_size.py: its layouts are what the issue asks for (at least 12, generated
and held-out kinds, 40 to 200 sites, all buildable, the same every time), and its speed-up
is mean ticks with 1 agent over mean ticks with N."""

from __future__ import annotations

from dataclasses import asdict, replace

from agent_runtime.config import AgentConfig
from experiments import team_size
from experiments.journal import Journal
from world_server.buildability import check_buildable
from world_server.scenario import parse_scenario


def test_the_layouts_are_twelve_or_more_buildable_ones_of_40_to_200_sites():
    layouts = team_size.layouts()
    assert len(layouts) >= 12
    assert {"circle", "conag"} <= set(layouts)                       # held-out kinds
    assert sum(name.startswith("gen-") for name in layouts) >= 10     # generated ones
    for name, text in layouts.items():
        sc = parse_scenario(text, name)
        assert 40 <= len(sc.cells_col_row("+")) <= 200, name
        assert check_buildable(sc).ok, name
    assert team_size.layouts() == layouts                             # deterministic
    assert set(team_size.QUICK_LAYOUTS) <= set(layouts)


def _run(agents: int, ticks: int, completed: bool = True, **behaviours) -> team_size.Run:
    return team_size.Run("x", agents, 1, 40, completed, not completed, ticks, 40, 100.0, 50.0,
                         behaviours or {"explore": ticks * agents}, 0.0)


def test_speed_up_is_mean_ticks_alone_over_mean_ticks_with_the_team():
    runs = [_run(1, 1000), _run(1, 3000), _run(4, 500), _run(4, 700, explore=100, brick_nav=300)]
    rows = {r["agents"]: r for r in team_size.summarise(runs)}
    assert rows[1]["speedup"] == 1.0
    assert rows[4]["speedup"] == 2000 / 600
    assert rows[4]["distance_bound"] == 2.0
    shares = rows[4]["shares"]
    assert abs(sum(shares.values()) - 1.0) < 1e-12 and shares["brick_nav"] == 300 / 2400


def test_a_resumed_run_runs_only_what_the_journal_holds_not_for_the_same_code_and_settings(tmp_path):
    cfg = AgentConfig()
    jobs = [("x", "", 1, 1, cfg), ("x", "", 4, 1, cfg), ("x", "", 4, 2, cfg)]
    journal = Journal(tmp_path / team_size.JOURNAL, resume=False)
    journal.append(team_size.job_key(jobs[1], "v1"), asdict(_run(4, 500)))
    journal.append(team_size.job_key(jobs[2], "v0"), asdict(_run(4, 600)))              # other code
    other = ("x", "", 1, 1, replace(cfg, share_bricks=True))
    journal.append(team_size.job_key(other, "v1"), asdict(_run(1, 900)))                 # other settings
    done, todo = team_size.pending(Journal(tmp_path / team_size.JOURNAL, resume=True), jobs, "v1")
    assert done == [_run(4, 500)]
    assert todo == [jobs[0], jobs[2]]
