"""The recording's cost, taken in alternating windows of the same builds (issue 34's 5% budget).

    python3 -m bench.bench_record_windows                          # nested_squares, 3 agents, 30 builds
    python3 -m bench.bench_record_windows --builds 50 --reference main   # this tree and main, builds alternating
    python3 -m bench.bench_record_windows --quick                  # one build: a smoke run, not a measurement

`bench.bench_record` pairs each build made with a recorder with the build before it, made
without one, some seconds earlier. On a machine whose speed moves by tens of percent from
one second to the next (the same loop of integer arithmetic, timed five times in a row, took
0.13 to 0.21 s of CPU) single pairs then spread from -37% to +36%, and 12 or even 40 pairs do
not tell 4% from 7%.

Here one build carries both conditions, taking turns. The recorder of a `conag run --record`
(the real `conag record` process at its default idle priority, started by the run as always)
listens to the world's keys for `--window` seconds, writing what comes as a recorder does,
then listens to none of them for `--window` seconds, so that the world and the agents send
it nothing; and so on to the end of the build. It stays subscribed all along to the world's
views (one message every 10 ticks) and its statuses, and timestamps each view as it comes:
the world's tick rate in a window is the ticks between its first and last view over the time
between them, leaving out the first `SETTLE` seconds (what the other condition left behind:
a backlog being written, routes being set up). Each window with the recorder listening is
set against the mean rate of the windows either side of it, which ran without it a few
seconds apart, on the same build: slowdown = 1 - its rate / theirs. The figure is the
median over all those pairs, with a bootstrap interval (a seeded resampling).

What a listening window holds is what a recording costs a run while it runs: the world's
and the agents' sends to one more subscriber, and the recorder's own receiving and writing.
The Foxglove channels are made when the recorder stops, after the build, as always. A window
without it still has a recorder process linked to the run, idle but for the views: the cost
of that link is not in the figure.

A build of nested_squares (complete at about 1,440 ticks) has some five windows of half a
second, two pairs; its start-up is not measured. With `--reference REV` (a git worktree of
REV, removed at the end) or `--reference-dir PATH`, the builds alternate between this tree
and that one, each side with its own code, the sides taking turns going first.

The turn-taking is a `sitecustomize` module put on the run's PYTHONPATH (`TOGGLE_SITE`): in
the recorder's process it replaces `conag.recording.recorder.run_recorder` with
`toggled_recorder` from a copy of `bench/record_toggle.py`, made of the tree's own recorder
parts; nothing in the product knows of it. Every run listens on a free port of its own.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import tempfile
import textwrap
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = "scenarios/nested_squares.toml"   # bench_record's build: 3 agents, complete at about 1,440 ticks
SETTLE = 0.15           # seconds left out at the start of each window
TOGGLE = Path(__file__).with_name("record_toggle.py")   # copied beside the sitecustomize, as conag_record_toggle
TOGGLE_SITE = textwrap.dedent('''
    """bench_record_windows: this run's recorder listens and stops listening in turns."""
    import os
    if os.environ.get("CONAG_BENCH_WINDOWS"):
        import conag.recording.recorder as recorder
        from conag_record_toggle import toggled_recorder
        recorder.run_recorder = toggled_recorder
