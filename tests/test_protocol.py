"""Tests of the bus protocol: key expressions, message validation and the codec.

The codec's contract is what every receiver relies on: `decode` returns a valid message
or raises ProtocolError, and nothing else, whatever bytes arrive.
"""

from __future__ import annotations

import array
import dataclasses
import math

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import protocol
from protocol import (
    ACTIONS,
    BEHAVIOURS,
    CHANNELS,
    MAX_MESSAGE_BYTES,
    MESSAGE_TYPES,
    SCHEMA_VERSION,
    AgentCommand,
    AgentMap,
    AgentState,
    Blueprint,
    BrickNews,
    CommandRejected,
    Decision,
    Hello,
    LockstepTimeout,
    Perturbation,
    Perturbed,
    PerturbResult,
    ProtocolError,
    Reinforcement,
    RunControl,
    RunControlResult,
    SensorFrame,
    Welcome,
    WorldStatus,
    WorldView,
    decode,
    encode,
    keys,
)

FUZZ = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
ROUNDTRIP = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])

NAN = float("nan")
INF = float("inf")


# --------------------------------------------------------------------------- examples

def _ranges(sectors: int) -> tuple[float, ...]:
    return tuple(-1.0 if (i % 3 == 0) else 0.25 * i for i in range(len(CHANNELS) * sectors))


EXAMPLES: dict[type, object] = {
    Hello: Hello(agent_id="a1", pid=4242),
    Welcome: Welcome(
        world_id="w", agent_id="a1", body=3, tick=120, x=4.5, y=-2.25, heading=1.5707963,
        holding=True, restarts=1, sectors=8, sensor_range=6.0, cell_size=1.0,
        site_xs=(0.0, 1.0, 2.0), site_ys=(5.0, 5.0, 5.0), blueprint_version=2, world_width=12.0,
        world_height=8.0, dt=0.1, max_speed=3.0, max_turn=1.5707963, inertia=0.5, agent_radius=0.3,
        disc_radius=0.5, grab_reach=1.2, grab_cone=1.0471976, drop_tolerance=0.5, touch_margin=0.25,
        sensor_noise=0.02, odometry_noise=0.01, epoch=2**62 + 5,
    ),
    SensorFrame: SensorFrame(
        agent_id="a1", tick=121, heading=3.14, odom_dx=0.1, odom_dy=-0.05, sectors=8,
        ranges=_ranges(8), holding=False, grabbed=True, dropped=False, ate=True, drank=False,
        epoch=2**62 + 5,
    ),
    AgentCommand: AgentCommand(agent_id="a1", tick=121, speed=0.5, turn=-0.2, action="grab"),
    CommandRejected: CommandRejected(agent_id="a1", tick=122, reason="command for tick 121, the world is at 122"),
    WorldStatus: WorldStatus(
        world_id="w", scenario="wall-5", seed=7, mode="lockstep", tick=500, sites_filled=2,
        sites_total=5, bricks_total=9, agents_alive=2, bad_messages=1, completed=False,
        agent_ids=("a1", "a2"), agent_alive=(True, False), agent_distance=(12.5, 3.0),
        agent_grabs=(2, 0), agent_drops=(1, 0), agent_restarts=(0, 3),
        agent_x=(2.5, 7.25), agent_y=(1.5, 0.5), seq=41, agent_present=(True, False),
    ),
    Perturbation: Perturbation(op="move", x=1.0, y=2.0, kind="brick", to_x=3.5, to_y=-1.0, force=True),
    PerturbResult: PerturbResult(ok=True, message="moved brick", tick=501),
    LockstepTimeout: LockstepTimeout(world_id="w", tick=7, agent_ids=("a2", "a3")),
    AgentMap: AgentMap(agent_id="a1", tick=30, layer="brick_nm", size=3, cells=(127, 3, 2, 2, 1, 0, 127, 2, 1)),
    WorldView: WorldView(world_id="w", tick=40, width=12.0, height=8.0, disc_xs=(1.5, 2.5), disc_ys=(0.5, 0.5),
                         disc_kinds=("brick", "food"), site_xs=(4.5,), site_ys=(3.5,), site_filled=(True,),
                         agent_ids=("a1",), agent_alive=(True,), agent_x=(6.0,), agent_y=(2.0,),
                         agent_heading=(0.5,), agent_holding=(False,), wall_xs=(0.5,), wall_ys=(7.5,),
                         cue_xs=(4.5, 9.5), cue_ys=(3.5, 1.5), cue_kinds=("site", "supply")),
    Perturbed: Perturbed(tick=501, op="move", x=1.0, y=2.0, kind="brick", to_x=3.5, to_y=-1.0, ok=True,
                         message="moved brick"),
    Decision: Decision(
        agent_id="a1", tick=121, state=(1.0, 0.0, 0.0, 0.5, 0.25, 0.0),
        outputs=(0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7), arm="drop", motor="go-to-site",
    ),
    Reinforcement: Reinforcement(agent_id="a1", tick=121, seq=17, arm=1, motor=-1),
    RunControl: RunControl(op="restart", agent_id="a2"),
    RunControlResult: RunControlResult(ok=True, message="restarted a2 (pid 4242)"),
    Blueprint: Blueprint(world_id="w", tick=40, version=2, site_xs=(0.5, 1.5), site_ys=(3.5, 3.5)),
    AgentState: AgentState(agent_id="a1", tick=300, behaviour="config_nav", holding=True, sites_open=3,
                           blocker="", behaviour_ticks=tuple(range(len(BEHAVIOURS)))),
    BrickNews: BrickNews(agent_id="a1", tick=40, seen_xs=(3, 7), seen_ys=(12, 12), taken_xs=(5,), taken_ys=(1,),
                         claimed_xs=(), claimed_ys=()),
}


