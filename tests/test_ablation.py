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
