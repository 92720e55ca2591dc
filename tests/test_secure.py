"""A secure deployment on disk (`conag keys`, `protocol.bus.deployment`) and the ACL it carries
(`protocol.bus.acl`): private files, random passwords, zenoh parses every file, and each rule lets
exactly the identities of the issue's list do each thing."""

from __future__ import annotations

import json
import stat

import pytest
import zenoh

from conag.cli import main as conag_main
from protocol import keys
from protocol.bus import BusOptions, make_config
from protocol.bus.acl import OBSERVER, OPERATOR, TEACHER, WORLD, access_control, agent_user, roles
from protocol.bus.deployment import (
    DICTIONARY_FILE,
    MANIFEST_FILE,
    ROUTER_FILE,
    DeploymentSpec,
    client_file,
    write_deployment,
)

W = "w0"
AGENTS = ("a1", "a2", "a3")


def _mode(path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def _get(config: zenoh.Config, key: str):
    return json.loads(config.get_json(key))


def test_conag_keys_writes_private_files_with_distinct_random_passwords(tmp_path, capsys):
    out = tmp_path / "deploy"
    assert conag_main(["keys", str(out), "--agents", "3"]) == 0
    assert "agent-a3.json5" in capsys.readouterr().out
    assert _mode(out) == 0o700
    expected = {ROUTER_FILE, DICTIONARY_FILE, MANIFEST_FILE,
                *(client_file(u) for u in (WORLD, TEACHER, OPERATOR, OBSERVER, *map(agent_user, AGENTS)))}
    assert {p.name for p in out.iterdir()} == expected
    for p in out.iterdir():
        if p.name != MANIFEST_FILE:  # the manifest holds no secret
            assert _mode(p) == 0o600, p.name
    lines = (out / DICTIONARY_FILE).read_text(encoding="utf-8").split()
    creds = dict(line.split(":", 1) for line in lines)
    assert set(creds) == {WORLD, TEACHER, OPERATOR, OBSERVER, "agent-a1", "agent-a2", "agent-a3"}
    assert len(set(creds.values())) == len(creds), "passwords must differ"
    assert all(len(pw) >= 24 for pw in creds.values())
    # Each client file carries its own identity's password, and none other.
    for user, pw in creds.items():
        config = zenoh.Config.from_file(str(out / client_file(user)))
        assert _get(config, "transport/auth/usrpwd/user") == user
        assert _get(config, "transport/auth/usrpwd/password") == pw
        assert _get(config, "mode") == "client"
        assert _get(config, "scouting/multicast/enabled") is False
        assert _get(config, "scouting/gossip/enabled") is False
    manifest = json.loads((out / MANIFEST_FILE).read_text(encoding="utf-8"))
    assert manifest["agents"] == list(AGENTS) and manifest["world_id"] == W
    assert not any(pw in (out / MANIFEST_FILE).read_text(encoding="utf-8") for pw in creds.values())

    assert conag_main(["keys", str(out), "--agents", "3"]) == 2
    assert "already holds a deployment" in capsys.readouterr().err
    assert conag_main(["keys", str(out), "--agents", "2", "--force"]) == 0
    assert (out / DICTIONARY_FILE).read_text(encoding="utf-8").split() != lines, "new passwords"


def test_router_file_resolves_its_dictionary_beside_itself(tmp_path):
    write_deployment(tmp_path / "d", DeploymentSpec(("a1",), router="tcp/10.0.0.5:7447", listen="tcp/0.0.0.0:7447"))
    config = make_config(BusOptions(zenoh_config=str(tmp_path / "d" / ROUTER_FILE)))
    assert _get(config, "mode") == "router"
    assert _get(config, "listen/endpoints") == ["tcp/0.0.0.0:7447"]
    assert _get(config, "transport/auth/usrpwd/dictionary_file") == str(tmp_path / "d" / DICTIONARY_FILE)
    assert _get(config, "access_control/enabled") is True
    assert _get(config, "access_control/default_permission") == "deny"
    agent = zenoh.Config.from_file(str(tmp_path / "d" / client_file("agent-a1")))
    assert _get(agent, "connect/endpoints") == ["tcp/10.0.0.5:7447"]


def test_deployment_refuses_bad_ids():
    with pytest.raises(ValueError, match="agent id"):
        DeploymentSpec(("a/1",))
    with pytest.raises(ValueError, match="distinct"):
        DeploymentSpec(("a1", "a1"))


# --- the ACL, read as a table: who may do what on which key ----------------------------------

def _intersects(pattern: str, key: str) -> bool:
    return zenoh.KeyExpr(pattern).intersects(zenoh.KeyExpr(key))


def _who(acl: dict, flow: str, message: str, key: str) -> set[str]:
    """The users some rule allows `message` in `flow` on a key intersecting `key`."""
    allowed_rules = {r["id"] for r in acl["rules"]
                     if r["permission"] == "allow" and flow in r["flows"] and message in r["messages"]
                     and any(_intersects(k, key) for k in r["key_exprs"])}
    users = {s["id"]: s["usernames"] for s in acl["subjects"]}
    return {u for p in acl["policies"] if allowed_rules & set(p["rules"]) for s in p["subjects"] for u in users[s]}


@pytest.fixture(scope="module")
def acl():
    return access_control(roles(W, AGENTS))


def test_the_acl_denies_by_default(acl):
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    assert all(r["permission"] == "allow" for r in acl["rules"])


@pytest.mark.parametrize("agent", AGENTS)
def test_an_agent_publishes_only_its_own_keys_and_reads_only_its_own_frames(acl, agent):
    me = agent_user(agent)
    for leaf in ("command", "decision", "state", "maps"):
        assert _who(acl, "ingress", "put", f"{keys.world_root(W)}/agent/{agent}/{leaf}") == {me}, leaf
    assert _who(acl, "ingress", "liveliness_token", keys.agent_token(W, agent)) == {me}
    assert _who(acl, "ingress", "query", keys.attach(W, agent)) == {me}
    # Its frames: the world alone puts them, and they go out to it and to the read-only roles.
    assert _who(acl, "ingress", "put", keys.sensors(W, agent)) == {WORLD}
    assert _who(acl, "egress", "put", keys.sensors(W, agent)) == {me, OPERATOR, OBSERVER}
    assert _who(acl, "ingress", "declare_subscriber", keys.sensors(W, agent)) == {me, OPERATOR, OBSERVER}
    assert _who(acl, "ingress", "put", keys.reinforcement(W, agent)) == {TEACHER}
    # Its newest decision: only it answers, a viewer (observer, operator) asks.
    assert _who(acl, "ingress", "declare_queryable", keys.decision(W, agent)) == {me}
    assert _who(acl, "ingress", "reply", keys.decision(W, agent)) == {me}
    assert _who(acl, "ingress", "query", keys.decision(W, agent)) == {OPERATOR, OBSERVER}


def test_only_the_world_serves_the_world_and_only_the_operator_perturbs_kills_restarts(acl):
    for key in (keys.attach(W, "a1"), keys.perturb(W), keys.status(W), keys.view(W), keys.blueprint(W)):
        assert _who(acl, "ingress", "declare_queryable", key) == {WORLD}, key
        assert _who(acl, "ingress", "reply", key) == {WORLD}, key
    for key in (keys.status(W), keys.view(W), keys.blueprint(W), keys.perturbed(W), keys.lockstep_timeouts(W),
                keys.welcome(W, "a1"), keys.command_error(W, "a1")):
        assert _who(acl, "ingress", "put", key) == {WORLD}, key
    assert _who(acl, "ingress", "query", keys.perturb(W)) == {OPERATOR}
    assert _who(acl, "ingress", "query", keys.run_control(W)) == {OPERATOR}
    assert _who(acl, "ingress", "declare_queryable", keys.run_control(W)) == {OPERATOR}
    assert _who(acl, "ingress", "liveliness_token", keys.world_token(W)) == {WORLD}
    assert _who(acl, "ingress", "liveliness_token", keys.teacher_token(W, "t")) == {TEACHER}


def test_nothing_outside_the_world_is_allowed(acl):
    for rule in acl["rules"]:
        for key in rule["key_exprs"]:
            assert key.startswith(keys.world_root(W) + "/"), (rule["id"], key)


def test_an_agent_refuses_another_agents_credential_at_once(tmp_path, capsys):
    write_deployment(tmp_path, DeploymentSpec(("a1", "a2")))
    code = conag_main(["agent", "--id", "a1", "--zenoh-config", str(tmp_path / client_file("agent-a2"))])
    assert code == 2 and "holds the credential of agent-a2, not of agent-a1" in capsys.readouterr().err


def test_a_world_through_a_router_is_told_apart(tmp_path):
    """`conag world` sends lockstep frames BLOCK when it is a client of a router (is_client)."""
    from protocol.bus import is_client

    write_deployment(tmp_path, DeploymentSpec(("a1",)))
    assert is_client(BusOptions(zenoh_config=str(tmp_path / client_file(WORLD))), serve=True)
    assert is_client(BusOptions(mode="client", connect=("tcp/127.0.0.1:7447",)), serve=True)
    assert not is_client(BusOptions(), serve=True)
