"""The `conag` command line: one console script, one subcommand per thing a user does.

    conag world SCENARIO      serve a world (loopback peer mode by default)
    conag status              print what a running world reports
    conag perturb OP ...      remove, add or move a disc, add or remove a drop site, in a running world
    conag render SCENARIO     draw a scenario as a bird's-eye PNG
    conag router              run a zenoh router (for several hosts)
    conag keys OUTDIR         write a secure deployment: router with access control, a credential per process
    conag agent --id ID       one agent process (--learn: a student learning from the teacher)
    conag agents --ids a1..a20  several agents in one process (each its own token and state)
    conag teacher             the teacher process: reinforces learning students (paper §5.1)
    conag run SCENARIO        a world and its agents as processes, until the structure is done
    conag generate --seed N   write seeded, buildable scenario files (or a --suite of them)
    conag check FILE...       parse scenario files and check their structure can be built
    conag record OUT.mcap     record every message of a world to an MCAP file
    conag replay FILE.mcap    publish a recording again (--verify: reproduce it with a fresh world)
    conag echo KEY_EXPR       print the decoded messages on a key

Every process that touches the bus takes --zenoh-config FILE, --connect ENDPOINT,
--listen ENDPOINT and --mode. Ctrl-C and SIGTERM stop a process cleanly.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import signal
import sys
import threading
import time
from dataclasses import asdict

from conag.common import PRIORITIES, RECORDER_PRIORITY, ignore_repeat
from conag.common import bus_args as _bus_args
from conag.common import bus_options as _bus
from conag.common import stop_on_signals as _stop_on_signals
from conag.layouts import add_commands as add_layout_commands
from conag.recording.command import add_commands as add_recording_commands
from conag.secure import add_commands as add_secure_commands
from conag.secure import check_agent_credential
from conag.viewer.command import add_commands as add_view_commands
from protocol.bus import BusOptions, Declarations, is_client, open_session
from world_server.summary import write_summary

EXIT_ERROR = 1         # something failed (conag run: e.g. the world kept dying as soon as it started)
EXIT_USAGE = 2
EXIT_INCOMPLETE = 3    # conag run: the tick limit passed before the structure was complete
EXIT_STALLED = 4       # conag run: no site was filled for --stall-ticks ticks
EXIT_INTERRUPTED = 130  # Ctrl-C or SIGTERM (128 + SIGINT, as shells report an interrupted command)
RUN_EPILOG = f"""exit codes: 0 the structure is complete; {EXIT_ERROR} an error (e.g. the world kept dying as
it started; a world that dies is otherwise restarted from its last checkpoint); {EXIT_USAGE} a usage or scenario
error; {EXIT_INCOMPLETE} not complete when the tick limit passed; {EXIT_STALLED} stalled: no site was filled for
--stall-ticks ticks (a report of every agent's position, behaviour and blocker is printed first); {EXIT_INTERRUPTED}
interrupted (Ctrl-C or SIGTERM) before the structure was complete"""
CHECKPOINT_EVERY = 100  # world_server.checkpoint.DEFAULT_EVERY, without importing it for --help
AGENT_MAP_SIZE = 41  # AgentConfig's default, without importing the agent for --help
TEACHER_RECORDER_WAIT = 60.0  # seconds `conag teacher --recorded` waits for the recorder before it teaches


def _status_line(st) -> str:
    return (f"tick {st.tick:>7}  sites {st.sites_filled}/{st.sites_total}  bricks {st.bricks_total}  "
            f"agents alive {st.agents_alive}/{len(st.agent_ids)}  bad {st.bad_messages}  seq {st.seq}"
            + ("  COMPLETE" if st.completed else ""))


def cmd_world(args) -> int:
    import numpy as np

    from world_server.checkpoint import DEFAULT_EVERY, CheckpointPlan
    from world_server.scenario import load_scenario
    from world_server.server import WorldServer
    from world_server.world import World

    plan = None
    if args.resume:
        world, every = _resumed_world(args)
        scenario = world.scenario
        path = args.checkpoint or args.resume  # a resumed world goes on checkpointing where it came from
        plan = CheckpointPlan(path, args.checkpoint_every or every or DEFAULT_EVERY)
    else:
        if args.scenario is None:
            raise ValueError("conag world needs a SCENARIO file (or --resume CHECKPOINT)")
        scenario = load_scenario(args.scenario)
        seed = scenario.seed if args.seed is None else args.seed
        world = World(scenario, np.random.default_rng(seed), world_id=args.world_id)
        if args.checkpoint:
            plan = CheckpointPlan(args.checkpoint, args.checkpoint_every or DEFAULT_EVERY)
    on_status = None if args.quiet else (lambda st: print(_status_line(st), flush=True))
    with _stop_on_signals() as stop:  # before the session opens: no signal finds us unprepared
        session = open_session(_bus(args), serve=True)
        try:
            print(f"world {world.world_id}: {scenario.name} ({scenario.cols}x{scenario.rows} cells, "
                  f"{len(world.sites_xy)} sites, {world.discs.bricks_total()} bricks), "
                  f"{args.mode_tick or scenario.tick_mode} mode"
                  + (f", resumed from {args.resume} at tick {world.tick}" if args.resume else "")
                  + (f", checkpoint every {plan.every} ticks to {plan.path}" if plan else ""), flush=True)
            if (args.mode_tick or scenario.tick_mode) == "lockstep" and not args.resume:
                print(f"lockstep: ticks start once {args.wait_agents} agent(s) have attached", flush=True)
            # Through a router, frames sent "latest wins" (DROP) were lost under load, each costing a
            # lockstep timeout and the agent's odometry of that tick (docs/results/reliability.md); lockstep waits
            # for every agent anyway, so there frames are sent BLOCK.
            block = (args.mode_tick or scenario.tick_mode) == "lockstep" and is_client(_bus(args), serve=True)
            server = WorldServer(world, session, mode=args.mode_tick, max_ticks=args.ticks,
                                 stop_when_complete=args.stop_when_complete, wait_agents=args.wait_agents,
                                 on_status=on_status, block_frames=block, checkpoint=plan,
                                 resumed=bool(args.resume), max_tick_rate=args.max_tick_rate)
            if args.stdin_control:
                from world_server.server import read_go_without_requests

                read_go_without_requests(server, sys.stdin)
            final = server.run(stop)
        finally:
            session.close()
    print("final: " + _status_line(final), flush=True)
    if args.summary:
        write_summary(final, args.summary, server.agent_states)
    if args.profile:
        with open(args.profile, "w", encoding="utf-8") as f:
            json.dump({"agents": len(final.agent_ids), **server.times.as_dict()}, f, indent=2)
    return 0


def _resumed_world(args):
    """The world of `--resume FILE` and the interval it was checkpointed at (CheckpointError
    is a ValueError: a usage error, exit 2)."""
    from world_server.checkpoint import load_state, restore_world, resumed_epoch
    from world_server.scenario import load_scenario

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


def _query(session, key: str, payload: bytes | None, timeout: float):
    replies = list(session.get(key, payload=payload, timeout=timeout))
    for r in replies:
        if r.ok is not None:
            return r.ok.payload.to_bytes(), None
        return None, r.err.payload.to_bytes().decode(errors="replace")
    return None, None


def cmd_status(args) -> int:
    from protocol import keys
    from protocol.codec import ProtocolError, decode
    from protocol.messages import WorldStatus

    shown = [None]  # the last status printed
    lock = threading.Lock()

    def show(st):
        # The query's answer and the subscription's samples can arrive in either order:
        # print a status only if it is newer than the last one printed (WorldStatus.seq).
        with lock:
            if not is_newer_status(st, shown[0]):
                return
            shown[0] = st
            print(json.dumps(asdict(st)) if args.json else _status_line(st), flush=True)

    session = open_session(_bus(args))
    try:
        deadline = time.monotonic() + args.timeout
        data = None
        while data is None and time.monotonic() < deadline:
            data, _ = _query(session, keys.status(args.world_id), None, min(1.0, args.timeout))
        if data is None:
            print(f"error: no world {args.world_id!r} answered within {args.timeout:g} s", file=sys.stderr)
            return 1
        try:
            show(decode(data, WorldStatus))
        except ProtocolError as exc:
            print(f"error: the world sent a bad status: {exc}", file=sys.stderr)
            return 1
        if args.watch:
            with _stop_on_signals() as stop:
                def on_status(sample):
                    try:
                        show(decode(sample.payload.to_bytes(), WorldStatus))
                    except ProtocolError as exc:
                        print(f"warning: ignored a bad status: {exc}", file=sys.stderr)

                with Declarations() as declared:
                    declared.add(session.declare_subscriber(keys.status(args.world_id), on_status))
                    stop.wait()
        return 0
    finally:
        session.close()


def is_newer_status(st, last) -> bool:
    """Whether status `st` is newer than `last` (None: nothing seen yet). Within one world's
    run `seq` grows by one per publication; a lower tick as well means the world was started
    again, whose statuses count from 1 anew."""
    return last is None or st.seq > last.seq or st.tick < last.tick


def non_negative(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}")
    return value


def positive(text: str) -> int:
    value = non_negative(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return value


def _point(text: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y (two numbers), got {text!r}") from None
    return x, y


def cmd_perturb(args) -> int:
    from protocol import keys
    from protocol.codec import ProtocolError, decode, encode
    from protocol.messages import Perturbation, PerturbResult

    if args.op == "move" and args.to is None:
        print("error: move needs --to X,Y", file=sys.stderr)
        return EXIT_USAGE
    to = args.to or (0.0, 0.0)
    msg = Perturbation(args.op.replace("-", "_"), args.at[0], args.at[1], args.kind, to[0], to[1], args.force)
    session = open_session(_bus(args))
    try:
        deadline = time.monotonic() + args.timeout
        data = err = None
        while data is None and err is None and time.monotonic() < deadline:
            data, err = _query(session, keys.perturb(args.world_id), encode(msg), min(1.0, args.timeout))
    finally:
        session.close()
    if err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    if data is None:
        print(f"error: no world {args.world_id!r} answered within {args.timeout:g} s", file=sys.stderr)
        return 1
    try:
        result = decode(data, PerturbResult)
    except ProtocolError as exc:
        print(f"error: bad reply: {exc}", file=sys.stderr)
        return 1
    print(f"tick {result.tick}: {result.message}")
    return 0 if result.ok else 1


def cmd_render(args) -> int:
    from world_server.render import render_scenario
    from world_server.scenario import load_scenario

    if args.agent_maps:
        from conag.sim.render_agent import render_agent_maps

        out = render_agent_maps(load_scenario(args.scenario), args.out,
                                agent=args.agent or "a1", ticks=args.ticks or 0)
    elif args.agent is not None or args.ticks is not None:
        raise ValueError("--agent and --ticks need --agent-maps")
    else:
        out = render_scenario(load_scenario(args.scenario), args.out)
    print(f"wrote {out}")
    return 0


def cmd_router(args) -> int:
    # The loopback default applies only without a config file: it must not replace the file's endpoints.
    listen = tuple(args.listen) or (() if args.zenoh_config else ("tcp/127.0.0.1:7447",))
    opts = BusOptions(args.zenoh_config, tuple(args.connect), listen, "router")
    with _stop_on_signals() as stop:
        session = open_session(opts, serve=True)
        try:
            where = ", ".join(opts.listen) or f"the endpoints in {args.zenoh_config}"
            print(f"zenoh router listening on {where}", flush=True)
            stop.wait()
        finally:
            session.close()
    return 0


class _Stopped(Exception):
    """Raised by the agent's signal handler, so a blocking frame wait ends at once."""


@contextlib.contextmanager
def _stopped_by_signal():
    """The first SIGINT/SIGTERM raises `_Stopped` where the process waits (for a frame), and
    the block ends quietly; later ones (a second Ctrl-C while closing) are let pass, so the
    cleanup finishes without a traceback. The previous handlers come back afterwards."""
    def raise_stop(_signum, _frame):
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, ignore_repeat)
        raise _Stopped()

    previous = {s: signal.signal(s, raise_stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    except _Stopped:
        pass
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def _agent_options(args):
    """The AgentOptions `conag agent` asks for (ValueError for learning flags without --learn)."""
    from agent_runtime.learning import Student
    from agent_runtime.node import AgentOptions, Learning

    if not args.learn and (args.eta is not None or args.weights_out or args.save_every is not None):
        raise ValueError("--eta, --weights-out and --save-every need --learn")
    learning = network = None
    if args.learn:
        learning = Learning(eta=0.1 if args.eta is None else args.eta, weights_in=args.weights_in,
                            weights_out=args.weights_out, save_every=args.save_every or 500)
    elif args.weights_in:
        network = Student.load(args.weights_in)  # a trained student, acting without learning
    cfg = _agent_config(args)
    return AgentOptions(args.world_id, args.id, cfg, args.seed, attach_timeout=args.attach_timeout,
                        recorded=args.recorded, learning=learning, network=network)


def cmd_agent(args) -> int:
    from agent_runtime.node import AgentReport, run_agent
    from agent_runtime.world_link import AttachError

    opts = _agent_options(args)
    check_agent_credential(args.zenoh_config, args.id)
    report = AgentReport()

    with _stopped_by_signal():
        session = open_session(_bus(args), leaf=True)
        try:
            run_agent(session, opts, report=report)
        except AttachError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        finally:
            session.close()
    if report.link is not None:
        c = report.link.counts
        saved = f"; weights saved to {opts.learning.weights_out}" if opts.learning.weights_out else ""
        print(f"agent {args.id}: {report.ticks} ticks, {c.reinforcements} reinforcements, {c.errors} errors "
              f"({c.teacher_restarts} teacher restarts, {c.gaps} gaps){saved}", flush=True)
    return 0


def cmd_agents(args) -> int:
    from agent_runtime.host import AgentHost, host_options, parse_ids, read_stop_requests
    from agent_runtime.node import AgentOptions
    from agent_runtime.world_link import AttachError

    ids = parse_ids(args.ids)
    base = AgentOptions(args.world_id, ids[0], _agent_config(args), args.seed,
                        attach_timeout=args.attach_timeout, recorded=args.recorded)

    with _stopped_by_signal():
        session = open_session(_bus(args), leaf=True)
        try:
            host = AgentHost(session, host_options(base, ids))
            try:
                if args.stdin_control:
                    read_stop_requests(host)
                host.attach()
                host.serve()
            except AttachError as exc:
                print(f"error: {exc}", file=sys.stderr)
                return 1
            finally:
                host.close()
        finally:
            session.close()
    return 0


def cmd_teacher(args) -> int:
    from teacher.node import run_teacher

    last = [""]

    def ready():
        print(f"teacher {args.id} for world {args.world_id}: reinforcing students' decisions", flush=True)

    def show(teacher, present):
        line = f"students present: {', '.join(sorted(present)) or 'none'}  {teacher.progress()}"
        if line != last[0]:
            print(line, flush=True)
            last[0] = line

    with _stop_on_signals() as stop:  # before the session opens: no signal finds us unprepared
        session = open_session(_bus(args))
        try:
            teacher = run_teacher(session, args.world_id, stop, args.id, on_ready=ready,
                                  on_progress=None if args.quiet else show,
                                  recorded=TEACHER_RECORDER_WAIT if args.recorded else 0.0)
        finally:
            session.close()
    print(f"final: {teacher.progress()}  bad {teacher.bad_messages}", flush=True)
    return 0


def cmd_run(args) -> int:
    from conag.layouts import warn_if_unbuildable
    from conag.run import RunOptions, run
    from conag.runs import check_name, endpoint_in_use, free_endpoint, register, unregister
    from world_server.scenario import load_scenario

    _agent_config(args)  # a bad size, preset or addition is a usage error here, not in every agent
    if not args.learn and (args.eta is not None or args.weights_dir):
        raise ValueError("--eta and --weights-dir need --learn")
    if args.per_process < 1 or (args.per_process > 1 and (args.learn or args.secure is not None)):
        raise ValueError("--per-process must be >= 1, and 1 for learning agents (each saves its own weights) "
                         "and on a secure bus (each agent has its own credential)")
    learn_args = ("--learn", "--eta", str(0.1 if args.eta is None else args.eta)) if args.learn else ()
    scenario = load_scenario(args.scenario)
    if args.name is not None:
        check_name(args.name)
    if args.listen and endpoint_in_use(args.listen[0]):
        raise ValueError(f"{args.listen[0]} is in use (another world or `conag run` listens there): choose "
                         "another --listen, or leave it out for a free one")
    endpoint = args.listen[0] if args.listen else free_endpoint()
    unbuildable = warn_if_unbuildable(args.scenario, scenario, args.agents)  # a repair experiment may want it
    opts = RunOptions(scenario_path=args.scenario, scenario=scenario, endpoint=endpoint, world_id=args.world_id,
                      agents=args.agents, seed=args.seed, max_ticks=args.max_ticks, summary=args.summary,
                      headless=args.headless, quiet=args.quiet,
                      extra_agent_args=("--map-size", str(args.map_size), *learn_args,
                                        *(("--nearest-first",) if args.nearest_first else ()),
                                        "--agent", args.agent, *(("--without", args.without) if args.without else ())),
                      teacher=args.teacher, weights_dir=args.weights_dir, stall_ticks=args.stall_ticks,
                      unbuildable=unbuildable,
                      record=args.record, record_priority=args.record_priority, view=args.view,
                      maps_every=args.maps_every, secure=args.secure,
                      checkpoint_every=args.checkpoint_every or CHECKPOINT_EVERY, profile=args.profile,
                      per_process=args.per_process, agent_mode=args.agent_mode)
    entry = register(args.name or scenario.name, endpoint, args.world_id, scenario.name, exact=args.name is not None)
    if not args.quiet:
        print(f"run {entry.name}: world {args.world_id} on {endpoint} (conag status --run {entry.name})", flush=True)
    with _stop_on_signals() as stop:
        _report_a_slow_stop(stop)
        try:
            summary = run(opts, stop)
        except RuntimeError as exc:  # a process of the run failed (the world died, the recorder did)
            print(f"\nerror: {exc}", file=sys.stderr)
            return EXIT_INTERRUPTED if stop.is_set() else EXIT_ERROR
        finally:
            unregister(entry)
    interrupted = stop.is_set() and not summary["completed"]
    state = ("complete" if summary["completed"] else "STALLED" if summary["stalled"]
             else "INTERRUPTED" if interrupted else "NOT complete")
    print(f"{summary['scenario']}: {state}: {summary['sites_filled']}/{summary['sites_total']} sites in "
          f"{summary['ticks']} ticks, {len(summary['agents'])} agents, total distance "
          f"{summary['total_distance']:.1f}", flush=True)
    if args.record:
        print(f"recording written to {args.record}")
        from conag.recording.mcap_log import read_end, world_cut_short

        short = world_cut_short(read_end(args.record), summary["ticks"])
        if short:
            print(f"warning: the recording {short}", file=sys.stderr, flush=True)
    if args.summary == "-":
        print(json.dumps(summary, indent=2))
    elif args.summary:
        print(f"summary written to {args.summary}")
    if summary["completed"]:
        return 0
    return EXIT_STALLED if summary["stalled"] else EXIT_INTERRUPTED if interrupted else EXIT_INCOMPLETE


SLOW_STOP = 60.0   # seconds after Ctrl-C / SIGTERM past which `conag run` shows where it waits


def _report_a_slow_stop(stop: threading.Event, after: float = SLOW_STOP) -> None:
    """Once `stop` is set, print every thread's stack to stderr if the process is still
    alive `after` seconds later. Stopping a run is bounded (each process gets its grace,
    then SIGKILL), yet CI saw `conag run` still there 120 s after two Ctrl-Cs, with no
    trace: the second signal's handler waited for ever on the Event's lock, which the first
    held (fixed in `conag.common.stop_on_signals`), and this thread, waiting on the same
    Event, never woke. So it polls the flag, which takes no lock. A daemon thread also
    fires while the interpreter waits for other threads at exit."""
    import faulthandler

    def watch() -> None:
        while not stop.is_set():
            time.sleep(0.5)
        time.sleep(after)
        print(f"conag run: still stopping {after:g} s after the signal; where each thread waits:",
              file=sys.stderr, flush=True)
        faulthandler.dump_traceback(file=sys.stderr, all_threads=True)

    threading.Thread(target=watch, name="slow-stop-report", daemon=True).start()


def cmd_control(args) -> int:
    from conag.run import control

    session = open_session(_bus(args))
    try:
        result = control(session, args.world_id, args.command, args.id, args.timeout)
    finally:
        session.close()
    print(result.message, file=sys.stdout if result.ok else sys.stderr)
    return 0 if result.ok else 1


def _agent_kind_args(p) -> None:
    p.add_argument("--agent", default="default", metavar="PRESET",
                   help="which agent: default (the best agent) or paper (the agent as the paper describes it, "
                        "every switchable addition off); see docs/design.md")
    p.add_argument("--without", metavar="NAMES",
                   help="switch these additions off, comma separated (e.g. unstick,seal_guard; "
                        "agent_runtime.config.ADDITIONS names them all)")


def _agent_config(args):
    """The AgentConfig the agent flags ask for (ValueError names what is wrong)."""
    from agent_runtime.config import ADDITIONS, AgentConfig

    off = [n.strip() for n in (args.without or "").split(",") if n.strip()]
    unknown = [n for n in off if n not in ADDITIONS]
    if unknown:
        raise ValueError(f"--without: unknown addition(s) {', '.join(unknown)}; known: {', '.join(ADDITIONS)}")
    return AgentConfig.preset(args.agent, map_size=args.map_size, goal_sequencing=not args.nearest_first,
                              **dict.fromkeys(off, False))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="conag", description="ConAg: agents that build structures from a blueprint.")
    p.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in (_add_world, _add_status, _add_perturb, _add_agent, _add_agents, _add_teacher, _add_run,
                _add_control, _add_render, add_layout_commands, add_recording_commands, add_view_commands,
                _add_router, add_secure_commands):
        add(sub)  # add_layout_commands: generate, check; add_recording_commands: record, replay, echo; keys
    for command in sub.choices.values():  # -v also after the subcommand: `conag world X -v`
        command.add_argument("-v", "--verbose", dest="verbose_after", action="count", default=0,
                             help="more log output (-vv for debug); also accepted before the subcommand")
    return p


def _add_world(sub) -> None:
    w = sub.add_parser("world", help="serve a world from a scenario file")
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
    w.add_argument("--max-tick-rate", type=float, metavar="HZ",
                   help="lockstep: step at most HZ ticks per wall second (default: as fast as the agents answer)")
    c = w.add_argument_group("checkpoints (the world survives its own death)")
    c.add_argument("--checkpoint", metavar="FILE",
                   help="write the whole world to FILE every --checkpoint-every ticks and when stopped (SIGTERM); "
                        "atomic, the one before kept as FILE.prev")
    c.add_argument("--checkpoint-every", type=positive, metavar="N",
                   help=f"ticks between checkpoints (default {CHECKPOINT_EVERY}; with --resume, the checkpoint's own, "
                        "so the resumed world steps exactly as one that never stopped)")
    c.add_argument("--resume", metavar="FILE",
                   help="continue the world saved in checkpoint FILE from its tick (and go on checkpointing to FILE "
                        "unless --checkpoint says otherwise); a truncated or corrupt FILE is refused")
    _bus_args(w)
    w.set_defaults(func=cmd_world)


def _add_status(sub) -> None:
    s = sub.add_parser("status", help="print what a running world reports")
    s.add_argument("--watch", action="store_true", help="keep printing each status update")
    s.add_argument("--json", action="store_true", help="print the status as JSON")
    s.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the world")
    _bus_args(s, find_run=True)
    s.set_defaults(func=cmd_status)


def _add_perturb(sub) -> None:
    q = sub.add_parser("perturb", help="remove, add or move a disc, add or remove a drop site, in a running world")
    q.add_argument("op", choices=("remove", "add", "move", "add-site", "remove-site"),
                   help="add-site: the cell holding --at becomes a drop site; remove-site: its site leaves "
                        "the blueprint (a brick on it stays, a free brick now)")
    q.add_argument("--at", type=_point, required=True, metavar="X,Y", help="world position (cell centres are at .5)")
    q.add_argument("--to", type=_point, metavar="X,Y", help="target position for move")
    q.add_argument("--kind", choices=("food", "water", "brick"), default="brick", help="kind for add")
    q.add_argument("--force", action="store_true",
                   help="add even in a drop site's cell (a brick there fills the site) or onto an agent's body")
    q.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the world")
    _bus_args(q, find_run=True)
    q.set_defaults(func=cmd_perturb)


def _attach_args(a) -> None:
    """How `conag agent` and `conag agents` attach."""
    a.add_argument("--attach-timeout", type=float, default=30.0, help="seconds to wait for the world")
    a.add_argument("--recorded", action="store_true",
                   help="the run is recorded: attach once a recorder of the world is heard (at most --attach-timeout "
                        "seconds), so the recording holds this agent's messages from its first tick")


def _add_agent(sub) -> None:
    a = sub.add_parser("agent", help="run one agent process")
    a.add_argument("--id", required=True, help="agent id; a restarted process with the same id gets its body back")
    a.add_argument("--seed", type=int, default=0, help="seed of the agent's own randomness (exploring)")
    _attach_args(a)
    a.add_argument("--map-size", type=int, default=AGENT_MAP_SIZE, metavar="N",
                   help=f"cells per side of the agent's maps, odd (default {AGENT_MAP_SIZE})")
    a.add_argument("--nearest-first", action="store_true",
                   help="no goal sequencing: always the nearest brick and site (the plain agent of paper §4)")
    _agent_kind_args(a)
    g = a.add_argument_group("learning (paper §5.1)")
    g.add_argument("--learn", action="store_true",
                   help="be a student: random construction weights (from --seed) learned from the teacher")
    g.add_argument("--eta", type=float, metavar="RATE", help="learning rate of the delta rule (default 0.1)")
    g.add_argument("--weights-in", metavar="FILE",
                   help="start from these weights (without --learn: act on them, learning nothing)")
    g.add_argument("--weights-out", metavar="FILE", help="save the weights here periodically and on exit")
    g.add_argument("--save-every", type=int, metavar="TICKS", help="ticks between saves (default 500)")
    _bus_args(a)
    a.set_defaults(func=cmd_agent)


def _add_agents(sub) -> None:
    a = sub.add_parser("agents", help="run several agents in one process (each its own token, body and state)",
                       description="Several agents in one process: the interpreter and the compiled kernels are "
                                   "loaded once (less memory, quicker start-up); the agents take turns on one "
                                   "core, and a crash of the process takes them all. A line `stop ID` on stdin "
                                   "(with --stdin-control) stops one agent alone.")
    a.add_argument("--ids", required=True, metavar="IDS", help="agent ids: ranges and commas, e.g. a1..a20 or a1,a3")
    a.add_argument("--seed", type=int, default=0, help="seed of every agent's own randomness (as conag agent)")
    _attach_args(a)
    a.add_argument("--map-size", type=int, default=AGENT_MAP_SIZE, metavar="N",
                   help=f"cells per side of the agents' maps, odd (default {AGENT_MAP_SIZE})")
    a.add_argument("--nearest-first", action="store_true", help="no goal sequencing (as conag agent)")
    _agent_kind_args(a)
    a.add_argument("--stdin-control", action="store_true",
                   help="read `stop ID` lines on stdin: stop that agent alone (conag run uses it for conag kill)")
    _bus_args(a)
    a.set_defaults(func=cmd_agents)


def _add_teacher(sub) -> None:
    t = sub.add_parser("teacher", help="run the teacher: reinforce learning students (paper §5.1)")
    t.add_argument("--id", default="teacher", help="teacher id for its liveliness token (default teacher)")
    t.add_argument("--quiet", action="store_true", help="no progress lines")
    t.add_argument("--recorded", action="store_true",
                   help="the run is recorded: start teaching once a recorder of the world is heard (at most "
                        f"{TEACHER_RECORDER_WAIT:g} s), so the recording holds the first reinforcements")
    _bus_args(t)
    t.set_defaults(func=cmd_teacher)


def _add_run(sub) -> None:
    u = sub.add_parser("run", help="build a scenario: a world and its agents as processes, until done",
                       epilog=RUN_EPILOG)
    u.add_argument("scenario")
    u.add_argument("--agents", type=int, help="number of agents (default: the scenario's)")
    u.add_argument("--seed", type=int, help="override the scenario's seed")
    u.add_argument("--max-ticks", type=int, help="stop after this many ticks (default: the scenario's)")
    u.add_argument("--stall-ticks", type=non_negative, default=3000, metavar="N",
                   help="stop as stalled when no site has been filled for N ticks (default 3000; 0: never)")
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
    u.add_argument("--view", nargs="?", type=int, const=8765, metavar="PORT",
                   help="watch the run in the browser: starts `conag view` on PORT (default 8765)")
    u.add_argument("--maps-every", type=non_negative, default=0, metavar="N",
                   help="the agents publish their maps every N ticks for --record (default 0: off); for --view, "
                        "the shown agent at most every N (default: conag view's), about once a second")
    u.add_argument("--checkpoint-every", type=positive, metavar="N",
                   help=f"the world checkpoints every N ticks (default {CHECKPOINT_EVERY}); when its process dies "
                        "the run restarts it from the last checkpoint and the agents attach again")
    u.add_argument("--map-size", type=int, default=AGENT_MAP_SIZE, metavar="N",
                   help=f"cells per side of every agent's maps, odd (default {AGENT_MAP_SIZE})")
    u.add_argument("--per-process", type=int, default=1, metavar="K",
                   help="host up to K agents in each agent process (conag agents): less memory and a quicker "
                        "start-up for large teams; a crash of a host takes its K agents (default 1)")
    u.add_argument("--agent-mode", choices=("auto", "peer", "client"), default="auto",
                   help="zenoh mode of the agent processes: peers reach each other directly (a full mesh), "
                        "clients only the world, which routes for them; auto: peers up to 32 agent processes, "
                        "clients beyond (default auto)")
    u.add_argument("--profile", metavar="PATH", help="the world writes where its loop's time went (conag world "
                                                     "--profile)")
    u.add_argument("--nearest-first", action="store_true",
                   help="agents without goal sequencing (paper §4), for comparison with ConAg-TS (§6)")
    _agent_kind_args(u)
    g = u.add_argument_group("learning (paper §5.1)")
    g.add_argument("--teacher", action="store_true", help="start a teacher process too")
    g.add_argument("--learn", action="store_true", help="agents are students with random weights (conag agent --learn)")
    g.add_argument("--eta", type=float, metavar="RATE", help="their learning rate (default 0.1)")
    g.add_argument("--weights-dir", metavar="DIR", help="each student saves its weights to DIR/<id>.json")
    u.set_defaults(func=cmd_run)


def _add_control(sub) -> None:
    for name, text in (("kill", "SIGKILL one agent process of a running `conag run`"),
                       ("restart", "kill and start again one agent process of a running `conag run`")):
        k = sub.add_parser(name, help=text)
        k.add_argument("id", help="agent id, e.g. a2")
        k.add_argument("--timeout", type=float, default=5.0)
        _bus_args(k, find_run=True)
        k.set_defaults(func=cmd_control)


def _add_render(sub) -> None:
    r = sub.add_parser("render", help="draw a scenario as a bird's-eye PNG")
    r.add_argument("scenario")
    r.add_argument("--out", default="world.png", help="output PNG path")
    r.add_argument("--agent-maps", action="store_true",
                   help="run the scenario in-process and draw one agent's ESMs and NMs beside the world")
    r.add_argument("--agent", metavar="ID", help="agent for --agent-maps (default a1)")
    r.add_argument("--ticks", type=int, metavar="N", help="lockstep ticks to run first (default 0)")
    r.set_defaults(func=cmd_render)


def _add_router(sub) -> None:
    z = sub.add_parser("router", help="run a zenoh router for several hosts")
    z.add_argument("--zenoh-config", metavar="FILE")
    z.add_argument("--listen", action="append", default=[], metavar="ENDPOINT")
    z.add_argument("--connect", action="append", default=[], metavar="ENDPOINT")
    z.set_defaults(func=cmd_router)


def log_level(args) -> int:
    """WARNING; INFO with one -v (rejected input, lockstep waits); DEBUG with two. The -v's
    before and after the subcommand add up."""
    return [logging.WARNING, logging.INFO, logging.DEBUG][min(args.verbose + args.verbose_after, 2)]


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    level = log_level(args)
    logging.basicConfig(level=level, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    from world_server.scenario import ScenarioError

    try:
        if getattr(args, "find_run", False) and not getattr(args, "file", None):  # (conag view FILE: no bus)
            from conag.runs import apply_run

            apply_run(args)
        return args.func(args)
    except (ScenarioError, FileNotFoundError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:  # Ctrl-C outside a command's own handling (starting up, a last print)
        return EXIT_INTERRUPTED
