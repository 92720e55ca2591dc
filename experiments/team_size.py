"""Issue 36, item 1: how the build time falls with the team size (paper §6.3's open question).

The default agent builds each layout in-process (conag/sim, lockstep, headless) with teams
of 1, 2, 4, 8, 16, 32 and 64 agents (the world places agents beyond a layout's `A` cells
on the empty cells nearest them), several seeds. The layouts are generated ones of 40 to
200 open sites (`world_server.generator`, several families, one seed each, found by
`layouts()`) and held-out kinds the generator does not make: a circle of 44 sites with
scattered bricks and the word CONAG with two piles (the layouts of the issue's study).

Reported per layout and team: ticks to complete (or to the stop: stalled, out of
ticks); speed-up = mean ticks with 1 agent / mean ticks with N (the ideal is N); the
distance all agents walked over the lower bound (experiments/replay.lower_bound on the
initial map, as in the generalisation tables); and each behaviour's share of the
agent-ticks (every agent's behaviour on every tick, summed over the team).

    python3 -m experiments.team_size --quick   # 3 layouts, teams 1, 4, 16, 1 seed (minutes):
                                               # writes out/team_size-quick/
    python3 -m experiments.team_size           # every layout and team, 3 seeds (about 2 h on 2 cores)
    python3 -m experiments.team_size --resume  # go on with an interrupted run (same options)
    python3 -m experiments.team_size --plot    # the curves of experiments/team_size.json -> out/team_size.png
    python3 -m experiments.team_size --report-only --out DIR   # the tables again from DIR/team_size.json

Writes team_size.json and team_size.md (experiments/ for the full run, --out otherwise)
and, for the full run, the team-size section of docs/results/experiments.md. Every run is
deterministic for its layout, team and seed: the same command gives the same tables.
Each run is journalled as it finishes (team_size.partial.jsonl in the output folder,
`experiments.journal`), so `--resume` runs only what an interrupted run had not finished,
for the same code and agent settings; a finished run removes its journal.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections import Counter
from concurrent.futures import as_completed
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from agent_runtime.config import ADDITIONS, AgentConfig
from conag import sim
from conag.agent_settings import split_names
from experiments.generalisation import DEFAULT_STALL, distance_bound, stall_limit
from experiments.journal import Journal, code_version
from experiments.report import RESULTS_DOC, write_section
from experiments.workers import pool
from protocol.messages import BEHAVIOURS
from world_server.generator import generate, word_sites
from world_server.scenario import Scenario, parse_scenario

ROOT = Path(__file__).resolve().parent.parent
TEAMS = (1, 2, 4, 8, 16, 32, 64)
SEEDS = (1, 2, 3)
QUICK_TEAMS, QUICK_SEEDS = (1, 4, 16), (1,)
QUICK_LAYOUTS = ("gen-ring-3601", "gen-nested_rings-3600", "gen-solid_hollow-3602")
MIN_SITES, MAX_SITES = 40, 200
# Generated layouts: (family, world side, max_sites); the first seed from 3600 up whose
# layout has at least MIN_SITES open sites is taken (deterministic); of LARGE, at least
# LARGE_SITES: issue 36's goal at 32 agents counts only layouts of 100 sites or more.
GENERATED = (("wall", 40, 80), ("ring", 45, 80), ("nested_rings", 40, 80), ("pocket", 40, 80),
             ("letter", 50, 120), ("polyomino", 40, 80), ("multi", 60, 160), ("block", 35, 100),
             ("spiral", 40, 90), ("corridor", 45, 80), ("solid_hollow", 40, 80), ("multi", 90, 200))
LARGE, LARGE_SITES = (("letter", 60, 200), ("polyomino", 60, 200)), 100
JOURNAL = "team_size.partial.jsonl"   # the runs finished so far (see --resume)
SHOWN = ("explore", "brick_nav", "config_nav", "approach_red", "grab", "drop", "avoid", "unstick")
FOOD_AND_WATER = ("approach_food", "approach_water", "eat", "drink")  # hunger and thirst, one column


# ------------------------------------------------------------------ the layouts

def _toml(name: str, description: str, grid: np.ndarray, max_ticks: int) -> str:
    body = "\n".join("".join(row) for row in grid)
    return (f'name = "{name}"\ndescription = "{description}"\nseed = 36\nagents = 1\n'
            f'tick_mode = "lockstep"\nmax_ticks = {max_ticks}\nlayout = """\n{body}\n"""\n')


def circle() -> str:
    """A circle of 44 sites (radius 7) in a 50 x 50 world, bricks scattered (seeded)."""
    grid = np.full((50, 50), ".")
    r, c = np.mgrid[0:50, 0:50]
    d = np.hypot(r - 24.5, c - 24.5)
    ring = np.abs(d - 7.0) < 0.5
    grid[ring] = "+"
    rng = np.random.default_rng(36)
    free = np.argwhere((grid == ".") & (np.abs(d - 7.0) > 2))
    for i in rng.choice(len(free), size=int(ring.sum()) + 6, replace=False):
        grid[tuple(free[i])] = "b"
    grid[2, 2] = "A"
    return _toml("circle", f"Held out: a circle of {int(ring.sum())} sites, bricks scattered.", grid, 80000)


def conag_word() -> str:
    """The word CONAG in block letters in a 45 x 15 world, bricks in two piles."""
    grid = np.full((15, 45), ".")
    word = word_sites("CONAG")
    grid[4:11, 8:8 + word.shape[1]][word] = "+"
    n = int(word.sum()) + 6
    for k in range(n):  # half in a pile at the west edge, half at the east edge, 5 wide
        grid[2 + k // 2 // 5, k // 2 % 5 + (0 if k % 2 == 0 else 40)] = "b"
    grid[13, 22] = "A"
    return _toml("conag", f"Held out: the word CONAG, {int(word.sum())} sites, two piles.", grid, 80000)


def generated_layouts() -> dict[str, str]:
    """The generated layouts: per GENERATED (LARGE) entry the first seed from 3600 up with at
    least MIN_SITES (LARGE_SITES) sites."""
    out = {}
    entries = [(*g, MIN_SITES) for g in GENERATED] + [(*g, LARGE_SITES) for g in LARGE]
    for family, side, cap, least in entries:
        for seed in range(3600, 3700):
            g = generate(seed, family, side, 1, max_sites=cap)
            if least <= g.sites <= MAX_SITES and g.name not in out:
                out[g.name] = g.text
                break
    return out


def layouts() -> dict[str, str]:
    """Every layout of the experiment by name: the held-out kinds, then the generated ones."""
    return {"circle": circle(), "conag": conag_word(), **generated_layouts()}


# ------------------------------------------------------------------ one run

@dataclass(frozen=True)
class Run:
    layout: str
    agents: int
    seed: int
    sites: int
    completed: bool
    stalled: bool
    ticks: int
    sites_filled: int
    distance: float
    bound: float
    behaviours: dict[str, int]   # agent-ticks per behaviour, summed over the team
    seconds: float


def run_one(name: str, text: str, agents: int, seed: int, cfg: AgentConfig | None = None) -> Run:
    began = time.perf_counter()
    sc: Scenario = parse_scenario(text, f"<{name}>")
    run = sim.start(sc, agents=agents, seed=seed, cfg=cfg or AgentConfig())
    starts = [tuple(int(v) for v in cell[::-1]) for cell in sc.to_cell(run.world.agent_poses()[:, :2])]
    result = run.run(sc.max_ticks, stall_ticks=stall_limit(sc, DEFAULT_STALL))
    status = run.world.status()
    ticks: Counter = Counter()
    for counts in run.behaviour_ticks.values():
        ticks.update(counts)
    return Run(name, agents, seed, status.sites_total, result.completed, result.stalled, result.ticks,
               status.sites_filled, float(sum(status.agent_distance)), distance_bound(sc, starts),
               {b: int(ticks[b]) for b in BEHAVIOURS if ticks[b]}, time.perf_counter() - began)


# ------------------------------------------------------------------ resuming

Job = tuple[str, str, int, int, AgentConfig]   # layout name, its TOML, agents, seed, agent settings


def job_key(job: Job, code: str) -> list:
    """What a journalled run is for: the layout, the team, the seed, every agent setting and
    the code version (`experiments.journal.code_version`)."""
    name, _, agents, seed, cfg = job
    return ["team_size", name, agents, seed, json.dumps(asdict(cfg), sort_keys=True), code]


def pending(journal: Journal, jobs: list[Job], code: str) -> tuple[list[Run], list[Job]]:
    """(the runs `journal` already holds for `jobs`, the jobs still to run)."""
    found = journal.results()
    keyed = [(job, tuple(job_key(job, code))) for job in jobs]
    return [Run(**found[key]) for _, key in keyed if key in found], [job for job, key in keyed if key not in found]


# ------------------------------------------------------------------ tables

def summarise(runs: list[Run]) -> list[dict]:
    """One row per (layout, team): mean and median ticks, speed-up, distance / bound, shares."""
    rows = []
    for name in dict.fromkeys(r.layout for r in runs):
        base = [r.ticks for r in runs if r.layout == name and r.agents == 1]
        for n in sorted({r.agents for r in runs if r.layout == name}):
            rs = [r for r in runs if r.layout == name and r.agents == n]
            total = Counter()
            for r in rs:
                total.update(r.behaviours)
            agent_ticks = sum(total.values()) or 1
            ratios = [r.distance / r.bound for r in rs if r.completed and r.bound > 0]
            mean = float(np.mean([r.ticks for r in rs]))
            rows.append(dict(layout=name, sites=rs[0].sites, agents=n, runs=len(rs),
                             completed=sum(r.completed for r in rs), ticks_mean=mean,
                             ticks_median=float(statistics.median(r.ticks for r in rs)),
                             speedup=float(np.mean(base)) / mean if base else float("nan"),
                             distance_bound=float(statistics.median(ratios)) if ratios else float("nan"),
                             shares={b: total[b] / agent_ticks for b in BEHAVIOURS if total[b]}))
    return rows


def _f(v: float, fmt: str = ".1f") -> str:
    return "-" if v is None or not np.isfinite(v) else format(v, fmt)


def _not_all_done(row: dict) -> str:
    """" (k/n done)" for a row whose runs did not all complete, else ""."""
    return "" if row["completed"] == row["runs"] else f" ({row['completed']}/{row['runs']} done)"


def tables(rows: list[dict]) -> str:
    teams = sorted({r["agents"] for r in rows})
    names = list(dict.fromkeys(r["layout"] for r in rows))
    at = {(r["layout"], r["agents"]): r for r in rows}
    head = "| layout | sites | 1 agent: ticks | " + " | ".join(f"speed-up at {n}" for n in teams[1:]) + " |"
    lines = [head, "|---|---:|---:|" + "---:|" * (len(teams) - 1)]
    for name in names:
        one = at.get((name, 1))
        cells = [_f(at[name, n]["speedup"]) + _not_all_done(at[name, n]) if (name, n) in at else ""
                 for n in teams[1:]]
        alone = "" if not one else _f(one["ticks_mean"], ",.0f") + _not_all_done(one)
        lines.append(f"| {name} | {one['sites'] if one else ''} | {alone} | "
                     + " | ".join(cells) + " |")
    lines += ["", "Distance / bound (median over completed runs):", "",
              "| layout | " + " | ".join(f"{n}" for n in teams) + " |", "|---|" + "---:|" * len(teams)]
    for name in names:
        lines.append(f"| {name} | " + " | ".join(_f(at[name, n]["distance_bound"], ".2f") if (name, n) in at else ""
                                                 for n in teams) + " |")
    lines += ["", "Share of agent-ticks per behaviour (all layouts, each layout weighted equally):", "",
              "| agents | " + " | ".join(SHOWN) + " | food and water | other |",
              "|---:|" + "---:|" * (len(SHOWN) + 2)]
    for n in teams:
        rs = [r for r in rows if r["agents"] == n]
        share = {b: float(np.mean([r["shares"].get(b, 0.0) for r in rs])) for b in BEHAVIOURS}
        food = sum(share[b] for b in FOOD_AND_WATER)
        other = max(1.0 - sum(share[b] for b in SHOWN) - food, 0.0)
        lines.append(f"| {n} | " + " | ".join(f"{100 * share[b]:.0f}%" for b in SHOWN)
                     + f" | {100 * food:.0f}% | {100 * other:.0f}% |")
    return "\n".join(lines)


def goals(rows: list[dict]) -> str:
    """Issue 36's goals for teams, checked on the rows: speed-up at 8 agents of at least 6
    (layouts of 40 or more sites), at 32 of at least 16 (100 or more sites), no layout slower
    with more agents (median ticks over seeds), distance / bound at 8 agents at most 2.0."""
    at = {(r["layout"], r["agents"]): r for r in rows}
    names = list(dict.fromkeys(r["layout"] for r in rows))

    def line(goal: str, n: int, min_sites: int, key: str, ok) -> str:
        vals = [(name, at[name, n][key]) for name in names
                if (name, n) in at and at[name, n]["sites"] >= min_sites and np.isfinite(at[name, n][key])]
        if not vals:
            return f"* {goal}: no layout of {min_sites} or more sites with a team of {n} in this run."
        met = [name for name, v in vals if ok(v)]
        low, high = min(v for _, v in vals), max(v for _, v in vals)
        return (f"* {goal}: met on {len(met)} of {len(vals)} layouts (from {low:.2f} to {high:.2f}, "
                f"median {statistics.median(v for _, v in vals):.2f})"
                + ("" if len(met) == len(vals) else
                   "; not on " + ", ".join(name for name, _ in vals if name not in met)) + ".")

    slower = []
    for name in names:
        # ticks of a team whose runs stalled say when it gave up, not how fast it builds
        teams = sorted(n for (layout, n) in at if layout == name and at[name, n]["completed"] == at[name, n]["runs"])
        for i, small in enumerate(teams):
            worse = [big for big in teams[i + 1:] if at[name, big]["ticks_median"] > at[name, small]["ticks_median"]]
            if worse:
                slower.append(f"{name} ({', '.join(map(str, worse))} agents slower than {small})")
                break
    return "\n".join([
        line("speed-up at 8 agents of at least 6", 8, 40, "speedup", lambda v: v >= 6),
        line("speed-up at 32 agents of at least 16, layouts of 100 or more sites", 32, 100, "speedup",
             lambda v: v >= 16),
        "* no layout slower with more agents (median ticks over seeds): "
        + ("met" if not slower else f"not met on {len(slower)} of {len(names)} layouts: " + "; ".join(slower))
        + " (teams whose every run completed).",
        line("distance / bound at 8 agents at most 2.0", 8, 40, "distance_bound", lambda v: v <= 2.0),
    ])


def merge(full: dict, part: dict) -> dict:
    """The full study `full` (a team_size.json) with the runs of `part` in place of its runs
    of the same layouts. `part` must be a run of `--layouts` with the study's own teams and
    seeds and no additions switched, so that the merged rows are what the whole study would
    have given; its command is kept beside the study's (`merged`). Raises ValueError."""
    runs = [Run(**r) for r in part["runs"]]
    names = list(dict.fromkeys(r.layout for r in runs))
    every = layouts()
    unknown = [n for n in names if n not in every]
    if unknown:
        raise ValueError(f"not layouts of the study: {', '.join(unknown)}")
    if not part["command"].startswith("python3 -m experiments.team_size --layouts ") or "--with" in part["command"]:
        raise ValueError(f"not a run of --layouts with the study's teams, seeds and agent: {part['command']}")
    want = {(n, a, s) for n in names for a in TEAMS for s in SEEDS}
    have = {(r.layout, r.agents, r.seed) for r in runs}
    if have != want:
        raise ValueError(f"the runs do not cover teams {TEAMS} x seeds {SEEDS} of {', '.join(names)}")
    kept = [Run(**r) for r in full["runs"] if r["layout"] not in names]
    order = {n: i for i, n in enumerate(every)}
    merged = sorted(kept + runs, key=lambda r: (order.get(r.layout, len(order)), r.agents, r.seed))
    earlier = [m for m in full.get("merged", []) if not set(m["layouts"]) & set(names)]
    return dict(command=full["command"], note=full["note"], rows=summarise(merged), runs=[asdict(r) for r in merged],
                merged=[*earlier, dict(layouts=names, command=part["command"])])


