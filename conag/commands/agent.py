"""`conag agent --id ID`: one agent process (--learn: a student learning from the teacher)."""

from __future__ import annotations

import argparse
import sys

from agent_runtime.learning import Student
from agent_runtime.node import ROLES, AgentOptions, AgentReport, Learning, run_agent
from agent_runtime.world_link import AttachError
from conag.agent_settings import AgentSettings, add_attach_args, add_correction_args, add_kind_args
from conag.common import bus_args, bus_options, stopped_by_signal
from conag.secure import check_agent_credential
from protocol.bus import open_session


def configure(a: argparse.ArgumentParser) -> None:
    a.add_argument("--id", required=True, help="agent id; a restarted process with the same id gets its body back")
    a.add_argument("--seed", type=int, default=0, help="seed of the agent's own randomness (exploring)")
    add_attach_args(a)
    a.add_argument("--map-size", type=int, default=AgentSettings.map_size, metavar="N",
                   help=f"cells per side of the agent's maps, odd (default {AgentSettings.map_size})")
    a.add_argument("--nearest-first", action="store_true",
                   help="no goal sequencing: always the nearest brick and site (the plain agent of paper §4)")
    a.add_argument("--role", choices=ROLES, default="agent",
                   help="agent: a ConAg agent (default); foreman: a ConAg agent that also marks cues for workers; "
                        "worker: a reactive worker without maps that follows cues (docs/society.md)")
    add_kind_args(a)
    add_correction_args(a)
    g = a.add_argument_group("learning (paper §5.1)")
    g.add_argument("--learn", action="store_true",
                   help="be a student: random construction weights (from --seed) learned from the teacher")
    g.add_argument("--eta", type=float, metavar="RATE",
                   help=f"learning rate of the delta rule (default {Learning.eta:g})")
    g.add_argument("--weights-in", metavar="FILE",
                   help="start from these weights (without --learn: act on them, learning nothing)")
    g.add_argument("--weights-out", metavar="FILE", help="save the weights here periodically and on exit")
    g.add_argument("--save-every", type=int, metavar="TICKS",
                   help=f"ticks between saves (default {Learning.save_every})")
    bus_args(a)


def agent_options(args: argparse.Namespace) -> AgentOptions:
    """The AgentOptions the flags ask for (ValueError for learning flags without --learn)."""
    if not args.learn and (args.eta is not None or args.weights_out or args.save_every is not None):
        raise ValueError("--eta, --weights-out and --save-every need --learn")
    settings = AgentSettings.from_args(args)
    learning = network = None
    if settings.learn:
        learning = Learning(eta=settings.eta, weights_in=args.weights_in, weights_out=args.weights_out,
                            save_every=args.save_every or Learning.save_every)
    elif args.weights_in:
        network = Student.load(args.weights_in)  # a trained student, acting without learning
    return AgentOptions(args.world_id, args.id, settings.config(), args.seed, attach_timeout=args.attach_timeout,
                        recorded=args.recorded, learning=learning, network=network, role=args.role)


def run(args: argparse.Namespace) -> int:
    opts = agent_options(args)
    check_agent_credential(args.zenoh_config, args.id)
    report = AgentReport()

    with stopped_by_signal():
        session = open_session(bus_options(args), leaf=True)
        try:
            run_agent(session, opts, report=report)
        except AttachError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        finally:
            session.close()
    if report.link is not None:
        c = report.link.counts
        saved = f"; weights saved to {opts.learning.weights_out}" if opts.learning and opts.learning.weights_out else ""
        print(f"agent {args.id}: {report.ticks} ticks, {c.reinforcements} reinforcements, {c.errors} errors "
              f"({c.teacher_restarts} teacher restarts, {c.gaps} gaps){saved}", flush=True)
    return 0