def test_public_api_exports():
    for name in protocol.__all__:
        assert hasattr(protocol, name), name
    assert len(set(MESSAGE_TYPES)) == len(MESSAGE_TYPES)
    assert len({c.__name__ for c in MESSAGE_TYPES}) == len(MESSAGE_TYPES)  # the wire names a type by its name


@pytest.mark.parametrize("cls", MESSAGE_TYPES, ids=lambda c: c.__name__)
def test_roundtrip_every_type(cls):
    msg = EXAMPLES[cls]  # KeyError here means a new message type lacks an example
    data = encode(msg)
    assert isinstance(data, bytes)
    assert len(data) <= MAX_MESSAGE_BYTES
    out = decode(data)
    assert type(out) is cls
    assert out == msg
    assert decode(data, expected=cls) == msg
    assert decode(data, expected=(cls, Hello)) == msg
    assert decode(bytearray(data)) == msg
    assert decode(memoryview(data)) == msg
    # Tuple fields come back as tuples, so decoded messages stay hashable.
    hash(out)


def test_int_values_in_float_fields_roundtrip():
    msg = AgentCommand(agent_id="a1", tick=0, speed=1, turn=0)  # ints where floats are declared
    out = decode(encode(msg))
    assert out == msg
    assert isinstance(out.speed, float) and isinstance(out.turn, float)


def test_encode_rejects_non_messages():
    with pytest.raises(TypeError):
        encode(object())
    with pytest.raises(TypeError):
        encode({"v": 1, "t": "Hello", "f": ["a1", 1]})

    @dataclasses.dataclass(frozen=True)
    class Hello:  # same name, not the protocol's class
        agent_id: str
        pid: int

    with pytest.raises(TypeError):
        encode(Hello("a1", 1))


# --------------------------------------------------------------------------- hypothesis round trips

ids = st.from_regex(r"[A-Za-z0-9_.\-]{1,64}", fullmatch=True)
finite = st.floats(allow_nan=False, allow_infinity=False)
nonneg_int = st.integers(min_value=0, max_value=2**63 - 1)


@st.composite
def sensor_frames(draw):
    sectors = draw(st.integers(min_value=1, max_value=64))
    reading = st.one_of(st.just(-1.0), st.floats(min_value=0.0, allow_infinity=False, allow_nan=False))
    ranges = draw(st.lists(reading, min_size=len(CHANNELS) * sectors, max_size=len(CHANNELS) * sectors))
    return SensorFrame(
        agent_id=draw(ids), tick=draw(nonneg_int), heading=draw(finite), odom_dx=draw(finite),
        odom_dy=draw(finite), sectors=sectors, ranges=tuple(ranges), holding=draw(st.booleans()),
        grabbed=draw(st.booleans()), dropped=draw(st.booleans()), ate=draw(st.booleans()),
        drank=draw(st.booleans()), epoch=draw(nonneg_int),
    )


agent_commands = st.builds(
    AgentCommand, agent_id=ids, tick=nonneg_int, speed=finite, turn=finite,
    action=st.sampled_from(ACTIONS),
)


# 50 examples: each frame holds up to 64 sectors' readings (hundreds of floats, the draws that
# cost), and 50 reach the same codec lines and branches as 100 did (a line tracer, 2026-11-27)
@settings(ROUNDTRIP, max_examples=50)
@given(sensor_frames())
def test_sensorframe_roundtrip_hypothesis(msg):
    data = encode(msg)
    out = decode(data, expected=SensorFrame)
    assert type(out) is SensorFrame
    assert out == msg
    # bit-exact floats (including -0.0)
    assert [math.copysign(1, r) for r in out.ranges] == [math.copysign(1, r) for r in msg.ranges]


