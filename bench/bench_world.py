"""World benchmark: ticks per second of the world core, and the bus round trip.

    python3 -m bench.bench_world                 # the full table of docs/results/benchmarks.md
    python3 -m bench.bench_world --quick         # a few hundred milliseconds, for CI

Ticks: a 100 x 100 world with 2,000 discs (food, water, bricks at random cells) and N
agents at random free cells; every tick applies a fresh command to every agent (speed,
turn, and for about 1% of agents a grab or a drop), then steps physics, gripper, odometry and the
noisy sensors. No bus. Round trip: a world-side process publishes an encoded sensor
frame, an agent-side process decodes it and answers with an encoded command, and the
world side times until that command is decoded (the agent side is the real WorldLink). Median.
"""

from __future__ import annotations

import argparse
import dataclasses
import multiprocessing as mp
import queue
import statistics
import sys
import time

import numpy as np

from world_server.scenario import Scenario
from world_server.world import World

TARGETS = {10: 10_000, 100: 2_000, 1000: 400}
RTT_TARGET_MS = 0.4


def make_world(n_agents: int, n_discs: int = 2000, side: int = 100, seed: int = 0) -> World:
    rng = np.random.default_rng(seed)
    grid = np.full(side * side, ".")
    cells = rng.permutation(side * side)
    grid[cells[:n_discs]] = np.array(list("FWb"))[rng.integers(0, 3, n_discs)]
    grid[cells[n_discs:n_discs + n_agents]] = "A"
    layout = tuple("".join(row) for row in grid.reshape(side, side))
    scenario = Scenario(name="bench", seed=seed, agents=n_agents, tick_mode="lockstep",
                        max_ticks=10**9, layout=layout)
    world = World(scenario, np.random.default_rng(seed))
    for i in range(n_agents):
        world.attach(f"a{i}")
    return world


def ticks_per_second(n_agents: int, seconds: float, repeats: int = 5) -> list[float]:
    """Ticks per second in `repeats` timed stretches of seconds/repeats each."""
    world = make_world(n_agents)
    rng = np.random.default_rng(1)
    index = np.arange(n_agents)
    # Pre-drawn command streams, so the timing measures the world, not the generator.
    speeds = rng.uniform(0, world.cfg.max_speed, (64, n_agents))
    turns = rng.uniform(-0.5, 0.5, (64, n_agents))
    # About 1% of agents grab or drop each tick: a building agent does one of the two
    # every few dozen ticks at most, so this is a generous load on the gripper.
    actions = rng.choice([1, 2], size=(64, n_agents)) * (rng.random((64, n_agents)) < 0.01)

    k = 0

    def tick() -> None:
        nonlocal k
        world.set_commands(index, speeds[k % 64], turns[k % 64], actions[k % 64])
        world.step()
        k += 1

    for _ in range(50):  # warm-up: compiled kernels, caches
        tick()
    rates = []
    for _ in range(repeats):
        start, k0 = time.perf_counter(), k
        while time.perf_counter() - start < seconds / repeats:
            tick()
        rates.append((k - k0) / (time.perf_counter() - start))
    return rates


def _agent_side(endpoint: str, ready, done) -> None:
    """Agent process: the real agent link, answering every frame with a command."""
    from agent_runtime.world_link import WorldLink
    from protocol.bus import BusOptions, open_session

    session = open_session(BusOptions(connect=(endpoint,)))
    try:
        link = WorldLink(session, "bench", "a1")
        ready.set()
        while not done.is_set():
            frame = link.next_frame(timeout=None)
            link.send(frame.tick, 1.0, 0.1)
        link.close()
    finally:
        session.close()


def round_trip_ms(samples: int, endpoint: str) -> tuple[float, float]:
    """(median, 90th percentile) of frame -> command round trips between two processes.

    The world side hands samples from zenoh's callback thread to its loop through a
    queue, as the world server does; the agent side is `agent_runtime.world_link.WorldLink`.
    Both ends decode what they receive and encode what they send.
    """
    from protocol import keys
    from protocol.bus import BusOptions, open_session
    from protocol.codec import decode, encode
    from protocol.messages import AgentCommand

    world = make_world(1, n_discs=200, side=30)
    frame = dataclasses.replace(world.frame("a0"), agent_id="a1")  # the link takes only its own agent's frames
    ctx = mp.get_context("spawn")
    ready, done = ctx.Event(), ctx.Event()
    session = open_session(BusOptions(listen=(endpoint,)), serve=True)
    proc = ctx.Process(target=_agent_side, args=(endpoint, ready, done), daemon=True)
    proc.start()
    try:
        inbox: queue.SimpleQueue = queue.SimpleQueue()
        sub = session.declare_subscriber(keys.command("bench", "a1"), lambda s: inbox.put(s.payload.to_bytes()))
        pub = session.declare_publisher(keys.sensors("bench", "a1"), express=True)
        if not ready.wait(30):
            raise RuntimeError("agent process did not start")
        times = []
        for i in range(samples + 200):
            payload = encode(dataclasses.replace(frame, tick=i + 1))
            t0 = time.perf_counter()
            pub.put(payload)
            try:
                decode(inbox.get(timeout=2.0), AgentCommand)
            except queue.Empty:
                continue  # the first frames may go out before the routes are up
            if i >= 200:  # warm-up
                times.append((time.perf_counter() - t0) * 1e3)
        done.set()
        pub.put(encode(dataclasses.replace(frame, tick=samples + 1000)))  # unblock the agent
        sub.undeclare()
        times.sort()
        return statistics.median(times), times[int(0.9 * (len(times) - 1))]
    finally:
        done.set()
        proc.join(10)
        if proc.is_alive():
            proc.terminate()
        session.close()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, nargs="+", default=[10, 100, 1000])
    p.add_argument("--seconds", type=float, default=5.0, help="timing per agent count")
    p.add_argument("--samples", type=int, default=5000, help="round trips to time")
    p.add_argument("--endpoint", default="tcp/127.0.0.1:7461")
    p.add_argument("--quick", action="store_true", help="tiny run for CI: a smoke test, not a measurement")
    args = p.parse_args(argv)
    if args.quick:
        args.agents, args.seconds, args.samples = [10, 100], 0.2, 50
    print("| agents | discs | ticks/s (median) | range over 5 stretches | target | met |")
    print("|---:|---:|---:|---:|---:|:---:|")
    for n in args.agents:
        rates = ticks_per_second(n, args.seconds)
        rate = statistics.median(rates)
        target = TARGETS.get(n)
        met = "" if target is None else ("yes" if rate >= target else "NO")
        print(f"| {n} | 2000 | {rate:,.0f} | {min(rates):,.0f}-{max(rates):,.0f} | {target or '':,} | {met} |",
              flush=True)
    median, p90 = round_trip_ms(args.samples, args.endpoint)
    print()
    print("| bus round trip (frame -> command, two processes) | median ms | p90 ms | target | met |")
    print("|---|---:|---:|---:|:---:|")
    print(f"| loopback, peer mode | {median:.3f} | {p90:.3f} | {RTT_TARGET_MS} | "
          f"{'yes' if median <= RTT_TARGET_MS else 'NO'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
