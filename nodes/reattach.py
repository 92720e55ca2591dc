"""An agent whose world went away and came back attaches again by itself (S7 in docs/design.md).

An agent's session can lose its world for a while with neither process dying: a network
partition between hosts. The agent's zenoh client then loses its router; zenoh drops
every remote liveliness token it knew (the world's among them), reconnects by itself
when the link is back, and declares the agent's token, subscribers and publishers again.
Meanwhile the world may have seen the agent's token go (the router's lease on the agent
expired): its body stopped, its brick was put down, and after `body_grace_ticks` the body
left the world. A world publishes no frames for an agent it holds for gone, so without
a new Hello the agent would wait for ever on a session that works again.

`Reattach` watches the world's liveliness token. When it goes, the agent says it is
waiting (a warning, not silence); when it is back, a thread of its own sends a new Hello
through the `WorldLink`, retrying until the world answers (the agent's loop is blocked
waiting for a frame, and a zenoh callback must not block on a query). The world answers
with a Welcome, a restart if it had held the agent for gone (the body back where it
stands, or at the free cell nearest where it left), and publishes the agent's frame,
which wakes the agent's loop; `WorldLink.welcome` is then the new Welcome, which the
agent compares with the one it acts on (`nodes.agent`). The same happens when the world
process itself is replaced by one with the same world id.
"""

from __future__ import annotations

import logging
import threading

from bus import watch_tokens
from nodes.world_link import AttachError, WorldLink
from protocol import keys

log = logging.getLogger("conag.agent")


class Reattach:
    """Attach `link` again whenever its world's token goes and comes back; `close` stops it.

    `attach_timeout`: seconds of one attach attempt (Hello retried within it); attempts go
    on, each logged, until one succeeds, the world goes again or `close` is called.
    `attached` counts the attaches made here (not the first one, which the agent makes).
    """

    def __init__(self, session, link: WorldLink, attach_timeout: float = 10.0):
        self.link, self.attach_timeout = link, attach_timeout
        self.attached = 0
        self._lock = threading.Lock()
        self._lost = False       # the world's token went after the link had attached
        self._generation = 0     # +1 each time the world's token comes back: a stale thread stops
        self._closed = False
        self._sub = watch_tokens(session, keys.world_token(link.world_id), self._on_world)

    def _on_world(self, _world: str, alive: bool) -> None:
        """zenoh's thread: note the loss, or start the attach thread when the world is back."""
        with self._lock:
            if self._closed:
                return
            if not alive:
                if self.link.welcome is not None and not self._lost:
                    self._lost = True
                    log.warning("agent %s lost world %s (its liveliness token went): waiting for it",
                                self.link.agent_id, self.link.world_id)
                return
            if not self._lost:
                return  # the token seen at subscribing, or a world never lost
            self._lost = False
            self._generation += 1
            generation = self._generation
        log.warning("agent %s: world %s is back: attaching again", self.link.agent_id, self.link.world_id)
        threading.Thread(target=self._attach, args=(generation,), daemon=True,
                         name=f"reattach-{self.link.agent_id}").start()

    def _current(self, generation: int) -> bool:
        with self._lock:
            return not self._closed and not self._lost and generation == self._generation

    def _attach(self, generation: int) -> None:
        while self._current(generation):
            try:
                welcome = self.link.attach(timeout=self.attach_timeout)
            except AttachError as exc:
                log.warning("%s; still trying", exc)
                continue
            except Exception:  # the session closed under us: the agent is stopping
                if self._current(generation):
                    log.exception("agent %s: attaching again failed", self.link.agent_id)
                return
            self.attached += 1
            log.warning("agent %s attached again to world %s: body %d at (%.2f, %.2f)%s", self.link.agent_id,
                        self.link.world_id, welcome.body, welcome.x, welcome.y,
                        f", restart {welcome.restarts}" if welcome.restarts else "")
            return

    def close(self) -> None:
        """Stop watching; an attach thread still running gives up at its next attempt."""
        with self._lock:
            self._closed = True
        try:
            self._sub.undeclare()
        except Exception:  # noqa: BLE001 -- the session may be closing already
            pass
