"""The benchmark scripts keep working (smoke runs; the figures are in docs/results/benchmarks.md)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.conftest import ROOT, free_port

pytestmark = pytest.mark.slow  # every test runs a benchmark script as a subprocess


def bench(script: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    r = subprocess.run([sys.executable, f"bench/{script}", "--quick", *args], cwd=ROOT, capture_output=True,
                       text=True, timeout=timeout)
    assert r.returncode == 0, r.stderr
    return r


def test_world_benchmark_quick_run_prints_both_tables():
    r = bench("bench_world.py", "--endpoint", f"tcp/127.0.0.1:{free_port()}")
    rows = [line for line in r.stdout.splitlines() if line.startswith(("| 10 |", "| 100 |"))]
    assert len(rows) == 2
    assert all(float(row.split("|")[3].replace(",", "")) > 0 for row in rows)
    rtt = [line for line in r.stdout.splitlines() if line.startswith("| loopback")]
    assert rtt and 0 < float(rtt[0].split("|")[2]) < 100


def test_agent_step_benchmark_quick_run_prints_a_row_per_layout():
    r = bench("bench_agent_step.py", timeout=300)
    rows = [line for line in r.stdout.splitlines() if line.startswith("| ") and "---" not in line][1:]
    assert len(rows) == 4
    assert all(float(row.split("|")[4].split()[0]) > 0 for row in rows)


def test_spreading_benchmark_quick_run_prints_the_table():
    r = bench("bench_spreading.py")
    rows = [line.split("|") for line in r.stdout.splitlines() if line.startswith(("| open", "| maze"))]
    assert len(rows) == 4
    assert all(float(row[3]) > 0 and float(row[4]) > 0 for row in rows)


def test_budgets_quick_run_measures_every_budget():
    r = bench("bench_budgets.py")
    rows = [line.split("|") for line in r.stdout.splitlines() if line.startswith("| ") and "---" not in line][1:]
    assert [row[1].split("(")[0].strip() for row in rows] == [
        "map update", "realtime world, no agent", "buildability, 120 x 120, 400 sites", "buildability, refused"]
    assert all(row[4].strip() in ("yes", "NO") for row in rows)


def test_checkpoint_benchmark_quick_run_prints_its_table():
    r = subprocess.run([sys.executable, "-m", "bench.bench_checkpoint", "--quick"], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    rows = [line for line in r.stdout.splitlines() if line.startswith("| nested_squares")]
    assert len(rows) == 1 and float(rows[0].split("|")[2].split()[0]) > 0


def test_step_stages_quick_run_times_every_stage_the_step_calls():
    r = subprocess.run([sys.executable, "-m", "bench.bench_step_stages", "--quick", "--layout", "fig6"], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    rows = {line.split("|")[1].strip(): line.split("|")[2:5] for line in r.stdout.splitlines()
            if line.startswith("| ") and not line.startswith("| stage")}
    from bench.bench_step_stages import STAGES
    assert set(rows) == {path for _, path in STAGES}
    # every step perceives and plans once: the wrappers really sit on the path the step takes
    assert float(rows["Brain.perceive"][1]) == 1.0 and float(rows["Brain.plan"][1]) == 1.0
    assert float(rows["Brain.plan"][0]) > float(rows["Brain.nav_masks"][0]) > 0


def test_recorder_benchmark_replays_a_build_into_the_recorder_and_prints_its_cpu():
    r = subprocess.run([sys.executable, "-m", "bench.bench_recorder", "--scenario", "scenarios/quick_wall.toml",
                        "--agents", "1", "--reps", "1"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    cpu = [line for line in r.stdout.splitlines() if "CPU s per 1000 ticks (median" in line]
    assert len(cpu) == 2 and all(float(line.split("recorder ")[1].split()[0]) > 0 for line in cpu), r.stdout
    assert sum("us per bus message" in line for line in r.stdout.splitlines()) == 2, r.stdout


def test_step_contention_replays_the_recorded_decisions_in_every_arrangement():
    r = subprocess.run([sys.executable, "-m", "bench.bench_step_contention", "--quick"], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr   # non-zero when any arrangement decided otherwise than the recording
    rows = {line.split("|")[1].strip(): line.split("|")[2:] for line in r.stdout.splitlines()
            if line.startswith("| ") and not line.startswith("| arrangement")}
    assert set(rows) == {"one process", "processes, lockstep", "processes, free", "two hosts, lockstep"}
    assert all(cells[-2].strip() == "yes" and float(cells[0]) > 0 for cells in rows.values())
    assert rows["one process"][2].strip() == "1.00x"


def test_floor_bench_runs_null_agents_and_prints_the_floor():
    r = subprocess.run([sys.executable, "-m", "bench.bench_floor", "--quick"], cwd=ROOT, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr   # non-zero when a replay decided otherwise than the recording
    figures = json.loads(r.stderr.strip().splitlines()[-1])
    # The null agents answered every frame and moved nobody; the real ones moved.
    assert all(n["last_line"].endswith("total distance 0.0") for n in figures["null"])
    assert not figures["processes"]["last_line"].endswith("total distance 0.0")
    row = next(line for line in r.stdout.splitlines() if line.startswith("| ") and line[2].isdigit())
    assert row.rstrip().endswith("| yes |") and figures["floor"] > 0


def test_windows_bench_has_the_recorder_listen_in_turns_and_pairs_the_windows():
    r = subprocess.run([sys.executable, "-m", "bench.bench_record_windows", "--quick", "--scenario",
                        "scenarios/large/scale.toml", "--ticks", "2500", "--window", "0.4"], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr   # non-zero when no window had two measured windows without it beside it
    [line] = [line for line in r.stdout.splitlines() if "paired slowdown" in line]
    pairs = int(line.split(" pairs, ")[0].rsplit("; ", 1)[1])
    assert pairs >= 1, line
    assert "ticks/s without the recorder" in line and "with it" in line