''')


# ------------------------------------------------------------------ the figures

@dataclass(frozen=True)
class Window:
    """One window of a build: when, whether the recorder listened, and the world's rate in it
    (ticks per second between its first and last view after `SETTLE`; None with fewer than two)."""

    start: float
    end: float
    listening: bool
    rate: float | None


def window_rates(windows: list[dict], views: list[tuple[float, int]], settle: float = SETTLE) -> list[Window]:
    """Each window's tick rate from the views heard in it (see the module)."""
    out = []
    for w in windows:
        inside = [(t, tick) for t, tick in views if w["start"] + settle <= t < w["end"]]
        rate = None
        if len(inside) >= 2 and inside[-1][0] > inside[0][0]:
            rate = (inside[-1][1] - inside[0][1]) / (inside[-1][0] - inside[0][0])
        out.append(Window(w["start"], w["end"], w["listening"], rate))
    return out


def paired_slowdowns(windows: list[Window]) -> list[float]:
    """1 - rate / (mean rate of the windows either side), for each listening window with a
    rate between two windows without the recorder that have one."""
    out = []
    for before, w, after in zip(windows, windows[1:], windows[2:]):
        if w.listening and not before.listening and not after.listening and None not in (w.rate, before.rate,
                                                                                          after.rate):
            out.append(1 - w.rate / ((before.rate + after.rate) / 2))  # type: ignore[operator]
    return out


def median_interval(values: list[float], draws: int = 2000, seed: int = 34) -> tuple[float, float, float]:
    """(median, 5th and 95th percentiles of the medians of `draws` resamplings)."""
    if not values:
        raise ValueError("no pairs to take a median of")
    rng = random.Random(seed)
    medians = sorted(statistics.median(rng.choices(values, k=len(values))) for _ in range(draws))
    return statistics.median(values), medians[int(0.05 * draws)], medians[int(0.95 * draws) - 1]


# ------------------------------------------------------------------ the builds

def one_build(tree: Path, scenario: str, agents: int, ticks: int, window: float) -> list[Window]:
    """One `conag run --record` on `tree`'s code whose recorder takes turns (see the module):
    its windows."""
    from bench.record_toggle import ENV_OUT, ENV_WINDOW
    from conag.runs import free_endpoint

    with tempfile.TemporaryDirectory() as tmp:
        site, out = Path(tmp) / "site", Path(tmp) / "windows.json"
        site.mkdir()
        (site / "sitecustomize.py").write_text(TOGGLE_SITE, encoding="utf-8")
        (site / "conag_record_toggle.py").write_text(TOGGLE.read_text(encoding="utf-8"), encoding="utf-8")
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(tree)]), ENV_OUT: str(out),
               ENV_WINDOW: repr(window)}
        cmd = [sys.executable, "-m", "conag", "run", scenario, "--headless", "--quiet", "--agents", str(agents),
               "--max-ticks", str(ticks), "--stall-ticks", "0", "--record", str(Path(tmp) / "r.mcap"),
               "--listen", free_endpoint()]
        done = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True, check=False)
        if not out.exists():
            raise RuntimeError(f"{' '.join(cmd)} in {tree}: the recorder wrote no windows (exit {done.returncode}): "
                               f"{done.stderr.strip()[-400:]}")
        got = json.loads(out.read_text(encoding="utf-8"))
    return window_rates(got["windows"], [tuple(v) for v in got["views"]])


@dataclass
class Side:
    """One tree's builds so far."""

    label: str
    tree: Path
    pairs: list[float] = field(default_factory=list)
    on: list[float] = field(default_factory=list)    # rates of the windows with the recorder listening
    off: list[float] = field(default_factory=list)   # ... and without

    def add(self, ws: list[Window]) -> list[float]:
        got = paired_slowdowns(ws)
        self.pairs += got
        self.on += [w.rate for w in ws if w.listening and w.rate is not None]
        self.off += [w.rate for w in ws if not w.listening and w.rate is not None]
        return got

    def summary(self, args) -> str:
        if not self.pairs:
            return f"[{self.label}] no pairs: the builds were shorter than three windows"
        median, low, high = median_interval(self.pairs)
        return (f"[{self.label}] {args.scenario}, {args.agents} agents, {args.builds} builds (at most {args.ticks} "
                f"ticks), windows of {args.window:g} s, the recorder at its default priority: paired slowdown "
                f"**{100 * median:.1f}%** (90% of resampled medians in {100 * low:.1f} to {100 * high:.1f}%; "
                f"{len(self.pairs)} pairs, {sum(p < 0.05 for p in self.pairs)} under 5%); ticks/s without the "
                f"recorder {statistics.median(self.off):.0f} ({min(self.off):.0f}-{max(self.off):.0f}), with it "
                f"{statistics.median(self.on):.0f} ({min(self.on):.0f}-{max(self.on):.0f})")


def main(argv: list[str] | None = None) -> int:
    from bench.bench_agent_step import reference_checkout, tree_label

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=SCENARIO)
    ap.add_argument("--agents", type=int, default=3)
    ap.add_argument("--ticks", type=int, default=3000, help="ticks per build at most (--max-ticks)")
    ap.add_argument("--builds", type=int, default=30)
    ap.add_argument("--window", type=float, default=0.5, help="seconds per window")
    ap.add_argument("--reference", metavar="REV", help="also build on a git worktree of REV, builds alternating")
    ap.add_argument("--reference-dir", type=Path, metavar="PATH", help="... or on an existing checkout")
    ap.add_argument("--quick", action="store_true", help="one build: a smoke run, not a measurement")
    args = ap.parse_args(argv)
    if args.quick:
        args.builds = 1
    if args.window <= 2 * SETTLE or args.builds < 1 or args.agents < 1:
        ap.error(f"need --window > {2 * SETTLE:g}, --builds >= 1 and --agents >= 1")
    reference = args.reference_dir is not None or args.reference is not None
    with (reference_checkout(args.reference, args.reference_dir) if reference else nullcontext()) as ref:
        sides = [Side(f"this {tree_label(ROOT, 'tree')}", ROOT)]
        if ref is not None:
            sides.append(Side(f"reference {tree_label(ref, args.reference or str(ref))}", ref))
        for b in range(args.builds):
            for side in (sides if b % 2 == 0 else sides[::-1]):  # the sides take turns going first
                got = side.add(one_build(side.tree, args.scenario, args.agents, args.ticks, args.window))
                print(f"[{side.label}] build {b + 1}: {len(got)} pairs: " + ", ".join(f"{100 * p:.1f}%" for p in got),
                      file=sys.stderr, flush=True)
    for side in sides:
        print(side.summary(args))
    return 0 if all(side.pairs for side in sides) else 1


if __name__ == "__main__":
    raise SystemExit(main())
