"""A fork server for a run's agent processes: the imports are paid once, and shared.

Every `conag agent` process imports numpy, numba (22 MB of private memory: LLVM) and the
agent's modules, and loads its compiled kernels, before its first step. A hundred of them
on two cores took 33 s to the first tick and held 52-84 MB PSS each
(docs/results/benchmarks.md, Scale). The fork server does all that once; each agent
process is then a fork of it, sharing those pages copy-on-write, and starts in
milliseconds.

Forking is safe here because of what the server is not: it opens no zenoh session and
runs no thread (OpenBLAS is held to one thread before numpy loads; importing zenoh, numba
and the agent's modules starts none, and the server checks that before it serves). A child
opens its own session after the fork, exactly as a spawned process does, so no session,
socket or runtime thread ever crosses a fork.

One line each way on the server's stdin and stdout (JSON):
  {"spawn": [argv of `conag`]}   ->  {"pid": N}  (or {"error": "..."})
  {"signal": [N, SIG]}           ->  nothing (a signal to a child not yet reaped; never a reused pid)
  (when a child ends)            ->  {"exit": [N, CODE]}  (CODE as Popen's: -SIG if killed)
End of input: the server sends SIGTERM to its children, waits for them a little, and exits.

`ForkServer` is the supervisor's side; `Forked` stands in for a `subprocess.Popen` of one
agent (pid, poll, wait, kill, send_signal).
"""

from __future__ import annotations

import gc
import importlib
import json
import os
import select
import signal
import subprocess
import sys
import threading
import time
import traceback
from dataclasses import dataclass, field

from conag.exit_codes import EXIT_INTERRUPTED, exit_words

# Set before numpy loads, in the server and so in every child: OpenBLAS would otherwise
# start a thread per core at import, and a process with threads must not fork.
_ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
_WARM_LAYOUT = """
name = "warm-up"
seed = 1
agents = 1
tick_mode = "lockstep"
layout = '''
.........
..b...+..
....W.+..
..A...+..
.b.......
'''
"""


# --- the server ------------------------------------------------------------------------


def _threads() -> int:
    return len(os.listdir("/proc/self/task")) if os.path.isdir("/proc/self/task") else 1


def preload(warm: bool = True) -> None:
    """Import what an agent process imports and, with `warm`, load its compiled kernels by
    running a small build in process (what a child then finds in memory)."""
    import conag.cli  # noqa: F401  (the command table; each command imports its module when first used)
    # `conag agent`'s module, loaded as the command table loads it (by name, when used):
    # the fork server runs commands, it does not depend on one.
    importlib.import_module("conag.commands.agent")
    if warm:
        from conag import sim
        from world_server.scenario import parse_scenario
        run = sim.start(parse_scenario(_WARM_LAYOUT, "<warm-up>"))
        run.run(200, until_complete=False)


def _child(argv: list[str], stdout_fd: int) -> None:
    """In the forked child: become `conag ARGV` and never return."""
    code = 1
    try:
        os.dup2(stdout_fd, 1)
        os.close(stdout_fd)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.close(null)
        sys.stdin = open(0, closefd=False)  # noqa: SIM115 (fd 0 is /dev/null now; the server's pipe is gone)
        sys.stdout = os.fdopen(1, "w", buffering=1, closefd=False)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        _title(argv)
        from conag.cli import main
        code = main(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except BaseException as exc:   # noqa: BLE001 (a child's crash is reported as a spawned process's would be)
        if _interrupted(exc):
            code = EXIT_INTERRUPTED   # Ctrl-C or SIGTERM landed inside a library call: stopped, not crashed
        else:
            traceback.print_exc()
            code = 1
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code if isinstance(code, int) else 1)


def _interrupted(exc: BaseException | None) -> bool:
    """Whether `exc` was caused by a stop signal: a KeyboardInterrupt or the commands' stop
    exception, perhaps wrapped by a library it interrupted (numba's loader turns it into a
    SystemError)."""
    seen = 0
    while exc is not None and seen < 20:
        if isinstance(exc, KeyboardInterrupt) or type(exc).__name__ == "_Stopped":
            return True
        exc, seen = exc.__cause__ or exc.__context__, seen + 1
    return False


