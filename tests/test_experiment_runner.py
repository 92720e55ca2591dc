"""The experiment scripts' runner (experiments/runner.py): the local pool by default, a Dask
cluster with --cluster; on the cluster a worker killed mid-sweep has its runs done elsewhere,
and the table is the local run's."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from experiments import generalisation as gen
from experiments import runner
from tests.conftest import ROOT, free_port


def test_the_local_pool_runs_every_job_once_and_says_where():
    done = list(runner.run(abs, [-1, 2, -3], runner.Where(workers=1)))   # a builtin: the worker imports little
    assert sorted((d.job, d.result) for d in done) == [(-3, 3), (-1, 1), (2, 2)]
    assert all(d.worker.startswith("pid ") and d.worker != f"pid {os.getpid()}" for d in done)


def test_cluster_without_dask_distributed_says_what_to_install(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)     # as if not installed
    with pytest.raises(runner.ClusterError, match=r"pip install -e '\.\[cluster\]'"):
        runner.connect("tcp://127.0.0.1:1")
    # ... and a script says so, runs nothing and writes nothing.
    code = gen.main(["--only", "000-gen-wall-20260000.toml", "--out", str(tmp_path), "--cluster", "tcp://127.0.0.1:1"])
    assert code == 2 and "needs Dask distributed" in capsys.readouterr().err
    assert not (tmp_path / "generalisation.json").exists()


def test_no_scheduler_at_the_address_is_a_clear_error(monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr(runner, "CONNECT_TIMEOUT", "300ms")
    with pytest.raises(runner.ClusterError, match=r"no Dask scheduler reachable at tcp://127\.0\.0\.1"):
        runner.connect(f"tcp://127.0.0.1:{free_port()}")


def test_the_fingerprint_covers_the_code_the_scenarios_and_nothing_else(tmp_path):
    for d in (*runner.CODE, *runner.DATA):
        (tmp_path / d).mkdir()
    (tmp_path / "conag" / "a.py").write_text("x = 1\n")
    (tmp_path / "scenarios" / "s.toml").write_text("name = 's'\n")
    first = runner.fingerprint.__wrapped__(tmp_path)
    (tmp_path / "README.md").write_text("docs change nothing")
    (tmp_path / "conag" / "__pycache__").mkdir()
    (tmp_path / "conag" / "__pycache__" / "a.cpython-311.pyc").write_bytes(b"\0")
    assert runner.fingerprint.__wrapped__(tmp_path) == first
    (tmp_path / "scenarios" / "s.toml").write_text("name = 't'\n")
    assert runner.fingerprint.__wrapped__(tmp_path) != first


def test_a_result_from_a_worker_running_other_code_stops_the_sweep(monkeypatch, tmp_path):
    distributed = pytest.importorskip("distributed")
    prints = iter(["here", "there", "there"])                 # this process's, then the worker's
    monkeypatch.setattr(runner, "fingerprint", lambda: next(prints))
    with (distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0",
                                   local_directory=str(tmp_path)) as c,
          pytest.raises(runner.ClusterError, match="runs other code or libraries than this checkout")):
        list(runner.run(abs, [1, 2], runner.Where(cluster=c.scheduler_address)))


# ------------------------------------------------------------------ a cluster of processes

def _start(args: list[str], log: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", *args], cwd=ROOT, env=env, stdout=log.open("w"),
                            stderr=subprocess.STDOUT, start_new_session=True)


@pytest.fixture
def cluster(tmp_path):
    """A Dask scheduler on a free loopback port and two workers of one thread each, every one
    a process of its own (no nanny: a worker killed stays dead). Yields (address, {name: process})."""
    distributed = pytest.importorskip("distributed")
    address = f"tcp://127.0.0.1:{free_port()}"
    procs = [_start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                     "--no-dashboard"], tmp_path / "scheduler.log")]
    try:
        workers = {}
        for name in ("w1", "w2"):
            workers[name] = _start(["distributed.cli.dask_worker", address, "--name", name, "--nthreads", "1",
                                    "--no-nanny", "--no-dashboard", "--local-directory", str(tmp_path / name)],
                                   tmp_path / f"{name}.log")
            procs.append(workers[name])
        with distributed.Client(address, timeout="60s") as client:
            client.wait_for_workers(2, timeout=120)
        yield address, workers
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(10)


def _quick(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "experiments.generalisation", "--quick", "--out", str(out), *extra],
                          cwd=ROOT, capture_output=True, text=True, timeout=900)


def _tables(out: Path) -> str:
    """The generalisation.md from its tables on (the line above says how long and where)."""
    text = (out / "generalisation.md").read_text(encoding="utf-8")
    return text[text.index("### Goals"):]


def _rows(out: Path) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "seconds"}
            for r in json.loads((out / "generalisation.json").read_text(encoding="utf-8"))]


@pytest.mark.slow
@pytest.mark.timeout(1500)
def test_a_quick_sweep_on_a_cluster_that_loses_a_worker_gives_the_local_table(cluster, tmp_path):
    import distributed

    address, workers = cluster
    seen: dict[str, set[str]] = {}      # run (task key) -> names of the workers the scheduler gave it to
    killed: list[str] = []              # the keys on w1 when it was killed
    stop = threading.Event()

    with distributed.Client(address, timeout="60s") as client:
        names = {a: w["name"] for a, w in client.scheduler_info(n_workers=-1)["workers"].items()}

        def watch():
            # Kill w1 once it has been running a run for a second; note who is given what.
            since = None
            while not stop.is_set():
                processing = client.processing()
                for addr, keys in processing.items():
                    for key in keys:
                        seen.setdefault(str(key), set()).add(names.get(addr, addr))
                on_w1 = [str(k) for a, ks in processing.items() if names.get(a) == "w1" for k in ks]
                if not killed and on_w1:
                    since = since or time.monotonic()
                    if time.monotonic() - since > 1.0:
                        killed.extend(on_w1)
                        workers["w1"].send_signal(signal.SIGKILL)
                time.sleep(0.02)

        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        try:
            on_cluster = _quick(tmp_path / "cluster", "--cluster", address)
        finally:
            stop.set()
            watcher.join(10)
        assert workers["w1"].wait(10) == -signal.SIGKILL
        assert on_cluster.returncode == 0, on_cluster.stderr[-3000:]
        # The runs w1 held when it died were given to w2 and done there.
        assert killed and all(seen[k] == {"w1", "w2"} for k in killed), (killed, seen)
        assert len(client.scheduler_info(n_workers=-1)["workers"]) == 1

    local = _quick(tmp_path / "local", "--jobs", "2")
    assert local.returncode == 0, local.stderr[-3000:]
    assert _tables(tmp_path / "cluster") == _tables(tmp_path / "local")
    assert _rows(tmp_path / "cluster") == _rows(tmp_path / "local")       # every run, field for field
    assert "a Dask cluster (tcp://127.0.0.1:" in (tmp_path / "cluster" / "generalisation.md").read_text()
    pictures = sorted(p.name for p in (tmp_path / "cluster" / "generalisation" / "failures").glob("*.png"))
    assert pictures == sorted(p.name for p in (tmp_path / "local" / "generalisation" / "failures").glob("*.png"))