@ROUNDTRIP
@given(agent_commands)
def test_agentcommand_roundtrip_hypothesis(msg):
    out = decode(encode(msg), expected=AgentCommand)
    assert type(out) is AgentCommand
    assert out == msg
    assert math.copysign(1, out.speed) == math.copysign(1, msg.speed)


# --------------------------------------------------------------------------- fuzzing decode

def _decode_or_protocol_error(data, expected=None):
    """decode must either return a valid message or raise ProtocolError, nothing else."""
    try:
        out = decode(data, expected=expected)
    except ProtocolError:
        return None
    assert type(out) in MESSAGE_TYPES
    if expected is not None:
        assert isinstance(out, expected)
    # What decodes re-encodes and decodes to the same message.
    assert decode(encode(out)) == out
    return out


@FUZZ
@given(st.binary(max_size=512))
def test_fuzz_random_bytes(data):
    _decode_or_protocol_error(data)


msgpackable = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-(2**63), max_value=2**64 - 1)
    | st.floats() | st.text(max_size=20) | st.binary(max_size=20),
    lambda children: st.lists(children, max_size=5)
    | st.dictionaries(st.text(max_size=5) | st.binary(max_size=5), children, max_size=5),
    max_leaves=20,
)


# 100 examples: an arbitrary object is never a {"v", "t", "f"} envelope, so every one ends at the
# envelope check (30, 100 and 300 examples reach the same codec lines); the envelopes and fields
# are fuzzed by the tests below. The drawing of nested objects was this file's largest cost.
@settings(FUZZ, max_examples=100)
@given(msgpackable)
def test_fuzz_arbitrary_msgpack_objects(obj):
    _decode_or_protocol_error(msgpack.packb(obj, use_bin_type=True))


scalars = (
    st.none() | st.booleans() | st.integers(min_value=-(2**63), max_value=2**64 - 1)
    | st.floats() | st.text(max_size=20) | st.binary(max_size=20)
)
field_values = scalars | st.lists(scalars, max_size=40)


@FUZZ
@given(
    st.sampled_from([c.__name__ for c in MESSAGE_TYPES] + ["Nope", ""]),
    # the schema version itself at times, so that the fields are checked: drawn from 0-3 only, no
    # example got past the version check once the schema passed version 3
    st.one_of(st.just(SCHEMA_VERSION), st.integers(0, SCHEMA_VERSION + 1), scalars),
    st.lists(field_values, max_size=16),
)
def test_fuzz_envelopes_with_arbitrary_fields(name, version, values):
    data = msgpack.packb({"v": version, "t": name, "f": values}, use_bin_type=True)
    _decode_or_protocol_error(data)


@FUZZ
@given(st.sampled_from(MESSAGE_TYPES), st.data())
def test_fuzz_one_field_replaced(cls, data):
    """A valid message with one field swapped for an arbitrary value."""
    values = list(msgpack.unpackb(encode(EXAMPLES[cls]))["f"])
    i = data.draw(st.integers(0, len(values) - 1))
    values[i] = data.draw(msgpackable)
    payload = msgpack.packb({"v": SCHEMA_VERSION, "t": cls.__name__, "f": values}, use_bin_type=True)
    out = _decode_or_protocol_error(payload, expected=cls)
    if out is not None:
        assert type(out) is cls


@FUZZ
@given(st.sampled_from(MESSAGE_TYPES), st.data())
def test_fuzz_byte_flips(cls, data):
    raw = bytearray(encode(EXAMPLES[cls]))
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(raw) - 1))
        raw[i] = data.draw(st.integers(0, 255))
    _decode_or_protocol_error(bytes(raw))


# --------------------------------------------------------------------------- targeted malformed input

def _fields(msg) -> list:
    return list(msgpack.unpackb(encode(msg))["f"])


def _pack(name: str, values: list, version: object = SCHEMA_VERSION) -> bytes:
    return msgpack.packb({"v": version, "t": name, "f": values}, use_bin_type=True)


def _with(msg, **changes) -> bytes:
    """The wire encoding of `msg` with some field values replaced, bypassing validation."""
    names = [f.name for f in dataclasses.fields(msg)]
    values = _fields(msg)
    for name, value in changes.items():
        values[names.index(name)] = value
    return _pack(type(msg).__name__, values)


def _bad(data, expected=None) -> None:
    with pytest.raises(ProtocolError):
        decode(data, expected=expected)


def test_protocol_error_is_a_value_error():
    assert issubclass(ProtocolError, ValueError)


@pytest.mark.parametrize("version", [0, 1, 2, 3, 4, 5, 6, 7, 9, -1, 2**40, "8", b"\x08", None, True, [8], {"v": 8}])
def test_wrong_schema_version(version):
    _bad(_pack("Hello", ["a1", 1], version=version))


