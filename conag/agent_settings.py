"""What an agent process is asked to be: the typed form of `conag agent`'s agent flags.

`conag agent`, `conag agents` and `conag run` read the same flags (--agent, --without,
--with, --map-size, --nearest-first; --learn and --eta) into one `AgentSettings`, and the first two
attach alike (`add_attach_args`). `conag run` checks
them once and hands them, typed, to the supervisor (`conag.run.RunOptions.agent`), which
starts the agent processes; `AgentSettings.argv` is the one place they become command-line
flags again, at that process boundary.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

from agent_runtime.config import ADDITIONS, CORRECTIONS, OFF_BY_DEFAULT, AgentConfig
from agent_runtime.node import Learning

# What --with switches on: the corrections for noisy worlds and the additions the default agent
# leaves off; what --without switches off: the additions, and the corrections.
SWITCH_ON = CORRECTIONS + OFF_BY_DEFAULT
SWITCH_OFF = ADDITIONS + CORRECTIONS


@dataclass(frozen=True)
class AgentSettings:
    """An agent's kind (preset, additions switched off, map size, goal sequencing) and
    whether it is a learning student, at which rate."""

    preset: str = "default"
    without: tuple[str, ...] = ()     # additions and corrections switched off (SWITCH_OFF)
    with_: tuple[str, ...] = ()       # corrections and off-by-default additions switched on (SWITCH_ON)
    map_size: int = AgentConfig.map_size
    nearest_first: bool = False       # no goal sequencing (paper §4)
    learn: bool = False               # a student with random weights, learning from the teacher
    eta: float = Learning.eta         # the student's learning rate

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> AgentSettings:
        """The settings parsed flags ask for (`--learn`, `--eta`: False and the default where
        a subcommand has no such flag)."""
        learn = getattr(args, "learn", False)
        eta = getattr(args, "eta", None)
        return cls(preset=args.agent, without=split_names(args.without),
                   with_=split_names(getattr(args, "with_", None)), map_size=args.map_size,
                   nearest_first=args.nearest_first, learn=learn, eta=Learning.eta if eta is None else eta)

    def config(self) -> AgentConfig:
        """The AgentConfig these settings describe (ValueError names what is wrong)."""
        unknown = [n for n in self.without if n not in SWITCH_OFF]
        if unknown:
            raise ValueError(f"--without: unknown name(s) {', '.join(unknown)}; known: {', '.join(SWITCH_OFF)}")
        wrong = [n for n in self.with_ if n not in SWITCH_ON]
        if wrong:
            raise ValueError(f"--with: unknown name(s) {', '.join(wrong)}; known: {', '.join(SWITCH_ON)}")
        return AgentConfig.preset(self.preset, map_size=self.map_size, goal_sequencing=not self.nearest_first,
                                  **dict.fromkeys(self.without, False), **dict.fromkeys(self.with_, True))

    def describe(self) -> dict:
        """Which agent these settings run, as the run summary records it: the preset, the
        additions switched off and other settings changed (`AgentConfig.describe`), and,
        for a learning student, `learn` and `eta`."""
        out = self.config().describe(self.preset)
        if self.learn:
            out.update(learn=True, eta=self.eta)
        return out

    def argv(self) -> list[str]:
        """The `conag agent` / `conag agents` flags that ask for these settings."""
        flags = ["--map-size", str(self.map_size)]
        if self.learn:
            flags += ["--learn", "--eta", str(self.eta)]
        if self.nearest_first:
            flags.append("--nearest-first")
        flags += ["--agent", self.preset]
        if self.without:
            flags += ["--without", ",".join(self.without)]
        if self.with_:
            flags += ["--with", ",".join(self.with_)]
        return flags


def split_names(text: str | None) -> tuple[str, ...]:
    """`--without a,b` as names, blanks dropped."""
    return tuple(n.strip() for n in (text or "").split(",") if n.strip())


def add_kind_args(p: argparse.ArgumentParser) -> None:
    """--agent and --without, as `conag agent`, `conag agents` and `conag run` take them."""
    p.add_argument("--agent", default="default", metavar="PRESET",
                   help="which agent: default (the best agent) or paper (the agent as the paper describes it, "
                        "every addition off but ghost association); see docs/design.md")
    p.add_argument("--without", metavar="NAMES",
                   help="switch these additions off, comma separated (e.g. unstick,seal_guard; "
                        "agent_runtime.config.ADDITIONS names them all), or a correction on by default "
                        "(occlusion_clearing)")


def add_correction_args(p: argparse.ArgumentParser) -> None:
    """--with, as `conag agent`, `conag agents` and `conag run` take it."""
    p.add_argument("--with", dest="with_", metavar="NAMES",
                   help="switch these on, comma separated: corrections for noisy worlds (anchor_maps: keep the "
                        "maps anchored to structure bricks and the world's edge; docs/noise.md) and the additions "
                        "for big teams the default agent leaves off (yield_goals, idle_wait, spread_search; "
                        "docs/design.md)")


def add_attach_args(a: argparse.ArgumentParser) -> None:
    """How `conag agent` and `conag agents` attach."""
    a.add_argument("--attach-timeout", type=float, default=30.0, help="seconds to wait for the world")
    a.add_argument("--recorded", action="store_true",
                   help="the run is recorded: attach once a recorder of the world is heard (at most --attach-timeout "
                        "seconds), so the recording holds this agent's messages from its first tick")
