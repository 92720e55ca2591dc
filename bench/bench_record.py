"""Recording overhead: the same lockstep `conag run` with and without `--record`.

    python3 -m bench.bench_record                      # nested_squares, 3 agents, 5 repetitions of each
    python3 -m bench.bench_record --scenario scenarios/fig6.toml --reps 3
    python3 -m bench.bench_record --main-job           # also: the size of a recording of the README's main job
    python3 -m bench.bench_record --record-priority normal,low,idle   # the recorder's priorities side by side
    python3 -m bench.bench_record --reps 12 --reference main          # this tree and main, side by side

Each repetition runs `conag run SCENARIO --agents N --max-ticks T` as a subprocess,
alternating without and with `--record` (so a slow spell of a shared machine hits both),
and times the build itself: from the first progress line of tick >= 1 to the last one
(process start-up and numba loading are left out). The default build (nested squares,
three agents, complete at about 1,550 ticks) lasts several seconds; fig6 completes in
about 300 ticks, a second, too short to time. Two figures per run:

* ticks per second of the build (what the 5% budget is about);
* CPU seconds per 1,000 ticks of every process of the run, and of the recorder alone,
  over the same span: the steadier figure on a shared machine, since the run is
  CPU-bound (its processes outnumber the cores) and the wall rate follows the CPU it needs.

With `--reference REV` (a detached git worktree of REV, removed at the end) or
`--reference-dir PATH` (an existing checkout), every repetition also runs the same builds on
the reference tree, right before or after this tree's (the two sides take turns going
first), each side with its own code: two trees' costs measured on the same machine state.
Every figure is printed per side. The recorded builds whose idle recorder starved and was
raised to the normal priority (`conag.recording.recorder.PriorityGuard`) are counted.

With `--record-priority P,Q,...` each repetition records once per CPU priority of the
recorder (`conag run --record-priority`: normal, low, idle; default: only the default,
idle), so the priorities can be compared in one run. Prints the medians and the slowdowns; the
recordings' sizes too.

Two slowdowns are printed. The *paired* one is the median over repetitions of each recorded
build's rate against the unrecorded build run just before it: a machine whose speed drifts
during the run (seen here: 169 -> 228 ticks/s over 12 repetitions) moves both builds of a pair
alike, while it moves the two medians of the unpaired figure apart. `--warmup` (default 1)
first runs unrecorded builds that are not counted: on a fresh machine the first build loads
and caches the compiled kernels (seen here: 97 ticks/s and twice the CPU of the next).
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path

from bench.bench_agent_step import reference_checkout, tree_label
from conag.common import PRIORITIES, RECORDER_PRIORITY

ROOT = Path(__file__).resolve().parent.parent
LINE = re.compile(r"^tick\s+(\d+)\s")


class BuildClock:
    """The build's tick rate from `conag run`'s progress lines: from the first line of tick
    >= `start_tick` (1: process start-up and numba loading left out) to the last one seen."""

    def __init__(self, start_tick: int = 1) -> None:
        self.start_tick = max(start_tick, 1)
        self.first: tuple[int, float] | None = None
        self.last: tuple[int, float] | None = None

    def observe(self, line: str) -> bool:
        """Take one output line; True if it was a progress line of tick >= `start_tick`."""
        m = LINE.match(line)
        if not m or int(m.group(1)) < self.start_tick:
            return False
        self.last = (int(m.group(1)), time.monotonic())
        self.first = self.first or self.last
        return True

    def rate(self, cmd: list[str]) -> tuple[float, float]:
        """(ticks per second, wall seconds) of the build; RuntimeError if it never progressed."""
        if self.first is None or self.last is None or self.last[0] <= self.first[0]:
            raise RuntimeError(f"no progress lines from {' '.join(cmd)}")
        seconds = self.last[1] - self.first[1]
        return (self.last[0] - self.first[0]) / seconds, seconds


def _proc_table() -> dict[int, tuple[int, float, str]]:
    """pid -> (parent pid, CPU seconds so far, command line) of every process (Linux /proc)."""
    table = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
                with open(f"/proc/{entry}/cmdline", "rb") as f:
                    cmdline = f.read().replace(b"\0", b" ").decode(errors="replace")
            except OSError:
                continue
            cpu = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
            table[int(entry)] = (int(fields[1]), cpu, cmdline)
    return table


def tree_cpu(pid: int, only: str | None = None) -> float:
    """CPU seconds used so far by process `pid` and its live descendants (Linux /proc);
    with `only`, just those whose command line holds that text."""
    table = _proc_table()
    total, todo = 0.0, [pid]
    while todo:
        p = todo.pop()
        if p in table and (only is None or only in table[p][2]):
            total += table[p][1]
        todo += [c for c, (ppid, _, _) in table.items() if ppid == p]
    return total


@dataclass(frozen=True)
class RunFigures:
    rate: float             # ticks per second of the build
    cpu_per_kilotick: float  # CPU seconds of all the run's processes per 1,000 ticks of the build
    recorder_per_kilotick: float  # of the recorder alone
    size: int               # bytes of the recording, or 0
    raised: bool = False    # its idle recorder starved and ran at the normal priority from then on


RAISED = "runs at the normal priority from now on"  # the recorder's warning when PriorityGuard raised it


def one_run(scenario: str, agents: int | None, ticks: int, record: Path | None, port: int,
            priority: str = RECORDER_PRIORITY, tree: Path = ROOT) -> RunFigures:
    """Run one build of the checkout `tree` and time it (see the module)."""
    cmd = [sys.executable, "-m", "conag", "run", scenario, "--headless", "--max-ticks", str(ticks),
           "--stall-ticks", "0", "--listen", f"tcp/127.0.0.1:{port}"]
    if agents is not None:
        cmd += ["--agents", str(agents)]
    if record is not None:
        cmd += ["--record", str(record), "--record-priority", priority]
    env = {**os.environ, "PYTHONPATH": str(tree)}  # every process of the run imports this tree's code
    with tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen(cmd, cwd=tree, env=env, stdout=subprocess.PIPE, stderr=err, text=True)
        clock = BuildClock()
        cpu: list[tuple[float, float]] = []   # (all, recorder) at the first and the newest progress line
        for line in proc.stdout:
            if clock.observe(line):
                now = (tree_cpu(proc.pid), tree_cpu(proc.pid, only="conag record"))
                cpu = [cpu[0] if cpu else now, now]
        proc.wait()
        err.seek(0)
        stderr = err.read()
    sys.stderr.write(stderr)
    rate, _ = clock.rate(cmd)
    assert clock.first is not None and clock.last is not None
    kiloticks = (clock.last[0] - clock.first[0]) / 1000
    return RunFigures(rate, (cpu[1][0] - cpu[0][0]) / kiloticks, (cpu[1][1] - cpu[0][1]) / kiloticks,
                      record.stat().st_size if record is not None and record.exists() else 0, RAISED in stderr)


def slowdown(without: float, with_: float) -> float:
    """How much slower a rate `with_` something is than `without` it; a fraction."""
    return 1 - with_ / without


def paired_slowdown(plain: list[float], recorded: list[float]) -> float:
    """The median over repetitions of the slowdown of each recorded build's rate against the
    plain build of its own repetition (see the module)."""
    if not plain or len(plain) != len(recorded):
        raise ValueError(f"need one plain build per recorded one, got {len(plain)} and {len(recorded)}")
    return statistics.median(slowdown(a, b) for a, b in zip(plain, recorded, strict=True))


def _priorities(text: str) -> list[str]:
    values = text.split(",")
    bad = [v for v in values if v not in PRIORITIES]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown priority {bad[0]!r}: expected some of {', '.join(PRIORITIES)}")
    return values


def _summary(label: str, args, plain: list[RunFigures], recorded: dict[str, list[RunFigures]]) -> None:
    def median(runs: list[RunFigures], field: str) -> float:
        return statistics.median(getattr(r, field) for r in runs)

    a, ca = median(plain, "rate"), median(plain, "cpu_per_kilotick")
    for priority, runs in recorded.items():
        b, cb = median(runs, "rate"), median(runs, "cpu_per_kilotick")
        pairs = sorted(100 * slowdown(p.rate, r.rate) for p, r in zip(plain, runs, strict=True))
        print(f"{label}{args.scenario}, {args.agents or 'its'} agents, {args.reps} repetitions, recorder at "
              f"priority {priority}: paired slowdown "
              f"{100 * paired_slowdown([r.rate for r in plain], [r.rate for r in runs]):.1f}% "
              f"(pairs {', '.join(f'{x:.1f}' for x in pairs)}); "
              f"median {a:.0f} ticks/s without, {b:.0f} with recording: "
              f"unpaired slowdown {100 * slowdown(a, b):.1f}% "
              f"(ranges {min(r.rate for r in plain):.0f}-{max(r.rate for r in plain):.0f} and "
              f"{min(r.rate for r in runs):.0f}-{max(r.rate for r in runs):.0f}); CPU per 1000 ticks "
              f"{ca:.2f} s without, {cb:.2f} s with (+{100 * (cb - ca) / ca:.1f}%), the recorder "
              f"{median(runs, 'recorder_per_kilotick'):.2f} s; recorders raised to normal: "
              f"{sum(r.raised for r in runs)} of {len(runs)}", flush=True)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", default="scenarios/nested_squares.toml")
    p.add_argument("--agents", type=int, default=3, help="agents (default 3; 0: the scenario's)")
    p.add_argument("--ticks", type=int, default=3000, help="tick limit of each build (it stops when complete)")
    p.add_argument("--reps", type=int, default=5)
    p.add_argument("--warmup", type=int, default=1,
                   help="unrecorded builds run first and not counted (kernel caches; default 1)")
    p.add_argument("--port", type=int, default=17601)
    p.add_argument("--record-priority", type=_priorities, default=[RECORDER_PRIORITY], metavar="P,P,...",
                   help=f"the recorder's priorities to compare, of {', '.join(PRIORITIES)} "
                        f"(default {RECORDER_PRIORITY})")
    p.add_argument("--main-job", action="store_true",
                   help="also record the README's main job (fig6 until complete) and print the file's size")
    p.add_argument("--reference", metavar="REV",
                   help="also run every repetition on a git worktree of REV (e.g. main), side by side")
    p.add_argument("--reference-dir", type=Path, metavar="PATH",
                   help="also run every repetition on this existing checkout, side by side")
    args = p.parse_args(argv)
    agents = args.agents or None
    reference = args.reference_dir is not None or args.reference is not None
    with (reference_checkout(args.reference, args.reference_dir) if reference else nullcontext()) as ref, \
            tempfile.TemporaryDirectory() as tmp:
        trees = {"": ROOT} if ref is None else {
            f"[this {tree_label(ROOT, 'this')}] ": ROOT,
            f"[reference {tree_label(ref, args.reference or str(ref))}] ": ref}
        plain: dict[str, list[RunFigures]] = {side: [] for side in trees}
        recorded = {side: {n: [] for n in args.record_priority} for side in trees}
        for side, tree in trees.items():
            for n in range(args.warmup):
                w = one_run(args.scenario, agents, args.ticks, None, args.port, tree=tree)
                print(f"{side}warm-up {n + 1}: {w.rate:.0f} ticks/s, not counted", flush=True)
        for rep in range(args.reps):
            order = list(trees.items())
            for side, tree in order[rep % len(order):] + order[:rep % len(order)]:  # sides take turns going first
                plain[side].append(one_run(args.scenario, agents, args.ticks, None, args.port, tree=tree))
                a = plain[side][-1]
                for priority, runs in recorded[side].items():
                    out = Path(tmp) / f"r{rep}-{priority}-{len(runs)}.mcap"
                    runs.append(one_run(args.scenario, agents, args.ticks, out, args.port, priority, tree=tree))
                    b = runs[-1]
                    out.unlink(missing_ok=True)
                    print(f"{side}rep {rep + 1}: {a.rate:.0f} ticks/s without, {b.rate:.0f} with recording "
                          f"at priority {priority} ({100 * slowdown(a.rate, b.rate):+.1f}%, {b.size / 1e6:.2f} MB"
                          f"{', recorder raised to normal' if b.raised else ''}); CPU s per 1000 ticks "
                          f"{a.cpu_per_kilotick:.2f} without, {b.cpu_per_kilotick:.2f} with "
                          f"(recorder {b.recorder_per_kilotick:.2f})", flush=True)
        for side in trees:
            _summary(side, args, plain[side], recorded[side])
        if args.main_job:
            out = Path(tmp) / "main.mcap"
            t0 = time.monotonic()
            run = subprocess.run([sys.executable, "-m", "conag", "run", "scenarios/fig6.toml", "--headless",
                                  "--quiet", "--record", str(out), "--listen", f"tcp/127.0.0.1:{args.port}"],
                                 cwd=ROOT, capture_output=True, text=True, check=False)  # exit 3: not complete
            print(f"main job (fig6 until complete) with --record: {run.stdout.strip().splitlines()[0]}; "
                  f"{out.stat().st_size / 1e6:.2f} MB in {time.monotonic() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
