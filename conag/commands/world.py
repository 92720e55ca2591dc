"""`conag world SCENARIO`: serve a world (loopback peer mode by default), or resume one from
its checkpoint."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys

import numpy as np

from conag.argtypes import positive
from conag.common import bus_args, bus_options, status_line, stop_on_signals
from conag.noise_flags import add_noise_args, noise_settings
from protocol.bus import is_client, open_session
from world_server.checkpoint import DEFAULT_EVERY, CheckpointPlan, load_state, restore_world, resumed_epoch
from world_server.scenario import load_scenario
from world_server.server import WorldServer, read_go_without_requests
from world_server.summary import write_summary
from world_server.world import World


def configure(w: argparse.ArgumentParser) -> None:
    w.add_argument("scenario", nargs="?",
                   help="scenario TOML file, e.g. scenarios/quick_wall.toml (may be left out with --resume)")
    w.add_argument("--ticks", type=int, help="stop after this many ticks")
    w.add_argument("--tick-mode", dest="mode_tick", choices=("lockstep", "realtime"),
                   help="override the scenario's tick mode")
    w.add_argument("--seed", type=int, help="override the scenario's seed")
    w.add_argument("--stop-when-complete", action="store_true", help="stop once every site holds a brick")
    w.add_argument("--wait-agents", type=int, default=1, metavar="N",
                   help="lockstep: do not tick before N agents have attached (default 1)")
    w.add_argument("--summary", metavar="PATH", help="write the final status as JSON")
    w.add_argument("--quiet", action="store_true", help="do not print periodic status lines")
    w.add_argument("--profile", metavar="PATH",
                   help="on exit, write where the loop's time went (JSON: seconds stepping, publishing frames, "
                        "waiting for commands, per tick from the second; when the first tick was out)")
    w.add_argument("--stdin-control", action="store_true",
                   help="read `without ID` lines on stdin: the first tick does not wait for agent ID (its process "
                        "died before attaching; conag run uses it)")
    w.add_argument("--recorded", action="store_true",
                   help="let agents attach only once a recorder's link is up (up to 10 s): the recording then holds "
                        "every attach, of a world started again too (conag run --record passes it)")
    w.add_argument("--max-tick-rate", type=float, metavar="HZ",
                   help="lockstep: step at most HZ ticks per wall second (default: as fast as the agents answer)")
    c = w.add_argument_group("checkpoints (the world survives its own death)")
    c.add_argument("--checkpoint", metavar="FILE",
                   help="write the whole world to FILE every --checkpoint-every ticks and when stopped (SIGTERM); "
                        "atomic, the one before kept as FILE.prev")
    c.add_argument("--checkpoint-every", type=positive, metavar="N",
                   help=f"ticks between checkpoints (default {DEFAULT_EVERY}; with --resume, the checkpoint's own, "
                        "so the resumed world steps exactly as one that never stopped)")
    c.add_argument("--resume", metavar="FILE",
                   help="continue the world saved in checkpoint FILE from its tick (and go on checkpointing to FILE "
                        "unless --checkpoint says otherwise); a truncated or corrupt FILE is refused")
    w.add_argument("--cue-reach", type=float, metavar="R",
                   help="a world with cues (docs/society.md): bodies mark cells within R world units; 0: no cues "
                        "(default: the scenario's world.cue_reach, 0)")
    add_noise_args(w)
    bus_args(w)


def run(args: argparse.Namespace) -> int:
    plan = None
    if args.resume:
        if not noise_settings(args).changes_nothing:
            raise ValueError("the checkpoint holds the world's noise settings: leave the noise flags out with --resume")
        world, every = _resumed_world(args)
        scenario = world.scenario
        path = args.checkpoint or args.resume  # a resumed world goes on checkpointing where it came from
        plan = CheckpointPlan(path, args.checkpoint_every or every or DEFAULT_EVERY)
    else:
        if args.scenario is None:
            raise ValueError("conag world needs a SCENARIO file (or --resume CHECKPOINT)")
        scenario = noise_settings(args).apply(load_scenario(args.scenario))
        if args.cue_reach is not None:
            scenario = dataclasses.replace(scenario, world=dataclasses.replace(scenario.world,
                                                                             cue_reach=args.cue_reach))
        seed = scenario.seed if args.seed is None else args.seed
        world = World(scenario, np.random.default_rng(seed), world_id=args.world_id)
        if args.checkpoint:
            plan = CheckpointPlan(args.checkpoint, args.checkpoint_every or DEFAULT_EVERY)
    mode = args.mode_tick or scenario.tick_mode
    on_status = None if args.quiet else (lambda st: print(status_line(st), flush=True))
    with stop_on_signals() as stop:  # before the session opens: no signal finds us unprepared
        session = open_session(bus_options(args), serve=True)
        try:
            print(f"world {world.world_id}: {scenario.name} ({scenario.cols}x{scenario.rows} cells, "
                  f"{len(world.sites_xy)} sites, {world.discs.bricks_total()} bricks), {mode} mode"
                  + (f", resumed from {args.resume} at tick {world.tick}" if args.resume else "")
                  + (f", checkpoint every {plan.every} ticks to {plan.path}" if plan else ""), flush=True)
            if mode == "lockstep" and not args.resume:
                print(f"lockstep: ticks start once {args.wait_agents} agent(s) have attached", flush=True)
            # Through a router, frames sent "latest wins" (DROP) were lost under load, each costing a
            # lockstep timeout and the agent's odometry of that tick (docs/results/reliability.md); lockstep waits
            # for every agent anyway, so there frames are sent BLOCK.
            block = mode == "lockstep" and is_client(bus_options(args), serve=True)
            server = WorldServer(world, session, mode=args.mode_tick, max_ticks=args.ticks,
                                 stop_when_complete=args.stop_when_complete, wait_agents=args.wait_agents,
                                 on_status=on_status, block_frames=block, checkpoint=plan,
                                 resumed=bool(args.resume), max_tick_rate=args.max_tick_rate,
                                 recorded=args.recorded)
            if args.stdin_control:
                read_go_without_requests(server, sys.stdin)
            final = server.run(stop)
        finally:
            session.close()
        # Still within stop_on_signals: `conag run` stops its world with SIGINT and then SIGTERM,
        # and a SIGTERM that came once the default handler was back killed the world while it
        # wrote its summary (the run then read an empty file).
        print("final: " + status_line(final), flush=True)
        if args.summary:
            write_summary(final, args.summary, server.agent_states)
        if args.profile:
            with open(args.profile, "w", encoding="utf-8") as f:
                json.dump({"agents": len(final.agent_ids), **server.times.as_dict()}, f, indent=2)
    return 0


def _resumed_world(args: argparse.Namespace):
    """The world of `--resume FILE` and the interval it was checkpointed at (CheckpointError
    is a ValueError: a usage error, exit 2)."""
    if args.seed is not None:
        raise ValueError("--seed cannot be used with --resume: the checkpoint holds the generator's state")
    state = load_state(args.resume)
    world = restore_world(state)
    if args.world_id != world.world_id:
        raise ValueError(f"{args.resume} holds world {world.world_id!r}, not {args.world_id!r} (--world-id)")
    if args.scenario is not None:
        given = load_scenario(args.scenario)
        if (given.name, given.layout) != (world.scenario.name, world.scenario.layout):
            raise ValueError(f"{args.resume} holds a world of scenario {world.scenario.name!r}, not of "
                             f"{args.scenario} ({given.name!r}); leave SCENARIO out to resume it")
    world.epoch = resumed_epoch(world)  # a new run of the world: frames of the dead one are refused
    return world, state.get("checkpoint_every")
