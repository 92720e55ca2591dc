"""Issue 33: what each addition beyond the paper buys. The ablation table.

    python3 -m experiments.ablation --quick             # three small layouts: ablation_quick.md
    python3 -m experiments.ablation --sample 60 --jobs 2  # the 60-layout table: ablation.md
    python3 -m experiments.ablation --cluster tcp://HOST:8786   # on a Dask cluster (experiments/runner.py)
    python3 -m experiments.ablation --sample 60 --resume  # go on with an interrupted run (same options)
    python3 -m experiments.ablation --sample 60 --status  # how far its journal is, and its table so far
    python3 -m experiments.ablation --quick --report-only # the table again from ablation_quick.json, running nothing
    python3 -m experiments.ablation --files tests/layouts/spiral.toml --seeds 3 --agents default,-unstick
    python3 -m experiments.ablation --files scenarios/nested_squares.toml --restart-at-drop 1 --out DIR

Each layout of a sample of the generated suite (`--sample` files evenly spaced in name
order, so every family and size comes in), or of the `--files` given, is built in process
(`conag.sim`, goal sequencing on; `--seeds N`: with N seeds) by several agents, named by
`AgentConfig`:

* `default`: the best agent, every addition on;
* `-NAME`: the default with one addition switched off, for each of ADDITIONS;
* `paper`: every addition off but ghost association (`AgentConfig.preset("paper")`;
  `agent_runtime.config` says why).

Per agent the table gives the layouts completed, the median ticks of the completed runs
and the median distance over the lower bound (`experiments.replay.lower_bound`, as in the
generalisation table). A run stops as stalled after `--stall` ticks with no site filled
(or the cells per agent on a large world), as in `experiments.generalisation`.

With `--restart-at-drop P` each agent's brain is started again, with chance P, on the tick
its body drops a brick (`conag.sim.restarts`): the moment a restarted process is most
likely to shut itself in, which chaos runs meet only by chance.

Each finished run is appended to a journal next to the results (`ablation.partial.jsonl`,
`experiments/journal.py`), removed when the table is written. `--resume` keeps the runs an
interrupted invocation with the same `--out` finished for the same layout, agent, stall
limit and code, and runs only the others: the 60-layout table takes hours.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from agent_runtime.config import ADDITIONS, OFF_BY_DEFAULT, AgentConfig
from experiments import runner
from experiments.generalisation import DEFAULT_STALL, LAYOUTS, distance_bound, family_of, materialise, stall_limit
from experiments.journal import Journal, code_version
from world_server.scenario import Scenario, parse_scenario

if TYPE_CHECKING:
    from conag.sim import SimRun

ROOT = Path(__file__).resolve().parent.parent
QUICK = ("000-gen-wall-20260000.toml", "001-gen-nested_rings-20260001.toml", "002-gen-polyomino-20260002.toml")


@dataclass(frozen=True)
class Job:
    layout: str        # the layout file's name
    agent: str         # a name `agent_of` knows
    stall: int
    text: str = field(default="", repr=False)   # the layout file's text: a task needs no file of the suite
    seed: int = 0      # added to the layout's seed (`--seeds`)
    restart_at_drop: float = 0.0   # the share of drops after which the brain starts again (`conag.sim.restarts`)


@dataclass(frozen=True)
class Run:
    layout: str
    family: str
    agent: str
    completed: bool
    ticks: int
    distance: float
    bound: float
    seconds: float = 0.0   # the run's wall time on its worker (absent from runs made before it was kept)
    seed: int = 0          # added to the layout's seed (absent from runs made before `--seeds`)
    restarts: int = 0      # brains started again (`--restart-at-drop`)


def variants() -> dict[str, AgentConfig]:
    """default, each addition it has off in turn, and the paper's agent (an addition the
    default leaves off, OFF_BY_DEFAULT, has no row: off, it is the default)."""
    out = {"default": AgentConfig.preset("default")}
    out.update({f"-{name}": AgentConfig(**{name: False}) for name in ADDITIONS if name not in OFF_BY_DEFAULT})
    out["paper"] = AgentConfig.preset("paper")
    return out


def agent_of(name: str) -> AgentConfig:
    """The agent a name stands for: one of `variants()`, or the default with several
    additions off, `-NAME-NAME...` (the names hold no hyphen), e.g. `-site_core-off_own_brick`.
    A ValueError names what is wrong."""
    known = variants()
    if name in known:
        return known[name]
    names = name.split("-")[1:] if name.startswith("-") else []
    wrong = [n for n in names if n not in ADDITIONS]
    if not names or wrong or len(set(names)) != len(names):
        raise ValueError(f"unknown agent {name!r}; known: {', '.join(known)}, or -NAME-NAME... of "
                         f"{', '.join(ADDITIONS)}")
    return AgentConfig(**dict.fromkeys(names, False))


def agents_arg(ap: argparse.ArgumentParser, text: str | None) -> list[str]:
    """The agents of a comma-separated `--agents` (none: every one of `variants()`); an
    unknown one is the parser's usage error."""
    agents = list(variants()) if not text else text.split(",")
    for agent in agents:
        try:
            agent_of(agent)
        except ValueError as exc:
            ap.error(str(exc))
    return agents


