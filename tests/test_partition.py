"""Issue 12, point 4: a build across three hosts survives one host cut off for 10 s.

The hosts are Linux network namespaces joined by veth links to a bridge (`faults.netns`):
the router and the world on host 1, agents a1 and a2 on host 2, a3 on host 3, every process
a client of the router, as deploy/README.md sets them up. Host 2's link goes down for 10 s
mid-build (`faults.partition`). Everything asserted is read from the world's statuses
(`conag status --watch --json` on host 1) and its summary. Skipped where namespaces cannot
be made (not root, no `ip`, a container that refuses).
"""

from __future__ import annotations

import os
import subprocess

import pytest

from faults.netns import unavailable
from faults.partition import PartitionOptions, partition_run

pytestmark = pytest.mark.slow


def _namespaces(prefix: str) -> list[str]:
    listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, check=False).stdout
    return [line.split()[0] for line in listed.splitlines() if line.startswith(prefix)]


def test_agents_cut_off_for_ten_seconds_are_seen_dead_leave_and_come_back_and_the_build_completes(tmp_path):
    reason = unavailable()
    if reason:
        pytest.skip(f"no network namespaces here: {reason}")
    opts = PartitionOptions(prefix=f"cgt{os.getpid()}h", cut_seconds=10.0, timeout=240.0)
    run = partition_run(opts, tmp_path, log=lambda line: None)
    logs = "\n".join(f"--- {p.name}\n{p.read_text(errors='replace')[-1500:]}" for p in sorted(tmp_path.glob("*.log"))
                     if p.name != "agent-states.log")  # (their gist is in the report)
    where = "\n".join([run.line(), *run.report, logs])
    assert _namespaces(opts.prefix) == [], "namespaces left behind"
    assert not run.error, where
    for agent in ("a1", "a2"):
        # Seen dead by the world (its liveliness token gone) while the link was down ...
        assert run.dead_after[agent] is not None and run.dead_after[agent] < opts.cut_seconds, where
        # ... its body left the world after the grace period, before the agent came back ...
        assert run.left_after[agent] is not None, where
        assert run.dead_after[agent] <= run.left_after[agent] <= opts.cut_seconds + run.back_after[agent], where
        # ... and once the link was back, the same process attached again (a restart in the
        # world's eyes), alive with its body in the world, and drove it again.
        assert run.back_after[agent] is not None, where
        assert run.restarts[agent] == 1 and run.moved_after_back[agent] > 0, where
    assert run.restarts["a3"] == 0 and run.kept_alive, where  # host 3 never noticed
    assert run.same_processes and run.said_waiting, where
    assert run.completed and run.sites_filled == run.sites_total, where
    assert run.bricks_seen == [run.bricks_expected], where
    assert run.survived(opts.cut_seconds)
