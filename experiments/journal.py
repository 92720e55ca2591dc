"""A run journal: a long benchmark's finished runs, one JSON line each, so an interrupted
run (a closed laptop, a killed session, the end of a CI slot) can be resumed without
running again what it already finished (`experiments.generalisation --resume`,
`experiments.ablation --resume`).

Each line is {"run": <when that invocation began>, "at": <its seconds so far>, "key": ...,
"result": ...}; `key` says which job it was and under which settings (a line whose settings
differ from the resumed run's is not used; `code_version` is the code part of a key). Lines
are appended and flushed one at a time: a kill loses at most the line being written, and a
torn last line is dropped on resuming.
"""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
CODE_DIRS = ("agent_runtime", "world_server", "conag/sim")   # what a run's outcome depends on


class Journal:
    """Append-only JSON lines at `path`; `entries` are the lines read when it was opened."""

    def __init__(self, path: Path, *, resume: bool, clock=time.time, readonly: bool = False):
        """`resume`: keep the earlier entries (else the file is started anew). `readonly`: only
        read them, writing nothing (a sweep may be appending to the file meanwhile)."""
        self.path = Path(path)
        self._clock = clock
        self._began = clock()
        self.readonly = readonly
        self.entries: list[dict[str, Any]] = _read(self.path) if resume or readonly else []
        if readonly:
            return
        if not resume:
            self.path.unlink(missing_ok=True)   # a fresh run: nothing earlier counts
        elif self.entries:
            # Written again without a line a kill cut short: the next line must not join it.
            self.path.write_text("".join(json.dumps(e) + "\n" for e in self.entries), encoding="utf-8")

    def results(self) -> dict[tuple, Any]:
        """Results of the earlier entries by key (as a tuple; the newest entry of a key wins)."""
        return {tuple(e["key"]): e["result"] for e in self.entries}

    def earlier_seconds(self) -> float:
        """Wall time of the earlier invocations: each one's last `at`, summed."""
        last: dict[float, float] = {}
        for e in self.entries:
            last[e["run"]] = max(last.get(e["run"], 0.0), e["at"])
        return sum(last.values())

    def append(self, key: Any, result: Any) -> None:
        """Record one finished job now."""
        if self.readonly:
            raise ValueError(f"{self.path}: opened to read only")
        line = json.dumps({"run": self._began, "at": self._clock() - self._began, "key": key, "result": result})
        with self.path.open("a", encoding="utf-8") as f:
            f.write(line + "\n")
            f.flush()

    def remove(self) -> None:
        """The run is complete: its results are written elsewhere."""
        self.path.unlink(missing_ok=True)


def _read(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    entries = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            e = json.loads(line)
        except json.JSONDecodeError:
            continue   # the line a kill cut short
        if isinstance(e, dict) and {"run", "at", "key", "result"} <= e.keys():
            entries.append(e)
    return entries


def code_version(root: Path = ROOT) -> str:
    """The git trees of the code a run depends on, and whether it has uncommitted changes
    ("" outside a git checkout): a journalled run counts on resuming only for the same code
    (a commit elsewhere, the docs, changes nothing)."""
    try:
        trees = subprocess.run(["git", "rev-parse", *(f"HEAD:{d}" for d in CODE_DIRS)], cwd=root,
                               capture_output=True, text=True, timeout=10, check=False)
        dirty = subprocess.run(["git", "status", "--porcelain", "--", *CODE_DIRS], cwd=root,
                               capture_output=True, text=True, timeout=10, check=False)
    except (OSError, subprocess.SubprocessError):
        return ""
    if trees.returncode != 0:
        return ""
    return " ".join(h[:12] for h in trees.stdout.split()) + (" +changes" if dirty.stdout.strip() else "")
