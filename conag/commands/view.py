"""`conag view`: the browser viewer, of a live world or of a recording.

    conag view [--port P]               serve http://127.0.0.1:P/ showing the world on the bus, live
    conag view FILE.mcap [--port P]     the same page over a recording, with a timeline to scrub and play
    conag view --foxglove [PORT]        serve the live world to Foxglove or Lichtblick instead (ws://127.0.0.1:PORT)

The shell is conag/viewer/server.py, the pure part conag/viewer/; with --foxglove,
conag/foxglove/live.py. `conag run --view` (`--foxglove`) starts `conag view` (`--foxglove`) beside the run.
"""

from __future__ import annotations

import argparse
import sys
import webbrowser

from conag.common import PRIORITIES, bus_args, bus_options, lower_priority, restore_priority, stop_on_signals
from conag.foxglove.live import DEFAULT_PORT as FOXGLOVE_PORT
from conag.foxglove.live import serve_foxglove
from conag.recording.mcap_log import read_recording
from conag.viewer.scene import DISPLAY_HZ, Timeline, wanted
from conag.viewer.server import DEFAULT_PORT, serve_live, serve_timeline
from protocol.bus import open_session

VIEWER_PRIORITY = "low"  # not "idle", as the recorder: on a machine the run fills, the page would freeze


def configure(v: argparse.ArgumentParser) -> None:
    v.add_argument("file", nargs="?", metavar="FILE.mcap", help="a recording to open instead of the live world")
    v.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"HTTP port (default {DEFAULT_PORT}; 0: any free)")
    v.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1: this machine only)")
    v.add_argument("--open", action="store_true", help="open the page in the default browser")
    v.add_argument("--maps-every", type=int, default=10, metavar="N",
                   help="live: ask the agent shown in the page's panel for its maps at most every N ticks "
                        "(default 10; 0: off); on a faster run, less often: about once a second, as the page "
                        "shows them")
    v.add_argument("--display-hz", type=_display_hz, default=DISPLAY_HZ, metavar="HZ",
                   help=f"live: send the page at most HZ pictures a second (default {DISPLAY_HZ:g}; each costs the "
                        "browser a frame, which a browser on the run's own cores takes from the run: "
                        "docs/results/benchmarks.md)")
    v.add_argument("--priority", choices=PRIORITIES, default=VIEWER_PRIORITY,
                   help=f"live: the viewer's CPU priority, so a run on the same cores gets the CPU first "
                        f"(default {VIEWER_PRIORITY}: nice +10; idle: only when a core would idle; normal)")
    v.add_argument("--foxglove", nargs="?", type=int, const=FOXGLOVE_PORT, metavar="PORT",
                   help="live: serve the world's Foxglove channels over the Foxglove WebSocket protocol on PORT "
                        f"(default {FOXGLOVE_PORT}; 0: any free) instead of the page, for Foxglove or Lichtblick "
                        "(docs/how-to/foxglove.md); a recording opens in them as it is")
    bus_args(v, find_run=True)  # live only: a recording needs no bus


def _display_hz(text: str) -> float:
    try:
        hz = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of pictures a second, got {text!r}") from None
    if not 0.2 <= hz <= 60:
        raise argparse.ArgumentTypeError(f"{hz:g} pictures a second is out of range (0.2 to 60)")
    return hz


def run(args: argparse.Namespace) -> int:
    if args.foxglove is not None:
        return _serve_foxglove(args)

    def ready(url: str) -> None:
        print(f"viewer at {url}", flush=True)
        if args.open:
            webbrowser.open(url)

    # Stopped, it leaves at the normal priority: idle, it could wait long for a core (as the recorder).
    with stop_on_signals(on_stop=lambda: restore_priority(args.priority)) as stop:
        if args.file:
            timeline = load_timeline(args.file)
            print(f"{args.file}: {len(timeline)} pictures, ticks {timeline.summary()['first']}-"
                  f"{timeline.summary()['last']}", flush=True)
            serve_timeline(timeline, stop, host=args.host, port=args.port, on_ready=ready)
            return 0
        lower_priority(args.priority)  # before the session opens, so zenoh's threads have it too
        session = open_session(bus_options(args))
        try:
            serve_live(session, args.world_id, stop, host=args.host, port=args.port, on_ready=ready,
                       maps_every=max(args.maps_every, 0), display_hz=args.display_hz)
        finally:
            session.close()
    return 0


def _serve_foxglove(args: argparse.Namespace) -> int:
    """`conag view --foxglove`: the live world over the Foxglove WebSocket protocol."""
    if args.file:
        raise ValueError(f"--foxglove serves a live world; open {args.file} in Foxglove or Lichtblick as it is")
    with stop_on_signals(on_stop=lambda: restore_priority(args.priority)) as stop:
        lower_priority(args.priority)  # before the session opens, so zenoh's threads have it too
        session = open_session(bus_options(args))
        try:
            serve_foxglove(session, args.world_id, stop, host=args.host, port=args.foxglove,
                           display_hz=args.display_hz, maps_every=max(args.maps_every, 0),
                           on_ready=lambda url: print(f"foxglove at {url}", flush=True))
        finally:
            session.close()
    return 0


def load_timeline(path: str) -> Timeline:
    """A recording's Timeline (only the keys the viewer draws are read)."""
    rec = read_recording(path, keep=wanted)
    if not rec.complete:
        print(f"warning: {path}: {rec.problem}", file=sys.stderr)
    info = {k: v for k, v in rec.info.items() if k in ("scenario_path", "scenario_name", "seed", "world_id",
                                                       "conag_version", "tick_mode")}
    return Timeline.from_entries(rec.entries, info)
