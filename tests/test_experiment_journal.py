"""The run journal behind `experiments/generalisation.py --resume`: finished runs survive
an interruption, a torn last line is skipped, a fresh run starts empty."""

from __future__ import annotations

from experiments.generalisation import Job, resumed
from experiments.journal import Journal


def _clock(times):
    it = iter(times)
    return lambda: next(it)


def test_a_resumed_journal_holds_what_the_interrupted_run_finished(tmp_path):
    path = tmp_path / "runs.jsonl"
    first = Journal(path, resume=False, clock=_clock([100.0, 130.0, 160.0]))
    first.append(["a.toml", "goal sequencing", 3000], {"ticks": 10})
    first.append(["b.toml", "goal sequencing", 3000], {"ticks": 20})
    with path.open("a", encoding="utf-8") as f:
        f.write('{"run": 100.0, "at": 61.0, "key": ["c.toml"')   # killed while writing

    again = Journal(path, resume=True, clock=_clock([500.0, 540.0]))
    found = {k: v for k, v in again.results().items() if k[2] == 3000}
    assert found == {("a.toml", "goal sequencing", 3000): {"ticks": 10},
                     ("b.toml", "goal sequencing", 3000): {"ticks": 20}}
    assert again.earlier_seconds() == 60.0      # the first invocation ran 60 s
    again.append(["c.toml", "goal sequencing", 3000], {"ticks": 30})
    assert len(Journal(path, resume=True).entries) == 3
    assert Journal(path, resume=True).earlier_seconds() == 60.0 + 40.0


def test_other_settings_do_not_count_and_a_fresh_run_starts_empty(tmp_path):
    path = tmp_path / "runs.jsonl"
    Journal(path, resume=False).append(["a.toml", "nearest-first", 5000, "trees"], {"ticks": 1})
    for job in (Job("a.toml", "nearest-first", 3000, "trees"), Job("a.toml", "nearest-first", 5000, "other")):
        assert resumed(Journal(path, resume=True), [job]) == ([], [job])   # another stall limit, other code
    fresh = Journal(path, resume=False)
    assert fresh.entries == [] and not path.exists()
    fresh.append(["a.toml", "nearest-first", 3000], {"ticks": 2})
    fresh.remove()
    assert not path.exists()
