"""How `conag` ends: the exit codes its subcommands share (`conag run --help` explains them)."""

EXIT_OK = 0
EXIT_ERROR = 1         # something failed (conag run: e.g. the world kept dying as soon as it started)
EXIT_USAGE = 2         # a usage or scenario error (argparse's own code for a bad flag)
EXIT_INCOMPLETE = 3    # conag run: the tick limit passed before the structure was complete
EXIT_STALLED = 4       # conag run: no site was filled for --stall-ticks ticks
EXIT_INTERRUPTED = 130  # Ctrl-C or SIGTERM (128 + SIGINT, as shells report an interrupted command)