@pytest.mark.parametrize("name", ["Nope", "hello", "HELLO", "", "Hello ", None, 1, b"Hello", ["Hello"]])
def test_unknown_type_name(name):
    _bad(msgpack.packb({"v": SCHEMA_VERSION, "t": name, "f": ["a1", 1]}, use_bin_type=True))


@pytest.mark.parametrize(
    "envelope",
    [
        ["Hello", 1, ["a1", 1]],
        {"v": 1, "t": "Hello"},
        {"v": 1, "f": ["a1", 1]},
        {"t": "Hello", "f": ["a1", 1]},
        {"v": 1, "t": "Hello", "f": ["a1", 1], "x": 0},
        {b"v": 1, b"t": "Hello", b"f": ["a1", 1]},
        {"v": 1, "t": "Hello", "f": {"agent_id": "a1", "pid": 1}},
        {"v": 1, "t": "Hello", "f": None},
        {"v": 1, "t": "Hello", "f": "a1"},
        None, 1, "Hello", b"", [],
    ],
    ids=repr,
)
def test_malformed_envelope(envelope):
    _bad(msgpack.packb(envelope, use_bin_type=True))


def test_non_string_map_keys_rejected():
    _bad(msgpack.packb({1: 1, "t": "Hello", "f": ["a1", 1]}))


@pytest.mark.parametrize("cls", MESSAGE_TYPES, ids=lambda c: c.__name__)
def test_missing_field(cls):
    values = _fields(EXAMPLES[cls])
    _bad(_pack(cls.__name__, values[:-1]))
    _bad(_pack(cls.__name__, values[1:]))
    _bad(_pack(cls.__name__, []))


def test_missing_field_with_default_still_rejected():
    # `action` has a default, but the wire format carries every field.
    _bad(_pack("AgentCommand", ["a1", 1, 0.5, 0.0]))


@pytest.mark.parametrize("cls", MESSAGE_TYPES, ids=lambda c: c.__name__)
def test_extra_field(cls):
    values = _fields(EXAMPLES[cls])
    _bad(_pack(cls.__name__, values + [0]))
    _bad(_pack(cls.__name__, values + [None]))


CMD = EXAMPLES[AgentCommand]
FRAME = EXAMPLES[SensorFrame]


@pytest.mark.parametrize(
    "data",
    [
        pytest.param(_with(CMD, tick="5"), id="str-for-int"),
        pytest.param(_with(CMD, tick=5.0), id="float-for-int"),
        pytest.param(_with(CMD, tick=True), id="bool-for-int"),
        pytest.param(_with(CMD, tick=None), id="none-for-int"),
        pytest.param(_with(CMD, tick=[5]), id="list-for-int"),
        pytest.param(_with(CMD, tick=2**63), id="int-over-int64"),
        pytest.param(_with(CMD, speed="0.5"), id="str-for-float"),
        pytest.param(_with(CMD, speed=True), id="bool-for-float"),
        pytest.param(_with(CMD, speed=[0.5]), id="list-for-float"),
        pytest.param(_with(CMD, speed=None), id="none-for-float"),
        pytest.param(_with(CMD, agent_id=1), id="int-for-str"),
        pytest.param(_with(CMD, agent_id=b"a1"), id="bytes-for-str"),
        pytest.param(_with(CMD, action=["grab"]), id="list-for-str"),
        pytest.param(_with(FRAME, holding=1), id="int-for-bool"),
        pytest.param(_with(FRAME, holding=0), id="zero-for-bool"),
        pytest.param(_with(FRAME, holding="true"), id="str-for-bool"),
        pytest.param(_with(FRAME, holding=None), id="none-for-bool"),
        pytest.param(_with(FRAME, sectors=8.0), id="float-for-sectors"),
        pytest.param(_with(FRAME, ranges=1.0), id="scalar-for-tuple"),
        pytest.param(_with(FRAME, ranges=None), id="none-for-tuple"),
        pytest.param(_with(FRAME, ranges={"a": 1.0}), id="map-for-tuple"),
        pytest.param(_with(FRAME, ranges=["x"] * (4 * 8)), id="str-items-in-float-tuple"),
        pytest.param(_with(FRAME, ranges=[[1.0]] * (4 * 8)), id="list-items-in-float-tuple"),
        pytest.param(_with(FRAME, ranges=[True] * (4 * 8)), id="bool-items-in-float-tuple"),
        pytest.param(_with(EXAMPLES[WorldStatus], agent_alive=[1, 0]), id="int-items-in-bool-tuple"),
        # int tuples are checked in C as a whole first: the odd item out must still be caught
        pytest.param(_with(EXAMPLES[AgentMap], cells=[1] * 8 + [True]), id="bool-item-in-int-tuple"),
        pytest.param(_with(EXAMPLES[AgentMap], cells=[1] * 8 + [1.0]), id="float-item-in-int-tuple"),
        pytest.param(_with(EXAMPLES[AgentMap], cells=[1] * 8 + ["1"]), id="str-item-in-int-tuple"),
        pytest.param(_with(EXAMPLES[AgentMap], cells=[1] * 8 + [2**64 - 1]), id="item-over-int64-in-int-tuple"),
        pytest.param(_with(EXAMPLES[AgentMap], cells=[1] * 8 + [-1]), id="map-cell-below-0"),
        pytest.param(_with(EXAMPLES[AgentMap], cells=[1] * 8 + [128]), id="map-cell-over-level"),
        pytest.param(_with(EXAMPLES[WorldStatus], agent_ids=[1, 2]), id="int-items-in-str-tuple"),
        pytest.param(_with(EXAMPLES[Hello], pid=True), id="hello-bool-pid"),
        pytest.param(_with(EXAMPLES[Reinforcement], arm=True), id="reinforcement-bool-arm"),
        pytest.param(_with(EXAMPLES[Reinforcement], arm=1.0), id="reinforcement-float-arm"),
        pytest.param(_with(EXAMPLES[PerturbResult], message="x" * 100_000), id="huge-string"),
    ],
)
def test_wrong_field_type(data):
    _bad(data)


