"""Recordings on a busy machine: how many lose data, and does any lose it silently (issue 35).

    python3 -m bench.bench_record_load                     # 18 recorded builds beside 6 busy loops, 2 at a time
    python3 -m bench.bench_record_load --runs 6 --json load.json

Every process it starts runs at the normal priority (`chrt -o 0`), whatever priority this
script was started at: `--load` busy loops (a Python `while True` each) for the whole
measurement, and `--runs` recorded builds, `--parallel` at a time: `conag run SCENARIO
--agents N --max-ticks T --record R.mcap` (its recorder at its own default priority, idle,
unless `--record-priority` says otherwise). On the 2-core machine six busy loops leave an
idle-priority recorder almost no CPU: once, 6 of 18 such recordings lacked ticks.

Per recording it finds from the file itself (`lost_data`):

* the world's ticks from 0 to the run's last of which it holds no frame (in lockstep the
  world sends every live agent a frame at every tick it steps);
* the commands it lacks: (agent, tick) whose frames of that tick and the next it holds,
  with neither the agent's command of that tick nor a LockstepTimeout naming the agent;

and whether that was said: the recording's `lost_ticks` (its closing metadata) or a
`warning: the recording` line of `conag run`. A recording that lacks data and says
nothing lost it silently. It also counts the recorders that starved and went on at the
normal priority (their warning in the run's output).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from conag.recording.gaps import format_gaps, lost_ticks
from conag.recording.mcap_log import read_end, read_recording
from protocol.codec import ProtocolError, decode
from protocol.messages import AgentCommand, LockstepTimeout, SensorFrame

ROOT = Path(__file__).resolve().parent.parent
NORMAL = ["chrt", "-o", "0"]   # the normal policy (SCHED_OTHER), nice as it is
RAISED = "runs at the normal priority from now on"   # the recorder's warning when it starved


@dataclass(frozen=True)
class Loss:
    """What one recording lacks (see the module)."""

    ticks: tuple[tuple[int, int], ...]   # the world's ticks without any frame, as (first, last) ranges
    commands: int                        # (agent, tick) commands it lacks

    @property
    def any(self) -> bool:
        return bool(self.ticks) or self.commands > 0


def lost_data(path: Path, final_tick: int) -> Loss:
    """The world's ticks 0..`final_tick` and the commands a recording lacks (see the module)."""
    frames: set[tuple[int, str]] = set()
    taken: set[tuple[int, str]] = set()
    for e in read_recording(path).entries:
        leaf = e.key.rsplit("/", 1)[-1]
        try:
            if leaf == "sensors":
                f = decode(e.data, SensorFrame)
                frames.add((f.tick, f.agent_id))
            elif leaf == "command":
                c = decode(e.data, AgentCommand)
                taken.add((c.tick, c.agent_id))
            elif leaf == "lockstep_timeout":
                t = decode(e.data, LockstepTimeout)
                taken.update((t.tick, a) for a in t.agent_ids)
        except ProtocolError:
            continue
    ticks = {t for t, _ in frames}
    missing = [t for t in range(final_tick + 1) if t not in ticks]
    commands = sum(1 for t, a in frames if t < final_tick and (t + 1, a) in frames and (t, a) not in taken)
    return Loss(_ranges(missing), commands)


def _ranges(ticks: list[int]) -> tuple[tuple[int, int], ...]:
    out: list[tuple[int, int]] = []
    for t in sorted(ticks):
        if out and t == out[-1][1] + 1:
            out[-1] = (out[-1][0], t)
        else:
            out.append((t, t))
    return tuple(out)


@dataclass(frozen=True)
class Outcome:
    """One recorded build: what the recording lacks, what was said, how it ran."""

    run: int
    exit_code: int
    final_tick: int
    lost_ticks: str          # the world's ticks without a frame (the measurement)
    lost_commands: int
    reported: str            # the recording's own `lost_ticks`
    warned: bool             # `conag run` printed a warning about the recording
    raised: bool             # its recorder starved and went on at the normal priority
    seconds: float

    @property
    def lost(self) -> bool:
        return bool(self.lost_ticks) or self.lost_commands > 0

    @property
    def silent(self) -> bool:
        return self.lost and not (self.reported or self.warned)


def _policy(args: argparse.Namespace) -> list[str]:
    return [] if args.inherit else NORMAL


