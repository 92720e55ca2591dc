"""`conag run SCENARIO`: a world and its agents as processes, until the structure is done.

This module reads the flags into a typed `conag.run.RunOptions` (the agents' settings an
`AgentSettings`), registers the run by name and reports how it ended; `conag.run` starts and
supervises the processes.
"""

from __future__ import annotations

import argparse
import faulthandler
import json
import sys
import threading
import time

from conag import run as supervisor
from conag.agent_settings import AgentSettings, add_correction_args, add_kind_args
from conag.argtypes import non_negative, positive, positive_float
from conag.common import PRIORITIES, RECORDER_PRIORITY, stop_on_signals
from conag.exit_codes import EXIT_ERROR, EXIT_INCOMPLETE, EXIT_INTERRUPTED, EXIT_STALLED, EXIT_USAGE
from conag.foxglove.live import DEFAULT_PORT as FOXGLOVE_PORT
from conag.noise_flags import add_noise_args, noise_settings
from conag.recording.gaps import describe_lost, lost_ticks
from conag.recording.mcap_log import read_end, world_cut_short
from conag.run import RunOptions
from conag.runs import check_name, endpoint_in_use, free_endpoint, register, unregister
from conag.sim.society import DEFAULT_CUE_REACH
from conag.viewer.server import DEFAULT_PORT
from world_server.buildability import check_layout
from world_server.checkpoint import DEFAULT_EVERY
from world_server.scenario import Scenario, load_scenario
from world_server.stall import DEFAULT_STALL_TICKS

EPILOG = f"""exit codes: 0 the structure is complete; {EXIT_ERROR} an error (e.g. the world kept dying as
it started; a world that dies is otherwise restarted from its last checkpoint); {EXIT_USAGE} a usage or scenario
error; {EXIT_INCOMPLETE} not complete when the tick limit passed; {EXIT_STALLED} stalled: no site was filled for
--stall-ticks ticks (a report of every agent's position, behaviour and blocker is printed first); {EXIT_INTERRUPTED}
interrupted (Ctrl-C or SIGTERM) before the structure was complete"""
SLOW_STOP = 60.0   # seconds after Ctrl-C / SIGTERM past which `conag run` shows where it waits


