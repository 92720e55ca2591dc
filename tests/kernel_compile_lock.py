"""One compile per kernel across the test workers: a numba kernel with an on-disk cache is
compiled under a file lock named after it, so a worker that wants a kernel another worker is
compiling waits and then loads it from the cache instead of compiling it too.

On a fresh clone every kernel is compiled once, by whichever worker wants it first. Without
the lock the xdist workers walk much the same kernels at much the same time (every build
steps a world and an agent), each compiling its own copy: 15-20 s of CPU a worker before
its first build runs. Numba's dispatcher looks in its cache (reading the index afresh) just
before compiling, so the waiting worker finds the other's result there.

Deadlock-free by construction: the in-process compiler lock (re-entrant, numba's own) is
taken before any file lock, so within a process one thread compiles at a time; and a
process waits for kernel B's lock while holding A's only when A calls B (the kernels it
compiles nested are its callees), so two processes could wait on each other only if the
call graph had a cycle. Locks are released when the process exits, however it exits.
"""

from __future__ import annotations

import fcntl
import hashlib
import tempfile
import threading
from pathlib import Path


def lock_dir_for(root: Path) -> Path:
    """The folder of lock files for the checkout at `root`: one per checkout, so two
    checkouts (whose caches are their own, beside their sources) never wait on each other."""
    digest = hashlib.sha1(str(root.resolve()).encode()).hexdigest()[:12]
    path = Path(tempfile.gettempdir()) / f"conag-kernel-locks-{digest}"
    path.mkdir(exist_ok=True)
    return path


def install(lock_dir: Path) -> None:
    """Wrap numba's `Dispatcher.compile` so that cached kernels compile under their lock."""
    from numba.core.caching import NullCache
    from numba.core.compiler_lock import global_compiler_lock
    from numba.core.dispatcher import Dispatcher

    original = Dispatcher.compile
    if getattr(original, "_kernel_compile_lock", False):
        return
    held = threading.local()

    def compile(self, sig):
        if isinstance(self._cache, NullCache):  # numba's own helpers: nothing to share
            return original(self, sig)
        name = f"{self.py_func.__module__}.{self.py_func.__qualname__}"
        names = held.__dict__.setdefault("names", set())
        if name in names:  # re-entered (a recursive kernel): the lock is ours already
            return original(self, sig)
        with global_compiler_lock, open(lock_dir / f"{name}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            names.add(name)
            try:
                return original(self, sig)
            finally:
                names.discard(name)

    compile._kernel_compile_lock = True  # type: ignore[attr-defined]
    Dispatcher.compile = compile
