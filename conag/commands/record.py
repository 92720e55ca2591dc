"""`conag record OUT.mcap`: record every message of a world to an MCAP file, until Ctrl-C or
SIGTERM. The shell is `conag/recording/recorder.py`, the file format `conag/recording/mcap_log.py`."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict
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
from conag.foxglove.convert import Translator
from conag.recording.gaps import describe_lost
from conag.recording.mcap_log import DEFAULT_TICK_NS, add_derived_channels
from conag.recording.recorder import LEASE_MS, RecordReport, run_recorder
from protocol.bus import open_session
from world_server.scenario import load_scenario


def configure(r: argparse.ArgumentParser) -> None:
    r.add_argument("out", metavar="OUT.mcap", help="written as OUT.mcap.part, renamed to OUT.mcap when complete")
    r.add_argument("--scenario", metavar="FILE", help="the world's scenario file, kept in the recording's metadata")
    r.add_argument("--seed", type=int, help="the world's seed, for the metadata (default: the scenario's)")
    r.add_argument("--note", action="append", default=[], metavar="KEY=VALUE",
                   help="more metadata, e.g. agent_args='--map-size 41' (repeatable)")
    r.add_argument("--id", default="recorder", help="recorder id for its liveliness token (default recorder)")
    r.add_argument("--maps-every", type=int, default=0, metavar="N",
                   help="ask the agents for their maps (ESMs, NMs, Matching grid) every N ticks, to record them "
                        "(default 0: off)")
    r.add_argument("--msgpack-only", action="store_true",
                   help="write the bus's msgpack channels only, without the Foxglove channels beside them "
                        "(docs/how-to/foxglove.md)")
    r.add_argument("--translate", metavar="IN.mcap",
                   help="record no world: write IN's bus messages to OUT with the Foxglove channels beside them "
                        "(for a recording made with --msgpack-only, one whose channels were cut short, or the "
                        ".part a killed recorder left)")
    r.add_argument("--priority", choices=PRIORITIES, default=RECORDER_PRIORITY,
                   help="the recorder's CPU priority, so the run it records gets the CPU first: idle (the default) "
                        "runs it only when a core would otherwise idle (Linux SCHED_IDLE; starved for a second, "
                        "it runs at the normal priority from then on), low raises its nice value by 10, normal "
                        "leaves it as any process")
    bus_args(r, find_run=True)


def run(args: argparse.Namespace) -> int:
    if args.translate is not None:
        return translate(args.translate, args.out, args.msgpack_only)
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
        session = open_session(bus_options(args), lease_ms=LEASE_MS)
        try:
            print(f"recording world {args.world_id} to {args.out}", flush=True)
            run_recorder(session, args.world_id, args.out, stop, metadata=meta, tick_ns=_tick_ns(args.scenario),
                         recorder_id=args.id, report=report, maps_every=max(args.maps_every, 0),
                         foxglove=not args.msgpack_only, idle=args.priority == "idle")
        finally:
            session.close()
    print(f"wrote {report.path}: {report.messages} messages, last tick {report.last_tick}", flush=True)
    if report.gaps.gaps:
        print(f"warning: the recording {describe_lost(report.gaps.gaps)}", file=sys.stderr, flush=True)
    return 0


def translate(src: str, out: str, msgpack_only: bool) -> int:
    """`conag record OUT --translate IN`: IN's bus messages and their Foxglove channels into OUT."""
    if msgpack_only:
        raise ValueError("--translate writes the Foxglove channels: it cannot be given with --msgpack-only")
    if Path(src).resolve() == Path(out).resolve():
        raise ValueError(f"--translate: OUT must be another file than {src}")
    rec = add_derived_channels(src, out, Translator().feed)
    lacks = "" if rec.complete else f" ({src} was cut short: {rec.problem})"
    print(f"wrote {out}: {len(rec.entries)} messages, last tick {rec.last_tick}, with the Foxglove channels{lacks}",
          flush=True)
    return 0


def _version() -> str:
    try:
        return version("conag")
    except PackageNotFoundError:
        return "unknown"


def recording_metadata(scenario_path: str | None, seed: int | None, notes: dict[str, str], world_id: str) -> dict:
    """The `conag` metadata record: scenario text and path, seed, world config, versions, notes."""
    meta = {"world_id": world_id, "conag_version": _version(), "command": " ".join(sys.argv)}
    if scenario_path:
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
    if not scenario_path:
        return DEFAULT_TICK_NS
    return round(1e9 / load_scenario(scenario_path).world.tick_rate)
