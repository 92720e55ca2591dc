"""experiments/team_size.py: its layouts are what the issue asks for (at least 12, generated
and held-out kinds, 40 to 200 sites, all buildable, the same every time), and its speed-up
is mean ticks with 1 agent over mean ticks with N."""

from __future__ import annotations

from dataclasses import asdict, replace

import pytest

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


def _row(layout: str, sites: int, agents: int, ticks: float, speedup: float, bound: float) -> dict:
    return dict(layout=layout, sites=sites, agents=agents, runs=3, completed=3, ticks_mean=ticks,
                ticks_median=ticks, speedup=speedup, distance_bound=bound, shares={})


def test_the_goals_name_the_layouts_that_miss_them():
    rows = [_row("a", 120, 1, 8000, 1.0, 1.5), _row("a", 120, 8, 1000, 8.0, 1.9), _row("a", 120, 32, 400, 20.0, 3.0),
            _row("b", 50, 1, 6000, 1.0, 1.5), _row("b", 50, 8, 1200, 5.0, 2.4), _row("b", 50, 16, 900, 6.7, 2.8),
            _row("b", 50, 32, 1500, 4.0, 4.0)]
    text = team_size.goals(rows).splitlines()
    assert text[0].startswith("* speed-up at 8 agents of at least 6: met on 1 of 2") and text[0].endswith("not on b.")
    assert "met on 1 of 1" in text[1]                              # only "a" has 100 sites or more
    assert "not met on 1 of 2 layouts: b (32 agents slower than 8)" in text[2]
    assert "met on 1 of 2" in text[3] and text[3].endswith("not on b.")


def _study(layout: str, ticks: int, seeds=team_size.SEEDS) -> list[dict]:
    return [asdict(replace(_run(n, ticks // n), layout=layout, seed=s)) for n in team_size.TEAMS for s in seeds]


def test_merge_puts_a_layouts_runs_in_place_of_the_studys_and_says_where_they_came_from():
    full = dict(command="python3 -m experiments.team_size", note="",
                runs=_study("circle", 6400) + _study("conag", 6400))
    full["rows"] = team_size.summarise([team_size.Run(**r) for r in full["runs"]])
    part = dict(command="python3 -m experiments.team_size --layouts conag", note=" (layouts conag)",
                runs=_study("conag", 3200))
    merged = team_size.merge(full, part)
    assert [r for r in merged["runs"] if r["layout"] == "circle"] == full["runs"][:len(full["runs"]) // 2]
    assert sorted(r["ticks"] for r in merged["runs"] if r["layout"] == "conag") == \
        sorted(r["ticks"] for r in part["runs"])
    assert {r["layout"]: r["ticks_mean"] for r in merged["rows"] if r["agents"] == 1} == {"circle": 6400, "conag": 3200}
    assert merged["merged"] == [dict(layouts=["conag"], command=part["command"])]
    text = team_size.report(merged["rows"], merged["command"], merged["note"], merged["merged"])
    assert "the runs of conag are from `python3 -m experiments.team_size --layouts conag`" in text
    # Merging the same layout again replaces the first merge's note too.
    again = team_size.merge(merged, part)
    assert len(again["merged"]) == 1 and again["runs"] == merged["runs"]


def test_merge_refuses_runs_that_are_not_the_studys_design():
    full = dict(command="python3 -m experiments.team_size", note="", runs=_study("circle", 6400))
    part = dict(command="python3 -m experiments.team_size --layouts conag", runs=_study("conag", 3200, seeds=(1,)))
    with pytest.raises(ValueError, match="do not cover"):
        team_size.merge(full, part)
    with pytest.raises(ValueError, match="not layouts of the study"):
        team_size.merge(full, dict(part, runs=_study("nowhere", 3200)))
    with pytest.raises(ValueError, match="not a run of --layouts"):
        team_size.merge(full, dict(part, command="python3 -m experiments.team_size --layouts conag --with x",
                                   runs=_study("conag", 3200)))


def test_merge_is_given_alone(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        team_size.main(["--merge", str(tmp_path), "--layouts", "conag"])
    assert stop.value.code == 2 and "give it alone" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:                      # no team_size.json there: a usage error
        team_size.main(["--merge", str(tmp_path)])
    assert stop.value.code == 2 and "--merge" in capsys.readouterr().err
