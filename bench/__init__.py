"""Benchmarks behind docs/results/benchmarks.md; run each from the repository root as `python3 -m bench.<name>`."""
