"""Key expressions of the ConAg bus, as functions of world and agent ids.

Everything lives under one versioned root so that two incompatible protocol versions
never see each other's traffic. Ids are validated here: a `/`, `*`, `$`, `?` or `#` in
an id would silently widen or break a key expression.
"""

from __future__ import annotations

import re

ROOT = "conag/v8"  # v + messages.SCHEMA_VERSION: incompatible versions never meet

# \Z, not $: `$` also matches before a trailing newline, which would let "a1\n" through.
_ID = re.compile(r"^[A-Za-z0-9_.\-]{1,64}\Z")


def check_id(value: str, what: str = "id") -> str:
    """Return `value` if it is a valid world/agent id, else raise ValueError."""
    if not isinstance(value, str) or not _ID.match(value):
        raise ValueError(
            f"invalid {what} {value!r}: expected 1-64 characters from A-Z a-z 0-9 _ . -"
        )
    return value


def valid_id(value: str) -> bool:
    """Whether `value` is a valid world/agent id (`check_id` without the error)."""
    return isinstance(value, str) and bool(_ID.match(value))


def world_root(world: str) -> str:
    """The key prefix of everything about one world."""
    return f"{ROOT}/world/{check_id(world, 'world id')}"


def status(world: str) -> str:
    """Periodic WorldStatus publications (and a queryable answering the latest)."""
    return f"{world_root(world)}/status"


def perturb(world: str) -> str:
    """Queryable: a Perturbation in, a PerturbResult back."""
    return f"{world_root(world)}/perturb"


def blueprint(world: str) -> str:
    """Blueprint publications (reliable) whenever the drop sites change, and a queryable
    answering the current one."""
    return f"{world_root(world)}/blueprint"


def view(world: str) -> str:
    """WorldView publications (every few ticks while someone subscribes) and a queryable
    answering the current one: what a viewer draws."""
    return f"{world_root(world)}/view"


def agent_maps(world: str, agent: str) -> str:
    """AgentMap publications (a debug key): one agent's map snapshots, while someone asks
    for them with a `maps_request_token`."""
    return f"{world_root(world)}/agent/{check_id(agent, 'agent id')}/maps"


MAPS_ALL = "_all_"  # the agent segment of a maps request token that asks every agent


def maps_request_token(world: str, requester: str, every: int, agent: str = MAPS_ALL) -> str:
    """A liveliness token asking `agent` (every agent: MAPS_ALL) for its map snapshot each
    `every` ticks (at ticks that are multiples of it); an agent follows the smallest
    `every` among the tokens up for it."""
    if not (isinstance(every, int) and 1 <= every <= MAPS_EVERY_MAX):
        raise ValueError(f"maps every must be an int from 1 to {MAPS_EVERY_MAX} (ticks)")
    return (f"{world_root(world)}/alive/maps/{check_id(requester, 'requester id')}/"
            f"{check_id(agent, 'agent id')}/{every}")


MAPS_EVERY_MAX = 10**9  # ticks: the longest period a maps request token may ask for


def maps_request_every(key: str) -> int | None:
    """The period (ticks) a maps request token's key asks for: its last segment, ASCII
    digits making 1 to MAPS_EVERY_MAX; None for anything else (a token from a foreign or
    broken process, to ignore). Not `str.isdigit`, which takes '²' and other digits int()
    refuses."""
    every = str(key).rsplit("/", 1)[-1]
    if not (every.isascii() and every.isdigit() and len(every) <= len(str(MAPS_EVERY_MAX))):
        return None
    return int(every) if 1 <= int(every) <= MAPS_EVERY_MAX else None


def maps_requests_for(world: str, agent: str) -> tuple[str, str]:
    """The maps request tokens that concern `agent`, to watch: its own and those for every agent."""
    return (f"{world_root(world)}/alive/maps/*/{check_id(agent, 'agent id')}/*",
            f"{world_root(world)}/alive/maps/*/{MAPS_ALL}/*")


def bricks(world: str, agent: str) -> str:
    """BrickNews publications from one agent (the bricks it sees, takes and heads for)."""
    return f"{world_root(world)}/agent/{check_id(agent, 'agent id')}/bricks"


def agent_state(world: str, agent: str) -> str:
    """AgentState publications from one agent (what it does, what blocks it)."""
    return f"{world_root(world)}/agent/{check_id(agent, 'agent id')}/state"


