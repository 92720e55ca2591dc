"""The ablation's journal (experiments/ablation.py --resume): an interrupted sweep resumed
runs only what the journal does not hold, and its table is the uninterrupted one's."""

from __future__ import annotations

import pytest

from experiments import ablation
from experiments.journal import Journal
from experiments.runner import Done

JOBS = [ablation.Job(layout, agent, 3000) for layout in ("a.toml", "b.toml", "c.toml")
        for agent in ("default", "paper")]


class Killed(Exception):
    """The sweep stopped by a kill after some runs."""


def fake_run(job: ablation.Job) -> ablation.Run:
    """A run whose result depends on its job only, as a real one does."""
    n = sum(map(ord, job.layout + job.agent))
    return ablation.Run(job.layout, "wall", job.agent, completed=n % 3 != 0, ticks=1000 + n, distance=n / 7,
                        bound=10.0, seconds=1.0)


def executor(ran: list[ablation.Job], kill_after: int | None = None):
    """`execute` of `ablation.sweep`, in process: each run recorded in `ran`, in reverse
    order (a pool finishes in no set order), and a kill after `kill_after` runs."""
    def execute(todo):
        for job in reversed(todo):
            if kill_after is not None and len(ran) == kill_after:
                raise Killed
            ran.append(job)
            yield Done(job, fake_run(job), "w1")
    return execute


def test_a_resumed_sweep_runs_only_what_the_journal_lacks_and_makes_the_same_table(tmp_path):
    whole: list[ablation.Job] = []
    uninterrupted = ablation.sweep(JOBS, executor(whole), Journal(tmp_path / "whole.jsonl", resume=False), "code")
    assert sorted(whole, key=JOBS.index) == JOBS

    path = tmp_path / "cut.jsonl"
    first: list[ablation.Job] = []
    with pytest.raises(Killed):
        ablation.sweep(JOBS, executor(first, kill_after=4), Journal(path, resume=False), "code")
    second: list[ablation.Job] = []
    resumed = ablation.sweep(JOBS, executor(second), Journal(path, resume=True), "code")

    assert len(first) == 4 and set(second) == set(JOBS) - set(first)   # nothing run twice, nothing left out
    assert resumed == uninterrupted
    assert ablation.table(resumed) == ablation.table(uninterrupted)


def test_runs_under_other_settings_or_code_are_run_again(tmp_path):
    path = tmp_path / "runs.jsonl"
    ablation.sweep(JOBS, executor([]), Journal(path, resume=False), "code")
    other_stall = [ablation.Job(j.layout, j.agent, 5000) for j in JOBS]
    for jobs, code in ((other_stall, "code"), (JOBS, "other code")):
        ran: list[ablation.Job] = []
        ablation.sweep(jobs, executor(ran), Journal(path, resume=True), code)
        assert sorted(ran, key=jobs.index) == jobs


def test_the_estimate_of_what_remains_goes_by_the_pace_so_far():
    assert ablation.remaining(elapsed=120.0, finished=4, left=10) == 300.0
    assert ablation.hms(ablation.remaining(120.0, 4, 10)) == "0:05:00"
    assert ablation.hms(3723.4) == "1:02:03"
    assert ablation.hms(ablation.remaining(0.0, 0, 10)) == "?"   # no run finished: no pace yet


def _run(layout: str, agent: str, completed: bool, ticks: int, distance: float) -> ablation.Run:
    return ablation.Run(layout, "wall", agent, completed, ticks, distance, bound=10.0)


def test_the_table_pairs_each_agent_with_the_default_on_the_same_layouts():
    runs = [_run("a", "default", True, 1000, 50.0), _run("b", "default", True, 2000, 80.0),
            _run("c", "default", False, 9000, 90.0),
            _run("a", "-unstick", True, 1000, 50.0),     # the default's run to the tick: unstick never acted
            _run("b", "-unstick", True, 3000, 99.0),     # 1.5x the ticks
            _run("c", "-unstick", True, 4000, 70.0),     # completes where the default stalls
            _run("a", "paper", False, 3000, 10.0), _run("b", "paper", False, 3000, 10.0),
            _run("c", "paper", False, 9000, 90.0)]       # stalled as the default did, to the tick
    rows = {line.split(" | ")[0].lstrip("| "): line.split(" | ") for line in ablation.table(runs).splitlines()[2:]}
    # agent | completed | gained / lost | same run | median ticks | ticks / default's | > 10% | distance / bound
    assert rows["default"][1:4] == ["2", "0 / 0", "3 of 3"]
    assert rows["-unstick"][1:4] == ["3", "1 / 0", "1 of 3"]
    assert rows["-unstick"][5:7] == ["1.22", "1 / 0"]     # the geometric mean of 1.0 and 1.5, on a and b
    assert rows["paper"][1:4] == ["0", "0 / 2", "1 of 3"]
    assert rows["paper"][5:7] == ["-", "-"]


def test_the_status_of_an_unfinished_sweep_counts_only_layouts_every_agent_finished(tmp_path):
    path = tmp_path / "runs.jsonl"
    with pytest.raises(Killed):
        ablation.sweep(JOBS, executor([], kill_after=3), Journal(path, resume=False), "code")
    before = path.read_bytes()
    text = ablation.journal_status(Journal(path, resume=False, readonly=True), JOBS, "code")
    assert path.read_bytes() == before                       # read only: a running sweep appends to it
    assert text.startswith("3 of 6 runs done at this code; 1 of 3 layouts have every agent's run")
    assert "completed (of 1)" in text
    with pytest.raises(ValueError, match="read only"):
        Journal(path, resume=False, readonly=True).append(["k"], {})


def test_runs_of_one_layout_with_other_seeds_are_paired_seed_by_seed():
    runs = [ablation.Run("a", "wall", "default", True, 1000, 50.0, 10.0, seed=0),
            ablation.Run("a", "wall", "default", False, 9000, 90.0, 10.0, seed=1),
            ablation.Run("a", "wall", "-unstick", False, 9000, 90.0, 10.0, seed=0),   # loses seed 0
            ablation.Run("a", "wall", "-unstick", True, 2000, 60.0, 10.0, seed=1)]    # gains seed 1
    rows = {line.split(" | ")[0].lstrip("| "): line.split(" | ") for line in ablation.table(runs).splitlines()[2:]}
    assert "completed (of 2)" in ablation.table(runs).splitlines()[0]
    assert rows["-unstick"][1:4] == ["1", "1 / 1", "0 of 2"]
    assert ablation.job_key(ablation.Job("a", "default", 3000, seed=2), "code")[-1] == 2
    assert ablation.job_key(ablation.Job("a", "default", 3000), "code") == ["a", "default", 3000, "code"]  # as before


def test_an_agent_with_several_additions_off_is_named_by_joining_them():
    cfg = ablation.agent_of("-site_core-off_own_brick")
    assert not cfg.site_core and not cfg.off_own_brick and cfg.agents_as_obstacles
    assert ablation.agent_of("-unstick") == ablation.variants()["-unstick"]
    for bad in ("-site_core-nope", "-", "site_core", "-unstick-unstick"):
        with pytest.raises(ValueError, match="unknown agent"):
            ablation.agent_of(bad)
    runs = [_run("a", "default", True, 1000, 50.0), _run("a", "-site_core-off_own_brick", True, 1100, 55.0)]
    assert ablation.table(runs).splitlines()[-1].startswith("| -site_core-off_own_brick | 1 | 0 / 0 |")
