"""`conag check FILE...`: parse scenario files and check their structure can be built (exit 1
if any cannot)."""

from __future__ import annotations

import argparse

from world_server.buildability import check_buildable
from world_server.scenario import ScenarioError, load_scenario


def configure(c: argparse.ArgumentParser) -> None:
    c.add_argument("files", nargs="+", metavar="FILE")


def run(args: argparse.Namespace) -> int:
    bad = 0
    for name in args.files:
        try:
            scenario = load_scenario(name)
        except (ScenarioError, OSError) as exc:
            print(f"{name}: invalid: {exc}")
            bad += 1
            continue
        verdict = check_buildable(scenario)
        if verdict.ok:
            print(f"{name}: OK ({len(verdict.order)} open sites, a fill order exists)")
        else:
            print(f"{name}: NOT buildable: {verdict.reason}")
            bad += 1
    return 1 if bad else 0
