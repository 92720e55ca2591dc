"""Viewer overhead: what watching a lockstep `conag run` costs it.

    python3 -m bench.bench_view                          # scale.toml, 10 agents, 1500 ticks, 4 repetitions
    python3 -m bench.bench_view --reps 6 --select a1     # the page also shows a1's details and maps
    python3 -m bench.bench_view --foxglove               # `conag view --foxglove` and a client watching everything
    python3 -m bench.bench_view --foxglove world         # ... a client watching the world's topics only

As bench/bench_record.py, alternating builds without and with a viewer. With it, `conag
view` (started here, connected to the run) serves the page and a headless Chromium
(`/usr/bin/chromium`) opens it as the run starts and keeps it open for the whole build,
receiving its pictures (Server-Sent Events, `--display-hz`, 5 a second); with `--select ID` the page
shows that agent (its details, and its maps every 10 ticks, which that agent then sends).

The build is timed from its progress line of tick `--from-tick` (default 300) to its last,
in both builds of a repetition: what is measured is following a run, not starting a browser
(Chromium's start-up, about a CPU second, lands in the first ticks). The default world,
`scenarios/large/scale.toml`, keeps 10 agents building for all 1,500 ticks (fig6, the
old default, is complete after about 230 ticks with 10 agents: builds of 3 s).

With `--foxglove`, the viewer is `conag view --foxglove` (the Foxglove WebSocket server, at
the same display rate; it asks every agent for its maps about once a second) and the page is
bench/foxglove_client.py, a client subscribed to every channel (world, poses, every agent's
scans and maps, log, progress) for the whole build; with `--foxglove world`, to the world's
channels only (no agent's scans or maps, which the server then neither subscribes to nor asks for).

The figure is the paired slowdown (the median over repetitions of each viewed build's
rate against its own repetition's plain build; see bench/bench_record.py), beside the CPU
the viewer and the page (Chromium and all its processes) used over the timed stretch, read
from /proc: on a machine whose cores the run fills, that is what they take from it.
"""

from __future__ import annotations

import argparse
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile

from bench.bench_record import ROOT, BuildClock, paired_slowdown, slowdown, tree_cpu
from conag.viewer.scene import DISPLAY_HZ

FOXGLOVE_CLIENTS = {"all": "every topic", "world": "the world's topics"}


