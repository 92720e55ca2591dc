"""Recording overhead: the same lockstep `conag run` with and without `--record`.

    python3 -m bench.bench_record                      # fig6, 1500 ticks, 3 repetitions of each
    python3 -m bench.bench_record --ticks 3000 --reps 5
    python3 -m bench.bench_record --main-job           # also: the size of a recording of the README's main job

Each repetition runs `conag run SCENARIO --max-ticks N` as a subprocess, alternating
without and with `--record` (so a slow spell of a shared machine hits both), and times
the tick rate of the build itself: from the first status of tick >= 1 to the final
status, read from the progress lines (process start-up and numba loading are left out).
Prints the median ticks per second of each and the slowdown; the recordings' sizes too.
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LINE = re.compile(r"^tick\s+(\d+)\s")


class BuildClock:
    """The build's tick rate from `conag run`'s progress lines: from the first line of tick
    >= 1 to the last one seen (process start-up and numba loading left out)."""

    def __init__(self) -> None:
        self.first: tuple[int, float] | None = None
        self.last: tuple[int, float] | None = None

    def observe(self, line: str) -> bool:
        """Take one output line; True if it was a progress line of tick >= 1."""
        m = LINE.match(line)
        if not m or int(m.group(1)) < 1:
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


def one_run(scenario: str, ticks: int, record: Path | None, port: int) -> tuple[float, int]:
    """(ticks per second of the build, the recording's size in bytes or 0)."""
    cmd = [sys.executable, "-m", "conag", "run", scenario, "--headless", "--max-ticks", str(ticks),
           "--stall-ticks", "0", "--listen", f"tcp/127.0.0.1:{port}"]
    if record is not None:
        cmd += ["--record", str(record)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, text=True)
    clock = BuildClock()
    for line in proc.stdout:
        clock.observe(line)
    proc.wait()
    rate, _ = clock.rate(cmd)
    return rate, (record.stat().st_size if record is not None and record.exists() else 0)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", default="scenarios/fig6.toml")
    p.add_argument("--ticks", type=int, default=1500)
    p.add_argument("--reps", type=int, default=3)
    p.add_argument("--port", type=int, default=17601)
    p.add_argument("--main-job", action="store_true",
                   help="also record the README's main job (fig6 until complete) and print the file's size")
    args = p.parse_args(argv)
    plain, recorded, sizes = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for rep in range(args.reps):
            rate, _ = one_run(args.scenario, args.ticks, None, args.port)
            plain.append(rate)
            rate, size = one_run(args.scenario, args.ticks, Path(tmp) / f"r{rep}.mcap", args.port)
            recorded.append(rate)
            sizes.append(size)
            print(f"rep {rep + 1}: {plain[-1]:.0f} ticks/s without, {recorded[-1]:.0f} with recording "
                  f"({size / 1e6:.2f} MB)", flush=True)
        a, b = statistics.median(plain), statistics.median(recorded)
        print(f"{args.scenario}, {args.ticks} ticks, {args.reps} repetitions: median {a:.0f} ticks/s without, "
              f"{b:.0f} with recording: slowdown {100 * (a - b) / a:.1f}% "
              f"(ranges {min(plain):.0f}-{max(plain):.0f} and {min(recorded):.0f}-{max(recorded):.0f})")
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
