"""The subcommands of `conag`, one module each (`conag.cli.COMMANDS` is their table).

Each module has the subcommand's flags and what it does:

* `configure(parser)` adds its arguments to its (sub)parser; it may also set the parser's
  `description` and `epilog`;
* `run(args) -> int` does the work and returns the exit code (`conag.exit_codes`); a
  ValueError is a usage error (exit 2, its message printed).

A module is imported only when its subcommand is parsed or its help is shown, so it imports
what it needs at the top. Command modules do not import each other: what several share is
in `conag.common` (bus flags, signals), `conag.argtypes` (flag value types),
`conag.agent_settings` (the agent flags) and `conag.exit_codes`.
"""
