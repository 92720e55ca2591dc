"""docs/protocol.md against the code: every message class has a field table there, with
the same fields in the same order and the msgpack type the codec puts on the wire; the
keys, the version and the Welcome's constants it names are the code's."""

from __future__ import annotations

import dataclasses
import re
import typing

import pytest

from protocol import keys
from protocol.messages import ACTIONS, CHANNELS, MESSAGE_TYPES, SCHEMA_VERSION, WELCOME_CONSTANTS
from tests.conftest import ROOT

DOC = (ROOT / "docs" / "protocol.md").read_text(encoding="utf-8")

# How the codec (protocol/codec.py) puts each field type on the wire.
WIRE_TYPES = {
    str: "str", int: "int", bool: "bool", float: "float",
    tuple[float, ...]: "bin float64", tuple[int, ...]: "array of int",
    tuple[bool, ...]: "array of bool", tuple[str, ...]: "array of str",
}
ROW = re.compile(r"^\| (\d+) \| `(\w+)` \| ([a-z0-9 ]+) \| .+ \|$")


def doc_tables() -> dict[str, list[tuple[int, str, str]]]:
    """Message name -> its table's rows (index, field, msgpack type), from the `### `Name`` sections."""
    tables: dict[str, list[tuple[int, str, str]]] = {}
    current = None
    for line in DOC.splitlines():
        heading = re.match(r"^### `(\w+)`$", line)
        if heading:
            current = heading.group(1)
            tables[current] = []
        elif line.startswith("#"):
            current = None
        elif current and (row := ROW.match(line)):
            tables[current].append((int(row.group(1)), row.group(2), row.group(3).strip()))
    return tables


def code_table(cls: type) -> list[tuple[int, str, str]]:
    hints = typing.get_type_hints(cls)
    return [(i, f.name, WIRE_TYPES[hints[f.name]]) for i, f in enumerate(dataclasses.fields(cls))]


def test_every_message_and_no_other_has_a_table():
    assert set(doc_tables()) == {cls.__name__ for cls in MESSAGE_TYPES}


@pytest.mark.parametrize("cls", MESSAGE_TYPES, ids=lambda c: c.__name__)
def test_the_table_lists_the_fields_in_wire_order_with_their_msgpack_types(cls):
    assert doc_tables()[cls.__name__] == code_table(cls)


def test_the_version_keys_and_enumerations_named_are_the_codes():
    assert f"Protocol version: **{SCHEMA_VERSION}**" in DOC and f'{{"v": {SCHEMA_VERSION}, ' in DOC
    assert f"`{keys.ROOT}/world/<world>/`" in DOC

    def doc_form(key: str) -> str:  # conag/v4/world/WORLD/agent/AGENT/command -> `W/agent/<agent>/command`
        rest = key[len(keys.world_root("WORLD")):]
        return "`W" + rest.replace("AGENT", "<agent>").replace("TEACHER", "<teacher>") + "`"

    for key in (keys.attach, keys.sensors, keys.command, keys.command_error, keys.agent_state, keys.decision,
                keys.reinforcement, keys.agent_token):
        assert doc_form(key("WORLD", "AGENT")) in DOC, key.__name__
    for key in (keys.status, keys.blueprint, keys.perturb, keys.run_control, keys.world_token):
        assert doc_form(key("WORLD")) in DOC, key.__name__
    assert doc_form(keys.teacher_token("WORLD", "TEACHER")) in DOC
    assert "`" + "`, `".join(ACTIONS) + "`" in DOC
    assert ", ".join(CHANNELS) in DOC
    for name in WELCOME_CONSTANTS:
        assert f"`{name}`" in DOC.split("## Conventions")[1].split("## Errors")[0], name  # each explained
