"""L3, L4 / Fig. 9: errors per trial while a student learns the construction sequence from the teacher.

Paper §5.1: a student with random weights (excitatory in [0, 0.5], inhibitory in
[-0.5, 0]) builds in the environment of Fig. 6 while the teacher reinforces its arm and
motor choices; a trial is 1,000 steps, after which the environment is reset and the
agent put back at its start (conag/sim/trials.py says why the bricks are reset too); an
error is a step where the student's (arm, motor) differs from the teacher's. For each
learning rate of the delta rule (agent_runtime/learning.py), and for Q-learning from the
same signals (agent_runtime/qlearning.py), 50 runs: mean and one standard deviation of
the errors per trial, the trial at which the mean reaches zero. Then the trained
students, learning off, are put into novel environments (quick_wall, Fig. 17) and the
teacher counts their errors while they build.

Runs in one process per core (spawn), each run with the real World, Brain, Student /
QLearner and teacher core (`conag.sim.trials`, stepping `conag.sim.loop` in lockstep). Writes
fig9_learning.md (tables), fig9_learning.png (Fig. 9), fig9_learning.json (every run's
errors per trial) and fig9_student.json (a trained student: `conag agent --weights-in`).

    python3 -m experiments.fig9_learning           # full run (about 25 min on 2 cores)
    python3 -m experiments.fig9_learning --quick   # seconds-long smoke run (to a temp dir)
    python3 -m experiments.fig9_learning --agent paper --runs 10   # the paper's agent (issue 33):
                                                   # fig9_learning_paper.md, .json, fig9_student_paper.json
    python3 -m experiments.fig9_learning --cluster tcp://HOST:8786   # on a Dask cluster (experiments/runner.py)
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from agent_runtime.config import AgentConfig
from agent_runtime.learning import Student
from agent_runtime.network import engineered
from agent_runtime.qlearning import QLearner
from conag.sim.trials import run_learning, run_trial, trial_seed
from experiments import runner
from experiments.agents import Agent, add_arguments, chosen
from teacher.core import Teacher
from world_server.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent

# Fig. 9 is the learning agent of §5, before goal sequencing (§6): which sites and bricks
# excite the navigation maps does not change what the network must learn, and the
# committed results were measured with the plain nearest-first agent (of the preset
# `Plan.agent`, with `Plan.without` switched off: `--agent`, `--without`).
AGENT = AgentConfig(goal_sequencing=False)

TRAINING = "scenarios/fig6.toml"
NOVEL = ("scenarios/quick_wall.toml", "scenarios/fig17.toml")
STEM = "fig9_learning"


@dataclass(frozen=True)
class Plan:
    etas: tuple[float, ...] = (0.01, 0.05, 0.2, 0.5)
    runs: int = 50
    trials: int = 20
    ticks: int = 1000
    q_alpha: float = 0.5
    q_gamma: float = 0.5
    seed: int = 9
    novel_students: int = 10   # trained students (runs 0..n-1 of each curve) put into the novel environments
    novel_ticks: int = 5000    # at most this many steps there
    student_eta: float = 0.05  # whose run 0 is saved as fig9_student.json
    agent: str = "default"     # the agent's preset (`--agent`) ...
    without: tuple[str, ...] = ()  # ... and the additions switched off from it (`--without`)

    def curves(self) -> list[tuple[str, float]]:
        return [("delta", eta) for eta in self.etas] + [("q", self.q_alpha)]

    def config(self) -> AgentConfig:
        """The agent the learners drive: AGENT's settings on the plan's preset."""
        return Agent(self.agent, tuple(self.without)).config(goal_sequencing=AGENT.goal_sequencing)


def label(kind: str, eta: float, plan: Plan) -> str:
    if kind == "delta":
        return f"delta rule, eta = {eta:g}"
    return f"Q-learning (alpha = {eta:g}, gamma = {plan.q_gamma:g})"


@dataclass(frozen=True)
class NovelTrial:
    """A learner building a novel scenario from its initial layout (a record of fig9_learning.json)."""

    completed: bool
    ticks: int
    errors: int
    sites_filled: int
    sites_total: int


@dataclass(frozen=True)
class LearningRun:
    """One learner through every trial; the novel environments only for the first `plan.novel_students` runs."""

    kind: str                                            # "delta" or "q"
    eta: float                                           # learning rate (alpha for Q-learning)
    run: int
    errors: tuple[int, ...]                              # per trial
    completed_at: tuple[int | None, ...]                 # per trial
    novel: dict[str, NovelTrial] | None = None           # by scenario stem, learning off
    novel_learning: dict[str, NovelTrial] | None = None  # the same student afterwards, learning on
    student: Student | None = None                       # the trained weights (delta rule only)

    def to_json(self) -> dict:
        """The run as fig9_learning.json stores it: no weights, the novel keys only where the run has them."""
        out: dict = dict(kind=self.kind, eta=self.eta, run=self.run, errors=list(self.errors),
                         completed_at=list(self.completed_at))
        for key, trials in (("novel", self.novel), ("novel_learning", self.novel_learning)):
            if trials is not None:
                out[key] = {name: asdict(t) for name, t in trials.items()}
        return out


@dataclass(frozen=True)
class Curve:
    """The runs of one learner and rate, and what the report reads off them (trials count from 1)."""

    runs: list[LearningRun]
    errors: np.ndarray                         # runs x trials
    mean: np.ndarray                           # per trial, over the runs
    sd: np.ndarray
    first_zero: int | None                     # first trial whose mean is 0
    stays_zero: int | None                     # first trial from which the mean stays 0
    per_run_first_zero: list[int | None]       # each run's first trial with 0 errors
    built_last: int                            # runs that completed the structure in their last trial


def one_run(job: tuple[str, float, int, Plan]) -> LearningRun:
    """One learner through every trial, then (for the first few runs) the novel environments."""
    kind, eta, run, plan = job
    rng = np.random.default_rng([plan.seed, run])  # run r starts from the same weights at every rate
    learner = Student.random(rng) if kind == "delta" else QLearner(rng, gamma=plan.q_gamma)
    results = run_learning(load_scenario(ROOT / TRAINING), learner, trials=plan.trials, ticks=plan.ticks, eta=eta,
                           seed=plan.seed, run=run, cfg=plan.config())
    novel = novel_learning = None
    if run < plan.novel_students:
        # Learning off first; then (the same student, so last) learning on, as it would in a `conag agent --learn`.
        novel = {Path(p).stem: novel_trial(learner, p, plan, run) for p in NOVEL}
        novel_learning = {Path(p).stem: novel_trial(learner, p, plan, run, eta=eta) for p in NOVEL}
    # a copy of the trained weights: the record should not share the learner's mutable arrays
    student = Student(learner.excite, learner.inhibit) if kind == "delta" else None
    return LearningRun(kind, eta, run, tuple(r.errors for r in results), tuple(r.completed_at for r in results),
                       novel, novel_learning, student)


def novel_trial(learner, path: str, plan: Plan, run: int, eta: float | None = None) -> NovelTrial:
    """Build `path` from its initial layout; the learner learns (at `eta`) only if `eta` is given."""
    r = run_trial(load_scenario(ROOT / path), learner, Teacher(), ticks=plan.novel_ticks, eta=eta or 0.0,
                  seed=trial_seed(plan.seed, run, 10_000), learn=eta is not None, until_complete=True,
                  cfg=plan.config())
    return NovelTrial(completed=r.completed_at is not None, ticks=r.ticks, errors=r.errors,
                      sites_filled=r.sites_filled, sites_total=r.sites_total)


def run_all(plan: Plan, where: runner.Where) -> tuple[list[LearningRun], float]:
    jobs = [(kind, eta, run, plan) for run in range(plan.runs) for kind, eta in plan.curves()]
    total_trials = len(jobs) * plan.trials
    started = time.monotonic()
    done: list[LearningRun] = []
    for finished in runner.run(one_run, jobs, where):
        out = finished.result
        done.append(out)
        elapsed = time.monotonic() - started
        left = elapsed / len(done) * (len(jobs) - len(done))
        print(f"[fig9] {len(done)}/{len(jobs)} runs, {len(done) * plan.trials}/{total_trials} trials done | "
              f"{label(out.kind, out.eta, plan)}, run {out.run}: errors per trial "
              f"{' '.join(map(str, out.errors))} (current {out.errors[-1]}) | "
              f"{elapsed / 60:.1f} min, about {left / 60:.1f} min left", file=sys.stderr, flush=True)
    done.sort(key=lambda o: (o.kind != "delta", o.eta, o.run))
    return done, time.monotonic() - started


def curves_of(done: list[LearningRun], plan: Plan) -> dict[tuple[str, float], Curve]:
    curves = {}
    for kind, eta in plan.curves():
        runs = [o for o in done if o.kind == kind and o.eta == eta]
        errors = np.array([o.errors for o in runs])
        mean = errors.mean(0)
        zero = np.flatnonzero(mean == 0)
        stays = next((t for t in range(plan.trials) if (mean[t:] == 0).all()), None)
        per_run = [next((t + 1 for t, e in enumerate(o.errors) if e == 0), None) for o in runs]
        curves[(kind, eta)] = Curve(runs=runs, errors=errors, mean=mean, sd=errors.std(0),
                                    first_zero=int(zero[0]) + 1 if len(zero) else None,
                                    stays_zero=None if stays is None else stays + 1, per_run_first_zero=per_run,
                                    built_last=sum(o.completed_at[-1] is not None for o in runs))
    return curves


def engineered_baseline(plan: Plan) -> dict[str, NovelTrial]:
    """The engineered network (the teacher's) on the novel environments, by scenario stem: ticks to build."""
    net = engineered()
    return {Path(p).stem: novel_trial(net, p, plan, 0) for p in NOVEL}


def plot(curves, plan: Plan, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    trials = np.arange(1, plan.trials + 1)
    keys = list(curves)
    for i, key in enumerate(keys):
        c = curves[key]
        shift = (i - (len(keys) - 1) / 2) * 0.08
        style = "s--" if key[0] == "q" else "o-"
        ax.errorbar(trials + shift, c.mean, yerr=c.sd, fmt=style, ms=3.5, capsize=2, lw=1.2,
                    label=label(*key, plan))
    ax.set_xlabel(f"trial ({plan.ticks:,} steps each, environment of Fig. 6)")
    ax.set_ylabel("errors per trial (steps where student ≠ teacher)")
    ax.set_title(f"Construction sequence learning (Fig. 9): mean ± 1 sd over {plan.runs} runs")
    ax.set_xticks(trials)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def report(curves, baseline, plan: Plan, seconds: float, where: str, quick: bool) -> str:
    keys = list(curves)
    names = [label(*k, plan) for k in keys]
    lines = [f"# L3, L4 — learning the construction sequence (Fig. 9){' — QUICK smoke run' if quick else ''}", "",
             (f"Written by `python3 -m experiments.{STEM}{' --quick' if quick else ''}{_agent_flags(plan)}` "
              f"in {seconds / 60:.1f} min "
              f"on {where}. Training environment `{TRAINING}` with one agent; {plan.runs} runs per "
             f"curve, {plan.trials} trials of {plan.ticks:,} steps; before each trial the environment is reset "
              "and the agent put at its start (fresh maps, weights kept). Error = a step where the student's "
              "arm or motor output differs from the teacher's (the engineered network of Fig. 8 on the same "
              "state nodes). Run r starts from the same random weights at every learning rate "
              f"(seed [{plan.seed}, r]). Mean ± one standard deviation over the runs."), "",
             "| trial | " + " | ".join(names) + " |", "|---:|" + "---:|" * len(keys)]
    lines.extend(f"| {t + 1} | " + " | ".join(f"{curves[k].mean[t]:.1f} ± {curves[k].sd[t]:.1f}"
                                              for k in keys) + " |" for t in range(plan.trials))

    def row(name, f):
        lines.append(f"| {name} | " + " | ".join(f(curves[k]) for k in keys) + " |")

    def trial(v):
        return "—" if v is None else str(v)

    lines += ["", "| | " + " | ".join(names) + " |", "|---|" + "---:|" * len(keys)]
    row("**first trial with mean errors 0**", lambda c: f"**{trial(c.first_zero)}**")
    row("first trial from which the mean stays 0", lambda c: trial(c.stays_zero))
    row("runs with 0 errors in the last trial", lambda c: f"{int((c.errors[:, -1] == 0).sum())}/{len(c.runs)}")
    row("first zero-error trial of a run: median (max)", lambda c: _median_max(c.per_run_first_zero))
    row("errors in trial 1: mean", lambda c: f"{c.mean[0]:.1f}")
    row("structure completed within the last trial", lambda c: f"{c.built_last}/{len(c.runs)}")

    lines += ["", "## The trained students in novel environments", "",
              (f"The first {plan.novel_students} trained students of each curve, after their last trial, build each "
               f"scenario from its initial layout (at most {plan.novel_ticks:,} steps), first with learning off "
               "(the teacher only counts their errors), then, the same students, with learning on at their "
               "training rate. The engineered network of Fig. 8 (the teacher's) is the reference."), "",
              ("| learner | scenario | learning | completed | steps to complete: median (range) | "
               "errors: mean (max) |"), "|---|---|---|---:|---:|---:|"]
    for name, b in baseline.items():
        lines.append(f"| engineered network (Fig. 8) | {name} | — | {'yes' if b.completed else 'no'} | "
                     f"{b.ticks} | {b.errors} |")
    for field, mode in (("novel", "off"), ("novel_learning", "on")):
        for k in keys:
            novel = [trials for o in curves[k].runs if (trials := getattr(o, field)) is not None]
            for name in baseline:
                rs = [n[name] for n in novel]
                done = [r.ticks for r in rs if r.completed]
                steps = f"{int(np.median(done))} ({min(done)}-{max(done)})" if done else "—"
                errs = [r.errors for r in rs]
                lines.append(f"| {label(*k, plan)} | {name} | {mode} | {len(done)}/{len(rs)} | {steps} | "
                             f"{np.mean(errs):.1f} ({max(errs)}) |")
    return "\n".join(lines) + "\n"


def _agent_flags(plan: Plan) -> str:
    """The --agent and --without flags of a plan's agent ("" for the default)."""
    flags = "" if plan.agent == "default" else f" --agent {plan.agent}"
    return flags + (f" --without {','.join(plan.without)}" if plan.without else "")


def _median_max(values) -> str:
    reached = [v for v in values if v is not None]
    missing = len(values) - len(reached)
    text = f"{int(np.median(reached))} ({max(reached)})" if reached else "—"
    return text + (f", {missing} never" if missing else "")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="seconds-long smoke run (few runs, short trials)")
    parser.add_argument("--out", type=Path, default=None,
                        help="output directory (default: experiments/, or the temp directory for --quick)")
    parser.add_argument("--runs", type=int, help="runs per curve (default 50)")
    parser.add_argument("--trials", type=int, help="trials per run (default 20)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 2, help="worker processes")
    runner.add_cluster_argument(parser)
    add_arguments(parser)
    args = parser.parse_args(argv)
    agent = chosen(parser, args)
    plan = Plan(etas=(0.05, 0.2, 0.5), runs=2, trials=3, ticks=200, novel_students=1, novel_ticks=400) \
        if args.quick else Plan()
    plan = Plan(**{**asdict(plan), **{k: v for k, v in (("runs", args.runs), ("trials", args.trials)) if v},
                   "agent": agent.preset, "without": agent.without})
    out = args.out or (Path(tempfile.gettempdir()) if args.quick else ROOT / "experiments")
    out.mkdir(parents=True, exist_ok=True)
    try:
        done, seconds = run_all(plan, runner.where_of(args, args.workers))
    except runner.ClusterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    curves = curves_of(done, plan)
    baseline = engineered_baseline(plan)
    stem, student = f"{STEM}{agent.suffix}", f"fig9_student{agent.suffix}.json"
    plot(curves, plan, out / f"{stem}.png")
    text = report(curves, baseline, plan, seconds, runner.where_of(args, args.workers).describe(), args.quick)
    (out / f"{stem}.md").write_text(text, encoding="utf-8")
    raw = dict(plan=asdict(plan), seconds=seconds, runs=[o.to_json() for o in done])
    (out / f"{stem}.json").write_text(json.dumps(raw) + "\n", encoding="utf-8")
    saved = next(o for o in done if o.kind == "delta" and o.run == 0
                 and o.eta == (plan.student_eta if plan.student_eta in plan.etas else plan.etas[0]))
    assert saved.student is not None  # every delta-rule run keeps its weights
    saved.student.save(out / student)
    print(text)
    print(f"wrote {out / stem}.md, .png, .json and {out / student}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(runner.by_name(main)())