def configure(u: argparse.ArgumentParser) -> None:
    u.epilog = EPILOG
    u.add_argument("scenario")
    u.add_argument("--agents", type=int, help="number of agents (default: the scenario's)")
    s = u.add_argument_group("a society of foremen and workers (docs/society.md)")
    s.add_argument("--foremen", type=non_negative, default=0, metavar="F",
                   help="instead of ConAg agents, F foremen (f1..fF: ConAg agents that mark cues for workers) ...")
    s.add_argument("--workers", type=non_negative, default=0, metavar="W",
                   help="... and W reactive workers (w1..wW: no maps, they follow the cues); the world gets cues")
    s.add_argument("--cue-reach", type=positive_float, default=DEFAULT_CUE_REACH, metavar="R",
                   help=f"how far (world units) a body marks, in a society's world (default {DEFAULT_CUE_REACH:g})")
    u.add_argument("--seed", type=int, help="override the scenario's seed")
    u.add_argument("--max-ticks", type=int, help="stop after this many ticks (default: the scenario's)")
    u.add_argument("--max-tick-rate", type=positive_float, metavar="HZ",
                   help="lockstep: step at most HZ ticks per wall second, to watch a run or to give an operator "
                        "time to act on it (default: as fast as the agents answer)")
    u.add_argument("--stall-ticks", type=non_negative, default=DEFAULT_STALL_TICKS, metavar="N",
                   help=f"stop as stalled when no site has been filled for N ticks (default {DEFAULT_STALL_TICKS}; "
                        "0: never)")
    u.add_argument("--summary", metavar="PATH", help="write the run summary (JSON); - prints it")
    u.add_argument("--headless", action="store_true", help="plain progress lines, no terminal tricks")
    u.add_argument("--quiet", action="store_true", help="no progress lines")
    u.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                   help="where the world listens (default: a free loopback port of its own, so that runs on one "
                        "machine never meet; the other verbs find the run by --run NAME)")
    u.add_argument("--name", help="the run's name, for --run of status, kill, restart, perturb, record, view and "
                                  "echo (default: the scenario's name, with -2, -3... while a run going has it)")
    u.add_argument("--world-id", default="w0")
    u.add_argument("--secure", nargs="?", const="", metavar="DIR",
                   help="a secure bus: a zenoh router with access control on the --listen endpoint, every "
                        "process its own credential (from DIR, written by `conag keys`; fresh ones without DIR)")
    u.add_argument("--record", metavar="OUT.mcap",
                   help="record every message of the run to an MCAP file (conag record; see conag replay)")
    u.add_argument("--record-priority", choices=PRIORITIES, default=RECORDER_PRIORITY,
                   help=f"the recorder's CPU priority, so the run gets the CPU first (default {RECORDER_PRIORITY}; "
                        "see conag record --priority)")
    u.add_argument("--view", nargs="?", type=int, const=DEFAULT_PORT, metavar="PORT",
                   help=f"watch the run in the browser: starts `conag view` on PORT (default {DEFAULT_PORT})")
    u.add_argument("--foxglove", nargs="?", type=int, const=FOXGLOVE_PORT, metavar="PORT",
                   help=f"watch the run in Foxglove or Lichtblick: starts `conag view --foxglove` on PORT (default "
                        f"{FOXGLOVE_PORT}), a Foxglove WebSocket server (docs/how-to/foxglove.md)")
    u.add_argument("--maps-every", type=non_negative, default=0, metavar="N",
                   help="the agents publish their maps every N ticks for --record (default 0: off); for --view, "
                        "the shown agent at most every N (default: conag view's), about once a second")
    u.add_argument("--checkpoint-every", type=positive, default=DEFAULT_EVERY, metavar="N",
                   help=f"the world checkpoints every N ticks (default {DEFAULT_EVERY}); when its process dies "
                        "the run restarts it from the last checkpoint and the agents attach again")
    u.add_argument("--map-size", type=int, default=AgentSettings.map_size, metavar="N",
                   help=f"cells per side of every agent's maps, odd (default {AgentSettings.map_size})")
    u.add_argument("--per-process", type=int, default=1, metavar="K",
                   help="host up to K agents in each agent process (conag agents): less memory and a quicker "
                        "start-up for large teams; a crash of a host takes its K agents (default 1)")
    u.add_argument("--attach-timeout", type=positive_float, metavar="S",
                   help="seconds each agent waits for the world to answer its attach before it gives up "
                        "(default: 30, or 2 per agent process if more); a host whose agent gives up exits with "
                        "all its agents, so give a crowd on a busy machine longer")
    u.add_argument("--no-fork-server", dest="fork_server", action="store_false",
                   help="start every single agent process as a fresh interpreter; by default they are forks of a "
                        "server that has loaded the agent's modules and kernels once (quicker to start, and "
                        "sharing that memory; conag/forkserver.py)")
    u.add_argument("--agent-mode", choices=("auto", "peer", "client"), default="auto",
                   help="zenoh mode of the agent processes: peers reach each other directly (a full mesh), "
                        "clients only the world, which routes for them; auto: peers up to 32 agent processes, "
                        "clients beyond (default auto)")
    u.add_argument("--profile", metavar="PATH", help="the world writes where its loop's time went (conag world "
                                                     "--profile)")
    u.add_argument("--nearest-first", action="store_true",
                   help="agents without goal sequencing (paper §4), for comparison with ConAg-TS (§6)")
    add_kind_args(u)
    add_correction_args(u)
    add_noise_args(u)
    g = u.add_argument_group("learning (paper §5.1)")
    g.add_argument("--teacher", action="store_true", help="start a teacher process too")
    g.add_argument("--learn", action="store_true", help="agents are students with random weights (conag agent --learn)")
    g.add_argument("--eta", type=float, metavar="RATE", help=f"their learning rate (default {AgentSettings.eta:g})")
    g.add_argument("--weights-dir", metavar="DIR", help="each student saves its weights to DIR/<id>.json")


def run(args: argparse.Namespace) -> int:
    opts = run_options(args)
    entry = register(args.name or opts.scenario.name, opts.endpoint, opts.world_id, opts.scenario.name,
                     exact=args.name is not None)
    if not opts.quiet:
        print(f"run {entry.name}: world {opts.world_id} on {opts.endpoint} (conag status --run {entry.name})",
              flush=True)
    with stop_on_signals() as stop:
        report_a_slow_stop(stop)
        try:
            summary = supervisor.run(opts, stop)  # (tests replace conag.run.run)
        except RuntimeError as exc:  # a process of the run failed (the world died, the recorder did)
            print(f"\nerror: {exc}", file=sys.stderr)
            return EXIT_INTERRUPTED if stop.is_set() else EXIT_ERROR
        finally:
            unregister(entry)
    return _report(opts, summary, interrupted=stop.is_set() and not summary["completed"])