def report(rows: list[dict], command: str, note: str, merged: list[dict] | None = None) -> str:
    added = "".join(f"; the runs of {', '.join(m['layouts'])} are from `{m['command']}`, merged in (`--merge`)"
                    for m in merged or [])
    subset = "" if not note else (f"\nA subset of the study; the whole of it is `python3 -m experiments.team_size` "
                                  f"({len(layouts())} layouts x {len(TEAMS)} teams x {len(SEEDS)} seeds).\n")
    picture = ("\n![speed-up and behaviour shares against the team size](../../experiments/team_size.png)\n\n"
               "The curves (speed-up per layout; each behaviour's share of agent-ticks, all layouts): "
               "`python3 -m experiments.pictures team_size`.\n" if not note else
               "\nThe curves: `python3 -m experiments.team_size --plot --out DIR` (out/team_size.png).\n")
    return f"""## Team size: 1 to 64 agents (issue 36) {{#team-size}}

`{command}`{note}{added}. The default agent (or the one `--with`/`--without` make), in-process and
lockstep; a run stops when complete, stalled (no site filled for {DEFAULT_STALL} ticks, or the
world's cells per agent if more) or at the layout's `max_ticks`. Speed-up = mean ticks with 1
agent / mean ticks with N (ideal: N).
{picture}{subset}
Issue 36's goals (item 2), on these runs:

{goals(rows)}

{tables(rows)}
"""


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    teams = sorted({r["agents"] for r in rows})
    for name in dict.fromkeys(r["layout"] for r in rows):
        rs = sorted((r for r in rows if r["layout"] == name), key=lambda r: r["agents"])
        a.plot([r["agents"] for r in rs], [r["speedup"] for r in rs], marker="o", lw=1, label=name)
    a.plot(teams, teams, color="grey", ls="--", label="ideal")
    a.set(xscale="log", yscale="log", xlabel="agents", ylabel="speed-up (ticks at 1 / ticks at N)")
    a.set_xticks(teams, [str(t) for t in teams])
    a.legend(fontsize=6, ncol=2)
    for beh in SHOWN:
        b.plot(teams, [float(np.mean([r["shares"].get(beh, 0.0) for r in rows if r["agents"] == n])) for n in teams],
               marker="o", lw=1, label=beh)
    b.set(xscale="log", xlabel="agents", ylabel="share of agent-ticks")
    b.set_xticks(teams, [str(t) for t in teams])
    b.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)


