"""`conag record`, `conag replay` and `conag echo`: watch the bus, keep it, play it back.

    conag record OUT.mcap [--scenario FILE]       every message of a world to an MCAP file, until Ctrl-C
    conag replay FILE.mcap [--rate R] [--from T]  publish a recording again, paced as recorded
    conag replay FILE.mcap --verify               a fresh world in lockstep, fed the recorded commands:
                                                  are its frames the recorded ones, tick for tick?
    conag echo KEY_EXPR [--once] [--json] [--hz]  print the messages on a key (relative to the world's root)

Registered by conag/cli.py; the shells are conag/recording/recorder.py, conag/recording/replayer.py and
conag/recording/echo_node.py, the pure parts conag/recording/.
"""

from __future__ import annotations

import json
import sys
import threading
from dataclasses import asdict, replace
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from conag.common import (
    PRIORITIES,
    RECORDER_PRIORITY,
    bus_args,
    bus_options,
    lower_priority,
    restore_priority,
    stop_on_signals,
)

EXIT_DIFFERENT = 1
VERIFY_TIMEOUT = 3600.0  # seconds: the replayed world's lockstep timeout (off, in effect)


def add_commands(sub) -> None:
    """Register `record`, `replay` and `echo` on the main parser's subparsers."""
    r = sub.add_parser("record", help="record every message of a world to an MCAP file, until Ctrl-C or SIGTERM")
    r.add_argument("out", metavar="OUT.mcap", help="written as OUT.mcap.part, renamed to OUT.mcap when complete")
    r.add_argument("--scenario", metavar="FILE", help="the world's scenario file, kept in the recording's metadata")
    r.add_argument("--seed", type=int, help="the world's seed, for the metadata (default: the scenario's)")
    r.add_argument("--note", action="append", default=[], metavar="KEY=VALUE",
                   help="more metadata, e.g. agent_args='--map-size 41' (repeatable)")
    r.add_argument("--id", default="recorder", help="recorder id for its liveliness token (default recorder)")
    r.add_argument("--maps-every", type=int, default=0, metavar="N",
                   help="ask the agents for their maps (ESMs, NMs, Matching grid) every N ticks, to record them "
                        "(default 0: off)")
    r.add_argument("--priority", choices=PRIORITIES, default=RECORDER_PRIORITY,
                   help="the recorder's CPU priority, so the run it records gets the CPU first: idle (the default) "
                        "runs it only when a core would otherwise idle (Linux SCHED_IDLE), low raises its nice "
                        "value by 10, normal leaves it as any process")
    bus_args(r, find_run=True)
    r.set_defaults(func=cmd_record)

    p = sub.add_parser("replay", help="publish a recording again (or --verify it against a fresh world)")
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
    p.set_defaults(func=cmd_replay)

    e = sub.add_parser("echo", help="print the decoded messages on a key expression")
    e.add_argument("key", metavar="KEY_EXPR",
                   help="e.g. 'agent/a1/command', 'agent/*/sensors' or '**' (relative to the world's root, "
                        "conag/v4/world/<id>/), or a full key starting with conag/")
    e.add_argument("--once", action="store_true", help="stop after the first message (with --hz: the first rate)")
    e.add_argument("--json", action="store_true", help="one JSON object per message")
    e.add_argument("--hz", action="store_true", help="print the rate of the messages instead, like ros2 topic hz")
    e.add_argument("--period", type=float, default=1.0, metavar="S", help="seconds between rate lines (default 1)")
    e.add_argument("--window", type=int, default=1000, metavar="N", help="messages the rate is taken over")
    bus_args(e, find_run=True)
    e.set_defaults(func=cmd_echo)


def _version() -> str:
    try:
        return version("conag")
    except PackageNotFoundError:
        return "unknown"


def recording_metadata(scenario_path: str | None, seed: int | None, notes: dict[str, str], world_id: str) -> dict:
    """The `conag` metadata record: scenario text and path, seed, world config, versions, notes."""
    meta = {"world_id": world_id, "conag_version": _version(), "command": " ".join(sys.argv)}
    if scenario_path:
        from world_server.scenario import load_scenario

        scenario = load_scenario(scenario_path)
        meta.update(scenario=Path(scenario_path).read_text(encoding="utf-8"), scenario_path=str(scenario_path),
                    scenario_name=scenario.name, tick_mode=scenario.tick_mode,
                    world_config=json.dumps(asdict(scenario.world)))
        seed = scenario.seed if seed is None else seed
    if seed is not None:
        meta["seed"] = str(seed)
    meta.update(notes)
    return meta


def _tick_ns(scenario_path: str | None) -> int:
    from conag.recording.mcap_log import DEFAULT_TICK_NS

    if not scenario_path:
        return DEFAULT_TICK_NS
    from world_server.scenario import load_scenario

    return round(1e9 / load_scenario(scenario_path).world.tick_rate)


