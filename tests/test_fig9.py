"""The Fig. 9 experiment (§5.1; L3, L4): trials in one process, and the script's --quick run."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from agent_runtime.learning import Student
from agent_runtime.network import engineered
from agent_runtime.qlearning import QLearner
from conag.sim.trials import run_learning, run_trial, trial_seed
from teacher.core import Teacher
from tests.conftest import ROOT, SCENARIOS
from world_server.scenario import load_scenario

pytestmark = pytest.mark.slow  # builds of thousands of ticks, and the experiment script

FIG6 = load_scenario(SCENARIOS / "fig6.toml")


def test_every_trial_starts_from_the_initial_layout_and_the_engineered_network_makes_no_errors():
    built = run_trial(FIG6, engineered(), Teacher(), ticks=1000, eta=0.0, seed=trial_seed(9, 0, 0), learn=False)
    again = run_trial(FIG6, engineered(), Teacher(), ticks=1000, eta=0.0, seed=trial_seed(9, 0, 0), learn=False)
    assert built.errors == 0 and built.completed_at is not None and built.sites_filled == built.sites_total == 4
    assert again == built                                    # same seed, same run
    fresh = run_trial(FIG6, engineered(), Teacher(), ticks=5, eta=0.0, seed=trial_seed(9, 0, 1), learn=False)
    assert fresh.sites_filled == 0 and fresh.ticks == 5      # bricks back where the scenario puts them
    quick = run_trial(load_scenario(SCENARIOS / "quick_wall.toml"), engineered(), Teacher(), ticks=1000, eta=0.0,
                      seed=1, learn=False, until_complete=True)
    assert quick.completed_at == quick.ticks < 1000


@pytest.mark.parametrize("kind, eta", [("delta", 0.2), ("q", 0.5)])
def test_errors_per_trial_fall_to_zero_on_fig6(kind, eta):
    rng = np.random.default_rng([9, 0])
    learner = Student.random(rng) if kind == "delta" else QLearner(rng)
    results = run_learning(FIG6, learner, trials=6, ticks=1000, eta=eta, seed=9, run=0)
    errors = [r.errors for r in results]
    assert errors[0] > 20, errors
    assert errors[-2:] == [0, 0], errors
    assert results[-1].completed_at is not None              # and it builds the diamond


def test_the_quick_experiment_writes_table_plot_data_and_a_reusable_student(tmp_path):
    r = subprocess.run([sys.executable, "-m", "experiments.fig9_learning", "--quick", "--out", str(tmp_path)], cwd=ROOT,
                       capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr
    progress = [line for line in r.stderr.splitlines() if line.startswith("[fig9]")]
    assert len(progress) == 8 and "8/8 runs, 24/24 trials done" in progress[-1]
    assert all("(current " in line for line in progress)
    md = (tmp_path / "fig9_learning.md").read_text()
    for text in ("delta rule, eta = 0.05", "delta rule, eta = 0.2", "delta rule, eta = 0.5", "Q-learning (alpha = 0.5",
                 "first trial with mean errors 0", "| 3 |", "novel environments", "| quick_wall | off |",
                 "| fig17 | on |"):
        assert text in md, text
    assert (tmp_path / "fig9_learning.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    data = json.loads((tmp_path / "fig9_learning.json").read_text())
    assert len(data["runs"]) == 8 and all(len(run["errors"]) == 3 for run in data["runs"])
    assert all(run["errors"][0] > 0 for run in data["runs"])  # random weights make mistakes
    student = Student.load(tmp_path / "fig9_student.json")
    assert (student.excite >= 0).all() and (student.inhibit <= 0).all()