def perturbed(world: str) -> str:
    """Perturbed publications (reliable): each perturbation the world was asked for, with its
    tick and outcome (the perturb query itself is seen by the world only; this is what a
    recorder keeps)."""
    return f"{world_root(world)}/perturbed"


def lockstep_timeouts(world: str) -> str:
    """LockstepTimeout publications (reliable): the world stepped without some agents' commands."""
    return f"{world_root(world)}/lockstep_timeout"


def run_control(world: str) -> str:
    """Queryable of a running `conag run`: a RunControl in, a RunControlResult back."""
    return f"{world_root(world)}/run/control"


def attach(world: str, agent: str) -> str:
    """Queryable: a Hello in, a Welcome back."""
    return f"{world_root(world)}/agent/{check_id(agent, 'agent id')}/attach"


def welcome(world: str, agent: str) -> str:
    """Welcome publications (reliable): the world's answer to each attach, for whoever
    listens besides the agent (a recorder keeps who attached at which tick, and how)."""
    return f"{world_root(world)}/agent/{check_id(agent, 'agent id')}/welcome"


def sensors(world: str, agent: str) -> str:
    """SensorFrame publications for one agent ("latest wins")."""
    return f"{world_root(world)}/agent/{check_id(agent, 'agent id')}/sensors"


def command(world: str, agent: str) -> str:
    """AgentCommand publications from one agent."""
    return f"{world_root(world)}/agent/{check_id(agent, 'agent id')}/command"


def command_error(world: str, agent: str) -> str:
    """CommandRejected publications: why the world did not take a command on `command`."""
    return f"{world_root(world)}/agent/{check_id(agent, 'agent id')}/error"


def decision(world: str, agent: str) -> str:
    """Decision publications (state nodes and chosen outputs), one a tick, for the teacher
    and a recorder; also the agent's queryable answering its newest one (a viewer asks at
    its display rate instead of taking every tick's)."""
    return f"{world_root(world)}/agent/{check_id(agent, 'agent id')}/decision"


def reinforcement(world: str, agent: str) -> str:
    """Reinforcement publications from the teacher to one student (reliable, never dropped)."""
    return f"{world_root(world)}/agent/{check_id(agent, 'agent id')}/reinforcement"


def all_agents(world: str, leaf: str) -> str:
    """Wildcard over every agent's `leaf` key, e.g. all_agents(w, "command")."""
    return f"{world_root(world)}/agent/*/{leaf}"


def agent_of(key: str) -> str | None:
    """The agent id inside a per-agent key expression, or None if it is not one."""
    parts = str(key).split("/")
    try:
        i = parts.index("agent")
    except ValueError:
        return None
    if i + 1 >= len(parts):
        return None
    return parts[i + 1] if _ID.match(parts[i + 1]) else None


# Liveliness tokens: the world declares one, every agent and teacher declares its own.
def world_token(world: str) -> str:
    """The world server's liveliness token."""
    return f"{world_root(world)}/alive/world"


def agent_token(world: str, agent: str) -> str:
    """An agent process's liveliness token (the world waits for it only while it exists)."""
    return f"{world_root(world)}/alive/agent/{check_id(agent, 'agent id')}"


def all_agent_tokens(world: str) -> str:
    """Every agent's liveliness token, to watch."""
    return f"{world_root(world)}/alive/agent/*"


def teacher_token(world: str, teacher: str) -> str:
    """A teacher's liveliness token (a student publishes decisions once it sees one)."""
    return f"{world_root(world)}/alive/teacher/{check_id(teacher, 'teacher id')}"


def recorder_token(world: str, recorder: str) -> str:
    """A recorder's liveliness token, declared once it hears the world (`conag run --record`
    starts the agents only then, and they attach once they hear it: so the recording holds
    the run from its first tick)."""
    return f"{world_root(world)}/alive/recorder/{check_id(recorder, 'recorder id')}"


def all_recorder_tokens(world: str) -> str:
    """Every recorder's liveliness token: a recorded run's agents wait for one before they attach."""
    return f"{world_root(world)}/alive/recorder/*"


def all_teacher_tokens(world: str) -> str:
    """Every teacher's liveliness token, to watch."""
    return f"{world_root(world)}/alive/teacher/*"
