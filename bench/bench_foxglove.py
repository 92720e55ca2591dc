"""What the Foxglove channels cost a recorder: the translation of a recording's messages.

    python3 -m conag run scenarios/large/scale.toml --agents 10 --max-ticks 1500 --stall-ticks 0 \
        --maps-every 100 --record /tmp/scale.mcap
    python3 -m bench.bench_foxglove /tmp/scale.mcap [--reps 5]

Feeds every bus message of the recording, in recorded order, through a fresh
`conag.foxglove.convert.Translator` (what `conag record` does beside writing each message),
`--reps` times, and prints the median CPU time (this process's, `time.process_time`) per
1,000 ticks of the run, split by the kind of message translated, with the number of Foxglove
messages and their bytes. Writing them to the file is left out (the MCAP writer's share,
which compresses them with the rest, is in bench/bench_record.py's recorder figure).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections import Counter, defaultdict

from conag.foxglove.convert import Translator
from conag.recording.mcap_log import read_recording


def translate(entries) -> tuple[dict[str, float], Counter, Counter]:
    """(CPU seconds per leaf key, messages made per topic group, bytes per topic group)."""
    t = Translator()
    cpu: dict[str, float] = defaultdict(float)
    made, size = Counter(), Counter()
    for e in entries:
        leaf = e.key.rsplit("/", 1)[-1]
        start = time.process_time()
        out = t.feed(e.key, e.data, e.log_time)
        cpu[leaf] += time.process_time() - start
        for d in out:
            group = "/agents/*/" + d.topic.split("/")[3] if d.topic.startswith("/agents/") else d.topic
            made[group] += 1
            size[group] += len(d.data)
    return cpu, made, size


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording")
    p.add_argument("--reps", type=int, default=5)
    args = p.parse_args(argv)
    rec = read_recording(args.recording)
    ticks = max(rec.last_tick, 1)
    runs = [translate(rec.entries) for _ in range(args.reps)]
    leaves = sorted({leaf for cpu, _, _ in runs for leaf in cpu})
    per_k = {leaf: statistics.median(cpu.get(leaf, 0.0) for cpu, _, _ in runs) * 1000 / ticks for leaf in leaves}
    total = statistics.median(sum(cpu.values()) for cpu, _, _ in runs) * 1000 / ticks
    print(f"{args.recording}: {len(rec.entries)} bus messages over {ticks} ticks, {args.reps} repetitions")
    print(f"translation: {total * 1000:.1f} ms CPU per 1,000 ticks (median), by the bus message translated:")
    for leaf in sorted(per_k, key=per_k.get, reverse=True):
        if per_k[leaf] >= 0.00005:
            print(f"  {leaf:18s} {per_k[leaf] * 1000:8.1f} ms")
    _, made, size = runs[0]
    print("made, per 1,000 ticks:")
    for group in sorted(made):
        print(f"  {group:22s} {made[group] * 1000 / ticks:8.1f} messages {size[group] * 1000 / ticks / 1024:8.1f} KiB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
