"""ConAg's tools above the card's process packages: everything that ships besides them.

* `cli`, `layouts`, `run`, `secure`, `common`: the `conag` command line and the `conag run`
  supervisor, which starts and stops the processes of `world_server`, `agent_runtime` and
  `teacher`;
* `sim`: the in-process simulator (world core and brains in one loop, no bus);
* `recording`: `conag record`, `replay` and `echo` (pure MCAP core and their shells);
* `viewer`: `conag view` (pure scene core, its HTTP shell and the page);
* `baselines`: the reactive lattice baseline of paper §5.2;
* `env`: ConAg as PettingZoo and Gymnasium environments.

Nothing in the card's packages imports `conag`.
"""
