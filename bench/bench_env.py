"""Steps per second of conag.env (every step over zenoh, in-process loopback) against the
in-process simulator on the same scenario: the world alone (`World`, the same commands, no
bus) and `conag.sim.SimRun` (the world and ConAg's brains in one loop).

    python3 -m bench.bench_env [--seconds S] [--scenario FILE]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from conag import sim
from conag.env import ConAgParallelEnv
from world_server.scenario import load_scenario
from world_server.world import World


def rate(step, seconds: float) -> float:
    for _ in range(20):  # warm-up (numba, zenoh routes)
        step()
    n, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < seconds:
        step()
        n += 1
    return n / elapsed


def main(argv=None) -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--seconds", type=float, default=3.0)
    p.add_argument("--scenario", action="append", default=[])
    args = p.parse_args(argv)
    for path in args.scenario or ["scenarios/quick_wall.toml", "scenarios/fig6.toml"]:
        sc = load_scenario(path)
        env = ConAgParallelEnv(sc, max_cycles=10**9)
        env.reset(seed=0)
        act = {"speed": np.array([1.0], np.float32), "turn": np.array([0.05], np.float32), "action": 0}
        env_rate = rate(lambda env=env, act=act: env.step(dict.fromkeys(env.agents, act)), args.seconds)
        env.close()
        world = World(sc, np.random.default_rng(0))
        ids = [f"a{i + 1}" for i in range(sc.agents)]
        for a in ids:
            world.attach(a)

        def world_step(world=world, ids=ids):
            for a in ids:
                world.set_command(a, 1.0, 0.05, "none")
            world.step()
            world.frames()

        world_rate = rate(world_step, args.seconds)
        run = sim.start(sc, seed=0)
        sim_rate = rate(run.step, args.seconds)
        print(f"{sc.name}: {sc.agents} agent(s): conag.env {env_rate:,.0f} steps/s; in-process World "
              f"{world_rate:,.0f} ticks/s; sim.SimRun with brains {sim_rate:,.0f} ticks/s", flush=True)


if __name__ == "__main__":
    main()