def sample(n: int) -> list[Path]:
    """`n` layout files of the suite, evenly spaced in name order (so every family and size
    comes in)."""
    paths = sorted(materialise(), key=lambda p: p.name)
    return paths[::max(len(paths) // n, 1)][:n]


def job_of(path: Path, agent: str, stall: int, seed: int = 0, restart_at_drop: float = 0.0) -> Job:
    """The job of one run of the layout file `path`, its text read here (a cluster's workers
    have no suite files)."""
    return Job(path.name, agent, stall, path.read_text(encoding="utf-8"), seed, restart_at_drop)


def start_job(job: Job) -> tuple[Scenario, SimRun]:
    """The job's scenario and its run, started (its agent, seed and layout), not yet stepped."""
    from conag import sim
    from conag.sim.restarts import RestartAtDrop

    sc = parse_scenario(job.text, job.layout)
    run = sim.start(sc, cfg=agent_of(job.agent), seed=sc.seed + job.seed)
    if job.restart_at_drop:
        run.before_step = RestartAtDrop(job.restart_at_drop, sc.seed + job.seed)
    return sc, run


def run_one(job: Job) -> Run:
    began = time.perf_counter()
    sc, run = start_job(job)
    starts = [tuple(int(v) for v in cell[::-1]) for cell in sc.to_cell(run.world.agent_poses()[:, :2])]
    result = run.run(sc.max_ticks, stall_ticks=stall_limit(sc, job.stall))
    status = run.world.status()
    return Run(layout=job.layout, family=family_of(sc), agent=job.agent, completed=result.completed,
               ticks=result.ticks, distance=float(sum(status.agent_distance)), bound=distance_bound(sc, starts),
               seconds=time.perf_counter() - began, seed=job.seed,
               restarts=getattr(run.before_step, "restarts", 0))


def job_key(job: Job, code: str) -> list:
    """A run's journal key: which run, under which settings and code."""
    return ([job.layout, job.agent, job.stall, code] + ([job.seed] if job.seed else [])
            + ([job.restart_at_drop] if job.restart_at_drop else []))


def resumed(journal: Journal, jobs: list[Job], code: str) -> tuple[dict[Job, Run], list[Job]]:
    """(the runs the journal already holds for `jobs`, the jobs still to run)."""
    found = journal.results()
    earlier = {j: Run(**found[k]) for j in jobs if (k := tuple(job_key(j, code))) in found}
    return earlier, [j for j in jobs if j not in earlier]


def remaining(elapsed: float, finished: int, left: int) -> float:
    """Seconds the `left` runs should take at this invocation's pace so far (`finished` in
    `elapsed`); the pace counts every worker, so it needs no worker count."""
    return elapsed / finished * left if finished else float("nan")


def hms(seconds: float) -> str:
    """1:02:03 for a duration; "?" before there is a pace to go by."""
    if seconds != seconds:   # nan
        return "?"
    s = round(seconds)
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"


def sweep(jobs: list[Job], execute: Callable[[list[Job]], Iterable[runner.Done]], journal: Journal,
          code: str, clock: Callable[[], float] = time.monotonic) -> list[Run]:
    """Every run of `jobs` (in their order), those the journal holds taken from it, the
    others by `execute` (each to the journal as it finishes), with progress on stderr."""
    done, todo = resumed(journal, jobs, code)
    if done:
        print(f"resuming: {len(done)} of {len(jobs)} runs already done ({journal.path})", file=sys.stderr, flush=True)
    began = clock()
    for k, d in enumerate(execute(todo), 1):
        r = done[d.job] = d.result
        journal.append(job_key(d.job, code), asdict(r))
        elapsed = clock() - began
        print(f"[{len(done)}/{len(jobs)} {hms(elapsed)} elapsed, ~{hms(remaining(elapsed, k, len(todo) - k))} left] "
              f"{r.layout} {r.agent}: {'complete' if r.completed else 'not complete'} in {r.ticks} ticks "
              f"({r.seconds:.0f} s, {d.worker})", file=sys.stderr, flush=True)
    return [done[j] for j in jobs]


def table(runs: list[Run]) -> str:
    """The markdown table: one row per agent, in `variants()` order, then any other agent
    (`agent_of`) in the order the runs first name it. Beside each agent's own
    figures, the paired ones against the default on the same layouts (the medians of the
    completed runs alone compare different sets of layouts): the layouts it completes that
    the default does not, and the reverse; on how many layouts its run is the default's to
    the tick and the unit of distance (the addition switched off never changed a decision
    there); and its ticks over the default's on the layouts both complete: their geometric
    mean (a run twice as long and one half as long cancel; the median is 1.00 whenever
    most runs are the default's), and on how many layouts it took more than 10% more or
    fewer ticks."""
    layouts = len({(r.layout, r.seed) for r in runs})
    base = {(r.layout, r.seed): r for r in runs if r.agent == "default"}
    lines = [(f"| agent | completed (of {layouts}) | gained / lost against default | same run as default | "
              "median ticks (completed) | ticks / default's (geometric mean, both completed) | "
              "> 10% more / fewer ticks | median distance / bound |"),
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    named = list(variants())
    for agent in named + [a for a in dict.fromkeys(r.agent for r in runs) if a not in named]:
        mine = [r for r in runs if r.agent == agent]
        if not mine:
            continue
        done = [r for r in mine if r.completed]
        ticks = f"{statistics.median(r.ticks for r in done):,.0f}" if done else "-"
        ratio = f"{statistics.median(r.distance / r.bound for r in done if r.bound > 0):.2f}" if done else "-"
        paired = [(r, base[r.layout, r.seed]) for r in mine if (r.layout, r.seed) in base]
        gained = sum(r.completed and not d.completed for r, d in paired)
        lost = sum(d.completed and not r.completed for r, d in paired)
        same = sum(r.completed == d.completed and r.ticks == d.ticks and r.distance == d.distance for r, d in paired)
        both = [r.ticks / d.ticks for r, d in paired if r.completed and d.completed]
        versus = f"{statistics.geometric_mean(both):.2f}" if both else "-"
        apart = f"{sum(x > 1.1 for x in both)} / {sum(x < 1 / 1.1 for x in both)}" if both else "-"
        lines.append(f"| {agent} | {len(done)} | {gained} / {lost} | {same} of {len(paired)} | {ticks} | {versus} "
                     f"| {apart} | {ratio} |")
    return "\n".join(lines)


def journal_status(journal: Journal, jobs: list[Job], code: str) -> str:
    """What an unfinished sweep's journal holds: how many of `jobs` are done, and the table
    of the layouts every agent has finished (an interim figure, not the sample's)."""
    done = resumed(journal, jobs, code)[0]
    agents = {j.agent for j in jobs}
    by_layout: dict[str, list[Run]] = {}
    for r in done.values():
        by_layout.setdefault(r.layout, []).append(r)
    whole = [r for rs in by_layout.values() if {r.agent for r in rs} == agents for r in rs]
    head = (f"{len(done)} of {len(jobs)} runs done at this code; {len({r.layout for r in whole})} of "
            f"{len({j.layout for j in jobs})} layouts have every agent's run")
    return head + ("\n\n" + table(whole) if whole else "")


def report_only(path: Path) -> int:
    """Write `path`'s table (the .md beside it) from its runs, running nothing."""
    try:
        runs = [Run(**r) for r in json.loads(path.read_text(encoding="utf-8"))]
    except FileNotFoundError:
        print(f"error: {path}: no such file (a finished sweep writes it)", file=sys.stderr)
        return 2
    except (json.JSONDecodeError, TypeError) as exc:
        print(f"error: {path}: not an ablation's runs ({exc})", file=sys.stderr)
        return 2
    write_table(path.with_suffix(".md"), runs)
    return 0


def write_table(path: Path, runs: list[Run]) -> None:
    """Write the runs' table to `path` (markdown) and print it."""
    text = table(runs)
    path.write_text(text + "\n", encoding="utf-8")
    print(text)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=f"the layouts {', '.join(QUICK)} only")
    ap.add_argument("--sample", type=int, default=60, help="layouts from the suite (default 60)")
    ap.add_argument("--files", nargs="+", type=Path, metavar="LAYOUT",
                    help="these layout files instead of the suite's (results: ablation_files.*)")
    ap.add_argument("--seeds", type=int, default=1,
                    help="runs per layout and agent, with the layout's seed plus 0, 1, ... (default 1)")
    ap.add_argument("--restart-at-drop", type=float, default=0.0, metavar="P",
                    help="start an agent's brain again, with chance P, on the tick its body drops a brick, "
                         "as a process restarted then is (conag.sim.restarts; default 0: never)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    runner.add_cluster_argument(ap)
    ap.add_argument("--stall", type=int, default=DEFAULT_STALL, help="ticks with no site filled that stop a run")
    ap.add_argument("--agents", help="only these agents, comma separated (default: every one of the table); "
                                     "-NAME-NAME... is the default with each NAME off (a list that starts "
                                     "with - needs --agents=...)")
    ap.add_argument("--out", type=Path, default=ROOT / "experiments",
                    help="folder for the json and md (ablation_quick.* with --quick, ablation_files.* with "
                         "--files, else ablation.*)")
    ap.add_argument("--resume", action="store_true",
                    help="keep the runs an interrupted invocation with the same --out finished "
                         "(its journal there, ablation.partial.jsonl)")
    ap.add_argument("--status", action="store_true",
                    help="run nothing: say how far the journal under --out is, with the table of the layouts "
                         "it holds every agent's run of")
    ap.add_argument("--report-only", action="store_true",
                    help="run nothing: write the table again from the json under --out (after a change to the table)")
    args = ap.parse_args(argv)
    missing = [str(p) for p in args.files or () if not p.is_file()]
    if missing:
        ap.error(f"no such layout file: {', '.join(missing)}")
    if args.seeds < 1:
        ap.error("--seeds must be at least 1")
    if not 0.0 <= args.restart_at_drop <= 1.0:
        ap.error("--restart-at-drop must be in [0, 1]")
    layouts = [LAYOUTS / n for n in QUICK] if args.quick else args.files or sample(args.sample)
    agents = agents_arg(ap, args.agents)
    jobs = [job_of(path, agent, args.stall, seed, args.restart_at_drop)
            for path in layouts for seed in range(args.seeds) for agent in agents]
    stem = "ablation_quick" if args.quick else "ablation_files" if args.files else "ablation"
    if args.report_only:
        return report_only(args.out / f"{stem}.json")
    args.out.mkdir(parents=True, exist_ok=True)
    journal = Journal(args.out / f"{stem}.partial.jsonl", resume=args.resume, readonly=args.status)
    if args.status:
        print(journal_status(journal, jobs, code_version()))
        return 0
    where = runner.where_of(args, args.jobs)
    try:
        runs = sweep(jobs, lambda todo: runner.run(run_one, todo, where), journal, code_version())
    except runner.ClusterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    (args.out / f"{stem}.json").write_text(json.dumps([asdict(r) for r in runs], indent=1) + "\n", encoding="utf-8")
    journal.remove()
    write_table(args.out / f"{stem}.md", runs)
    return 0


if __name__ == "__main__":
    raise SystemExit(runner.by_name(main)())
