"""Viewer overhead: what watching a lockstep `conag run` costs it.

    python3 -m bench.bench_view                          # fig6 with 10 agents, 800 ticks, 2 repetitions
    python3 -m bench.bench_view --agents 10 --ticks 2000 --reps 3 --select a1

As bench/bench_record.py, alternating runs without and with a viewer, timing the build's
tick rate from its progress lines. With the viewer, `conag view` (started here, connected
to the run) serves the page and a headless Chromium (`/usr/bin/chromium`) keeps it open
for the whole run, receiving its pictures (Server-Sent Events, ten a second); with
`--select ID` the page shows that agent (its decisions and maps every 10 ticks).

On a shared machine the tick rates swing with everyone else's load, so the CPU time the
viewer and the page (Chromium and all its processes) used while the build went on (from the
first progress line to the last, read from /proc) is printed too: that is what they take
from the run on a machine whose cores the run fills.
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys

from bench.bench_record import ROOT, BuildClock, tree_cpu


def one_run(scenario: str, agents: int, ticks: int, port: int, view_port: int | None,
            select: str | None) -> tuple[float, float, float, float]:
    """(ticks per second, wall seconds of the build, CPU seconds of the viewer, of the page)."""
    cmd = [sys.executable, "-m", "conag", "run", scenario, "--headless", "--agents", str(agents), "--max-ticks",
           str(ticks), "--stall-ticks", "0", "--listen", f"tcp/127.0.0.1:{port}"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    viewer = browser = None
    clock = BuildClock()
    cpu_view = cpu_page = 0.0
    start_cpu = (0.0, 0.0)
    try:
        for line in proc.stdout:
            if view_port is not None and viewer is None:
                viewer = subprocess.Popen([sys.executable, "-m", "conag", "view", "--connect", f"tcp/127.0.0.1:{port}",
                                           "--port", str(view_port)], cwd=ROOT, stdout=subprocess.PIPE, text=True)
                url = viewer.stdout.readline().split()[-1]
                if select:
                    url += f"#select={select}"
                browser = subprocess.Popen([shutil.which("chromium") or "/usr/bin/chromium", "--headless=new",
                                            "--no-sandbox", "--disable-gpu", "--remote-debugging-port=0", url],
                                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            starting = clock.first is None
            if clock.observe(line):
                if starting and viewer is not None:
                    start_cpu = (tree_cpu(viewer.pid), tree_cpu(browser.pid))
                if viewer is not None:  # the CPU they used while the build went on
                    cpu_view, cpu_page = tree_cpu(viewer.pid) - start_cpu[0], tree_cpu(browser.pid) - start_cpu[1]
        proc.wait()
    finally:
        for p in (browser, viewer):
            if p is not None:
                p.terminate()
                p.wait(10)
    rate, seconds = clock.rate(cmd)
    return rate, seconds, cpu_view, cpu_page


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", default="scenarios/fig6.toml")
    p.add_argument("--agents", type=int, default=10)
    p.add_argument("--ticks", type=int, default=800)
    p.add_argument("--reps", type=int, default=2)
    p.add_argument("--port", type=int, default=17611)
    p.add_argument("--view-port", type=int, default=17612)
    p.add_argument("--select", metavar="ID", help="the page shows this agent (its decisions and maps)")
    args = p.parse_args(argv)
    plain, viewed, share = [], [], []
    for rep in range(args.reps):
        plain.append(one_run(args.scenario, args.agents, args.ticks, args.port, None, None)[0])
        rate, wall, cpu_view, cpu_page = one_run(args.scenario, args.agents, args.ticks, args.port, args.view_port,
                                                 args.select)
        viewed.append(rate)
        share.append((cpu_view + cpu_page) / wall)
        print(f"rep {rep + 1}: {plain[-1]:.0f} ticks/s without, {rate:.0f} with the viewer and a page; viewer "
              f"{cpu_view:.1f} s CPU, page {cpu_page:.1f} s CPU over a {wall:.0f} s build "
              f"({100 * share[-1]:.0f}% of one core)", flush=True)
    a, b = statistics.median(plain), statistics.median(viewed)
    print(f"{args.scenario}, {args.agents} agents, {args.ticks} ticks, {args.reps} repetitions"
          f"{', page showing ' + args.select if args.select else ''}: median {a:.0f} ticks/s without, {b:.0f} "
          f"with the viewer: slowdown {100 * (a - b) / a:.1f}% (ranges {min(plain):.0f}-{max(plain):.0f} and "
          f"{min(viewed):.0f}-{max(viewed):.0f}); viewer and page used {100 * statistics.median(share):.0f}% of "
          "one core")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