def start_build(args: argparse.Namespace, out: Path, k: int) -> subprocess.Popen:
    cmd = [*_policy(args), sys.executable, "-m", "conag", "run", args.scenario, "--headless", "--quiet",
           "--agents", str(args.agents), "--max-ticks", str(args.ticks), "--stall-ticks", "0",
           "--record", str(out / f"r{k}.mcap"), "--record-priority", args.record_priority,
           "--summary", str(out / f"r{k}.json")]
    with open(out / f"r{k}.log", "w") as log:  # the child has its own copy of the file
        return subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, text=True)


def finish(proc: subprocess.Popen, out: Path, k: int, started: float) -> Outcome:
    text = (out / f"r{k}.log").read_text()
    summary = out / f"r{k}.json"
    final = json.loads(summary.read_text())["ticks"] if summary.exists() else -1
    mcap = out / f"r{k}.mcap"
    loss = lost_data(mcap, final) if mcap.exists() and final >= 0 else Loss(((0, max(final, 0)),), 0)
    return Outcome(k, proc.returncode, final, format_gaps(list(loss.ticks)), loss.commands,
                   format_gaps(lost_ticks(read_end(mcap))), "warning: the recording" in text, RAISED in text,
                   round(time.monotonic() - started, 1))


def measure(args: argparse.Namespace, out: Path) -> list[Outcome]:
    """The busy loops for the whole measurement; the builds `--parallel` at a time."""
    loops = [subprocess.Popen([*_policy(args), sys.executable, "-c", "while True: pass"]) for _ in range(args.load)]
    outcomes: list[Outcome] = []
    going: dict[int, tuple[subprocess.Popen, float]] = {}
    try:
        k = 0
        while len(outcomes) < args.runs:
            while len(going) < args.parallel and k < args.runs:
                going[k] = (start_build(args, out, k), time.monotonic())
                k += 1
            time.sleep(0.5)
            for j, (proc, started) in list(going.items()):
                if proc.poll() is not None:
                    del going[j]
                    outcomes.append(finish(proc, out, j, started))
                    print(_line(outcomes[-1]), flush=True)
    finally:
        for p in loops + [proc for proc, _ in going.values()]:
            p.kill()
            p.wait()
    return sorted(outcomes, key=lambda o: o.run)


def _line(o: Outcome) -> str:
    lost = f"lacks ticks {o.lost_ticks or '-'} and {o.lost_commands} commands" if o.lost else "complete"
    said = f"; says {o.reported or '-'}{', warned' if o.warned else ''}" if o.lost or o.reported or o.warned else ""
    return (f"run {o.run:2d}: exit {o.exit_code}, {o.final_tick} ticks, {o.seconds:.0f} s: {lost}{said}"
            f"{' (recorder raised to normal)' if o.raised else ''}{' SILENT' if o.silent else ''}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", type=int, default=18, help="recorded builds (default 18)")
    p.add_argument("--load", type=int, default=6, help="busy loops beside them (default 6)")
    p.add_argument("--parallel", type=int, default=2, help="builds at a time (default 2)")
    p.add_argument("--scenario", default="scenarios/nested_squares.toml")
    p.add_argument("--agents", type=int, default=3)
    p.add_argument("--ticks", type=int, default=1000, help="tick limit of each build (default 1000)")
    p.add_argument("--record-priority", default="idle", choices=("idle", "low", "normal"))
    p.add_argument("--inherit", action="store_true",
                   help="run everything at this script's own priority, not the normal one (a quick check)")
    p.add_argument("--keep", metavar="DIR", help="keep the recordings and logs in DIR (default: a temporary one)")
    p.add_argument("--json", metavar="PATH", help="write every outcome as JSON")
    args = p.parse_args(argv)
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="bench-record-load-") as tmp:
        out = Path(args.keep or tmp)
        out.mkdir(parents=True, exist_ok=True)
        outcomes = measure(args, out)
    lost = [o for o in outcomes if o.lost]
    silent = [o for o in outcomes if o.silent]
    print(f"{len(outcomes)} recordings beside {args.load} busy loops ({args.parallel} builds at a time, recorder "
          f"{args.record_priority}): {len(lost)} lost data, {len(silent)} silently; "
          f"{sum(o.raised for o in outcomes)} recorders starved and went on at the normal priority; "
          f"{time.monotonic() - started:.0f} s", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps([asdict(o) for o in outcomes], indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
