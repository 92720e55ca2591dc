"""Viewer overhead: the same lockstep `conag run` with and without `--view` and a page following it.

    python3 -m bench.bench_view                          # fig6 with 10 agents, 1000 ticks, 2 repetitions
    python3 -m bench.bench_view --agents 10 --ticks 2000 --reps 3

As bench/bench_record.py, alternating without and with the viewer, timing the build's tick
rate from its progress lines. With the viewer, `conag run --view PORT` serves the page and
a headless Chromium (`/usr/bin/chromium`) keeps it open, receiving its pictures (Server-Sent
Events at ten a second) for the whole run; the agents publish no maps (`--maps-every 0`
is the run's default) unless `--maps-every N` is given.
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import time

from bench.bench_record import LINE, ROOT


def one_run(scenario: str, agents: int, ticks: int, port: int, view_port: int | None, maps_every: int) -> float:
    cmd = [sys.executable, "-m", "conag", "run", scenario, "--headless", "--agents", str(agents), "--max-ticks",
           str(ticks), "--stall-ticks", "0", "--listen", f"tcp/127.0.0.1:{port}"]
    if view_port is not None:
        cmd += ["--view", str(view_port), "--maps-every", str(maps_every)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    browser = None
    first = last = None
    try:
        for line in proc.stdout:
            if view_port is not None and browser is None and line.startswith("viewer at "):
                browser = subprocess.Popen([shutil.which("chromium") or "/usr/bin/chromium", "--headless=new",
                                            "--no-sandbox", "--disable-gpu", "--remote-debugging-port=0",
                                            line.split()[-1]], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            m = LINE.match(line)
            if m and int(m.group(1)) >= 1:
                now = time.monotonic()
                first = first or (int(m.group(1)), now)
                last = (int(m.group(1)), now)
        proc.wait()
    finally:
        if browser is not None:
            browser.terminate()
            browser.wait(10)
    if first is None or last is None or last[0] <= first[0]:
        raise RuntimeError(f"no progress lines from {' '.join(cmd)}")
    return (last[0] - first[0]) / (last[1] - first[1])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", default="scenarios/fig6.toml")
    p.add_argument("--agents", type=int, default=10)
    p.add_argument("--ticks", type=int, default=1000)
    p.add_argument("--reps", type=int, default=2)
    p.add_argument("--port", type=int, default=17611)
    p.add_argument("--view-port", type=int, default=17612)
    p.add_argument("--maps-every", type=int, default=0)
    args = p.parse_args(argv)
    plain, viewed = [], []
    for rep in range(args.reps):
        plain.append(one_run(args.scenario, args.agents, args.ticks, args.port, None, 0))
        viewed.append(one_run(args.scenario, args.agents, args.ticks, args.port, args.view_port, args.maps_every))
        print(f"rep {rep + 1}: {plain[-1]:.0f} ticks/s without, {viewed[-1]:.0f} with the viewer and a page",
              flush=True)
    a, b = statistics.median(plain), statistics.median(viewed)
    print(f"{args.scenario}, {args.agents} agents, {args.ticks} ticks, {args.reps} repetitions: median {a:.0f} "
          f"ticks/s without, {b:.0f} with the viewer (maps every {args.maps_every or 'never'}): slowdown "
          f"{100 * (a - b) / a:.1f}% (ranges {min(plain):.0f}-{max(plain):.0f} and "
          f"{min(viewed):.0f}-{max(viewed):.0f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
