"""`stop_on_signals`: a second SIGINT while the first is being handled must not hang.

Python runs a signal handler between any two bytecodes of the main thread, also inside the
first handler's `Event.set()`, which holds the Event's (not re-entrant) lock. CI saw
`conag run` hang for good after two quick Ctrl-Cs (1 run in about 25 here). The test
below puts the process in exactly that state: the Event's lock held by the main thread
when the second signal arrives. It runs in a child process, since the bug is a hang."""

from __future__ import annotations

import subprocess
import sys
import textwrap

from tests.conftest import ROOT

SECOND_SIGNAL_INSIDE_SET = textwrap.dedent("""
    import os, signal
    from conag.common import stop_on_signals

    calls = []
    before = signal.getsignal(signal.SIGINT)   # SIG_IGN where started in the background by a shell
    with stop_on_signals(on_stop=lambda: calls.append("stop")) as stop:
        os.kill(os.getpid(), signal.SIGINT)          # the first Ctrl-C: handled at once
        assert stop.is_set()
        with stop._cond:                              # as inside the first handler's stop.set()
            os.kill(os.getpid(), signal.SIGINT)       # ... the second Ctrl-C arrives
            os.kill(os.getpid(), signal.SIGTERM)      # ... and a SIGTERM from a supervisor
            for _ in range(1000):                     # bytecodes: the handlers run here
                pass
    assert calls == ["stop"], calls                   # on_stop once, for the first signal
    assert signal.getsignal(signal.SIGINT) is before  # given back
    print("done")
""")


def test_a_second_signal_while_the_first_is_handled_does_not_hang():
    proc = subprocess.run([sys.executable, "-c", SECOND_SIGNAL_INSIDE_SET], cwd=ROOT, capture_output=True,
                          text=True, timeout=30)
    assert proc.returncode == 0 and proc.stdout.strip() == "done", proc.stderr


def test_two_signals_in_a_row_stop_once_and_the_handlers_come_back():
    # In this process: the ordinary path, two signals one after the other.
    import os
    import signal

    from conag.common import stop_on_signals

    calls = []
    before = signal.getsignal(signal.SIGINT)   # SIG_IGN where started in the background by a shell
    with stop_on_signals(on_stop=lambda: calls.append(1)) as stop:
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGINT)
        assert stop.wait(5)
    assert calls == [1]
    assert signal.getsignal(signal.SIGINT) is before
