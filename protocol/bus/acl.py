"""Who may do what on a secure bus: ConAg's roles as zenoh 1.x `access_control` rules.

A secure deployment (`protocol.bus.deployment`) runs one zenoh router with user/password
authentication; every process is a client of it with its own credential, so every message
crosses the router and its ACL (peers that reach each other directly would bypass it:
zenoh issue #2137). The router denies by default; this module says what each identity is
allowed, as *grants* on key expressions of one world (`protocol.keys`), and compiles them
to zenoh's rules, subjects and policies.

A grant names what a process does; each expands to the messages zenoh checks on both sides
of the router (ingress: from the process; egress: to it):

* `publish` keys: put them (ingress);
* `subscribe` keys: declare a subscriber (ingress) and receive the puts (egress);
* `serve` keys: declare a queryable and reply (ingress), receive the queries (egress);
* `ask` keys: send queries (ingress), receive the replies (egress);
* `token` keys: declare liveliness tokens;
* `watch` keys: subscribe to and query liveliness tokens (ingress), receive them (egress);
* `learn` keys: hear of the subscribers and queryables declared there (egress).

Every identity also learns of the subscribers and queryables declared under the world's root
(egress declarations, which carry no data): a zenoh client does not send a put that no
subscriber it knows of would match, and a publisher's matching status (the world builds a
WorldView only while someone watches) comes from them. Without it an agent's commands would
never leave its process: the world subscribes to `agent/*/command`, which no rule about
`agent/a1/command` alone includes.

The roles (a username each; `agent_user(id)` for agents):

* `world`: publishes every frame, error, welcome, status, view, blueprint; hears every
  command and AgentState; answers attach, perturb, view, status and blueprint queries;
* an agent `a1`: publishes only its own command, decision, state, maps and brick news, and
  declares only its own liveliness token; receives only its own frames, reinforcements and
  errors (and the blueprint, and every agent's brick news); may attach only as itself;
  answers queries for its own newest decision;
  watches the world's token, teachers and maps requests for itself;
* `teacher`: hears every decision, publishes the reinforcements, its own teacher token;
* `operator`: the only one that may perturb the world or ask a `conag run` to kill or restart
  an agent (RunControl); a `conag run` serves its RunControl as the operator; reads everything;
* `observer` (recorder, viewer, `conag status`, `conag echo`): reads everything, asks for
  status, blueprint, view and agents' newest decisions, may ask agents for their maps;
  writes nothing else.

With these rules a process holding `a2`'s credential cannot drive `a1`'s body, read its
frames, declare its token or send its Hello (so it cannot take over the id `a1`); only the
holder of `a1`'s credential can attach as `a1` again (a restart). Pure: no zenoh import.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocol import keys

WORLD, TEACHER, OPERATOR, OBSERVER = "world", "teacher", "operator", "observer"
ROLES = (WORLD, TEACHER, OPERATOR, OBSERVER)

# grant -> ((flow, messages), ...): what zenoh checks for it on each side of the router
_EXPANSION: dict[str, tuple[tuple[str, tuple[str, ...]], ...]] = {
    "publish": (("ingress", ("put", "delete")),),
    "subscribe": (("ingress", ("declare_subscriber",)), ("egress", ("put", "delete"))),
    "serve": (("ingress", ("declare_queryable", "reply")), ("egress", ("query",))),
    "ask": (("ingress", ("query",)), ("egress", ("reply",))),
    "token": (("ingress", ("liveliness_token",)),),
    "watch": (("ingress", ("declare_liveliness_subscriber", "liveliness_query")),
              ("egress", ("liveliness_token", "reply"))),
    "learn": (("egress", ("declare_subscriber", "declare_queryable")),),
}
GRANTS = tuple(_EXPANSION)


def agent_user(agent: str) -> str:
    """The username of agent `agent`'s credential (never one of the ROLES)."""
    return f"agent-{keys.check_id(agent, 'agent id')}"


@dataclass(frozen=True)
class Role:
    """One identity's grants: grant name -> key expressions."""

    user: str
    grants: tuple[tuple[str, tuple[str, ...]], ...]


def world_role(world: str) -> Role:
    """The world server: frames, errors, welcomes and the world's own keys out; commands and
    AgentStates in; attach, perturb, view, status and blueprint answered."""
    w = keys.world_root(world)
    agent = f"{w}/agent/*"
    return Role(WORLD, (
        ("publish", (f"{agent}/sensors", f"{agent}/error", f"{agent}/welcome", keys.status(world),
                     keys.view(world), keys.blueprint(world), keys.perturbed(world),
                     keys.lockstep_timeouts(world))),
        ("subscribe", (keys.all_agents(world, "command"), keys.all_agents(world, "state"))),
        ("serve", (keys.all_agents(world, "attach"), keys.perturb(world), keys.view(world),
                   keys.status(world), keys.blueprint(world))),
        ("token", (keys.world_token(world),)),
        ("watch", (keys.all_agent_tokens(world),)),
    ))


