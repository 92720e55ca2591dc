"""The bus layer: how ConAg processes open zenoh sessions and declare what they use on them.

It sits on the rest of `protocol` and below everything that talks over zenoh (the process
shells in `world_server`, `agent_runtime` and `teacher`, and `conag`); the pure cores never
import it.

* `session`: a process's session (`BusOptions`, `open_session`);
* `declarations`: what a process declared, undeclared in one place (`Declarations`, a
  context manager; `undeclare`), and liveliness samples as (id, alive) events
  (`token_event`, `watch_tokens`);
* `inbox`: the FIFO subscription with a timed receive (`Inbox`), and the set of ids
  whose liveliness token is up, read through one (`Presence`).

zenoh itself is imported only when a session is opened or a liveliness sample read, so
`conag --help` does not load it.
"""

from protocol.bus.declarations import Declarations, token_event, undeclare, wait_for_token, watch_tokens
from protocol.bus.inbox import Inbox, Presence
from protocol.bus.session import (
    DEFAULT_ENDPOINT,
    MODES,
    BusOptions,
    EndpointInUse,
    is_client,
    join_callback_threads,
    make_config,
    open_session,
)

__all__ = ["DEFAULT_ENDPOINT", "MODES", "BusOptions", "Declarations", "EndpointInUse", "Inbox", "Presence", "is_client",
           "join_callback_threads", "make_config", "open_session", "token_event", "undeclare", "wait_for_token",
           "watch_tokens"]
