"""The benchmark script keeps working (a smoke run; the figures are in BENCHMARKS.md)."""

from __future__ import annotations

import subprocess
import sys

from tests.conftest import ROOT, free_port


def test_world_benchmark_quick_run_prints_both_tables():
    r = subprocess.run([sys.executable, "bench/bench_world.py", "--quick", "--endpoint",
                        f"tcp/127.0.0.1:{free_port()}"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    rows = [line for line in r.stdout.splitlines() if line.startswith("| 10 |") or line.startswith("| 100 |")]
    assert len(rows) == 2
    assert all(float(row.split("|")[3].replace(",", "")) > 0 for row in rows)
    rtt = [line for line in r.stdout.splitlines() if line.startswith("| loopback")]
    assert rtt and 0 < float(rtt[0].split("|")[2]) < 100


def test_agent_step_benchmark_quick_run_prints_a_row_per_layout():
    r = subprocess.run([sys.executable, "bench/bench_agent_step.py", "--quick"], cwd=ROOT, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    rows = [line for line in r.stdout.splitlines() if line.startswith("| ") and "---" not in line][1:]
    assert len(rows) == 4
    assert all(float(row.split("|")[4].split()[0]) > 0 for row in rows)
