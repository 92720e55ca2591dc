"""Where the CPU of a `conag run` goes, thread by thread, in steady state (issue 15).

    python3 -m bench.bench_cpu_split                     # scale.toml, 10 agent processes, 800 ticks
    python3 -m bench.bench_cpu_split --agents 1 --ticks 2000
    python3 -m bench.bench_cpu_split --agents 10 -- --per-process 10   # after --: more `conag run` flags

`bench/bench_scale.py` says how fast a run goes and where the *world's* tick goes. This one
says what every process of the run spends its CPU on, to find the floor of the
multi-process rate: it runs the same lockstep `conag run` (`--stall-ticks 0`), samples the
CPU time of every thread of every process of the run (Linux `/proc/PID/task/TID/stat`) at
its progress lines, and reports the CPU per tick between the first progress line at tick
`--from-tick` or later and the last one, so the start-up and the first ticks (each process
loads its compiled kernels on first use) are left out. Threads are grouped by process role
(world, agent, agents host, the `conag run` supervisor) and by thread name: `python3` is
the interpreter's main thread (the world's loop, the agent's decision step), `rx`, `tx`,
`net`, `acc`, `app` are zenoh's runtimes.

Printed: the steady rate (ticks/s), every group's CPU ms per tick, their sum, and how many
of the machine's cores the run kept busy (the sum over the wall time): a run that keeps
every core busy cannot go faster without spending less CPU per tick.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

from bench.bench_scale import SCENARIO, process_tree

ROOT = Path(__file__).resolve().parent.parent
PROGRESS = re.compile(r"^tick\s+(\d+)\s")
ROLES = ("world", "agents", "agent", "record", "view", "teacher", "run")
MIN_SPAN = 1.0   # seconds of steady span, at the least, to split


def role(cmdline: str) -> str:
    """The `conag` subcommand a process runs ("other" for anything else)."""
    words = cmdline.split()
    if "conag" in words and words.index("conag") + 1 < len(words):
        sub = words[words.index("conag") + 1]
        return sub if sub in ROLES else "other"
    return "other"


def thread_cpu(root: int) -> dict[tuple[int, int], tuple[str, str, float]]:
    """(pid, tid) -> (process role, thread name without its number, CPU seconds so far) of
    every thread of `root` and its descendants."""
    ticks_per_s = os.sysconf("SC_CLK_TCK")
    out = {}
    for pid, cmdline in process_tree(root).items():
        try:
            tids = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        for tid in tids:
            try:
                with open(f"/proc/{pid}/task/{tid}/stat", encoding="ascii", errors="replace") as f:
                    stat = f.read()
            except OSError:
                continue  # the thread ended meanwhile
            name = stat[stat.index("(") + 1:stat.rindex(")")]
            fields = stat.rsplit(")", 1)[1].split()
            out[(pid, int(tid))] = (role(cmdline), re.sub(r"-\d+$", "", name),
                                    (int(fields[11]) + int(fields[12])) / ticks_per_s)
    return out


def split(before: dict, after: dict) -> dict[tuple[str, str], float]:
    """CPU seconds by (role, thread name) between two `thread_cpu` samples (threads that
    started in between count from zero)."""
    spent: dict[tuple[str, str], float] = defaultdict(float)
    for key, (r, name, cpu) in after.items():
        spent[(r, name)] += cpu - before.get(key, (r, name, 0.0))[2]
    return dict(spent)


def measure(scenario: str, agents: int, ticks: int, from_tick: int, port: int, extra: list[str]) -> dict:
    """Run the build and return the steady span's ticks, seconds and CPU split."""
    cmd = [sys.executable, "-m", "conag", "run", scenario, "--agents", str(agents), "--max-ticks", str(ticks),
           "--stall-ticks", "0", "--headless", "--listen", f"tcp/127.0.0.1:{port}", *extra]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    first = last = None   # (tick, wall seconds, thread_cpu) at the first and the newest counted progress line
    assert proc.stdout is not None
    for line in proc.stdout:
        m = PROGRESS.match(line)
        if m and int(m.group(1)) >= from_tick:
            last = (int(m.group(1)), os.times().elapsed, thread_cpu(proc.pid))
            first = first or last
    proc.wait()
    if first is None or last is None or last[0] <= first[0]:
        raise RuntimeError(f"too few progress lines past tick {from_tick} from {' '.join(cmd)} (exit "
                           f"{proc.returncode})")
    (t0, w0, c0), (t1, w1, c1) = first, last
    if w1 - w0 < MIN_SPAN:
        # /proc counts CPU in clock ticks (10 ms): a shorter span rounds whole processes to 0.
        raise RuntimeError(f"the steady span was {t1 - t0} ticks in {w1 - w0:.2f} s, under {MIN_SPAN:g} s: "
                           "too short to split its CPU; ask for more --ticks")
    return {"ticks": t1 - t0, "seconds": w1 - w0, "split": split(c0, c1)}


def report(m: dict) -> str:
    ticks, seconds, spent = m["ticks"], m["seconds"], m["split"]
    lines = [f"steady span: {ticks} ticks in {seconds:.1f} s, {ticks / seconds:.1f} ticks/s", "",
             "| process | thread | CPU ms per tick |", "|---|---|---:|"]
    for (r, name), cpu in sorted(spent.items(), key=lambda kv: -kv[1]):
        if 1000 * cpu / ticks >= 0.01:
            lines.append(f"| {r} | {name} | {1000 * cpu / ticks:.2f} |")
    total = sum(spent.values())
    lines.append(f"| all | | {1000 * total / ticks:.2f} |")
    lines += ["", (f"wall time per tick {1000 * seconds / ticks:.2f} ms; cores kept busy {total / seconds:.2f} "
                  f"of {os.cpu_count()}")]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", default=SCENARIO)
    p.add_argument("--agents", type=int, default=10)
    p.add_argument("--ticks", type=int, default=800, help="ticks of the build (default 800)")
    p.add_argument("--from-tick", type=int, default=30,
                   help="the steady span starts at the first progress line of this tick or later (default 30)")
    p.add_argument("--port", type=int, default=17930)
    p.add_argument("run_args", nargs="*", help="after --: more `conag run` flags")
    args = p.parse_args(argv)
    if args.agents < 1 or args.ticks <= args.from_tick:
        p.error("need --agents >= 1 and --ticks > --from-tick")
    try:
        measured = measure(args.scenario, args.agents, args.ticks, args.from_tick, args.port, args.run_args)
    except RuntimeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(report(measured))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
