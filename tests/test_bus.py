"""The bus layer: declarations undeclared in one place, liveliness as (id, alive) events."""

from __future__ import annotations

import threading
import time

import pytest

from protocol.bus import Declarations, Inbox, Presence, join_callback_threads, undeclare
from protocol.bus.session import CALLBACK_THREAD


class Entity:
    def __init__(self, name: str, log: list[str], fails: bool = False):
        self.name, self.log, self.fails = name, log, fails

    def undeclare(self) -> None:
        self.log.append(self.name)
        if self.fails:
            raise RuntimeError("the session is closing")


def test_undeclare_skips_none_and_goes_on_after_a_failure():
    log: list[str] = []
    undeclare(Entity("a", log, fails=True), None, Entity("b", log))
    assert log == ["a", "b"]


def test_declarations_undeclare_last_declared_first_once_on_leaving_the_block():
    log: list[str] = []
    with Declarations() as declared:
        first = declared.add(Entity("token", log))
        declared.add(Entity("subscriber", log, fails=True))
        declared.add(Entity("publisher", log))
        assert first.name == "token" and log == []
    assert log == ["publisher", "subscriber", "token"]
    declared.close()
    assert log == ["publisher", "subscriber", "token"]   # nothing is undeclared twice


def test_declarations_undeclare_on_an_exception_too():
    log: list[str] = []
    with pytest.raises(ValueError), Declarations() as declared:  # noqa: PT012 -- the raise is inside the block under test
        declared.add(Entity("subscriber", log))
        raise ValueError("boom")
    assert log == ["subscriber"]


def _until(predicate, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.01)


def test_presence_follows_tokens_there_before_it_and_coming_and_going(bus):
    watcher, holder = bus.server_session(), bus.client_session()
    early = holder.liveliness().declare_token("test/alive/early")
    events: list[tuple[str, bool]] = []
    presence = Presence(watcher, "test/alive/*")

    def seen(event) -> bool:
        events.extend(presence.update())
        return event in events

    _until(lambda: seen(("early", True)))
    late = holder.liveliness().declare_token("test/alive/late")
    _until(lambda: seen(("late", True)))
    assert presence.present == {"early", "late"}
    early.undeclare()
    _until(lambda: seen(("early", False)))
    assert presence.present == {"late"}
    presence.undeclare()
    late.undeclare()


def test_an_inbox_keeps_every_sample_in_order_until_it_is_closed(bus):
    sub, pub = bus.server_session(), bus.client_session()
    with Inbox(capacity=16).subscribe(sub, "test/inbox") as inbox:
        def probe() -> bool:  # until the route is up: then nothing put after is lost
            pub.put("test/inbox", b"probe")
            return inbox.get(0.05) is not None

        _until(probe)
        for i in range(10):
            pub.put("test/inbox", str(i).encode())
        got = []
        while len(got) < 10:
            sample = inbox.get(5.0)
            assert sample is not None
            if sample.payload.to_bytes() != b"probe":
                got.append(sample.payload.to_bytes().decode())
        assert got == [str(i) for i in range(10)]
        assert inbox.get(0) is None


def test_callback_threads_declared_from_a_daemon_thread_are_joined_once_the_session_is_closed(bus):
    # zenoh-python runs a Python callback in a thread that is a daemon if its starter was: exit
    # does not wait for those, and one woken during finalisation aborted `conag replay --verify`.
    session = bus.server_session()

    def callbacks():
        return [t for t in threading.enumerate() if t.name.endswith(CALLBACK_THREAD)]

    before = set(callbacks())
    declared = threading.Thread(target=lambda: session.declare_queryable("test/q", lambda q: None), daemon=True)
    declared.start()
    declared.join(5)
    started = [t for t in callbacks() if t not in before]
    assert started and all(t.daemon for t in started)
    session.close()
    assert join_callback_threads(timeout=5.0)
    assert not any(t.is_alive() for t in started)