# ------------------------------------------------------------------ main

def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=f"layouts {', '.join(QUICK_LAYOUTS)}, teams "
                    f"{', '.join(map(str, QUICK_TEAMS))}, seed 1; writes to --out (default out/team_size-quick)")
    ap.add_argument("--layouts", nargs="+", help="only these layouts (names as in the tables)")
    ap.add_argument("--teams", type=int, nargs="+", help=f"team sizes (default {' '.join(map(str, TEAMS))})")
    ap.add_argument("--seeds", type=int, nargs="+", help=f"seeds (default {' '.join(map(str, SEEDS))})")
    ap.add_argument("--with", dest="on", default="", metavar="NAMES",
                    help="additions to switch on (comma-separated, agent_runtime.config.ADDITIONS)")
    ap.add_argument("--without", default="", metavar="NAMES", help="additions to switch off (comma-separated)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--resume", action="store_true", help="go on with an interrupted run of the same options "
                    "(its finished runs are in --out's team_size.partial.jsonl)")
    ap.add_argument("--out", type=Path, default=None, help="folder for team_size.json and .md")
    ap.add_argument("--plot", action="store_true", help="draw the curves of team_size.json (in --out, default "
                    "experiments/) into out/team_size.png, running nothing")
    ap.add_argument("--report-only", action="store_true", help="write team_size.md again from team_size.json "
                    "(in --out, default experiments/; there also the docs section), running nothing")
    ap.add_argument("--merge", type=Path, metavar="DIR", help="put the runs of DIR/team_size.json (a run of "
                    "--layouts with the study's teams and seeds) into experiments/team_size.json in place of its "
                    "runs of those layouts, and write the report again, running nothing")
    args = ap.parse_args(argv)
    if args.merge:
        if args.out or args.quick or args.layouts or args.teams or args.seeds or args.on or args.without:
            ap.error("--merge runs nothing and writes into experiments/: give it alone")
        target = ROOT / "experiments" / "team_size.json"
        try:
            data = merge(json.loads(target.read_text(encoding="utf-8")),
                         json.loads((args.merge / "team_size.json").read_text(encoding="utf-8")))
        except (OSError, ValueError, KeyError, TypeError) as e:
            ap.error(f"--merge {args.merge}: {e}")
        target.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
        args.report_only = True
    if args.report_only:
        folder = args.out or ROOT / "experiments"
        data = json.loads((folder / "team_size.json").read_text(encoding="utf-8"))
        text = report(data["rows"], data["command"], data["note"], data.get("merged"))
        (folder / "team_size.md").write_text(text, encoding="utf-8")
        if folder.resolve() == (ROOT / "experiments").resolve():
            write_section(RESULTS_DOC, "team-size", text)
        print(text)
        return 0
    if args.plot:
        src = (args.out or ROOT / "experiments") / "team_size.json"
        target = ROOT / "out" / "team_size.png"
        plot(json.loads(src.read_text(encoding="utf-8"))["rows"], target)
        print(target)
        return 0
    flags = {**dict.fromkeys(split_names(args.on), True), **dict.fromkeys(split_names(args.without), False)}
    if set(flags) - set(ADDITIONS):
        ap.error(f"unknown addition(s): {', '.join(sorted(set(flags) - set(ADDITIONS)))}")
    cfg = replace(AgentConfig(), **flags)
    every = layouts()
    names = args.layouts or (list(QUICK_LAYOUTS) if args.quick else list(every))
    teams = args.teams or (QUICK_TEAMS if args.quick else TEAMS)
    seeds = args.seeds or (QUICK_SEEDS if args.quick else SEEDS)
    full = not (args.quick or args.layouts or args.teams or args.seeds or flags)
    out = args.out or (ROOT / "experiments" if full else ROOT / "out" / "team_size-quick")
    out.mkdir(parents=True, exist_ok=True)
    jobs: list[Job] = [(n, every[n], a, s, cfg) for n in names for a in teams for s in seeds]
    jobs.sort(key=lambda j: -j[2])  # the big teams first: they take longest
    code = code_version()
    journal = Journal(out / JOURNAL, resume=args.resume)
    runs, todo = pending(journal, jobs, code)
    if args.resume:
        print(f"resuming: {len(runs)} of {len(jobs)} runs already done", file=sys.stderr, flush=True)
    with pool(args.jobs) as ex:
        futures = {ex.submit(run_one, *j): j for j in todo}
        for fut in as_completed(futures):
            r = fut.result()
            runs.append(r)
            journal.append(job_key(futures[fut], code), asdict(r))
            print(f"[{len(runs)}/{len(jobs)}] {r.layout} {r.agents} agent(s) seed {r.seed}: "
                  f"{'complete' if r.completed else 'stalled' if r.stalled else 'out of ticks'} at tick {r.ticks} "
                  f"({r.sites_filled}/{r.sites}), distance / bound {r.distance / r.bound if r.bound else 0:.2f} "
                  f"({r.seconds:.0f} s)", file=sys.stderr, flush=True)
    order = {n: i for i, n in enumerate(names)}
    runs.sort(key=lambda r: (order[r.layout], r.agents, r.seed))
    rows = summarise(runs)
    picked = [("--layouts", args.layouts), ("--teams", args.teams), ("--seeds", args.seeds),
              ("--with", [args.on] if args.on else None), ("--without", [args.without] if args.without else None)]
    command = " ".join(["python3 -m experiments.team_size", *(["--quick"] if args.quick else []),
                        *(f"{flag} {' '.join(map(str, v))}" for flag, v in picked if v)])
    agent = "".join(f"; {'with' if on else 'without'} {name}" for name, on in flags.items())
    note = "" if full else (f" (layouts {', '.join(names)}; teams {', '.join(map(str, teams))}; seeds "
                            f"{', '.join(map(str, seeds))}{agent})")
    (out / "team_size.json").write_text(json.dumps(dict(command=command, note=note, rows=rows,
                                                        runs=[asdict(r) for r in runs]), indent=1) + "\n",
                                        encoding="utf-8")
    text = report(rows, command, note)
    (out / "team_size.md").write_text(text, encoding="utf-8")
    if full:
        write_section(RESULTS_DOC, "team-size", text)
    journal.remove()
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
