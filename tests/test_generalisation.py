"""The generalisation benchmark (experiments/generalisation.py): the committed suite is what
the generator makes, and the script's --quick run writes its table."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from experiments import generalisation as gen
from world_server.buildability import check_buildable
from world_server.generator import generate_suite
from world_server.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_the_committed_suite_is_the_generators_and_every_layout_is_buildable():
    files = gen.suite_files()
    assert len(files) == gen.SUITE_SIZE
    # Made again from the suite's seed, the layouts are byte for byte the committed files.
    for name, g in zip(files, generate_suite(gen.SUITE_SIZE, gen.SUITE_SEED)):
        assert (gen.LAYOUTS / name).read_text(encoding="utf-8") == g.text, name
    for name in files[::10]:
        sc = load_scenario(gen.LAYOUTS / name)
        assert check_buildable(sc).ok, name


def test_the_stall_limit_grows_with_the_world_per_agent():
    small = load_scenario(gen.LAYOUTS / gen.quick_files(1)[0])
    assert gen.stall_limit(small, 3000) == 3000
    big = next(load_scenario(gen.LAYOUTS / n) for n in gen.suite_files()
               if load_scenario(gen.LAYOUTS / n).cols * load_scenario(gen.LAYOUTS / n).rows > 6000)
    assert gen.stall_limit(big, 3000) == big.cols * big.rows // big.agents


@pytest.mark.slow
def test_the_quick_run_builds_small_layouts_with_both_agents_and_writes_its_table(tmp_path):
    r = subprocess.run([sys.executable, "-m", "experiments.generalisation", "--quick", "--jobs", "1",
                        "--out", str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    runs = json.loads((tmp_path / "generalisation.json").read_text())
    assert len(runs) == 8 and {o["mode"] for o in runs} == {"goal sequencing", "nearest-first"}
    assert all(o["bricks_total_end"] == o["bricks_total_start"] for o in runs)
    assert all(o["completed"] for o in runs if o["mode"] == "goal sequencing")
    table = (tmp_path / "generalisation.md").read_text()
    assert "### Goals" in table and "### Per family" in table


@pytest.mark.slow
def test_the_quick_run_refuses_to_overwrite_the_committed_results():
    r = subprocess.run([sys.executable, "-m", "experiments.generalisation", "--quick"], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--out" in r.stderr


def test_a_resumed_run_links_the_pictures_in_its_own_folder(tmp_path):
    # A journal carried on in another --out folder, its pictures copied along, linked 54
    # failures of the committed table to the folder they were first drawn in.
    first, now = tmp_path / "first" / "failures", tmp_path / "now" / "failures"
    first.mkdir(parents=True)
    now.mkdir(parents=True)
    (now / "a-ts.png").write_bytes(b"png")
    o = gen.Outcome(layout="a.toml", family="ring", cols=20, rows=20, agents=1, mode="goal sequencing",
                    completed=False, stalled=True, ticks=3000, max_ticks=9000, sites_filled=1, sites_total=4,
                    bricks_total_start=4, bricks_total_end=4, distance=1.0, bound=1.0, seconds=1.0,
                    picture=str(first / "a-ts.png"))
    assert gen.in_folder(o, now).picture == str((now / "a-ts.png").resolve())
    gone = gen.in_folder(gen.Outcome(**{**o.__dict__, "picture": str(first / "b-ts.png")}), now)
    assert gone.picture == str(first / "b-ts.png")                # none of that name here: as it was
    assert gen.in_folder(gen.Outcome(**{**o.__dict__, "picture": ""}), now).picture == ""


@pytest.mark.slow
def test_an_interrupted_run_resumes_without_running_again_what_it_finished(tmp_path):
    layout = "000-gen-wall-20260000.toml"

    def run(out, *extra):
        return subprocess.run([sys.executable, "-m", "experiments.generalisation", "--only", layout, "--jobs", "1",
                               "--out", str(out), *extra], cwd=ROOT, capture_output=True, text=True, timeout=600)

    whole = run(tmp_path / "whole")
    assert whole.returncode == 0, whole.stderr[-2000:]
    assert not (tmp_path / "whole" / gen.JOURNAL).exists()    # a finished run leaves no journal
    rows = json.loads((tmp_path / "whole" / "generalisation.json").read_text())
    # As if the run had been killed after its goal-sequencing run: only that one is in the journal.
    first = next(r for r in rows if r["mode"] == "goal sequencing")
    (tmp_path / "cut").mkdir()
    key = [layout, "goal sequencing", gen.DEFAULT_STALL, gen._code_version()]
    (tmp_path / "cut" / gen.JOURNAL).write_text(json.dumps({"run": 1.0, "at": 5.0, "key": key, "result": first}) + "\n")
    resumed = run(tmp_path / "cut", "--resume")
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert "resuming: 1 of 2 runs already done" in resumed.stderr
    assert resumed.stderr.count("] 000-gen-wall") == 1 and "nearest-first" in resumed.stderr   # one run, the other
    again = json.loads((tmp_path / "cut" / "generalisation.json").read_text())
    same = ("layout", "mode", "completed", "ticks", "sites_filled", "distance")
    assert [{k: r[k] for k in same} for r in again] == [{k: r[k] for k in same} for r in rows]


def test_a_goal_with_no_layout_in_the_run_is_not_reported_as_measured_or_missed():
    big = gen.Outcome("x.toml", "wall", 80, 80, 5, "goal sequencing", True, False, 900, 9000, 10, 10, 12, 12,
                      50.0, 25.0, 1.0)
    table = gen.goals([big])
    assert "| goal sequencing completes buildable layouts | >= 98% | 100.0% of 1 | yes |" in table
    assert "| ... with <= 3 agents in worlds up to 60 x 60 | 100% | no such layout in this run | — |" in table
    assert "nan" not in table