def free_port() -> int:
    """A port no one listens on now (runs of others share the machine)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def one_run(scenario: str, agents: int, ticks: int, port: int, view_port: int | None, select: str | None,
            from_tick: int, display_hz: float = DISPLAY_HZ, page: bool = True,
            foxglove: str = "") -> tuple[float, float, float, float]:
    """(ticks per second, wall seconds of the timed build, CPU seconds of the viewer, of the page)."""
    port = port or free_port()
    cmd = [sys.executable, "-m", "conag", "run", scenario, "--headless", "--agents", str(agents), "--max-ticks",
           str(ticks), "--stall-ticks", "0", "--listen", f"tcp/127.0.0.1:{port}"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    viewer = browser = None
    clock = BuildClock(from_tick)
    cpu_view = cpu_page = 0.0
    start_cpu = (0.0, 0.0)
    profile = tempfile.TemporaryDirectory(prefix="conag-bench-view-")
    try:
        for line in proc.stdout:
            if view_port is not None and viewer is None:
                viewer = subprocess.Popen([sys.executable, "-m", "conag", "view", "--connect", f"tcp/127.0.0.1:{port}",
                                           *(("--foxglove",) if foxglove else ("--port",)), str(view_port),
                                           "--display-hz", str(display_hz)],
                                          cwd=ROOT, stdout=subprocess.PIPE, text=True)
                url = viewer.stdout.readline().split()[-1]
                if select:
                    url += f"#select={select}"
                if foxglove:
                    browser = None if not page else subprocess.Popen(
                        [sys.executable, "-m", "bench.foxglove_client", url,
                         *(("--world-only",) if foxglove == "world" else ())], cwd=ROOT, stdout=subprocess.DEVNULL)
                else:
                    browser = None if not page else subprocess.Popen([
                                            shutil.which("chromium") or "/usr/bin/chromium", "--headless=new",
                                            "--no-sandbox", "--disable-gpu", "--no-first-run",
                                            "--disable-background-networking", "--disable-component-update",
                                            "--disable-sync", f"--user-data-dir={profile.name}",
                                            "--remote-debugging-port=0", url],
                                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            starting = clock.first is None
            if clock.observe(line):
                if starting and viewer is not None:
                    start_cpu = (tree_cpu(viewer.pid), tree_cpu(browser.pid) if browser else 0.0)
                if viewer is not None:  # the CPU they used over the timed stretch
                    cpu_view = tree_cpu(viewer.pid) - start_cpu[0]
                    cpu_page = tree_cpu(browser.pid) - start_cpu[1] if browser else 0.0
        proc.wait()
    finally:
        for p in (browser, viewer):
            if p is not None:
                p.terminate()
                p.wait(10)
        profile.cleanup()
    rate, seconds = clock.rate(cmd)
    return rate, seconds, cpu_view, cpu_page


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", default="scenarios/large/scale.toml")
    p.add_argument("--agents", type=int, default=10)
    p.add_argument("--ticks", type=int, default=1500)
    p.add_argument("--from-tick", type=int, default=300, metavar="T",
                   help="time each build from its progress line of tick T on (default 300)")
    p.add_argument("--reps", type=int, default=4)
    p.add_argument("--port", type=int, default=0, help="the runs' bus port (default 0: a free one for each run)")
    p.add_argument("--view-port", type=int, default=0, help="the viewer's port (default 0: any free one)")
    p.add_argument("--select", metavar="ID", help="the page shows this agent (its details and maps)")
    p.add_argument("--display-hz", type=float, default=DISPLAY_HZ, metavar="HZ",
                   help=f"conag view --display-hz: pictures a second sent to the page "
                        f"(default {DISPLAY_HZ:g}, the viewer's)")
    p.add_argument("--no-page", action="store_true", help="the viewer alone, no browser (its own share)")
    p.add_argument("--foxglove", nargs="?", const="all", default="", choices=("all", "world"),
                   help="conag view --foxglove and a client subscribed to every channel (all, the default) or to "
                        "the world's only (world), instead of the page")
    args = p.parse_args(argv)
    if args.from_tick >= args.ticks:
        p.error(f"--from-tick {args.from_tick} leaves nothing to time in --ticks {args.ticks}")
    plain, viewed, share = [], [], []
    for rep in range(args.reps):
        plain.append(one_run(args.scenario, args.agents, args.ticks, args.port, None, None, args.from_tick)[0])
        rate, wall, cpu_view, cpu_page = one_run(args.scenario, args.agents, args.ticks, args.port, args.view_port,
                                                 args.select, args.from_tick, args.display_hz, not args.no_page,
                                                 args.foxglove)
        viewed.append(rate)
        share.append((cpu_view + cpu_page) / wall)
        print(f"rep {rep + 1}: {plain[-1]:.1f} ticks/s without, {rate:.1f} with the viewer and a page "
              f"({100 * slowdown(plain[-1], rate):+.1f}%); viewer {cpu_view:.2f} s CPU "
              f"({100 * cpu_view / wall:.1f}% of a core), page {cpu_page:.2f} s CPU ({100 * cpu_page / wall:.1f}%) "
              f"over a {wall:.0f} s build", flush=True)
    a, b = statistics.median(plain), statistics.median(viewed)
    print(f"{args.scenario}, {args.agents} agents, ticks {args.from_tick}-{args.ticks}, {args.reps} repetitions"
          f"{', page showing ' + args.select if args.select else ''}, {args.display_hz:g} pictures a second"
          f"{', no page' if args.no_page else ''}"
          f"{', Foxglove server and a client of ' + FOXGLOVE_CLIENTS[args.foxglove] if args.foxglove else ''}: "
          "paired slowdown "
          f"{100 * paired_slowdown(plain, viewed):.1f}% (median {a:.1f} ticks/s without, {b:.1f} with: "
          f"{100 * slowdown(a, b):.1f}% unpaired; ranges {min(plain):.1f}-{max(plain):.1f} and "
          f"{min(viewed):.1f}-{max(viewed):.1f}); viewer and page used {100 * statistics.median(share):.1f}% of "
          "one core")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
