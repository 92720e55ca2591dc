"""The recorder's own CPU: one recorded build replayed into `conag record`, without the run.

    python3 -m bench.bench_recorder                          # record nested_squares (3 agents) once, then measure
    python3 -m bench.bench_recorder --recording R.mcap --reps 5
    python3 -m bench.bench_recorder --reference main         # this tree and main, side by side

`bench/bench_record.py` times whole builds, whose tick rate on a shared 2-core machine
varies by tens of percent from one build to the next. This script measures what the
recorder process itself spends, on a workload that is the same every time: `conag replay`
publishes a recording's messages at their recorded pace (`--rate 1`) into a `conag record`
at the normal priority (so that nothing it needs waits for an idle core), and the
recorder's CPU seconds (every thread's, from /proc) are read between the replay's start and
its end, per 1,000 ticks of the recording. Each repetition measures the recorder as `conag
run --record` starts it (the Foxglove channels beside the bus's) and with `--msgpack-only`.
With `--reference REV` or `--reference-dir PATH`, every repetition also runs on that tree
(its own `conag record` and `conag replay`), right after this tree's.

In process, without the bus, it also times the write path alone (`McapRecorder.add` for
every message of the recording, and then its `close`, which makes the Foxglove channels;
with and without the Translator; microseconds per bus message): what the recorder does
beside receiving, during the run and in all.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from contextlib import nullcontext
from pathlib import Path

from bench.bench_agent_step import reference_checkout, tree_label
from bench.bench_record import _proc_table

ROOT = Path(__file__).resolve().parent.parent
MODES = {"with Foxglove": [], "msgpack only": ["--msgpack-only"]}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def record_build(out: Path, scenario: str, agents: int) -> None:
    """Record one lockstep build of `scenario` (until complete) into `out`, with this tree."""
    subprocess.run([sys.executable, "-m", "conag", "run", scenario, "--headless", "--quiet", "--agents", str(agents),
                    "--max-ticks", "3000", "--stall-ticks", "0", "--record", str(out),
                    "--listen", f"tcp/127.0.0.1:{_free_port()}"], cwd=ROOT, check=False, capture_output=True)
    if not out.exists():
        raise SystemExit(f"bench_recorder: recording {scenario} failed")


def recorder_cpu(tree: Path, recording: Path, extra: list[str], tmp: Path) -> float:
    """CPU seconds of a `conag record` (this `tree`'s) while `conag replay` publishes `recording` into it."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    rec = subprocess.Popen([sys.executable, "-m", "conag", "record", str(tmp / "r.mcap"), "--listen", endpoint,
                            "--priority", "normal", *extra], cwd=tree, env=env, stdout=subprocess.PIPE,
                           stderr=subprocess.DEVNULL, text=True)
    try:
        assert rec.stdout is not None
        rec.stdout.readline()  # "recording world ...": its session is open
        before = _proc_table()[rec.pid][1]
        subprocess.run([sys.executable, "-m", "conag", "replay", str(recording), "--rate", "1", "--quiet",
                        "--connect", endpoint, "--wait", "3"], cwd=tree, env=env, check=True,
                       stdout=subprocess.DEVNULL)
        return _proc_table()[rec.pid][1] - before
    finally:
        rec.send_signal(signal.SIGINT)
        rec.wait(60)


def write_path(recording: Path, reps: int) -> dict[str, tuple[float, float]]:
    """Microseconds per bus message of `McapRecorder.add` (what a recorder does during the
    run) and of the adds and `close` together (the Foxglove channels are made on close), with
    and without the Translator (medians of `reps`), in this process."""
    from conag.foxglove.convert import Translator
    from conag.recording.mcap_log import McapRecorder, read_recording

    entries = read_recording(recording).entries
    out: dict[str, tuple[float, float]] = {}
    for mode, foxglove in (("with Foxglove", True), ("msgpack only", False)):
        times = []
        for _ in range(reps):
            with tempfile.TemporaryDirectory() as d:
                rec = McapRecorder(Path(d) / "w.mcap", derive=Translator().feed if foxglove else None)
                t0 = time.process_time()
                for e in entries:
                    rec.add(e.key, e.data, e.log_time)
                during = time.process_time() - t0
                rec.close()  # with Foxglove: their channels are made now, from the file
                times.append((during, time.process_time() - t0))
        per = 1e6 / len(entries)
        out[mode] = (per * statistics.median(t[0] for t in times), per * statistics.median(t[1] for t in times))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--recording", type=Path, help="the recording to replay (default: record one build first)")
    p.add_argument("--scenario", default="scenarios/nested_squares.toml", help="the build to record, without one")
    p.add_argument("--agents", type=int, default=3)
    p.add_argument("--reps", type=int, default=3)
    p.add_argument("--reference", metavar="REV", help="also measure a git worktree of REV, side by side")
    p.add_argument("--reference-dir", type=Path, metavar="PATH", help="also measure this checkout, side by side")
    args = p.parse_args(argv)
    reference = args.reference is not None or args.reference_dir is not None
    with (reference_checkout(args.reference, args.reference_dir) if reference else nullcontext()) as ref, \
            tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        recording = args.recording
        if recording is None:
            recording = tmp / "build.mcap"
            record_build(recording, args.scenario, args.agents)
        from conag.recording.mcap_log import read_recording

        kiloticks = read_recording(recording).last_tick / 1000
        trees = {tree_label(ROOT, "this"): ROOT} | ({} if ref is None else {tree_label(ref, "reference"): ref})
        cpu: dict[tuple[str, str], list[float]] = {(t, m): [] for t in trees for m in MODES}
        for rep in range(args.reps):
            for label, tree in trees.items():
                for mode, extra in MODES.items():
                    cpu[label, mode].append(recorder_cpu(tree, recording, extra, tmp) / kiloticks)
                    print(f"rep {rep + 1}, {label}, {mode}: recorder {cpu[label, mode][-1]:.3f} CPU s per 1000 ticks",
                          flush=True)
        print(f"recording: {recording} ({kiloticks * 1000:.0f} ticks), replayed at its pace into `conag record`")
        for (label, mode), values in cpu.items():
            print(f"{label} {mode}: recorder {statistics.median(values):.3f} CPU s per 1000 ticks "
                  f"(median of {len(values)}: {', '.join(f'{v:.3f}' for v in values)})")
        for mode, (during, closed) in write_path(recording, args.reps).items():
            print(f"write path, this tree, {mode}: {during:.1f} us per bus message during the run, "
                  f"{closed:.1f} with the close")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
