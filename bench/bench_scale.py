"""Scale (issue 15): the same build in one process and as `conag run` processes, 1 to 100 agents.

    python3 -m bench.bench_scale                          # 1, 3, 10, 30, 100 agents: a few minutes
    python3 -m bench.bench_scale --agents 1,3,10 --ticks 300
    python3 -m bench.bench_scale --per-process 1,20       # processes of 1 agent, and of 20 (conag agents)
    python3 -m bench.bench_scale --json scale.json
    python3 -m bench.bench_scale --reference-dir ../old     # an existing checkout as the reference
    python3 -m bench.bench_scale --no-reference             # this tree alone

For each agent count, on one scenario and seed (`scenarios/large/scale.toml` by default: a
generated 60 x 60 world, 136 open sites, room for 100 agents round its starts), one after
the other on the same machine:

* in-process: `conag.sim.start` and `SimRun.step` in a fresh interpreter (the simulator the
  experiments use: one core, the agents one after another);
* processes: `conag run --agents N --max-ticks T --stall-ticks 0 --profile ...`: a world
  process and one process per agent (with `--per-process K`, `conag agents` processes of K
  agents each), over zenoh on loopback, in lockstep.

Side by side with a reference (issue 31): every row also runs on a git worktree of
`--reference` (default f7f6a27, `bench_agent_step.REFERENCE`: the code before issue 31) or
on the checkout `--reference-dir`, right after this tree's run of the same row, so both
share the machine's state. Each side runs its own code: cwd and PYTHONPATH are its tree.

* The in-process measurement is a script passed with `python3 -c` (`CHILD`); it imports
  `start` from `sim.loop` in a tree from before the package move (f7f6a27), else from
  `conag.sim.loop` (tried in that order: an installed `conag` must not lend a reference
  tree this tree's simulator).
* The processes row is the same `conag run` command line on both sides: f7f6a27's
  `conag run` already has `--listen`, `--profile` and `--per-process`, and its world writes
  the same profile, so both sides' ticks/s come from their world's profile. A reference
  without those flags fails its first row with its own usage message.
* Both trees load their compiled kernels before the first row (a 3-tick in-process run
  and a 3-tick `conag run`), so a fresh worktree's first row does not pay for compiling.
* `--quick` leaves the reference out unless `--reference` or `--reference-dir` is given;
  `--no-reference` always does.
* Every run listens on a free port of its own (the machine may be shared).

Every row runs a fixed number of ticks (`--ticks`, fewer for large teams: at most
`--agent-ticks` agent steps), so the bench ends in bounded time. Reported per row:

* ticks/s from the second tick to the last (start-up left out), and processes / in-process;
* with a reference: its in-process and processes ticks/s, and this tree's processes ticks/s
  over the reference's (issue 31's target: at least 3 with 10 agent processes);
* the time from launching the interpreter(s) to the first tick (the world's first frames
  out), which includes imports, loading the compiled kernels and attaching;
* memory as PSS and USS (from /proc/PID/smaps_rollup; RSS counts shared pages in every
  process), sampled every second while the run goes on (the sample halfway through is
  reported): per agent process and in total (the world,
  the supervisor and the agents; in-process: the one process);
* where a tick's time goes: in-process, the world's step and the agents' decisions; in the
  world process, its step, publishing the frames and waiting for the agents' commands
  (`conag world --profile`, `world_server/loop_times.py`).

Progress goes to stderr; the markdown table (and with `--json` every figure) at the end.
The machine should be otherwise idle: on a shared one the figures swing widely.
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import nullcontext
from pathlib import Path

from bench.bench_agent_step import REFERENCE, reference_checkout, tree_label

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = "scenarios/large/scale.toml"


def free_port() -> int:
    """A TCP port free on loopback now (the kernel's pick): every run gets its own, as other
    runs may share the machine."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def tree_env(tree: Path) -> dict[str, str]:
    """The environment of a run of `tree`: its own packages first (cwd is the tree too)."""
    return {**os.environ, "PYTHONPATH": str(tree)}


# ------------------------------------------------------------------ memory

def smaps(pid: int) -> tuple[int, int]:
    """(PSS, USS) of a process in bytes, from /proc/PID/smaps_rollup; (0, 0) if it is gone."""
    fields: dict[str, int] = {}
    try:
        with open(f"/proc/{pid}/smaps_rollup", encoding="ascii") as f:
            for line in f:
                parts = line.split()
                if len(parts) >= 2 and parts[0].endswith(":") and parts[1].isdigit():
                    fields[parts[0][:-1]] = int(parts[1]) * 1024
    except OSError:
        return 0, 0
    return fields.get("Pss", 0), fields.get("Private_Clean", 0) + fields.get("Private_Dirty", 0)


def process_tree(root: int) -> dict[int, str]:
    """pid -> command line of `root` and all its descendants."""
    parent: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat", encoding="ascii", errors="replace") as f:
                    parent[int(entry)] = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
    tree, frontier = {root}, [root]
    while frontier:
        p = frontier.pop()
        kids = [c for c, pp in parent.items() if pp == p and c not in tree]
        tree.update(kids)
        frontier.extend(kids)
    out = {}
    for pid in tree:
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                out[pid] = f.read().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            pass
    return out


def memory_of_run(root: int) -> dict:
    """PSS/USS in MB of a `conag run` tree: in total, and per agent process (mean)."""
    procs = process_tree(root)
    sizes = {pid: smaps(pid) for pid in procs}
    agents = [pid for pid, cmd in procs.items() if " conag agent" in cmd]
    mb = 1 / 2**20
    hosted = max(sum(_agents_in(procs[pid]) for pid in agents), 1)
    return {"processes": len(procs), "agent_processes": len(agents),
            "total_pss_mb": sum(p for p, _ in sizes.values()) * mb,
            "total_uss_mb": sum(u for _, u in sizes.values()) * mb,
            "agent_pss_mb": sum(sizes[p][0] for p in agents) * mb / hosted,
            "agent_uss_mb": sum(sizes[p][1] for p in agents) * mb / hosted}


class _MemorySampler:
    """Samples `memory_of_run` every `period` seconds in a thread while the run lives (not
    more often: reading smaps of a hundred processes costs CPU the run needs); `middle`
    is the sample halfway through those that saw agents (a run too short for a progress line
    at its halfway tick still gets one, and none is taken from processes already gone)."""

    def __init__(self, root: int, period: float = 1.0):
        self.root, self.period = root, period
        self.samples: list[dict] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        # Every 0.2 s until a sample has seen agents: forked agent processes start at once
        # and a short run may be over within the first period.
        while not self._stop.wait(self.period if self.samples else 0.2):
            sample = memory_of_run(self.root)
            if sample["agent_processes"] and sample["agent_pss_mb"] > 0:
                self.samples.append(sample)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()

    def middle(self) -> dict:
        return self.samples[len(self.samples) // 2] if self.samples else {}


def _agents_in(cmd: str) -> int:
    """How many agents an agent process's command line serves (`conag agents --ids a1..a20`)."""
    words = cmd.split()
    if "--ids" in words:
        from agent_runtime.host import parse_ids

        return len(parse_ids(words[words.index("--ids") + 1]))
    return 1


# ------------------------------------------------------------------ in-process

# Runs in a fresh interpreter (`python3 -c`, cwd and PYTHONPATH the tree measured), so
# imports count in its start-up; `smaps` is prepended. It must run on this tree's package
# layout and on the one before the move (`sim` at the top level, as at f7f6a27).
CHILD_MAIN = r"""
import json, os, sys, time
from pathlib import Path
try:
    from sim.loop import start  # the tree before the package move (f7f6a27): its own simulator
except ImportError:
    from conag.sim.loop import start
from world_server.scenario import load_scenario

scenario, agents, ticks, launched, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), \
    sys.argv[5]
run = start(load_scenario(scenario), agents=agents)
run.step()
first = time.monotonic() - launched
world_s = agents_s = 0.0
mem = (0, 0)
t_start = time.perf_counter()
for i in range(ticks - 1):
    t0 = time.perf_counter()
    frames = run.world.frames()
    t1 = time.perf_counter()
    for frame in frames:
        s = run.brains[frame.agent_id].step(frame)
        run.world.set_command(frame.agent_id, s.speed, s.turn, s.action)
    t2 = time.perf_counter()
    run.world.step()
    world_s += time.perf_counter() - t2 + (t1 - t0)
    agents_s += t2 - t1
    if i == ticks // 2:
        mem = smaps(os.getpid())
seconds = time.perf_counter() - t_start
n = max(ticks - 1, 1)
Path(out).write_text(json.dumps({
    "rate": n / seconds, "first_tick_s": first, "world_ms": 1000 * world_s / n, "agents_ms": 1000 * agents_s / n,
    "total_pss_mb": mem[0] / 2**20, "total_uss_mb": mem[1] / 2**20,
    "sites": f"{int(run.world.sites_filled().sum())}/{len(run.world.sites_xy)}"}))
"""
CHILD = inspect.getsource(smaps) + CHILD_MAIN


def in_process(tree: Path, scenario: str, agents: int, ticks: int) -> dict:
    """The in-process row on `tree`'s code."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "sim.json"
        launched = time.monotonic()
        r = subprocess.run([sys.executable, "-c", CHILD, scenario, str(agents), str(ticks), repr(launched), str(out)],
                           cwd=tree, env=tree_env(tree), capture_output=True, text=True, check=False)
        if r.returncode != 0:
            raise RuntimeError(f"the in-process run failed in {tree}:\n{r.stderr[-3000:]}")
        return json.loads(out.read_text())


NO_SIM = {"rate": float("nan"), "first_tick_s": float("nan"), "world_ms": float("nan"), "agents_ms": float("nan"),
          "total_pss_mb": float("nan")}


# ------------------------------------------------------------------ processes

def processes_command(scenario: str, agents: int, ticks: int, port: int, per_process: int, profile: Path) -> list[str]:
    """The processes row's command line, the same for this tree and the reference (f7f6a27's
    `conag run` has every flag used here)."""
    cmd = [sys.executable, "-m", "conag", "run", scenario, "--agents", str(agents), "--max-ticks", str(ticks),
           "--stall-ticks", "0", "--headless", "--listen", f"tcp/127.0.0.1:{port}", "--profile", str(profile)]
    if per_process > 1:
        cmd += ["--per-process", str(per_process)]
    return cmd


def as_processes(tree: Path, scenario: str, agents: int, ticks: int, per_process: int,
                 extra_env: dict[str, str] | None = None) -> dict:
    """The processes row on `tree`'s code, on a free port of its own (`extra_env` over its
    environment)."""
    with tempfile.TemporaryDirectory() as tmp:
        profile = Path(tmp) / "world.json"
        cmd = processes_command(scenario, agents, ticks, free_port(), per_process, profile)
        launched = time.monotonic()
        proc = subprocess.Popen(cmd, cwd=tree, env={**tree_env(tree), **(extra_env or {})}, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)
        last = [""]
        samples = _MemorySampler(proc.pid)
        assert proc.stdout is not None
        for line in proc.stdout:
            last[0] = line.strip() or last[0]
        samples.stop()
        mem = samples.middle()
        proc.wait()
        if not profile.exists():
            raise RuntimeError(f"{' '.join(cmd)} in {tree} wrote no profile (exit {proc.returncode}): {last[0]}")
        prof = json.loads(profile.read_text())
    if prof.get("first_tick") is None:   # e.g. agents that never all attached on a starved machine
        raise RuntimeError(f"{' '.join(cmd)} in {tree}: the world never ticked (exit {proc.returncode}): {last[0]}")
    busy = sum(prof[k] for k in ("step", "publish", "wait", "other"))
    per_tick = prof["per_tick_ms"]
    return {"rate": prof["ticks"] / busy if busy else 0.0, "first_tick_s": prof["first_tick"] - launched,
            "step_ms": per_tick.get("step", 0.0), "publish_ms": per_tick.get("publish", 0.0),
            "wait_ms": per_tick.get("wait", 0.0), **mem, "last_line": last[0]}


# ------------------------------------------------------------------ realtime

def realtime_scenario(scenario: str, out: Path, rate: float) -> Path:
    """A copy of `scenario` in realtime mode at `rate` ticks per second."""
    text = (ROOT / scenario).read_text(encoding="utf-8")
    lines = [('tick_mode = "realtime"' if line.startswith("tick_mode") else line) for line in text.splitlines()]
    if "[world]" in lines:
        lines.insert(lines.index("[world]") + 1, f"tick_rate = {rate}")
    else:
        lines += ["", "[world]", f"tick_rate = {rate}"]
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return out


def realtime(scenario: str, agents: int, seconds: float, per_process: int, rate: float) -> dict:
    """Run `conag run` in realtime mode at `rate`; once every agent is alive, `seconds` more
    (after the world's own 2 s warm-up), then stop it; the world's profile says how fast it
    ticked and how far behind the agents' commands were."""
    with tempfile.TemporaryDirectory() as tmp:
        profile = Path(tmp) / "world.json"
        sc = realtime_scenario(scenario, Path(tmp) / "realtime.toml", rate)
        cmd = [sys.executable, "-m", "conag", "run", str(sc), "--agents", str(agents), "--stall-ticks", "0",
               "--headless", "--listen", f"tcp/127.0.0.1:{free_port()}", "--profile", str(profile),
               "--per-process", str(per_process)]
        proc = subprocess.Popen(cmd, cwd=ROOT, env=tree_env(ROOT), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True)
        assert proc.stdout is not None
        everyone = f"agents alive {agents}/{agents}"
        for line in proc.stdout:
            if everyone in line:
                break
        time.sleep(seconds + 2.0)
        proc.send_signal(2)  # SIGINT: conag run stops the world, which writes its profile
        proc.communicate(timeout=120)
        prof = json.loads(profile.read_text())
    busy = sum(prof[k] for k in ("step", "publish", "wait", "other"))
    return {"agents": agents, "per_process": per_process, "target": rate,
            "rate": prof["ticks"] / busy if busy else 0.0, "commands": prof["commands"],
            "answered": answered_share(prof["commands"], agents, prof["ticks"]),
            "stale_share": prof["stale_commands"] / max(prof["commands"], 1), "max_lag": prof["max_lag"]}


def answered_share(commands: int, agents: int, ticks: int) -> float:
    """The share of the frames sent that a command answered. A frame is "latest wins": an
    agent still thinking when the next one comes skips the older one, so an agent count
    that the cores cannot keep up with shows as fewer commands, not as late ones."""
    return commands / (agents * ticks) if agents and ticks else 0.0


def realtime_kept(row: dict) -> bool:
    """The tick kept: the target rate, no command answering a frame older than one tick, and
    (nearly) every frame answered."""
    return row["rate"] >= 0.97 * row["target"] and row["max_lag"] <= 1 and row["answered"] >= 0.95


def realtime_table(rows: list[dict]) -> str:
    head = ("| agents | per process | target ticks/s | ticks/s | commands | frames answered | older than one tick "
            "| max lag (ticks) | kept |")
    lines = [head, "|" + "---:|" * 8 + ":---:|"]
    lines += [f"| {r['agents']} | {r['per_process']} | {r['target']:g} | {r['rate']:.1f} | {r['commands']} "
              f"| {100 * r['answered']:.0f}% | {100 * r['stale_share']:.1f}% | {r['max_lag']} "
              f"| {'yes' if realtime_kept(r) else 'no'} |" for r in rows]
    return "\n".join(lines)


# ------------------------------------------------------------------ the table

def row_ticks(agents: int, ticks: int, agent_ticks: int, min_ticks: int = 60) -> int:
    """The row's tick budget: `ticks`, fewer for large teams (at most `agent_ticks` agent steps)."""
    return max(min_ticks, min(ticks, agent_ticks // agents))


def table(rows: list[dict], reference: str | None = None) -> str:
    """The lockstep table; with `reference` (its label), three more columns from each row's
    `ref_sim` and `ref_proc`: the reference's ticks/s and this tree's processes over its."""
    nan = float("nan")
    ref_head = (f" in-process ticks/s at {reference} | processes ticks/s at {reference} "
                f"| processes this / {reference} |" if reference else "")
    head = ("| agents | per process | ticks | in-process ticks/s | processes ticks/s | ratio |" + ref_head +
            " first tick in-process s | first tick processes s | PSS per agent MB | USS per agent MB "
            "| total PSS MB (in-process) | in-process: world / agents ms | world process: step / publish / wait ms |")
    lines = [head, "|" + "---:|" * (16 if reference else 13)]
    for r in rows:
        s, p = r["sim"], r["proc"]
        ref = ""
        if reference:
            rs, rp = r.get("ref_sim") or {}, r.get("ref_proc") or {}
            ref_rate = rp.get("rate", nan)
            ref = (f" {rs.get('rate', nan):.1f} | {ref_rate:.1f} "
                   f"| {p['rate'] / ref_rate if ref_rate else nan:.2f} |")
        lines.append(
            f"| {r['agents']} | {r['per_process']} | {r['ticks']} | {s['rate']:.1f} | {p['rate']:.1f} "
            f"| {p['rate'] / s['rate'] if s['rate'] else nan:.2f} |{ref} {s['first_tick_s']:.1f} "
            f"| {p['first_tick_s']:.1f} "
            f"| {p.get('agent_pss_mb', nan):.0f} | {p.get('agent_uss_mb', nan):.0f} "
            f"| {p.get('total_pss_mb', nan):.0f} ({s['total_pss_mb']:.0f}) "
            f"| {s['world_ms']:.2f} / {s['agents_ms']:.1f} "
            f"| {p['step_ms']:.2f} / {p['publish_ms']:.2f} / {p['wait_ms']:.1f} |")
    return "\n".join(lines)


def lockstep(trees: dict[str, Path], scenario: str, args) -> list[dict]:
    """The lockstep rows; each run on this tree is followed at once by the same run on the
    reference (`trees["reference"]`, if any)."""
    rows = []
    warmed: set[Path] = set()
    for side, tree in trees.items():  # compile and cache both sides' kernels before anything is timed
        if tree.resolve() in warmed:
            continue  # the reference is this tree (--reference-dir .)
        warmed.add(tree.resolve())
        t0 = time.monotonic()
        in_process(tree, scenario, 1, 3)
        as_processes(tree, scenario, 1, 3, 1)  # conag run's own kernels too (the layout check)
        print(f"{side}: kernels loaded ({time.monotonic() - t0:.0f} s)", file=sys.stderr, flush=True)
    for n in args.agents:
        ticks = row_ticks(n, args.ticks, args.agent_ticks)
        sims = {}
        for side, tree in trees.items():
            t0 = time.monotonic()
            sims[side] = NO_SIM if args.no_sim else in_process(tree, scenario, n, ticks)
            print(f"{n} agents, {ticks} ticks in-process, {side}: {sims[side]['rate']:.1f} ticks/s, first tick "
                  f"after {sims[side]['first_tick_s']:.1f} s ({time.monotonic() - t0:.0f} s)", file=sys.stderr,
                  flush=True)
        for k in args.per_process:
            if k > 1 and k >= n * 2:
                continue  # one host for everyone is the in-process row again, plus the bus
            procs = {}
            for side, tree in trees.items():
                t0 = time.monotonic()
                procs[side] = proc = as_processes(tree, scenario, n, ticks, k)
                print(f"{n} agents, {k} per process, {side}: {proc['rate']:.1f} ticks/s, first tick after "
                      f"{proc['first_tick_s']:.1f} s, {proc.get('total_pss_mb', 0):.0f} MB PSS in total "
                      f"({time.monotonic() - t0:.0f} s)", file=sys.stderr, flush=True)
            rows.append({"agents": n, "per_process": k, "ticks": ticks, "sim": sims["this"], "proc": procs["this"],
                         "ref_sim": sims.get("reference"), "ref_proc": procs.get("reference")})
    return rows


def _ints(text: str) -> list[int]:
    return [int(v) for v in text.split(",") if v]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", default=SCENARIO)
    p.add_argument("--agents", type=_ints, default=[1, 3, 10, 30, 100], metavar="N,N,...")
    p.add_argument("--per-process", type=_ints, default=[1], metavar="K,K,...",
                   help="agents per agent process (1: one process each; K > 1: conag agents hosts of K)")
    p.add_argument("--ticks", type=int, default=1000, help="ticks per row (default 1000)")
    p.add_argument("--agent-ticks", type=int, default=20000,
                   help="at most this many agent steps per row: fewer ticks for large teams (default 20000)")
    p.add_argument("--no-sim", action="store_true", help="skip the in-process runs (their columns say nan)")
    p.add_argument("--reference", metavar="REV",
                   help=f"the commit every lockstep row also runs at, in a git worktree (default {REFERENCE})")
    p.add_argument("--reference-dir", type=Path, metavar="PATH",
                   help="an existing checkout of the reference, instead of a worktree")
    p.add_argument("--no-reference", action="store_true", help="this tree alone")
    p.add_argument("--realtime", type=_ints, default=[], metavar="N,N,...",
                   help="also run these agent counts in realtime mode at --rate: does the tick keep up?")
    p.add_argument("--rate", type=float, default=20.0, help="realtime ticks per second (default 20)")
    p.add_argument("--seconds", type=float, default=10.0, help="seconds measured per realtime row (default 10)")
    p.add_argument("--json", metavar="PATH", help="write every figure as JSON")
    p.add_argument("--quick", action="store_true",
                   help="a smoke run (1 and 2 agents, 300 ticks, 1 s of realtime; no reference unless "
                        "--reference or --reference-dir), not a measurement")
    args = p.parse_args(argv)
    if args.quick:
        args.agents, args.per_process, args.ticks, args.realtime, args.seconds = [1, 2], [1, 2], 300, [2], 1.0
    scenario = str((ROOT / args.scenario).resolve())  # both sides load this tree's scenario file
    with_reference = not args.no_reference and (not args.quick or args.reference or args.reference_dir)
    rev = args.reference or REFERENCE
    with reference_checkout(rev, args.reference_dir) if with_reference else nullcontext() as ref:
        trees = {"this": ROOT} | ({"reference": ref} if ref is not None else {})
        label = None if ref is None else tree_label(ref, str(ref)) if args.reference_dir else rev
        try:
            rows = lockstep(trees, scenario, args) if args.agents else []
        except RuntimeError as exc:   # a run that failed: say which and why, without a traceback
            print(f"bench_scale: {exc}", file=sys.stderr)
            return 1
    live = []
    for n in args.realtime:
        for k in args.per_process:
            if k > 1 and k >= n * 2:
                continue
            live.append(realtime(scenario, n, args.seconds, k, args.rate))
            r = live[-1]
            print(f"{n} agents, {k} per process, realtime {args.rate:g} Hz: {r['rate']:.1f} ticks/s, "
                  f"{100 * r['answered']:.0f}% of frames answered, {100 * r['stale_share']:.1f}% of commands "
                  f"older than one tick", file=sys.stderr, flush=True)
    print(f"{args.scenario}, {os.cpu_count()} cores, load average at the end {os.getloadavg()[0]:.1f}"
          + (f"; reference {label}" if label else "") + "\n")
    if rows:
        print(table(rows, label))
    if live:
        print()
        print(realtime_table(live))
    if args.json:
        Path(args.json).write_text(json.dumps({"reference": label, "lockstep": rows, "realtime": live}, indent=2)
                                   + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
