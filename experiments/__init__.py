"""The experiment scripts behind EXPERIMENTS.md, importable as `experiments.*` (and runnable as files)."""
