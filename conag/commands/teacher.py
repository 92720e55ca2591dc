"""`conag teacher`: the teacher process, reinforcing learning students (paper §5.1)."""

from __future__ import annotations

import argparse

from conag.common import bus_args, bus_options, stop_on_signals
from protocol.bus import open_session
from teacher.node import run_teacher

RECORDER_WAIT = 60.0  # seconds `conag teacher --recorded` waits for the recorder before it teaches


def configure(t: argparse.ArgumentParser) -> None:
    t.add_argument("--id", default="teacher", help="teacher id for its liveliness token (default teacher)")
    t.add_argument("--quiet", action="store_true", help="no progress lines")
    t.add_argument("--recorded", action="store_true",
                   help="the run is recorded: start teaching once a recorder of the world is heard (at most "
                        f"{RECORDER_WAIT:g} s), so the recording holds the first reinforcements")
    bus_args(t)


def run(args: argparse.Namespace) -> int:
    last = [""]

    def ready() -> None:
        print(f"teacher {args.id} for world {args.world_id}: reinforcing students' decisions", flush=True)

    def show(teacher, present) -> None:
        line = f"students present: {', '.join(sorted(present)) or 'none'}  {teacher.progress()}"
        if line != last[0]:
            print(line, flush=True)
            last[0] = line

    with stop_on_signals() as stop:  # before the session opens: no signal finds us unprepared
        session = open_session(bus_options(args))
        try:
            teacher = run_teacher(session, args.world_id, stop, args.id, on_ready=ready,
                                  on_progress=None if args.quiet else show,
                                  recorded=RECORDER_WAIT if args.recorded else 0.0)
        finally:
            session.close()
    print(f"final: {teacher.progress()}  bad {teacher.bad_messages}", flush=True)
    return 0
