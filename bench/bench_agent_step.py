"""The agent's decision step, side by side with a reference commit (issue 31).

    python3 -m bench.bench_agent_step                      # the table of docs/results/benchmarks.md
    python3 -m bench.bench_agent_step --maps 41,81,121     # also at larger maps
    python3 -m bench.bench_agent_step --quick              # a smoke run, not a measurement

For each layout (scenarios/fig6.toml and three of the generalisation suite: a 21 x 21, a
51 x 50 and a 117 x 116 world) and map size, the in-process sim (default AgentConfig but
for the map size) warms up for `--warmup` ticks, then every agent's `Brain.step(frame)` is
timed on every tick for `--ticks` ticks (the world's step is not timed), as the CPU time
of the thread that steps (what the step costs: a machine shared with other jobs preempts
the process, and wall time then counts the others' work too) and as wall time. The same worker
runs on this checkout and on a git worktree of `--reference` (default f7f6a27, the code
before the cheaper step), one after the other for each row and `--repeats` times in
alternation, so both sides share the machine's load; the table gives both sides' CPU
medians and their ratio, and the wall-time medians. Both sides also hash every decision
(speed, turn, action, behaviour, state nodes, outputs): "same decisions" says whether the
two codes chose alike, step for step.

`REFERENCE` and `reference_checkout` are shared with `bench_scale`: one reference commit for
the benches of issue 31.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from world_server.suite import materialise

ROOT = Path(__file__).resolve().parent.parent
# the generalisation suite's layouts, made from its manifest on first use (experiments/generalisation.py)
SUITE = ROOT / "experiments" / "generalisation" / "layouts"
MANIFEST = ROOT / "experiments" / "generalisation" / "layouts.json"
LAYOUTS = (ROOT / "scenarios" / "fig6.toml", SUITE / "001-gen-nested_rings-20260001.toml",
           SUITE / "021-gen-wall-20260021.toml", SUITE / "028-gen-nested_rings-20260028.toml")
REFERENCE = "f7f6a27"

# Runs in a fresh interpreter with the tree under test first on sys.path; it must import
# both this layout of the packages and the one before the move (`sim` at the top level).
WORKER = r"""
import hashlib, json, statistics, sys, time
try:
    import sim  # the tree before the package move (f7f6a27): its own simulator, not this one's
except ImportError:
    from conag import sim
from agent_runtime.config import AgentConfig
from world_server.scenario import load_scenario

path, map_size, warmup, ticks = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
sc = load_scenario(path)
run = sim.start(sc, cfg=AgentConfig(map_size=map_size))
run.run(warmup, until_complete=False)
steps, cpu, digest = [], [], hashlib.sha256()
for _ in range(ticks):
    for frame in run.world.frames():
        brain = run.brains[frame.agent_id]
        c = time.thread_time()
        t = time.perf_counter()
        s = brain.step(frame)
        steps.append(time.perf_counter() - t)
        cpu.append(time.thread_time() - c)
        d = s.decision
        digest.update(repr((frame.agent_id, frame.tick, s.speed, s.turn, s.action, s.behaviour, d.state,
                            d.outputs, d.arm, d.motor)).encode())
        run.world.set_command(frame.agent_id, s.speed, s.turn, s.action)
    run.world.step()
steps.sort()
print(json.dumps(dict(size=f"{sc.cols} x {sc.rows}", agents=len(run.brains), median_ms=1e3 * statistics.median(steps),
                      p90_ms=1e3 * steps[int(0.9 * (len(steps) - 1))], cpu_ms=1e3 * statistics.median(cpu),
                      digest=digest.hexdigest())))
"""


def measure(tree: Path, layout: Path, map_size: int, warmup: int, ticks: int) -> dict:
    """One worker run of `tree` on `layout`: its step medians (CPU, wall), wall p90 and decision digest."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, "-c", WORKER, str(layout), str(map_size), str(warmup), str(ticks)],
                         cwd=tree, env=env, capture_output=True, text=True, timeout=3600, check=False)
    if out.returncode != 0:
        raise SystemExit(f"bench_agent_step: the worker failed in {tree}:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def reference_tree(rev: str, where: Path) -> Path:
    """A detached git worktree of `rev` under `where` (removed by the caller's tempdir)."""
    tree = where / f"ref-{rev}"
    r = subprocess.run(["git", "worktree", "add", "--detach", "-f", str(tree), rev], cwd=ROOT,
                       capture_output=True, text=True, check=False)
    if r.returncode != 0:
        raise SystemExit(f"{Path(sys.argv[0]).stem}: cannot make a worktree of {rev}: {r.stderr.strip()}")
    return tree


@contextmanager
def reference_checkout(rev: str, directory: Path | None = None) -> Iterator[Path]:
    """The reference tree: `directory` if given (an existing checkout, left as it is), else a
    detached git worktree of `rev` in a temporary directory, removed again at the end."""
    if directory is not None:
        yield directory.resolve()
        return
    with tempfile.TemporaryDirectory(prefix="bench-reference-") as tmp:
        tree = reference_tree(rev, Path(tmp))
        try:
            yield tree
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, capture_output=True,
                           check=False)