def _title(argv: list[str]) -> None:
    """Show the child as what it runs, `python -m conag ARGV`, not as the server: `ps`, and
    tools that find an agent by its command line, see the same as for a spawned one."""
    sys.argv = ["conag", *argv]
    try:
        from setproctitle import setproctitle, setthreadtitle
    except ImportError:   # a checkout without it installed: the title stays the server's
        return
    interpreter = os.path.basename(sys.executable)
    setproctitle(" ".join([interpreter, "-m", "conag", *argv]))
    # setproctitle names the main thread after the title too (top, /proc/PID/task/TID/comm):
    # give it back the interpreter's name, as a spawned agent's main thread has.
    setthreadtitle(interpreter)


def _exit_code(status: int) -> int:
    return -os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status)


def serve(stdout_fd: int) -> int:
    """The server's loop: spawn on request, report exits, until end of input."""
    out = sys.stdout
    live: set[int] = set()

    def say(message: dict) -> None:
        out.write(json.dumps(message) + "\n")
        out.flush()

    def reap() -> None:
        for pid in list(live):
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                live.discard(pid)
                say({"exit": [pid, _exit_code(status)]})

    buffer = b""
    while True:
        ready, _, _ = select.select([0], [], [], 0.05)
        reap()
        if not ready:
            continue
        chunk = os.read(0, 65536)
        if not chunk:
            break
        buffer += chunk
        while b"\n" in buffer:
            line, buffer = buffer.split(b"\n", 1)
            if line.strip():
                _handle(json.loads(line), live, say, stdout_fd)
    for pid in live:
        os.kill(pid, signal.SIGTERM)
    deadline = time.monotonic() + 5.0
    while live and time.monotonic() < deadline:
        reap()
        time.sleep(0.05)
    for pid in live:
        os.kill(pid, signal.SIGKILL)
    return 0


def _handle(request: dict, live: set[int], say, stdout_fd: int) -> None:
    if "spawn" in request:
        if _threads() != 1:   # something started a thread: forking now could deadlock a child
            say({"error": f"the fork server has {_threads()} threads; it forks only with one"})
            return
        pid = os.fork()
        if pid == 0:
            _child([str(a) for a in request["spawn"]], stdout_fd)
        live.add(pid)
        say({"pid": pid})
    elif "signal" in request:
        pid, sig = request["signal"]
        if pid in live:   # not reaped yet, so the pid is still this child's (a zombie at worst)
            os.kill(pid, sig)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    stdout_fd = int(args[0])
    os.set_inheritable(stdout_fd, True)
    preload(warm="--no-warm" not in args)
    # Everything loaded so far is moved out of the collector's reach: a collection in a
    # child would otherwise write to every object's header and copy every page it shares.
    gc.collect()
    gc.freeze()
    if _threads() != 1:
        print(f"conag fork server: {_threads()} threads after loading; cannot fork safely", file=sys.stderr)
        return 1
    print(json.dumps({"ready": os.getpid()}), flush=True)
    # Ctrl-C reaches the whole process group: the supervisor stops the children; the server
    # itself ends when its input does.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    return serve(stdout_fd)


# --- the supervisor's side -------------------------------------------------------------


class ForkServerError(RuntimeError):
    """The fork server could not start or could not spawn."""


def not_started(code: int | None, timeout: float) -> str:
    """Why the fork server did not start, from its exit code (None: it is still running). Only
    a server that exited by itself printed why (a traceback, on the supervisor's stderr); one
    killed by a signal printed nothing."""
    if code is None:
        return f"the fork server did not say it was ready within {timeout:g} s"
    return f"the fork server {exit_words(code)} before it was ready" + (" (its error is above)" if code > 0 else "")


@dataclass
class Forked:
    """One agent process spawned by the fork server, with the parts of `subprocess.Popen`
    the supervisor uses."""

    pid: int
    server: ForkServer
    returncode: int | None = None
    stdin: None = None
    _ended: threading.Event = field(default_factory=threading.Event)

    def poll(self) -> int | None:
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if not self._ended.wait(timeout):
            raise subprocess.TimeoutExpired(f"agent pid {self.pid}", timeout or 0.0)
        assert self.returncode is not None
        return self.returncode

    def send_signal(self, sig: int) -> None:
        if self.returncode is None:
            self.server.signal(self.pid, int(sig))

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def _exited(self, code: int) -> None:
        self.returncode = code
        self._ended.set()


