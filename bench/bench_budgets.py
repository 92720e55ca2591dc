"""Timing budgets: how long some pieces may take, measured here rather than asserted in
the unit tests (a test checks what the code does; a busy machine must not fail it).

    python3 -m bench.bench_budgets           # measure each budget; exit 1 if one is missed
    python3 -m bench.bench_budgets --quick   # a smoke run, not a measurement (never exit 1)

The budgets:

* one agent's map update, `EgocentricMaps.move` then `sense` (41 x 41 maps, 16 sectors, about
  half the sectors reading something): under 300 us (about 40 us measured; a per-cell
  Python loop would take milliseconds). Best of 20 stretches of 50 updates.
* a realtime world server with no agent attached ticks at its `tick_rate` (50 per second):
  between 0.6 and 1.2 times that, over one second of wall time after a short warm-up.
* the buildability check of a 120 x 120 layout with 400 sites (a solid blob, nested rings,
  dead-end pockets): under a second. Best of two, after a run that loads the kernels.
* a layout whose only agent sits inside two nested rings with every brick outside is
  refused ("no fill order found") in under 5 s.
"""

from __future__ import annotations

import argparse
import math
import socket
import sys
import threading
import time
from pathlib import Path

import numpy as np

from agent_runtime.esm import EgocentricMaps
from protocol.messages import CHANNELS, NO_READING
from world_server.buildability import check_layout

ROOT = Path(__file__).resolve().parent.parent


def map_update_seconds(rounds: int = 20, updates: int = 50) -> float:
    """Best mean time of one move + sense over `rounds` stretches of `updates` each."""
    m = EgocentricMaps(41)
    rng = np.random.default_rng(0)
    nch = len(CHANNELS)
    readings = np.where(rng.random((nch, 16)) < 0.5, rng.uniform(0, 6, (nch, 16)), NO_READING)
    m.move(0.17, -0.09)
    m.sense(readings, 6.0)  # warm-up: compiled kernels, the sector geometry
    best = math.inf
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(updates):
            m.move(0.17, -0.09)
            m.sense(readings, 6.0)
        best = min(best, (time.perf_counter() - start) / updates)
    return best


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def realtime_ticks_per_second(seconds: float = 1.0) -> tuple[float, float]:
    """(measured ticks per second, the configured tick_rate) of a realtime world server
    serving quick_wall with no agent, on a loopback zenoh session."""
    from protocol.bus import BusOptions, open_session
    from world_server.scenario import load_scenario
    from world_server.server import WorldServer
    from world_server.world import World

    scenario = load_scenario(ROOT / "scenarios" / "quick_wall.toml")
    world = World(scenario, np.random.default_rng(scenario.seed))
    session = open_session(BusOptions(listen=(f"tcp/127.0.0.1:{_free_port()}",)), serve=True)
    stop = threading.Event()
    server = WorldServer(world, session, mode="realtime")
    thread = threading.Thread(target=server.run, args=(stop,), daemon=True)
    thread.start()
    try:
        deadline = time.monotonic() + 10
        while world.tick < 5 and time.monotonic() < deadline:  # warm-up
            time.sleep(0.01)
        t0, tick0 = time.perf_counter(), world.tick
        time.sleep(seconds)
        return (world.tick - tick0) / (time.perf_counter() - t0), world.cfg.tick_rate
    finally:
        stop.set()
        thread.join(10)
        session.close()


def big_layout() -> list[str]:
    """120 x 120, 400 sites (the layout of tests/test_buildability.py's `_big_layout`)."""
    g = np.full((120, 120), ".")
    g[10:18, 10:18] = "+"
    for lo, hi in ((60, 100), (63, 97)):
        g[lo, lo:hi] = g[hi - 1, lo:hi] = "+"
        g[lo:hi, lo] = g[lo:hi, hi - 1] = "+"
    g[60:100, 101:110] = "#"
    g[60:72, 102:110:2] = "+"
    g[35, :] = "F"
    g[35, 50:53] = "."
    rng = np.random.default_rng(0)
    free = np.argwhere(g[40:, :] == ".") + [40, 0]  # noqa: RUF005 -- numpy addition (row offset), not concatenation
    for r, c in free[rng.choice(len(free), int((g == "+").sum()) + 30, replace=False)]:
        g[r, c] = "b"
    g[119, 0] = "A"
    return ["".join(row) for row in g]


RINGS = [
    "bbbbbbbbbbbbbbbbbbbbbbbbbbbbbbbb",
    "bbbbbbbbbbbbbbbbbbbbbbbbbbbbbbbb",
    "................................",
    "..+++++++.......................",
    "..+.....+.......................",
    "..+.+++.+.......................",
    "..+.+A+.+.......................",
    "..+.+++.+.......................",
    "..+.....+.......................",
    "..+++++++.......................",
]


def check_seconds(layout: list[str], expect_ok: bool, repeats: int = 2) -> float:
    """Best time of `check_layout` over `repeats` runs, after one that loads the kernels."""
    result = check_layout(layout)
    if result.ok != expect_ok:
        raise AssertionError(f"check_layout said ok={result.ok} ({result.reason})")
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        check_layout(layout)
        best = min(best, time.perf_counter() - start)
    return best


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="a smoke run, not a measurement: never exit 1")
    args = p.parse_args(argv)
    rounds, seconds, repeats = (2, 0.2, 1) if args.quick else (20, 1.0, 2)
    rows = []
    us = map_update_seconds(rounds) * 1e6
    rows.append(("map update (move + sense, 41 x 41)", f"{us:.0f} us", "< 300 us", us < 300))
    rate, target = realtime_ticks_per_second(seconds)
    rows.append(("realtime world, no agent", f"{rate:.1f} ticks/s", f"{0.6 * target:g}-{1.2 * target:g} ticks/s",
                 0.6 * target <= rate <= 1.2 * target))
    s = check_seconds(big_layout(), True, repeats)
    rows.append(("buildability, 120 x 120, 400 sites", f"{s:.2f} s", "< 1 s", s < 1.0))
    s = check_seconds(RINGS, False, repeats)
    rows.append(("buildability, refused (agent inside two rings)", f"{s:.2f} s", "< 5 s", s < 5.0))
    print("| what | measured | budget | met |")
    print("|---|---:|---:|:---:|")
    for what, measured, budget, met in rows:
        print(f"| {what} | {measured} | {budget} | {'yes' if met else 'NO'} |")
    if args.quick:
        return 0
    return 0 if all(met for *_, met in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