def agent_role(world: str, agent: str) -> Role:
    """Agent `agent`: its own keys only, in and out (see the module)."""
    return Role(agent_user(agent), (
        ("publish", (keys.command(world, agent), keys.decision(world, agent), keys.agent_state(world, agent),
                     keys.agent_maps(world, agent), keys.bricks(world, agent))),
        # Every agent's brick news (`share_bricks`): the one traffic from agent to agent.
        ("subscribe", (keys.sensors(world, agent), keys.reinforcement(world, agent),
                       keys.command_error(world, agent), keys.blueprint(world), keys.all_agents(world, "bricks"))),
        ("ask", (keys.attach(world, agent), keys.blueprint(world), keys.status(world))),
        ("serve", (keys.decision(world, agent),)),  # its newest Decision, to a viewer
        ("token", (keys.agent_token(world, agent),)),
        # The world's token too: an agent whose world dies waits for it and attaches again.
        # A recorder's, so a recorded run's agent attaches once the recorder hears it.
        ("watch", (keys.world_token(world), keys.all_teacher_tokens(world), keys.all_recorder_tokens(world),
                   *keys.maps_requests_for(world, agent))),
    ))


def teacher_role(world: str) -> Role:
    """The teacher: every decision in, every reinforcement out, its own token."""
    return Role(TEACHER, (
        ("publish", (keys.all_agents(world, "reinforcement"),)),
        ("subscribe", (keys.all_agents(world, "decision"),)),
        ("token", (keys.all_teacher_tokens(world),)),
        ("watch", (keys.all_agent_tokens(world), keys.all_recorder_tokens(world))),
    ))


def _reader_grants(world: str) -> tuple[tuple[str, tuple[str, ...]], ...]:
    w = keys.world_root(world)
    return (
        ("subscribe", (f"{w}/**",)),
        ("token", (f"{w}/alive/maps/**", f"{w}/alive/recorder/*")),
        ("watch", (f"{w}/alive/**",)),
    )


def operator_role(world: str) -> Role:
    """The operator: perturb and RunControl (asking and serving), and everything the observer reads."""
    return Role(OPERATOR, (
        ("ask", (keys.perturb(world), keys.run_control(world), keys.status(world), keys.blueprint(world),
                 keys.view(world), keys.all_agents(world, "decision"))),
        ("serve", (keys.run_control(world),)),
        *_reader_grants(world),
    ))


def observer_role(world: str) -> Role:
    """A read-only observer (recorder, viewer, status, echo): reads everything, asks for maps
    and for an agent's newest Decision."""
    return Role(OBSERVER, (
        ("ask", (keys.status(world), keys.blueprint(world), keys.view(world), keys.all_agents(world, "decision"))),
        *_reader_grants(world),
    ))


def roles(world: str, agents: tuple[str, ...]) -> tuple[Role, ...]:
    """Every identity of a deployment: the fixed roles, then one per agent id; each also
    learns of the declarations under the world's root (see the module)."""
    learn = ("learn", (f"{keys.world_root(world)}/**",))
    fixed = (world_role(world), teacher_role(world), operator_role(world), observer_role(world))
    return tuple(Role(r.user, (*r.grants, learn)) for r in (*fixed, *(agent_role(world, a) for a in agents)))


def access_control(roles_: tuple[Role, ...]) -> dict:
    """zenoh's `access_control` section for `roles_`: default deny, one subject per username,
    one policy per subject with the rules its grants expand to."""
    rules, subjects, policies = [], [], []
    for role in roles_:
        subject = f"user:{role.user}"
        subjects.append({"id": subject, "usernames": [role.user]})
        ids = []
        for grant, key_exprs in role.grants:
            if grant not in _EXPANSION:
                raise ValueError(f"unknown grant {grant!r}; expected one of {', '.join(GRANTS)}")
            for flow, messages in _EXPANSION[grant]:
                rule_id = f"{role.user}:{grant}:{flow}"
                rules.append({"id": rule_id, "permission": "allow", "flows": [flow], "messages": list(messages),
                              "key_exprs": list(key_exprs)})
                ids.append(rule_id)
        policies.append({"id": f"policy:{role.user}", "rules": ids, "subjects": [subject]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}
