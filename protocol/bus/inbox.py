"""A FIFO subscription with a timed receive (`Inbox`), and liveliness read through one (`Presence`)."""

from __future__ import annotations

import queue

from protocol.bus.declarations import Declarations, token_event


class Inbox:
    """A FIFO subscription with a timed receive: nothing is dropped, nothing reordered.

    zenoh's FifoChannel keeps every sample but its `recv` cannot time out, so a waiting
    loop would have to poll (and sleep between polls, adding latency). Here zenoh's
    callback puts each sample into a bounded `queue.Queue`: a full queue blocks zenoh's
    thread (back-pressure, like a full FifoChannel), and `get(timeout)` wakes at once.
    Liveliness subscriptions can feed the same inbox (`watch`), so one loop sees both.
    `close()` (or leaving a `with` block) undeclares the subscriptions.
    """

    def __init__(self, capacity: int = 4096):
        self._q: queue.Queue = queue.Queue(maxsize=capacity)
        self._declared = Declarations()

    def subscribe(self, session, key: str) -> Inbox:
        """Also receive every sample published under `key`."""
        self._declared.add(session.declare_subscriber(key, self._q.put))
        return self

    def watch(self, session, key: str) -> Inbox:
        """Liveliness tokens under `key` (those already there first) as PUT / DELETE samples."""
        self._declared.add(session.liveliness().declare_subscriber(key, self._q.put, history=True))
        return self

    def get(self, timeout: float | None = None):
        """The next sample, or None if none came within `timeout` (0: do not wait)."""
        try:
            return self._q.get_nowait() if timeout == 0 else self._q.get(timeout=timeout)
        except queue.Empty:
            return None

    def undeclare(self) -> None:
        """Undeclare the subscriptions."""
        self._declared.close()

    close = undeclare

    def __enter__(self) -> Inbox:
        return self

    def __exit__(self, *exc) -> None:
        self.undeclare()


class Presence:
    """The ids whose liveliness token under `key` is up, for a polling loop.

    Events wait in a FIFO inbox (none is dropped); `update()` applies those that came
    since the last call to `present` and returns them in order.
    """

    def __init__(self, session, key: str, capacity: int = 256):
        self.present: set[str] = set()
        self._inbox = Inbox(capacity).watch(session, key)

    def update(self) -> list[tuple[str, bool]]:
        """Apply the events that arrived since the last call; returns them as (id, alive)."""
        events = []
        while (sample := self._inbox.get(0)) is not None:
            name, alive = token_event(sample)
            if alive:
                self.present.add(name)
            else:
                self.present.discard(name)
            events.append((name, alive))
        return events

    def undeclare(self) -> None:
        """Undeclare the liveliness subscription."""
        self._inbox.undeclare()
