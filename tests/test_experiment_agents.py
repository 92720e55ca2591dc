"""The experiments' `--agent PRESET` and `--without NAMES` (experiments/agents.py): the agent a
job carries, the files and rows it names, and the Fig. 6 experiment that compares agents."""

from __future__ import annotations

import argparse
import json

import pytest

from agent_runtime.config import AgentConfig
from experiments import fig6
from experiments import goal_sequencing as gs
from experiments.agents import DEFAULT, Agent, add_arguments, chosen


def parse(*argv: str) -> Agent:
    ap = argparse.ArgumentParser()
    add_arguments(ap)
    return chosen(ap, ap.parse_args(list(argv)))


def test_the_flags_name_the_agent_its_files_and_its_rows():
    assert parse() == DEFAULT and DEFAULT.suffix == "" and DEFAULT.label == "default"
    paper = parse("--agent", "paper", "--without", "ghost_association")
    assert paper.config(goal_sequencing=False) == AgentConfig.preset("paper", ghost_association=False,
                                                                      goal_sequencing=False)
    assert (paper.suffix, paper.label) == ("_paper-ghost_association", "paper -ghost_association")
    assert Agent("paper").suffix == "_paper"


@pytest.mark.parametrize("argv", [["--agent", "papr"], ["--without", "ghosts"]])
def test_an_unknown_preset_or_addition_is_a_usage_error(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        parse(*argv)
    assert exc.value.code == 2 and "known" in capsys.readouterr().err


def test_goal_sequencing_runs_read_back_with_their_agent_and_without_one(tmp_path):
    row = {"job": {"scenario": "fig17", "mode": "nearest-first", "agents": 1, "seed": 1, "max_ticks": 20000,
                   "stall": 5000}, "completed": True, "ticks": 230, "filled": 3, "paper_order": None, "total": 3,
           "distance": 32.5, "starts": [[11, 7]], "stalled": False, "seconds": 0.1}
    paper = {**row, "job": {**row["job"], "agent": {"preset": "paper", "without": ["unstick"]}}}
    path = tmp_path / "runs.json"
    path.write_text(json.dumps([row, paper]))
    old, new = gs.load_runs(path)
    assert old.job.agent == DEFAULT and new.job.agent == Agent("paper", ("unstick",))
    assert old.starts == [(11, 7)] and hash(new.job)


def test_the_fig6_table_has_a_row_per_agent_measured(tmp_path):
    def runs(label, done):
        return [fig6.Run("build", s, label, s <= done, 300 + s, 100.0) for s in (1, 2, 3)] + \
               [fig6.Run("repair", s, label, s <= done, 600 + s, 50.0) for s in (1, 2, 3)]

    for name, label, done in (("fig6", "default", 3), ("fig6_paper", "paper", 1)):
        (tmp_path / f"{name}.json").write_text(json.dumps([r.__dict__ for r in runs(label, done)]))
    lines = fig6.table(fig6.measured(tmp_path)).splitlines()
    assert lines[2] == "| default | 3/3 | 302 | 100 | 3/3 | 602 |"
    assert lines[3] == "| paper | 1/3 | 301 | 100 | 1/3 | 601 |"


@pytest.mark.slow  # seconds: two builds of Fig. 6
def test_the_fig6_experiment_builds_and_repairs_and_writes_its_section(tmp_path):
    doc = tmp_path / "doc.md"
    assert fig6.main(["--seeds", "1", "--jobs", "1", "--out", str(tmp_path), "--doc", str(doc)]) == 0
    (build, repair) = [fig6.Run(**r) for r in json.loads((tmp_path / "fig6.json").read_text())]
    assert build.completed and repair.completed and repair.ticks > 0
    text = doc.read_text()
    assert "<!-- section:fig6 -->" in text and "| default | 1/1 |" in text
