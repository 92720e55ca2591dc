"""How `conag` ends: the exit codes its subcommands share (`conag run --help` explains them),
and how a process it started ended, in words."""

import signal

EXIT_OK = 0
EXIT_ERROR = 1         # something failed (conag run: e.g. the world kept dying as soon as it started)
EXIT_USAGE = 2         # a usage or scenario error (argparse's own code for a bad flag)
EXIT_INCOMPLETE = 3    # conag run: the tick limit passed before the structure was complete
EXIT_STALLED = 4       # conag run: no site was filled for --stall-ticks ticks
EXIT_INTERRUPTED = 130  # Ctrl-C or SIGTERM (128 + SIGINT, as shells report an interrupted command)


def exit_words(code: int) -> str:
    """How a process ended, from its return code: "exited (code 1)", "was killed (SIGKILL)"."""
    if code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        return f"was killed ({name})"
    return f"exited (code {code})"