def run_options(args: argparse.Namespace) -> RunOptions:
    """The run the flags ask for (ValueError for flags that do not go together)."""
    agent = AgentSettings.from_args(args)
    agent.config()  # a bad size, preset or addition is a usage error here, not in every agent
    if not args.learn and (args.eta is not None or args.weights_dir):
        raise ValueError("--eta and --weights-dir need --learn")
    if args.per_process < 1 or (args.per_process > 1 and (args.learn or args.secure is not None)):
        raise ValueError("--per-process must be >= 1, and 1 for learning agents (each saves its own weights) "
                         "and on a secure bus (each agent has its own credential)")
    society = args.foremen + args.workers > 0
    if society and (args.agents is not None or args.learn or args.teacher or args.per_process > 1
                    or args.secure is not None):
        raise ValueError("--foremen and --workers make the run's agents: they do not go with --agents, --learn, "
                         "--teacher, --per-process or --secure")
    noise = noise_settings(args)
    scenario = noise.apply(load_scenario(args.scenario))
    if args.name is not None:
        check_name(args.name)
    if args.listen and endpoint_in_use(args.listen[0]):
        raise ValueError(f"{args.listen[0]} is in use (another world or `conag run` listens there): choose "
                         "another --listen, or leave it out for a free one")
    endpoint = args.listen[0] if args.listen else free_endpoint()
    agents = args.foremen + args.workers if society else args.agents
    unbuildable = warn_if_unbuildable(args.scenario, scenario, agents)  # a repair experiment may want it
    return RunOptions(scenario_path=args.scenario, scenario=scenario, endpoint=endpoint, world_id=args.world_id,
                      agents=args.agents, seed=args.seed, max_ticks=args.max_ticks, summary=args.summary,
                      max_tick_rate=args.max_tick_rate,
                      headless=args.headless, quiet=args.quiet, agent=agent,
                      teacher=args.teacher, weights_dir=args.weights_dir, stall_ticks=args.stall_ticks,
                      unbuildable=unbuildable, record=args.record, record_priority=args.record_priority,
                      view=args.view, foxglove=args.foxglove, maps_every=args.maps_every, secure=args.secure,
                      checkpoint_every=args.checkpoint_every, profile=args.profile,
                      per_process=args.per_process, agent_mode=args.agent_mode, noise=noise,
                      attach_timeout=args.attach_timeout,
                      fork_server=args.fork_server, foremen=args.foremen, workers=args.workers,
                      cue_reach=args.cue_reach)


def warn_if_unbuildable(path: str, scenario: Scenario, agents: int | None = None) -> str:
    """`conag run` still runs an unbuildable scenario (a repair experiment may want one),
    but says so first. Returns why it cannot be built ("" if it can), for the stall report."""
    verdict = check_layout(scenario.layout, scenario.agents if agents is None else agents)
    if not verdict.ok:
        print(f"warning: {path} cannot be built: {verdict.reason}", file=sys.stderr, flush=True)
    return verdict.reason


def _report(opts: RunOptions, summary: dict, interrupted: bool) -> int:
    """Print how the run ended (and where its recording and summary went); its exit code."""
    state = ("complete" if summary["completed"] else "STALLED" if summary["stalled"]
             else "INTERRUPTED" if interrupted else "NOT complete")
    print(f"{summary['scenario']}: {state}: {summary['sites_filled']}/{summary['sites_total']} sites in "
          f"{summary['ticks']} ticks, {len(summary['agents'])} agents, total distance "
          f"{summary['total_distance']:.1f}", flush=True)
    if opts.record:
        print(f"recording written to {opts.record}")
        end = read_end(opts.record)
        for short in (describe_lost(lost_ticks(end)), world_cut_short(end, summary["ticks"])):
            if short:
                print(f"warning: the recording {short}", file=sys.stderr, flush=True)
    if opts.summary == "-":
        print(json.dumps(summary, indent=2))
    elif opts.summary:
        print(f"summary written to {opts.summary}")
    if summary["completed"]:
        return 0
    return EXIT_STALLED if summary["stalled"] else EXIT_INTERRUPTED if interrupted else EXIT_INCOMPLETE


def report_a_slow_stop(stop: threading.Event, after: float = SLOW_STOP) -> None:
    """Once `stop` is set, print every thread's stack to stderr if the process is still
    alive `after` seconds later. Stopping a run is bounded (each process gets its grace,
    then SIGKILL), yet CI saw `conag run` still there 120 s after two Ctrl-Cs, with no
    trace: the second signal's handler waited for ever on the Event's lock, which the first
    held (fixed in `conag.common.stop_on_signals`), and this thread, waiting on the same
    Event, never woke. So it polls the flag, which takes no lock. A daemon thread also
    fires while the interpreter waits for other threads at exit."""
    def watch() -> None:
        while not stop.is_set():
            time.sleep(0.5)
        time.sleep(after)
        print(f"conag run: still stopping {after:g} s after the signal; where each thread waits:",
              file=sys.stderr, flush=True)
        faulthandler.dump_traceback(file=sys.stderr, all_threads=True)

    threading.Thread(target=watch, name="slow-stop-report", daemon=True).start()
