"""The `conag` command line: one console script, a table of subcommands, one module each.

    conag world SCENARIO      serve a world (loopback peer mode by default)
    conag status              print what a running world reports
    conag perturb OP ...      remove, add or move a disc, add or remove a drop site, in a running world
    conag agent --id ID       one agent process (--learn: a student learning from the teacher)
    conag agents --ids a1..a20  several agents in one process (each its own token and state)
    conag teacher             the teacher process: reinforces learning students (paper §5.1)
    conag run SCENARIO        a world and its agents as processes, until the structure is done
    conag kill ID / restart ID  kill (and start again) one agent process of a `conag run`
    conag render SCENARIO     draw a scenario as a bird's-eye PNG
    conag generate --seed N   write seeded, buildable scenario files (or a --suite of them)
    conag check FILE...       parse scenario files and check their structure can be built
    conag record OUT.mcap     record every message of a world to an MCAP file
    conag replay FILE.mcap    publish a recording again (--verify: reproduce it with a fresh world)
    conag echo KEY_EXPR       print the decoded messages on a key
    conag view [FILE.mcap]    watch a world, or a recording, in the browser
    conag router              run a zenoh router (for several hosts)
    conag keys OUTDIR         write a secure deployment: router with access control, a credential per process

`COMMANDS` maps each name to its module under `conag.commands` (which says what a module
holds) and its one-line help. A module is imported only when its subcommand is parsed or
its help is printed, so `conag --help` loads none of them.

Every process that touches the bus takes --zenoh-config FILE, --connect ENDPOINT,
--listen ENDPOINT and --mode. Ctrl-C and SIGTERM stop a process cleanly.
"""

from __future__ import annotations

import argparse
import faulthandler
import importlib
import logging
import signal
import sys
from dataclasses import dataclass
from types import ModuleType

from conag.exit_codes import EXIT_INTERRUPTED, EXIT_USAGE
from conag.runs import apply_run


@dataclass(frozen=True)
class Command:
    """A subcommand: the module with its `configure` and `run`, and its line in `conag --help`."""

    module: str
    help: str


COMMANDS: dict[str, Command] = {
    "world": Command("conag.commands.world", "serve a world from a scenario file"),
    "status": Command("conag.commands.status", "print what a running world reports"),
    "perturb": Command("conag.commands.perturb",
                       "remove, add or move a disc, add or remove a drop site, in a running world"),
    "agent": Command("conag.commands.agent", "run one agent process"),
    "agents": Command("conag.commands.agents",
                      "run several agents in one process (each its own token, body and state)"),
    "teacher": Command("conag.commands.teacher", "run the teacher: reinforce learning students (paper §5.1)"),
    "run": Command("conag.commands.run", "build a scenario: a world and its agents as processes, until done"),
    "kill": Command("conag.commands.control", "SIGKILL one agent process of a running `conag run`"),
    "restart": Command("conag.commands.control", "kill and start again one agent process of a running `conag run`"),
    "render": Command("conag.commands.render", "draw a scenario as a bird's-eye PNG"),
    "generate": Command("conag.commands.generate", "write seeded, buildable scenario files (one, or a --suite)"),
    "check": Command("conag.commands.check",
                     "parse scenario files and check that their structure can be built"),
    "record": Command("conag.commands.record",
                      "record every message of a world to an MCAP file, until Ctrl-C or SIGTERM"),
    "replay": Command("conag.commands.replay", "publish a recording again (or --verify it against a fresh world)"),
    "echo": Command("conag.commands.echo", "print the decoded messages on a key expression"),
    "view": Command("conag.commands.view", "watch a world (or a recording) in the browser"),
    "router": Command("conag.commands.router", "run a zenoh router for several hosts"),
    "keys": Command("conag.commands.keys",
                    "write a secure deployment: a router with access control and one credential per process"),
}


class CommandParser(argparse.ArgumentParser):
    """A subcommand's parser, filled in by its module's `configure` the first time it parses
    or prints its help."""

    def __init__(self, *args, module: str = "", **kwargs):
        super().__init__(*args, **kwargs)
        self._module = module
        self._configured = False

    def command(self) -> ModuleType:
        """The subcommand's module, its flags added to this parser."""
        module = importlib.import_module(self._module)
        if not self._configured:
            self._configured = True
            module.configure(self)
            # -v also after the subcommand: `conag world X -v`
            self.add_argument("-v", "--verbose", dest="verbose_after", action="count", default=0,
                              help="more log output (-vv for debug); also accepted before the subcommand")
            self.set_defaults(func=module.run)
        return module

    def parse_known_args(self, args=None, namespace=None):
        self.command()
        return super().parse_known_args(args, namespace)

    def format_help(self) -> str:
        self.command()
        return super().format_help()

    def format_usage(self) -> str:
        self.command()
        return super().format_usage()


def build_parser() -> argparse.ArgumentParser:
    """The `conag` parser: every subcommand of `COMMANDS`, each configured when first used."""
    p = argparse.ArgumentParser(prog="conag", description="ConAg: agents that build structures from a blueprint.")
    p.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=CommandParser)
    for name, command in COMMANDS.items():
        sub.add_parser(name, help=command.help, module=command.module)
    return p


def log_level(args: argparse.Namespace) -> int:
    """WARNING; INFO with one -v (rejected input, lockstep waits); DEBUG with two. The -v's
    before and after the subcommand add up."""
    return [logging.WARNING, logging.INFO, logging.DEBUG][min(args.verbose + args.verbose_after, 2)]


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    # SIGUSR1 prints every thread's stack to stderr and the process goes on: where a
    # process that does not stop, or seems stuck, is waiting (a test that times out asks).
    if hasattr(signal, "SIGUSR1"):
        try:
            faulthandler.register(signal.SIGUSR1, all_threads=True)
        except ValueError:   # (io.UnsupportedOperation) stderr is no file: main() called under a capture
            pass
    logging.basicConfig(level=log_level(args), format="%(asctime)s %(name)s %(levelname)s %(message)s")
    try:
        offline = getattr(args, "file", None) or getattr(args, "translate", None)  # view FILE, record --translate
        if getattr(args, "find_run", False) and not offline:  # (those use no bus)
            apply_run(args)
        return args.func(args)
    except (FileNotFoundError, ValueError) as exc:  # a ScenarioError is a ValueError
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:  # Ctrl-C outside a command's own handling (starting up, a last print)
        return EXIT_INTERRUPTED