def cmd_record(args) -> int:
    from conag.recording.recorder import RecordReport, run_recorder
    from protocol.bus import open_session

    notes = {}
    for note in args.note:
        key, sep, value = note.partition("=")
        if not sep or not key:
            raise ValueError(f"--note expects KEY=VALUE, got {note!r}")
        notes[key] = value
    meta = recording_metadata(args.scenario, args.seed, notes, args.world_id)
    lower_priority(args.priority)  # before the session opens, so zenoh's threads have it too
    report = RecordReport()
    # Stopped, it finishes its file at the normal priority: idle, it could starve on a busy machine.
    with stop_on_signals(on_stop=lambda: restore_priority(args.priority)) as stop:
        session = open_session(bus_options(args))
        try:
            print(f"recording world {args.world_id} to {args.out}", flush=True)
            run_recorder(session, args.world_id, args.out, stop, metadata=meta, tick_ns=_tick_ns(args.scenario),
                         recorder_id=args.id, report=report, maps_every=max(args.maps_every, 0))
        finally:
            session.close()
    print(f"wrote {report.path}: {report.messages} messages, last tick {report.last_tick}", flush=True)
    return 0


def cmd_replay(args) -> int:
    from conag.recording.mcap_log import read_recording
    from conag.recording.replayer import entries_for

    rec = read_recording(args.file)
    if not rec.complete:
        print(f"warning: {args.file}: {rec.problem}", file=sys.stderr)
    world_id = rec.info.get("world_id", args.world_id)
    entries = entries_for(rec.entries, world_id)
    if args.verify:
        return _verify(args, rec, entries, world_id)
    from conag.recording.replayer import publish_recording
    from protocol.bus import open_session

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


def _verify(args, rec, entries, world_id: str) -> int:
    """Run the recorded scenario in lockstep in this process and drive it with the recording."""
    import socket

    import numpy as np

    from conag.recording.replay import LockstepScript
    from conag.recording.replayer import DriveError, drive_world
    from protocol.bus import BusOptions, join_callback_threads, open_session
    from world_server.checkpoint import CheckpointPlan
    from world_server.scenario import parse_scenario
    from world_server.server import WorldServer
    from world_server.world import World

    if "scenario" not in rec.info or "seed" not in rec.info:
        raise ValueError(f"{args.file} holds no scenario or seed (record with --scenario, or conag run --record)")
    script = LockstepScript.from_entries(entries)
    if not script.frames:
        raise ValueError(f"{args.file} holds no agent's frame to compare (it ends before any agent attached)")
    for limit in script.limits:
        print(f"warning: {limit}: the replay may differ from then on", file=sys.stderr)
    if script.cut_short:
        print(f"note: {script.cut_short}: the replay ends at tick {script.end_tick}", file=sys.stderr)
    scenario = parse_scenario(rec.info["scenario"], rec.info.get("scenario_path", "<recording>"))
    # The script stands in for every command the recorded world stepped without: this one
    # never times out itself (a busy machine makes the replay slower, not different).
    scenario = replace(scenario, world=replace(scenario.world, lockstep_timeout=VERIFY_TIMEOUT))
    world = World(scenario, np.random.default_rng(int(rec.info["seed"])), world_id=world_id)
    # A world that checkpointed rebuilt its physics at every checkpoint: so does this one.
    every = rec.info.get("checkpoint_every")
    plan = CheckpointPlan(None, int(every)) if every else None
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{s.getsockname()[1]}"
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
    if result.identical:
        lost = f" ({result.dropped} dropped on the bus, not compared)" if result.dropped else ""
        print(f"identical: {result.matched} frames of {len(script.agents())} agents over ticks 0-"
              f"{script.end_tick} match the recording{lost}", flush=True)
        return 0
    print(f"DIFFERENT: {result.first_difference or 'no frame compared'} ({result.matched} frames matched before)",
          flush=True)
    return EXIT_DIFFERENT


def echo_key(key: str, world_id: str) -> str:
    """A key expression as `conag echo` takes it: relative to the world's root unless it
    starts with conag/."""
    from protocol import keys

    return key if key.startswith("conag/") else f"{keys.world_root(world_id)}/{key.lstrip('/')}"


def cmd_echo(args) -> int:
    from conag.recording.echo_node import run_echo
    from protocol.bus import open_session

    key = echo_key(args.key, args.world_id)
    with stop_on_signals() as stop:
        session = open_session(bus_options(args))
        try:
            run_echo(session, key, stop, once=args.once, as_json=args.json, hz=args.hz, period=args.period,
                     window=args.window, out=lambda line: print(line, flush=True))
        finally:
            session.close()
    return 0