def tree_label(tree: Path, fallback: str) -> str:
    """A checkout's short commit hash (`fallback` if it is not a git checkout)."""
    r = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=tree, capture_output=True, text=True, check=False)
    return r.stdout.strip() if r.returncode == 0 and r.stdout.strip() else fallback


def compare(trees: dict[str, Path], layouts, maps, warmup: int, ticks: int, repeats: int):
    """Rows of both sides' medians per (layout, map size), runs alternating between sides."""
    for layout in layouts:
        for map_size in maps:
            runs: dict[str, list[dict]] = {side: [] for side in trees}
            for _ in range(repeats):
                for side, tree in trees.items():
                    runs[side].append(measure(tree, layout, map_size, warmup, ticks))
            new, ref = runs["this"], runs["reference"]
            yield dict(layout=layout.stem, map=map_size, size=new[0]["size"], agents=new[0]["agents"],
                       this_cpu_ms=statistics.median(r["cpu_ms"] for r in new),
                       ref_cpu_ms=statistics.median(r["cpu_ms"] for r in ref),
                       this_ms=statistics.median(r["median_ms"] for r in new),
                       ref_ms=statistics.median(r["median_ms"] for r in ref),
                       same=all(a["digest"] == b["digest"] for a, b in zip(new, ref)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a few ticks: a smoke run, not a measurement")
    ap.add_argument("--warmup", type=int, default=500, help="sim ticks before timing starts")
    ap.add_argument("--ticks", type=int, default=1000, help="timed ticks per layout")
    ap.add_argument("--maps", default="41", help="map sizes, comma separated (default 41)")
    ap.add_argument("--repeats", type=int, default=1, help="runs per side, alternating (default 1)")
    ap.add_argument("--reference", default=REFERENCE, help=f"the commit to compare with (default {REFERENCE})")
    ap.add_argument("--reference-dir", type=Path, help="an existing checkout of the reference, instead of a worktree")
    ap.add_argument("--layouts", help="only the layouts whose name contains one of these, comma separated")
    ap.add_argument("--json", type=Path, help="also write the rows as JSON")
    args = ap.parse_args(argv)
    layouts = LAYOUTS
    if args.layouts:
        wanted = args.layouts.split(",")
        layouts = tuple(p for p in LAYOUTS if any(w in p.stem for w in wanted))
        if not layouts:
            ap.error(f"no layout matches {args.layouts!r}; the layouts: {', '.join(p.stem for p in LAYOUTS)}")
    warmup, ticks = (20, 20) if args.quick else (args.warmup, args.ticks)
    maps = [int(m) for m in args.maps.split(",")]
    materialise(MANIFEST, SUITE)
    with reference_checkout(args.reference, args.reference_dir) as ref:
        label = args.reference if args.reference_dir is None else tree_label(ref, str(ref))
        print(f"| layout | world | agents | map | step CPU median ms, this | at {label} | ratio "
              f"| wall median ms, this | at {label} | same decisions |")
        print("|---|---|---:|---:|---:|---:|---:|---:|---:|---|")
        rows = []
        for r in compare({"this": ROOT, "reference": ref}, layouts, maps, warmup, ticks, args.repeats):
            rows.append(r)
            print(f"| {r['layout']} | {r['size']} | {r['agents']} | {r['map']} | {r['this_cpu_ms']:.3f} | "
                  f"{r['ref_cpu_ms']:.3f} | {r['ref_cpu_ms'] / r['this_cpu_ms']:.2f}x | {r['this_ms']:.3f} | "
                  f"{r['ref_ms']:.3f} | {'yes' if r['same'] else 'no'} |", flush=True)
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
