"""What a process declares on a session, undeclared in one place; liveliness as events.

Every subscriber, publisher, queryable and liveliness token a process declares goes into
a `Declarations` (a context manager) and is undeclared when it closes, last declared
first; an entity that fails to undeclare (the session may be closing already) is
skipped, so a shutdown never fails half-way. `token_event` reads a liveliness sample as
(id, alive): the last segment of its key, and whether the token was declared (PUT) or
undeclared or lost with its process (DELETE). `watch_tokens` declares the liveliness
subscriber that delivers those events (tokens already there first); `protocol.bus.inbox.Presence`
keeps the set of ids whose token is up, for a loop that polls it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def undeclare(*entities) -> None:
    """Undeclare each entity in turn (None is skipped); one that fails does not stop the rest."""
    for entity in entities:
        if entity is None:
            continue
        try:
            entity.undeclare()
        except Exception:  # noqa: BLE001 -- the session may be closing already; nothing is left to free
            pass


class Declarations:
    """Entities declared on a session, undeclared together, last declared first.

        with Declarations() as declared:
            sub = declared.add(session.declare_subscriber(key, handler))
            ...
    """

    def __init__(self) -> None:
        self._entities: list = []

    def add(self, entity: T) -> T:
        """Keep `entity` (anything with `undeclare()`) to undeclare on `close`; returns it."""
        self._entities.append(entity)
        return entity

    def close(self) -> None:
        """Undeclare every entity, last declared first."""
        entities, self._entities = self._entities[::-1], []
        undeclare(*entities)

    def __enter__(self) -> Declarations:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def token_event(sample) -> tuple[str, bool]:
    """(id, alive) of a liveliness sample: its key's last segment, and whether it is a PUT."""
    import zenoh

    return str(sample.key_expr).rsplit("/", 1)[-1], sample.kind == zenoh.SampleKind.PUT


def watch_tokens(session, key: str, on_event: Callable[[str, bool], None]):
    """Declare a liveliness subscriber on `key` calling `on_event(id, alive)` from zenoh's
    thread, tokens already there first; returns the subscriber (to undeclare)."""
    return session.liveliness().declare_subscriber(key, lambda sample: on_event(*token_event(sample)),
                                                   history=True)


def wait_for_token(session, key: str, timeout: float, poll: float = 0.05, stop=None) -> bool:
    """Wait until a liveliness token matching `key` reaches `session`; False if none came
    within `timeout` seconds, or once `stop` (an Event) is set. (On the one-host bus, peers
    do not forward for each other: a peer's token comes only over a direct link to it, and
    so does what it publishes.)"""
    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        if any(r.ok is not None for r in session.liveliness().get(key, timeout=min(max(left, 0.05), 0.5))):
            return True
        if time.monotonic() >= deadline or (stop is not None and stop.is_set()):
            return False
        time.sleep(poll)
