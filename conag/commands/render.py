"""`conag render SCENARIO`: draw a scenario as a bird's-eye PNG (--agent-maps: with one
agent's maps beside it, after running it in-process)."""

from __future__ import annotations

import argparse

from conag.noise_flags import add_noise_args, noise_settings
from world_server.render import render_scenario
from world_server.scenario import load_scenario


def configure(r: argparse.ArgumentParser) -> None:
    r.add_argument("scenario")
    r.add_argument("--out", default="world.png", help="output PNG path")
    r.add_argument("--agent-maps", action="store_true",
                   help="run the scenario in-process and draw one agent's ESMs and NMs beside the world")
    r.add_argument("--agent", metavar="ID", help="agent for --agent-maps (default a1)")
    r.add_argument("--ticks", type=int, metavar="N", help="lockstep ticks to run first (default 0)")
    add_noise_args(r)


def run(args: argparse.Namespace) -> int:
    if args.agent_maps:
        from conag.sim.render_agent import render_agent_maps  # the simulator and the agent: only for this

        out = render_agent_maps(noise_settings(args).apply(load_scenario(args.scenario)), args.out,
                                agent=args.agent or "a1", ticks=args.ticks or 0)
    elif args.agent is not None or args.ticks is not None or not noise_settings(args).changes_nothing:
        raise ValueError("--agent, --ticks and the noise flags need --agent-maps")
    else:
        out = render_scenario(load_scenario(args.scenario), args.out)
    print(f"wrote {out}")
    return 0
