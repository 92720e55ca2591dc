"""ConAg's tools above the card's process packages: everything that ships besides them.

* `cli` and `commands`: the `conag` command line, a table of subcommands with one module
  each; `common`, `argtypes`, `agent_settings`, `exit_codes`: what those modules share;
* `run`, `runs`, `secure`: the `conag run` supervisor, which starts and stops the processes
  of `world_server`, `agent_runtime` and `teacher`, finds runs by name and sets up a secure
  bus;
* `sim`: the in-process simulator (world core and brains in one loop, no bus);
* `recording`: what `conag record`, `replay` and `echo` run (pure MCAP core and their shells);
* `viewer`: what `conag view` runs (pure scene core, its HTTP shell and the page);
* `baselines`: the reactive lattice baseline of paper §5.2;
* `env`: ConAg as PettingZoo and Gymnasium environments.

Nothing in the card's packages imports `conag`.
"""
