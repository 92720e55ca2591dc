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
from conag.recording.replay import Comparison, LockstepScript, world_runs
from conag.recording.replayer import DriveError, drive_world, entries_for, publish_recording
from conag.runs import free_endpoint
from protocol import keys
from protocol.bus import BusOptions, Declarations, join_callback_threads, open_session, wait_for_token
from world_server.checkpoint import CheckpointPlan, checkpoint_world, decode_checkpoint, restore_world, resumed_epoch
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


def _scripts(args: argparse.Namespace, rec, entries) -> list[LockstepScript]:
    """What the recording asks of fresh worlds, one script per run of the world
    (`conag.recording.replay.world_runs`); ValueError if it cannot be replayed."""
    if "scenario" not in rec.info or "seed" not in rec.info:
        raise ValueError(f"{args.file} holds no scenario or seed (record with --scenario, or conag run --record)")
    scripts = world_runs(entries)
    if not scripts[0].frames:
        raise ValueError(f"{args.file} holds no agent's frame to compare (it ends before any agent attached)")
    if len(scripts) > 1 and "checkpoint_every" not in rec.info:
        raise ValueError(f"{args.file} holds a world that was restarted, but not the interval it checkpointed at "
                         "(record with conag run --record, or conag record --note checkpoint_every=N)")
    for script in scripts:
        for limit in script.limits:
            print(f"warning: {limit}: the replay may differ from then on", file=sys.stderr)
    return scripts


def _welcomed_cue_reach(scripts: list[LockstepScript]) -> float | None:
    """The cue reach the recorded world stated in its first Welcome (None if it welcomed no
    one): `conag run --foremen/--workers` and `conag world --cue-reach` set it beside the
    scenario, and a world with cues senses them in every frame."""
    for script in scripts:
        for tick in sorted(script.attaches):
            for w in script.attaches[tick]:
                return w.cue_reach
    return None


def _fresh_world(rec, world_id: str, cue_reach: float | None = None) -> tuple[World, CheckpointPlan | None]:
    """The recorded scenario's world from its seed (with `cue_reach`, the recorded world's),
    and the checkpoint interval it stepped with."""
    scenario = parse_scenario(rec.info["scenario"], rec.info.get("scenario_path", "<recording>"))
    if "noise" in rec.info:  # the noise flags of the recorded `conag run`
        scenario = from_note(rec.info["noise"]).apply(scenario)
    if cue_reach is not None:
        scenario = replace(scenario, world=replace(scenario.world, cue_reach=cue_reach))
    # The script stands in for every command the recorded world stepped without: this one
    # never times out itself (a busy machine makes the replay slower, not different).
    scenario = replace(scenario, world=replace(scenario.world, lockstep_timeout=VERIFY_TIMEOUT))
    world = World(scenario, np.random.default_rng(int(rec.info["seed"])), world_id=world_id)
    # A world that checkpointed rebuilt its physics at every checkpoint: so does this one.
    every = rec.info.get("checkpoint_every")
    return world, (CheckpointPlan(None, int(every)) if every else None)


def _verify(args: argparse.Namespace, rec, entries, world_id: str) -> int:
    """Run the recorded scenario in lockstep in this process and drive it with the recording:
    each run of the world in turn, a resumed one from the state the replay reached at its
    checkpoint's tick."""
    scripts = _scripts(args, rec, entries)
    cue_reach = _welcomed_cue_reach(scripts)
    world, plan = _fresh_world(rec, world_id, cue_reach)
    results: list[Comparison] = []
    with stop_on_signals() as stop:
        for k, script in enumerate(scripts):
            if script.cut_short:
                print(f"note: {script.cut_short}: the replay ends at tick {script.end_tick}", file=sys.stderr)
            try:
                if k:
                    world = _world_for(script, world, plan, rec, world_id, cue_reach)
                results.append(_replay_run(args, script, world, plan, world_id, stop))
            except DriveError as exc:  # the replayed world did not answer: nothing compared from there on
                print(f"error: {args.file}: the replay stopped: {exc}", file=sys.stderr)
                return EXIT_DIFFERENT
            if not results[-1].identical or script.cut_short or stop.is_set():
                break
    return _verdict(results, scripts[:len(results)])


