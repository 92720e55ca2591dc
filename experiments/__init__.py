"""The experiment scripts behind docs/results/experiments.md, and the analysis they share (`replay`).

Importable as `experiments.*`; run one from the repository root with `python3 -m
experiments.NAME` (a script path works too, with the project installed).
"""
