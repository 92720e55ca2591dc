"""`conag replay FILE.mcap`: publish a recording again, paced as recorded; or (--verify) run a
fresh world in lockstep, feed it the recorded commands, and check its frames are the recorded
ones, tick for tick. The shells are `conag/recording/replayer.py`; the script of a
recording `conag/recording/replay.py`."""

from __future__ import annotations

import argparse
import sys
import threading
from dataclasses import replace

import numpy as np

from conag.common import bus_args, bus_options, stop_on_signals
from conag.noise_flags import from_note
from conag.recording.mcap_log import read_recording
from conag.recording.replay import LockstepScript
from conag.recording.replayer import DriveError, drive_world, entries_for, publish_recording
from conag.runs import free_endpoint
from protocol.bus import BusOptions, join_callback_threads, open_session
from world_server.checkpoint import CheckpointPlan
from world_server.scenario import parse_scenario
from world_server.server import WorldServer
from world_server.world import World

EXIT_DIFFERENT = 1
VERIFY_TIMEOUT = 3600.0  # seconds: the replayed world's lockstep timeout (off, in effect)


def configure(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.mcap")
    p.add_argument("--rate", type=float, default=1.0,
                   help="speed: 2 is twice as fast as recorded, 0.5 half; 0 as fast as possible (default 1)")
    p.add_argument("--from", dest="from_tick", type=int, default=0, metavar="TICK",
                   help="start at the first message of this tick (default 0)")
    p.add_argument("--wait", type=float, default=2.0, metavar="S",
                   help="seconds to wait for a subscriber before publishing (default 2)")
    p.add_argument("--verify", action="store_true",
                   help="run a fresh world in lockstep from the recorded scenario and seed, feed it the "
                        "recorded attaches, perturbations and commands, and compare its frames with the "
                        f"recorded ones (exit {EXIT_DIFFERENT} at the first difference)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    bus_args(p)


def run(args: argparse.Namespace) -> int:
    rec = read_recording(args.file)
    if not rec.complete:
        print(f"warning: {args.file}: {rec.problem}", file=sys.stderr)
    world_id = rec.info.get("world_id", args.world_id)
    entries = entries_for(rec.entries, world_id)
    if args.verify:
        return _verify(args, rec, entries, world_id)
    shown = [-1]

    def progress(entry) -> None:
        if not args.quiet and entry.tick // 500 != shown[0] // 500:
            print(f"tick {entry.tick}", flush=True)
        shown[0] = entry.tick

    with stop_on_signals() as stop:
        session = open_session(bus_options(args))
        try:
            sent = publish_recording(session, entries, stop, rate=args.rate, from_tick=args.from_tick,
                                     wait=args.wait, on_message=progress)
        finally:
            session.close()
    print(f"published {sent} of {len(entries)} messages from {args.file}", flush=True)
    return 0


def _script(args: argparse.Namespace, rec, entries) -> LockstepScript:
    """What the recording asks of a fresh world (ValueError if it cannot be replayed)."""
    if "scenario" not in rec.info or "seed" not in rec.info:
        raise ValueError(f"{args.file} holds no scenario or seed (record with --scenario, or conag run --record)")
    script = LockstepScript.from_entries(entries)
    if not script.frames:
        raise ValueError(f"{args.file} holds no agent's frame to compare (it ends before any agent attached)")
    for limit in script.limits:
        print(f"warning: {limit}: the replay may differ from then on", file=sys.stderr)
    if script.cut_short:
        print(f"note: {script.cut_short}: the replay ends at tick {script.end_tick}", file=sys.stderr)
    return script


def _fresh_world(rec, world_id: str) -> tuple[World, CheckpointPlan | None]:
    """The recorded scenario's world from its seed, and the checkpoint interval it stepped with."""
    scenario = parse_scenario(rec.info["scenario"], rec.info.get("scenario_path", "<recording>"))
    if "noise" in rec.info:  # the noise flags of the recorded `conag run`
        scenario = from_note(rec.info["noise"]).apply(scenario)
    # The script stands in for every command the recorded world stepped without: this one
    # never times out itself (a busy machine makes the replay slower, not different).
    scenario = replace(scenario, world=replace(scenario.world, lockstep_timeout=VERIFY_TIMEOUT))
    world = World(scenario, np.random.default_rng(int(rec.info["seed"])), world_id=world_id)
    # A world that checkpointed rebuilt its physics at every checkpoint: so does this one.
    every = rec.info.get("checkpoint_every")
    return world, (CheckpointPlan(None, int(every)) if every else None)


def _verify(args: argparse.Namespace, rec, entries, world_id: str) -> int:
    """Run the recorded scenario in lockstep in this process and drive it with the recording."""
    script = _script(args, rec, entries)
    world, plan = _fresh_world(rec, world_id)
    endpoint = free_endpoint()
    first = min(script.attaches, default=0)
    with stop_on_signals() as stop:
        serve = open_session(BusOptions(listen=(endpoint,)), serve=True)
        client = open_session(BusOptions(connect=(endpoint,)))
        try:
            server = WorldServer(world, serve, mode="lockstep", max_ticks=script.last_tick + 1,
                                 wait_agents=len({w.agent_id for w in script.attaches.get(first, ())}),
                                 checkpoint=plan)
            world_stop = threading.Event()
            thread = threading.Thread(target=server.run, args=(world_stop,), daemon=True)
            thread.start()

            def progress(tick: int) -> None:
                if not args.quiet and tick % 500 == 0:
                    print(f"tick {tick}", flush=True)

            try:
                result = drive_world(client, script, world_id, stop, on_tick=progress, timeout=60.0)
            except DriveError as exc:  # the replayed world did not answer: nothing compared from there on
                print(f"error: {args.file}: the replay stopped: {exc}", file=sys.stderr)
                return EXIT_DIFFERENT
            finally:
                world_stop.set()
                thread.join(10)
        finally:
            client.close()
            serve.close()
            join_callback_threads()  # the world's, declared in a daemon thread (bus.session says why)
    return _verdict(result, script)


def _verdict(result, script: LockstepScript) -> int:
    if result.identical:
        lost = f" ({result.dropped} dropped on the bus, not compared)" if result.dropped else ""
        print(f"identical: {result.matched} frames of {len(script.agents())} agents over ticks 0-"
              f"{script.end_tick} match the recording{lost}", flush=True)
        return 0
    print(f"DIFFERENT: {result.first_difference or 'no frame compared'} ({result.matched} frames matched before)",
          flush=True)
    return EXIT_DIFFERENT