@pytest.mark.parametrize("value", [NAN, INF, -INF])
@pytest.mark.parametrize("field", ["speed", "turn"])
def test_non_finite_float_field(field, value):
    _bad(_with(CMD, **{field: value}))


@pytest.mark.parametrize("value", [NAN, INF, -INF])
def test_non_finite_in_ranges(value):
    ranges = list(FRAME.ranges)
    ranges[5] = value
    _bad(_with(FRAME, ranges=ranges))


@pytest.mark.parametrize("value", [NAN, INF])
def test_non_finite_in_other_float_tuples(value):
    _bad(_with(EXAMPLES[Welcome], site_xs=[0.0, value, 2.0]))
    _bad(_with(EXAMPLES[Decision], state=[value, 0.0, 0.0, 0.0, 0.0, 0.0]))
    _bad(_with(EXAMPLES[WorldStatus], agent_distance=[value, 0.0]))
    _bad(_with(EXAMPLES[Perturbation], to_x=value))
    _bad(_with(EXAMPLES[Welcome], heading=value))


@pytest.mark.parametrize("delta", [-1, 1, -len(CHANNELS), len(CHANNELS)])
def test_ranges_wrong_length(delta):
    ranges = list(FRAME.ranges)
    ranges = ranges[:delta] if delta < 0 else ranges + [1.0] * delta
    _bad(_with(FRAME, ranges=ranges))


def test_ranges_length_must_match_sectors():
    _bad(_with(FRAME, sectors=FRAME.sectors + 1))
    _bad(_with(FRAME, sectors=0, ranges=[]))
    _bad(_with(FRAME, sectors=65, ranges=[1.0] * (len(CHANNELS) * 65)))
    _bad(_with(FRAME, ranges=[-0.5] + list(FRAME.ranges[1:])))


@pytest.mark.parametrize("agent_id", ["a/1", "a*", "*", "**", "a$b", "a?", "a#", "a 1", "a1\n", "", "x" * 65, "é"])
@pytest.mark.parametrize("cls", [c for c in MESSAGE_TYPES if "agent_id" in {f.name for f in dataclasses.fields(c)}],
                         ids=lambda c: c.__name__)
def test_invalid_agent_id(cls, agent_id):
    _bad(_with(EXAMPLES[cls], agent_id=agent_id))


@pytest.mark.parametrize("cls", [Welcome, WorldStatus], ids=lambda c: c.__name__)
def test_invalid_world_id(cls):
    _bad(_with(EXAMPLES[cls], world_id="w/1"))
    _bad(_with(EXAMPLES[cls], world_id="*"))


def test_invalid_agent_id_in_world_status_list():
    _bad(_with(EXAMPLES[WorldStatus], agent_ids=["a1", "a/2"]))


@pytest.mark.parametrize("action", ["fly", "", "GRAB", "grab ", "none\x00"])
def test_bad_action(action):
    _bad(_with(CMD, action=action))


@pytest.mark.parametrize("arm", [0, 2, -2])
def test_reinforcement_arm_out_of_range(arm):
    _bad(_with(EXAMPLES[Reinforcement], arm=arm))
    _bad(_with(EXAMPLES[Reinforcement], motor=arm))


