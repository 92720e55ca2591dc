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
    r = subprocess.run([sys.executable, "experiments/generalisation.py", "--quick", "--jobs", "1",
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
    r = subprocess.run([sys.executable, "experiments/generalisation.py", "--quick"], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--out" in r.stderr