class ForkServer:
    """The supervisor's handle on a fork server process: `spawn(argv)` gives a `Forked`.
    A context manager; leaving it ends the server (and any child still running)."""

    def __init__(self, warm: bool = True, start_timeout: float = 120.0):
        self._out_fd = os.dup(sys.stdout.fileno())   # where the children print: our stdout
        cmd = [sys.executable, "-m", "conag.forkserver", str(self._out_fd)] + ([] if warm else ["--no-warm"])
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                     pass_fds=(self._out_fd,), env={**os.environ, **_ONE_THREAD})
        self._lock = threading.Lock()          # one request at a time
        self._replies: list[dict] = []
        self._reply = threading.Condition()
        self._children: dict[int, Forked] = {}
        self._early_exits: dict[int, int] = {}   # exits read before the pid's reply was handled
        ready = self._read_line(start_timeout)
        if ready is None or "ready" not in ready:
            try:
                code: int | None = self.proc.wait(0.5)  # its output ended: it has exited, or is exiting
            except subprocess.TimeoutExpired:
                code = None
            self.close()
            raise ForkServerError(not_started(code, start_timeout))
        self._reader = threading.Thread(target=self._read, name="forkserver-reader", daemon=True)
        self._reader.start()

    def _read_line(self, timeout: float) -> dict | None:
        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        line = self.proc.stdout.readline() if ready else ""
        return json.loads(line) if line.strip() else None

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if not line.strip():
                continue
            message = json.loads(line)
            if "exit" in message:
                pid, code = message["exit"]
                with self._reply:
                    child = self._children.get(pid)
                    if child is None:
                        self._early_exits[pid] = code
                if child is not None:
                    child._exited(code)
            else:
                with self._reply:
                    self._replies.append(message)
                    self._reply.notify_all()
        with self._reply:   # the server is gone: so are its children
            self._replies.append({"error": "the fork server exited"})
            self._reply.notify_all()
            orphans = [c for c in self._children.values() if c.returncode is None]
        for child in orphans:
            child._exited(-signal.SIGKILL)

    def _request(self, message: dict) -> None:
        assert self.proc.stdin is not None
        try:
            self.proc.stdin.write(json.dumps(message) + "\n")
            self.proc.stdin.flush()
        except (OSError, ValueError) as exc:   # a broken pipe; a closed one (ValueError)
            raise ForkServerError(f"the fork server is gone: {exc}") from exc

    def spawn(self, argv: list[str], timeout: float = 30.0) -> Forked:
        """`conag ARGV` in a new process forked from the server."""
        with self._lock:
            self._request({"spawn": list(argv)})
            with self._reply:
                if not self._reply.wait_for(lambda: self._replies, timeout):
                    raise ForkServerError(f"no answer from the fork server in {timeout:g} s")
                reply = self._replies.pop(0)
                if "pid" not in reply:
                    raise ForkServerError(reply.get("error", f"unexpected answer {reply}"))
                child = Forked(reply["pid"], self)
                self._children[child.pid] = child
                early = self._early_exits.pop(child.pid, None)
        if early is not None:
            child._exited(early)
        return child

    def signal(self, pid: int, sig: int) -> None:
        with self._lock:
            try:
                self._request({"signal": [pid, sig]})
            except ForkServerError:
                pass   # the server is gone, and its children with it

    def close(self, grace: float = 10.0) -> None:
        """End the server: it stops its children (SIGTERM, then SIGKILL) and exits."""
        if self.proc.stdin is not None and not self.proc.stdin.closed:
            try:
                self.proc.stdin.close()
            except OSError:
                pass
        try:
            self.proc.wait(grace)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
        if self._out_fd >= 0:
            os.close(self._out_fd)
            self._out_fd = -1

    def __enter__(self) -> ForkServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


if __name__ == "__main__":
    raise SystemExit(main())