@pytest.mark.parametrize(
    "data",
    [
        pytest.param(_with(CMD, tick=-1), id="negative-tick"),
        pytest.param(_with(EXAMPLES[Hello], pid=-1), id="negative-pid"),
        pytest.param(_with(EXAMPLES[Perturbation], op="explode"), id="bad-op"),
        pytest.param(_with(EXAMPLES[Perturbation], kind="agent"), id="bad-kind"),
        pytest.param(_with(EXAMPLES[WorldStatus], mode="fast"), id="bad-mode"),
        pytest.param(_with(EXAMPLES[WorldStatus], sites_filled=6), id="sites-overfilled"),
        pytest.param(_with(EXAMPLES[WorldStatus], agent_alive=[True]), id="status-list-mismatch"),
        pytest.param(_with(EXAMPLES[WorldStatus], agent_y=b""), id="status-position-mismatch"),
        pytest.param(_with(EXAMPLES[Welcome], site_ys=[1.0]), id="sites-length-mismatch"),
        pytest.param(_with(EXAMPLES[Welcome], sensor_range=0.0), id="zero-sensor-range"),
        pytest.param(_with(EXAMPLES[Welcome], sectors=0), id="zero-sectors"),
        pytest.param(_with(EXAMPLES[Decision], state=[0.0] * 5), id="decision-state-length"),
        pytest.param(_with(EXAMPLES[Decision], outputs=[0.0] * 8), id="decision-outputs-length"),
        pytest.param(_with(EXAMPLES[Decision], arm="x" * 33), id="decision-name-too-long"),
        pytest.param(_with(EXAMPLES[PerturbResult], tick=-1), id="perturb-result-negative-tick"),
        pytest.param(_with(EXAMPLES[Reinforcement], seq=-1), id="negative-seq"),
        pytest.param(_with(EXAMPLES[WorldView], cue_kinds=["site", "paint"]), id="bad-cue-kind"),
        pytest.param(_with(EXAMPLES[WorldView], cue_ys=b""), id="cue-length-mismatch"),
    ],
)
def test_out_of_domain_values(data):
    _bad(data)


def test_oversize_payload():
    _bad(b"\x00" * (MAX_MESSAGE_BYTES + 1))
    # A well-formed envelope that is simply too big is refused on size.
    big = _with(EXAMPLES[PerturbResult], message="x" * MAX_MESSAGE_BYTES)
    assert len(big) > MAX_MESSAGE_BYTES
    with pytest.raises(ProtocolError, match="exceeds"):
        decode(big)
    with pytest.raises(ProtocolError, match="exceeds"):
        decode(bytearray(big))
    with pytest.raises(ProtocolError, match="exceeds"):
        decode(memoryview(big))