def _world_for(script: LockstepScript, before: World, plan: CheckpointPlan | None, rec, world_id: str,
               cue_reach: float | None) -> World:
    """The world a later run of the recorded one started as: afresh from the seed, or resumed
    from the state the world replayed before it has reached (its checkpoint's tick)."""
    if not script.resumed:
        return _fresh_world(rec, world_id, cue_reach)[0]
    if plan is None or before.tick != script.first_tick:
        raise DriveError(f"the world was resumed at tick {script.first_tick}, which the replay did not reach")
    world = restore_world(decode_checkpoint(checkpoint_world(before, plan.every)))
    world.epoch = resumed_epoch(world)  # as `conag world --resume` does
    if script.epoch is not None and world.epoch != script.epoch:
        raise DriveError(f"the world resumed at tick {script.first_tick} had epoch {script.epoch}, the replay's "
                         f"{world.epoch}: it was not resumed from the state the replay reached")
    return world


def _replay_run(args: argparse.Namespace, script: LockstepScript, world: World, plan: CheckpointPlan | None,
                world_id: str, stop: threading.Event) -> Comparison:
    """Serve `world` on a bus of its own and drive it with one run's script; the world is
    left as it ended (at the script's `end`, for the next run to resume from)."""
    endpoint = free_endpoint()
    first = min(script.attaches, default=script.first_tick)
    serve = open_session(BusOptions(listen=(endpoint,)), serve=True)
    client = open_session(BusOptions(connect=(endpoint,)))
    try:
        with Declarations() as declared:
            # A resumed world lets go of the agents whose tokens it does not see when its first
            # tick comes: the recorded agents' processes held theirs all along.
            back = [w.agent_id for w in script.attaches.get(script.first_tick, ())] if script.resumed else []
            for agent in back:
                declared.add(client.liveliness().declare_token(keys.agent_token(world_id, agent)))
                if not wait_for_token(serve, keys.agent_token(world_id, agent), 60.0, stop=stop):
                    raise DriveError(f"the replayed world's bus never saw agent {agent}'s token")
            ends_at = script.end if script.end is not None else script.last_tick + 1
            server = WorldServer(world, serve, mode="lockstep", max_ticks=ends_at,
                                 wait_agents=len({w.agent_id for w in script.attaches.get(first, ())}),
                                 checkpoint=plan, resumed=script.resumed)
            world_stop = threading.Event()
            thread = threading.Thread(target=server.run, args=(world_stop,), daemon=True)
            thread.start()

            def progress(tick: int) -> None:
                if not args.quiet and tick % 500 == 0:
                    print(f"tick {tick}", flush=True)

            try:
                return drive_world(client, script, world_id, stop, on_tick=progress, timeout=60.0, tokens=back)
            finally:
                world_stop.set()
                thread.join(10)
                if thread.is_alive():
                    raise DriveError("the replayed world did not stop within 10 s")
    finally:
        client.close()
        serve.close()
        join_callback_threads()  # the world's, declared in a daemon thread (bus.session says why)


def _verdict(results: list[Comparison], scripts: list[LockstepScript]) -> int:
    for result in results:
        if not result.identical:
            print(f"DIFFERENT: {result.first_difference or 'no frame compared'} "
                  f"({sum(r.matched for r in results[:-1]) + result.matched} frames matched before)", flush=True)
            return EXIT_DIFFERENT
    matched, dropped = sum(r.matched for r in results), sum(r.dropped for r in results)
    agents = {a for script in scripts for a in script.agents()}
    lost = f" ({dropped} dropped on the bus, not compared)" if dropped else ""
    restarts = ""
    if len(scripts) > 1:
        resumed = ", ".join(str(s.first_tick) for s in scripts[1:])
        restarts = (f", across {len(scripts) - 1} world restart{'s' if len(scripts) > 2 else ''} (started again at "
                    f"tick {resumed}; the ticks a dead world went past its checkpoint were undone, not compared)")
    print(f"identical: {matched} frames of {len(agents)} agents over ticks 0-{scripts[-1].end_tick} match the "
          f"recording{lost}{restarts}", flush=True)
    return 0
