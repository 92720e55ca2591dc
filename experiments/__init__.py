"""The experiment scripts behind docs/results/experiments.md, and the analysis they share (`replay`).

Importable as `experiments.*`; run one from the repository root with `python3 -m
experiments.NAME`. The scripts that run many builds hand them to `experiments.runner`: local
worker processes, or a Dask cluster with `--cluster ADDRESS`.
"""
