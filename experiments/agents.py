"""The agent an experiment builds with: `--agent PRESET` and `--without NAMES`, as `conag run` takes them.

`add_arguments` adds the two flags; `chosen(ap, args)` checks them (a bad name is a usage
error) and gives an `Agent`: the preset and the additions switched off, which a job can
carry to a worker (`config` makes the AgentConfig there) and which names the result files
(`suffix`) and table rows (`label`).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any

from agent_runtime.config import AgentConfig
from conag.agent_settings import AgentSettings, add_kind_args, split_names


@dataclass(frozen=True)
class Agent:
    """A preset and the additions switched off from it."""

    preset: str = "default"
    without: tuple[str, ...] = ()

    def config(self, **settings: Any) -> AgentConfig:
        """The AgentConfig, with `settings` (e.g. goal_sequencing, hunger_rate) on top."""
        return AgentConfig.preset(self.preset, **dict.fromkeys(self.without, False), **settings)

    @property
    def label(self) -> str:
        """"paper", "paper -ghost_association": as a table row names it."""
        return " ".join([self.preset, *(f"-{name}" for name in self.without)])

    @property
    def suffix(self) -> str:
        """"" for the default agent, else "_paper", "_paper-ghost_association": for file names."""
        if self == Agent("default"):
            return ""
        return "_" + "-".join([self.preset, *self.without])


DEFAULT = Agent()


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """--agent PRESET and --without NAMES (`conag run`'s)."""
    add_kind_args(ap)


def chosen(ap: argparse.ArgumentParser, args: argparse.Namespace) -> Agent:
    """The agent the flags ask for; `ap.error` (exit 2) names a bad preset or addition."""
    agent = Agent(args.agent, split_names(args.without))
    try:
        AgentSettings(preset=agent.preset, without=agent.without).config()
    except ValueError as exc:
        ap.error(str(exc))
    return agent
