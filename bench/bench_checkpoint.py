"""What a world checkpoint costs (issue 12, point 2; the figures are in docs/results/reliability.md).

    python3 -m bench.bench_checkpoint            # the table of docs/results/reliability.md
    python3 -m bench.bench_checkpoint --quick    # a smoke run, not a measurement

For a small world (nested_squares with 4 agents, 200 ticks into its build) and a large one
(120 x 120 cells, 3,000 bricks scattered by seed 0, 500 agents), it times, per checkpoint:
`checkpoint_world` (the plain state, msgpack, and the physics rebuilt from that state, as a
checkpointing world does), `write_checkpoint` (temporary file, fsync, read back and
checked, rename, directory fsync), and one world tick for scale. Medians of `--repeats`.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from conag.sim.loop import start
from world_server.checkpoint import checkpoint_world, write_checkpoint
from world_server.scenario import load_scenario, parse_scenario
from world_server.world import World

ROOT = Path(__file__).resolve().parent.parent


def _median_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1000 * statistics.median(times)


def small_world() -> World:
    run = start(load_scenario(ROOT / "scenarios" / "nested_squares.toml"), agents=4)
    for _ in range(200):
        run.step()
    return run.world


def large_world(side: int = 120, bricks: int = 3000, agents: int = 500) -> World:
    rng = np.random.default_rng(0)
    rows = [["."] * side for _ in range(side)]
    for r, c in rng.integers(side, size=(bricks, 2)):
        rows[r][c] = "b"
    per_row = side // 2
    for i in range(agents):
        rows[(i // per_row) * 2 + 1][(i % per_row) * 2] = "A"
    text = (f'name = "large"\nseed = 1\nagents = {agents}\nlayout = """\n'
            + "\n".join("".join(r) for r in rows) + '\n"""\n')
    world = World(parse_scenario(text))
    for i in range(agents):
        world.attach(f"a{i + 1}")
    for _ in range(5):
        world.step()
    return world


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="a smoke run (small sizes, few repeats)")
    p.add_argument("--repeats", type=int, default=20)
    args = p.parse_args(argv)
    repeats = 2 if args.quick else args.repeats
    worlds = [("nested_squares, 4 agents", small_world())]
    if args.quick:
        worlds.append(("30 x 30 cells, 100 bricks, 20 agents", large_world(30, 100, 20)))
    else:
        worlds.append(("120 x 120 cells, 3,000 bricks, 500 agents", large_world()))
    print("| world | checkpoint size | state + physics rebuilt | written (fsync, checked) | one tick |")
    print("| --- | ---: | ---: | ---: | ---: |")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "w.ckpt"
        for name, world in worlds:
            data = checkpoint_world(world)
            build = _median_ms(lambda w=world: checkpoint_world(w), repeats)
            write = _median_ms(lambda d=data: write_checkpoint(path, d), repeats)
            tick = _median_ms(world.step, repeats)
            print(f"| {name} | {len(data) / 1024:.1f} KiB | {build:.1f} ms | {write:.1f} ms | {tick:.2f} ms |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
