"""What an agent process's memory is made of, stage by stage (issue 31: the floor of PSS per agent).

    python3 -m bench.bench_agent_memory            # scale.toml, 300 decision steps
    python3 -m bench.bench_agent_memory --steps 1000

One fresh interpreter (`--child`) grows as an agent process does: the interpreter, numpy,
zenoh, numba, the agent's own modules, a zenoh session connected to a world, the brain
built from a Welcome (this loads the compiled kernels from numba's cache), then
`--steps` decision steps. After each stage it reads its own USS (private memory: what
one more agent process costs) and PSS from /proc/self/smaps_rollup. The world is a
`conag.sim` world in the same process, but its memory is read before and after it is
made and left out of the brain's figure.

A process per agent pays every stage; a host of K agents (`conag agents`) pays the
stages up to the session once and only the brain and its steps K times.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = "scenarios/large/scale.toml"


def own_memory() -> tuple[float, float]:
    """(USS, PSS) of this process in MB. Not `bench_scale.smaps`: importing that module (and
    bench_agent_step with it) would be counted in the child's first stages."""
    fields: dict[str, int] = {}
    with open("/proc/self/smaps_rollup", encoding="ascii") as f:
        for line in f:
            parts = line.split()
            if len(parts) >= 2 and parts[1].isdigit():
                fields[parts[0].rstrip(":")] = int(parts[1])
    return (fields["Private_Clean"] + fields["Private_Dirty"]) / 1024, fields["Pss"] / 1024


def child(scenario: str, steps: int) -> list[tuple[str, float, float]]:
    """The stages, in one interpreter: (stage, USS MB, PSS MB) after each."""
    stages = [("interpreter", *own_memory())]
    import numpy

    stages.append(("numpy", *own_memory()))
    import zenoh

    stages.append(("zenoh", *own_memory()))
    import numba  # noqa: F401

    stages.append(("numba", *own_memory()))
    from agent_runtime.brain import Brain
    from agent_runtime.node import AgentProcess  # noqa: F401

    stages.append(("agent modules", *own_memory()))
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
    session = zenoh.open(config)
    stages.append(("zenoh session", *own_memory()))
    from conag.sim.loop import start
    from world_server.scenario import load_scenario

    before = own_memory()
    run = start(load_scenario(scenario), agents=0)  # the world alone: its memory is left out
    world = own_memory()[0] - before[0], own_memory()[1] - before[1]
    brain = Brain(run.world.attach("probe"), None, numpy.random.default_rng(0))
    stages.append(_less("brain, kernels loaded", world))
    for _ in range(steps):
        for frame in run.world.frames():
            s = brain.step(frame)
            run.world.set_command(frame.agent_id, s.speed, s.turn, s.action)
        run.world.step()
    stages.append(_less(f"after {steps} decision steps", world))
    session.close()
    return stages


def _less(stage: str, world: tuple[float, float]) -> tuple[str, float, float]:
    uss, pss = own_memory()
    return stage, uss - world[0], pss - world[1]


def table(stages: list[tuple[str, float, float]]) -> str:
    """A markdown table: each stage, its USS and PSS, and what it added."""
    lines = ["| stage | USS MB | PSS MB | added USS MB |", "|---|---:|---:|---:|"]
    last = 0.0
    for name, uss, pss in stages:
        lines.append(f"| {name} | {uss:.1f} | {pss:.1f} | {uss - last:+.1f} |")
        last = uss
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--child":
        print(json.dumps(child(sys.argv[2], int(sys.argv[3]))))
        return 0
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", default=SCENARIO)
    p.add_argument("--steps", type=int, default=300, help="decision steps after the brain is built (default 300)")
    args = p.parse_args(argv)
    out = subprocess.run([sys.executable, "-m", "bench.bench_agent_memory", "--child", args.scenario,
                          str(args.steps)], cwd=ROOT, check=True, capture_output=True, text=True).stdout
    print(table([tuple(s) for s in json.loads(out.splitlines()[-1])]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
