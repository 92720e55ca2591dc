"""The generalisation benchmark (experiments/generalisation.py): the committed manifest is what
the generator makes, the suite's files are made from it (world_server/suite.py), and the
script's --quick run writes its table."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from experiments import generalisation as gen
from experiments.journal import code_version
from world_server import suite
from world_server.buildability import check_buildable
from world_server.generator import GENERATOR_VERSION
from world_server.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_the_manifest_is_what_the_generator_makes_and_every_layout_is_buildable(tmp_path):
    manifest = suite.read_manifest(gen.MANIFEST)
    assert manifest.generator == GENERATOR_VERSION
    assert len(manifest.layouts) == gen.SUITE_SIZE
    assert {(e.count, e.suite_seed) for e in manifest.layouts} == {(gen.SUITE_SIZE, gen.SUITE_SEED)}
    # Made again from the suite's seed, the layouts have exactly the committed checksums.
    again, texts = suite.manifest_of([(gen.SUITE_SIZE, gen.SUITE_SEED, None)])
    assert again == manifest
    assert again.to_json() == gen.MANIFEST.read_text(encoding="utf-8")
    assert suite.manifest_of(gen.UNSEEN_LAYOUTS)[0].to_json() == gen.UNSEEN_MANIFEST.read_text(encoding="utf-8")
    # ... and materialised in a fresh folder (a fresh clone), the files are those texts.
    paths = suite.materialise(gen.MANIFEST, tmp_path)
    assert [p.read_text(encoding="utf-8") for p in paths] == [texts[e.file] for e in manifest.layouts]
    for path in paths[::10]:
        assert check_buildable(load_scenario(path)).ok, path.name


def test_the_suite_files_are_made_from_the_manifest():
    files = gen.suite_files()
    assert files == sorted(suite.read_manifest(gen.MANIFEST).files())
    assert all((gen.LAYOUTS / name).is_file() for name in files)


def test_materialise_makes_missing_and_changed_files_and_removes_strays(tmp_path):
    manifest, texts = suite.manifest_of([(30, 7, (2, 5))])
    assert manifest.files() == [e.file for e in manifest.layouts] and len(texts) == 2
    assert suite.Manifest.from_json(manifest.to_json()) == manifest
    first, second = suite.materialise(manifest, tmp_path)
    assert first.read_text(encoding="utf-8") == texts[first.name]
    first.write_text("edited", encoding="utf-8")
    second.unlink()
    (tmp_path / "stray.toml").write_text("x", encoding="utf-8")
    (tmp_path / "notes.txt").write_text("kept", encoding="utf-8")
    assert suite.materialise(manifest, tmp_path) == [first, second]
    assert [p.read_text(encoding="utf-8") for p in (first, second)] == [texts[first.name], texts[second.name]]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([first.name, second.name, "notes.txt"])


def test_materialise_refuses_a_layout_the_generator_no_longer_makes(tmp_path):
    manifest, _ = suite.manifest_of([(30, 7, (2,))])
    wrong = suite.Manifest(manifest.generator, (replace(manifest.layouts[0], sha256="0" * 64),))
    with pytest.raises(suite.SuiteError, match="GENERATOR_VERSION"):
        suite.materialise(wrong, tmp_path)
    assert not list(tmp_path.glob("*.toml"))                  # nothing half made
    old = suite.Manifest(GENERATOR_VERSION - 1, manifest.layouts)
    with pytest.raises(suite.SuiteError, match="version"):
        suite.materialise(old, tmp_path)
    suite.materialise(manifest, tmp_path)                     # made by this version: the files are there...
    assert suite.materialise(old, tmp_path)                   # ... so an older manifest with their checksums is fine
    with pytest.raises(suite.SuiteError, match="not a suite manifest"):
        suite.Manifest.from_json('{"layouts": []}')


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


@pytest.mark.slow
def test_the_pictures_of_the_tables_failures_are_drawn_again_as_recorded(tmp_path):
    layout = "167-gen-pocket-20260167.toml"       # a nearest-first failure of the table, 15 x 15
    r = subprocess.run([sys.executable, "-m", "experiments.generalisation", "--pictures", "--only", layout,
                        "--jobs", "1", "--out", str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "1 of 1 runs stopped as recorded" in r.stderr
    row = next(r for r in json.loads((ROOT / "experiments" / "generalisation.json").read_text())
               if r["layout"] == layout and r["picture"])
    assert (tmp_path / row["picture"]).stat().st_size > 1000   # where the table links it, under --out


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
    key = [layout, "goal sequencing", gen.DEFAULT_STALL, code_version()]
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


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_the_ablation_quick_run_reproduces_the_committed_rows(tmp_path):
    # Two of its agents on the three quick layouts: the default and the paper's; each run is
    # in-process lockstep from the layout's seed, so the rows are the committed ones exactly.
    r = subprocess.run([sys.executable, "-m", "experiments.ablation", "--quick", "--agents", "default,paper",
                        "--jobs", "2", "--out", str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    committed = (ROOT / "experiments" / "ablation_quick.md").read_text(encoding="utf-8").splitlines()
    rows = (tmp_path / "ablation_quick.md").read_text(encoding="utf-8").splitlines()
    for agent in ("default", "paper"):
        mine = next(line for line in rows if line.startswith(f"| {agent} |"))
        assert mine in committed, (mine, committed)