def test_oversize_memoryview_counts_bytes_not_items():
    # A memoryview over 8-byte items: its len() is an item count, its size is nbytes.
    view = memoryview(array.array("d", [0.0] * (MAX_MESSAGE_BYTES // 8 + 1)))
    assert view.nbytes > MAX_MESSAGE_BYTES >= len(view)
    with pytest.raises(ProtocolError, match="exceeds"):
        decode(view)


def test_largest_legal_messages_fit():
    n = 4096  # MAX_SITES
    welcome = dataclasses.replace(EXAMPLES[Welcome], site_xs=(1e300,) * n, site_ys=(-1e300,) * n)
    assert decode(encode(welcome)) == welcome
    m = 1024  # MAX_AGENTS_IN_STATUS
    status = dataclasses.replace(
        EXAMPLES[WorldStatus], agent_ids=tuple(f"{i:064d}" for i in range(m)),
        agent_alive=(True,) * m, agent_distance=(1e300,) * m, agent_grabs=(2**62,) * m,
        agent_drops=(2**62,) * m, agent_restarts=(2**62,) * m, agent_x=(1e300,) * m, agent_y=(-1e300,) * m,
        agent_present=(True,) * m,
    )
    assert decode(encode(status)) == status


@pytest.mark.parametrize(
    "data", ["hello", None, 1, 1.5, [1, 2], {"v": 1}, EXAMPLES[Hello], bytearray, array.array("b")],
    ids=repr,
)
def test_non_bytes_input(data):
    _bad(data)


def test_str_of_a_valid_encoding_is_not_bytes():
    _bad(encode(EXAMPLES[Hello]).decode("latin-1"))


@pytest.mark.parametrize("cls", MESSAGE_TYPES, ids=lambda c: c.__name__)
def test_expected_type_mismatch(cls):
    data = encode(EXAMPLES[cls])
    others = tuple(c for c in MESSAGE_TYPES if c is not cls)
    for other in others:
        _bad(data, expected=other)
    _bad(data, expected=others)
    assert decode(data, expected=cls) == EXAMPLES[cls]


@pytest.mark.parametrize("cls", MESSAGE_TYPES, ids=lambda c: c.__name__)
def test_truncated_encoding(cls):
    data = encode(EXAMPLES[cls])
    for n in range(len(data)):
        _bad(data[:n])


@pytest.mark.parametrize("cls", MESSAGE_TYPES, ids=lambda c: c.__name__)
def test_trailing_garbage(cls):
    data = encode(EXAMPLES[cls])
    _bad(data + b"\x00")
    _bad(data + data)


def test_invalid_utf8_string():
    good = encode(EXAMPLES[Hello])
    i = good.index(b"a1")
    _bad(good[:i] + b"\xff\xfe" + good[i + 2:])


def test_deep_nesting():
    # Deeply nested arrays, built by hand (msgpack's packer refuses them).
    data = b"\x91" * 100_000 + b"\x00"
    _bad(data)
    _bad(_pack("Hello", ["a1", [[[[[[1]]]]]]]))


def test_ext_types_rejected():
    ext = msgpack.ExtType(5, b"xx")
    _bad(msgpack.packb({"v": SCHEMA_VERSION, "t": "Hello", "f": ["a1", ext]}))
    _bad(msgpack.packb(ext))
    ts = msgpack.Timestamp(1, 0)
    _bad(msgpack.packb({"v": SCHEMA_VERSION, "t": "Hello", "f": ["a1", ts]}))


# --------------------------------------------------------------------------- local construction

@pytest.mark.parametrize(
    "build",
    [
        pytest.param(lambda: AgentCommand("a1", 0, 0.0, 0.0, action="fly"), id="bad-action"),
        pytest.param(lambda: AgentCommand("a1", 0, NAN, 0.0), id="nan-speed"),
        pytest.param(lambda: AgentCommand("a1", 0, 0.0, INF), id="inf-turn"),
        pytest.param(lambda: AgentCommand("a1", -1, 0.0, 0.0), id="negative-tick"),
        pytest.param(lambda: AgentCommand("a/1", 0, 0.0, 0.0), id="bad-agent-id"),
        pytest.param(lambda: dataclasses.replace(FRAME, ranges=(NAN,) + FRAME.ranges[1:]), id="nan-range"),
        pytest.param(lambda: dataclasses.replace(FRAME, heading=NAN), id="nan-heading"),
        pytest.param(lambda: dataclasses.replace(FRAME, ranges=FRAME.ranges[:-1]), id="short-ranges"),
        pytest.param(lambda: dataclasses.replace(FRAME, sectors=0, ranges=()), id="zero-sectors"),
        pytest.param(lambda: dataclasses.replace(FRAME, ranges=(-0.5,) + FRAME.ranges[1:]), id="negative-range"),
        pytest.param(lambda: Hello("", 1), id="empty-agent-id"),
        pytest.param(lambda: Hello("a1", -1), id="negative-pid"),
        pytest.param(lambda: Reinforcement("a1", 0, 0, 0, 1), id="arm-zero"),
        pytest.param(lambda: Reinforcement("a1", 0, 0, 1, 2), id="motor-two"),
        pytest.param(lambda: Perturbation(op="explode", x=0.0, y=0.0), id="bad-op"),
        pytest.param(lambda: Perturbation(op="add", x=0.0, y=0.0, kind="agent"), id="bad-kind"),
        pytest.param(lambda: dataclasses.replace(EXAMPLES[WorldStatus], mode="fast"), id="bad-mode"),
        pytest.param(lambda: dataclasses.replace(EXAMPLES[WorldStatus], agent_grabs=(1,)), id="status-mismatch"),
        pytest.param(lambda: dataclasses.replace(EXAMPLES[Welcome], site_ys=()), id="sites-mismatch"),
        pytest.param(lambda: dataclasses.replace(EXAMPLES[Decision], state=(0.0,)), id="decision-state"),
        pytest.param(lambda: PerturbResult(ok=True, message="m", tick=-1), id="perturb-negative-tick"),
    ],
)
def test_invalid_construction_raises_value_error(build):
    with pytest.raises(ValueError):
        build()


@pytest.mark.parametrize("cls", MESSAGE_TYPES, ids=lambda c: c.__name__)
def test_constructible_string_fields_decode(cls):
    """Whatever can be built locally can be decoded: free-text fields are bounded at build time."""
    msg = EXAMPLES[cls]
    for f in dataclasses.fields(msg):
        if f.type not in ("str", str) or f.name in ("agent_id", "world_id"):
            continue
        long_msg = None
        try:
            long_msg = dataclasses.replace(msg, **{f.name: "x" * 1000})
        except ValueError:
            continue  # refused at construction: fine
        assert decode(encode(long_msg)) == long_msg, f"{cls.__name__}.{f.name}"


# --------------------------------------------------------------------------- keys

W, A = "w1", "a1"

PER_AGENT = [keys.attach, keys.welcome, keys.sensors, keys.command, keys.command_error, keys.decision,
             keys.reinforcement]
PER_WORLD = [keys.status, keys.perturb, keys.perturbed, keys.lockstep_timeouts, keys.world_token, keys.all_agent_tokens,
             keys.all_teacher_tokens, keys.world_root]


def test_root_carries_the_schema_version():
    # Processes speaking different wire versions must not even see each other's traffic.
    assert f"conag/v{SCHEMA_VERSION}" == keys.ROOT


@pytest.mark.parametrize("fn", PER_WORLD, ids=lambda f: f.__name__)
def test_world_keys_under_root(fn):
    key = fn(W)
    assert key.startswith(keys.ROOT + "/")
    assert f"/{W}" in key
    assert "//" not in key and not key.endswith("/")


@pytest.mark.parametrize("fn", PER_AGENT + [keys.agent_token], ids=lambda f: f.__name__)
def test_agent_keys_under_root_and_contain_agent(fn):
    key = fn(W, A)
    assert key.startswith(keys.ROOT + "/")
    assert key.split("/").count(A) == 1
    assert W in key.split("/")
    assert "*" not in key and "$" not in key
    assert fn(W, A) != fn(W, "a2")
    assert fn(W, A) != fn("w2", A)


def test_agent_keys_are_distinct():
    all_keys = [fn(W, A) for fn in PER_AGENT] + [keys.agent_token(W, A), keys.teacher_token(W, A),
                                                 keys.recorder_token(W, A)]
    all_keys += [fn(W) for fn in PER_WORLD]
    assert len(set(all_keys)) == len(all_keys)


@pytest.mark.parametrize("fn", PER_AGENT, ids=lambda f: f.__name__)
def test_agent_of(fn):
    assert keys.agent_of(fn(W, A)) == A
    assert keys.agent_of(fn(W, "robot_7.x-y")) == "robot_7.x-y"


def test_agent_of_examples():
    assert keys.agent_of(keys.sensors("w", "a1")) == "a1"
    assert keys.agent_of(keys.status(W)) is None
    assert keys.agent_of(keys.all_agents(W, "command")) is None  # '*' is not an id
    assert keys.agent_of(f"{keys.world_root(W)}/agent") is None
    assert keys.agent_of("") is None


@given(ids, ids)
@settings(max_examples=100, deadline=None)
def test_agent_of_roundtrip_hypothesis(world, agent):
    for fn in PER_AGENT:
        assert keys.agent_of(fn(world, agent)) == agent


BAD_IDS = ["", "a/b", "/", "a*", "*", "**", "a$b", "$", "a b", " ", "a?", "a#", "x" * 65, "é", "a\n",
           None, 1, b"a1"]


@pytest.mark.parametrize("bad", BAD_IDS, ids=repr)
def test_invalid_ids_raise(bad):
    with pytest.raises(ValueError):
        keys.check_id(bad)
    with pytest.raises(ValueError):
        keys.sensors(W, bad)
    with pytest.raises(ValueError):
        keys.sensors(bad, A)
    for fn in PER_AGENT + [keys.agent_token, keys.teacher_token]:
        with pytest.raises(ValueError):
            fn(W, bad)
    for fn in PER_WORLD:
        with pytest.raises(ValueError):
            fn(bad)


def test_valid_ids():
    for good in ["a", "A-1", "a_b.c", "x" * 64, "0"]:
        assert keys.check_id(good) == good
        assert keys.agent_of(keys.command(W, good)) == good


def test_wildcards():
    for key in (keys.all_agents(W, "command"), keys.all_agent_tokens(W), keys.all_teacher_tokens(W)):
        assert "*" in key
        assert key.startswith(keys.ROOT + "/")
        assert "**" not in key
    # The wildcard matches exactly the agent segment of the per-agent keys.
    for fn, leaf in [(keys.command, "command"), (keys.sensors, "sensors"), (keys.decision, "decision")]:
        pattern = keys.all_agents(W, leaf).split("/")
        concrete = fn(W, A).split("/")
        assert len(pattern) == len(concrete)
        assert all(p == c or p == "*" for p, c in zip(pattern, concrete))
    pattern = keys.all_agent_tokens(W).split("/")
    concrete = keys.agent_token(W, A).split("/")
    assert len(pattern) == len(concrete) and all(p == c or p == "*" for p, c in zip(pattern, concrete))
    pattern = keys.all_teacher_tokens(W).split("/")
    concrete = keys.teacher_token(W, "t1").split("/")
    assert len(pattern) == len(concrete) and all(p == c or p == "*" for p, c in zip(pattern, concrete))
