"""Frozen dataclasses for every message on the ConAg bus.

Each message checks its own domain in `__post_init__` (enumerations, signs, lengths,
finite numbers), so a bad message cannot be built locally any more than it can be
decoded from the wire. The codec adds the wire-level checks (types, version, size).
"""

from __future__ import annotations

import functools
import math
import typing
from dataclasses import dataclass, fields

from protocol.keys import check_id

# 2: the obstacle channel in sensor frames, site perturbations, Blueprint and AgentState.
# 3: the world's constants in Welcome; CommandRejected; WorldStatus.seq; Perturbation.force.
# 4: the world's epoch in Welcome and every SensorFrame (an agent refuses frames of another).
# 5: cues (marks on the floor): SensorFrame.cues and cue_under, the mark / unmark actions and
#    AgentCommand.mark_*, Welcome.cue_reach.
# 6: the cues lying in the world in WorldView (cue_xs, cue_ys, cue_kinds), for viewers and recorders.
# 7: BrickNews between agents, on the key agent/<id>/bricks (AgentConfig.share_bricks).
# 8: Welcome.occlusion: whether the world's sensors occlude (a sector's nearest object of any channel).
# An incompatible change raises this and keys.ROOT together (see docs/protocol.md, Versioning).
SCHEMA_VERSION = 8

# Sensor channels, in the order of SensorFrame.ranges (channel-major).
# Disc-like channels first (food, water, brick, obstacle: fixed `#` cells and the world's
# edge, sensed at the cell centres just outside it), then other agents' bodies.
CHANNELS = ("food", "water", "brick", "obstacle", "agent")
# Disc kinds a scenario or a perturbation can name.
DISC_KINDS = ("food", "water", "brick")
# Gripper / consummatory actions an AgentCommand can carry besides the motors; mark and
# unmark put a cue on, or take one off, the cell at the command's mark offset.
BODY_ACTIONS = ("none", "grab", "drop", "eat", "drink")  # what any body does (the env's action space)
ACTIONS = (*BODY_ACTIONS, "mark", "unmark")
# Kinds of cue (marks on the floor, sensed on a channel of their own: SensorFrame.cues):
# "site" says "drop a brick here", "supply" says "take bricks from around here".
CUE_KINDS = ("site", "supply")
PERTURB_OPS = ("remove", "add", "move", "add_site", "remove_site")
SITE_OPS = ("add_site", "remove_site")  # blueprint changes: a drop site at (x, y) appears or goes
TICK_MODES = ("lockstep", "realtime")
NO_READING = -1.0  # a sector that senses nothing of its colour

MAX_SECTORS = 64
MAX_SITES = 4096
MAX_AGENTS_IN_STATUS = 1024
MAX_STRING = 256  # longest string the codec accepts; free-text fields are bounded here too


@functools.cache
def _float_fields(cls: type) -> tuple[str, ...]:
    hints = typing.get_type_hints(cls)
    return tuple(f.name for f in fields(cls) if hints[f.name] in (float, tuple[float, ...]))


def _finite(msg: object) -> None:
    """Reject NaN and infinity in any float or float tuple field."""
    cls: type = type(msg)  # (a `type` for mypy, which does not take type[object] as hashable)
    for name in _float_fields(cls):
        value = getattr(msg, name)
        values = value if isinstance(value, tuple) else (value,)
        # One sum is finite iff every term is (short of overflow, which the slow path
        # sorts out); this keeps a 64-reading frame cheap to check.
        if math.isfinite(sum(values)):
            continue
        bad = next((v for v in values if not math.isfinite(v)), None)
        if bad is not None:
            raise ValueError(f"{type(msg).__name__}.{name} is not finite: {bad!r}")


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


@dataclass(frozen=True)
class Hello:
    """Agent -> world (as an attach query): attach me to my body, creating it if new."""

    agent_id: str
    pid: int

    def __post_init__(self) -> None:
        check_id(self.agent_id, "agent id")
        _require(self.pid >= 0, "Hello.pid must be >= 0")


# The Welcome fields that state the world's constants: named as in the world's WorldConfig,
# except drop_tolerance (half a cell), which the world works out.
WELCOME_CONSTANTS = ("dt", "max_speed", "max_turn", "inertia", "agent_radius", "disc_radius", "grab_reach",
                     "grab_cone", "drop_tolerance", "touch_margin", "sensor_noise", "odometry_noise",
                     "cue_reach")


@dataclass(frozen=True)
class Welcome:
    """World -> agent: the body it got, its pose now, the blueprint, the world's extent,
    the sensor layout and the world's constants.

    Site coordinates are world coordinates (x east, y north, one unit = one cell).
    The agent seeds its configuration map from them and its pose, once, at attach. The pose
    is the body's after tick `tick`: it already includes the odometry of the frame of that
    tick (the world publishes one right after the Welcome). `sensor_range` is measured from
    the agent's centre to the sensed object's centre (a disc's, a body's, an obstacle cell's).
    """

    world_id: str
    agent_id: str
    body: int
    tick: int
    x: float
    y: float
    heading: float
    holding: bool
    restarts: int
    sectors: int
    sensor_range: float
    cell_size: float
    site_xs: tuple[float, ...]
    site_ys: tuple[float, ...]
    blueprint_version: int = 0   # the Blueprint version these sites are (see Blueprint)
    world_width: float = 0.0     # the world's extent (x from 0 to width, y from 0 to height),
    world_height: float = 0.0    # in world units; 0 when not told. Its edge is a wall.
    # The world's constants (its WorldConfig). The world always sends them; the defaults (0,
    # "not told") only spare local code that builds a Welcome by hand from spelling them out.
    dt: float = 0.0              # simulated seconds per tick
    max_speed: float = 0.0       # AgentCommand.speed is clipped to [0, max_speed], world units per second
    max_turn: float = 0.0        # AgentCommand.turn is clipped to [-max_turn, max_turn], radians per tick
    inertia: float = 0.0         # fraction of the gap to the commanded speed closed per tick
    agent_radius: float = 0.0    # the agent body's radius
    disc_radius: float = 0.0     # every disc's (food, water, brick) radius
    grab_reach: float = 0.0      # grab: agent centre to brick centre at most this ...
    grab_cone: float = 0.0       # ... and the brick's bearing within this many radians of the heading
    drop_tolerance: float = 0.0  # a drop fills a site if the brick's centre (the agent's) is within this
                                 # of the site cell's centre along x and along y (half a cell)
    touch_margin: float = 0.0    # eat / drink: surfaces (body to disc) at most this far apart
    sensor_noise: float = 0.0    # reading error: uniform, zero mean, std sensor_noise x distance
    odometry_noise: float = 0.0  # odometry error: normal, std odometry_noise x distance moved
    epoch: int = 0               # this run of the world: every SensorFrame it sends carries it
    cue_reach: float = 0.0       # a body marks cells within this distance; 0: the world has no cues
    occlusion: bool = False      # a sector reports only the nearest object of any channel (a range
                                 # sensor's view): a channel with no reading may be hidden, not absent

    def __post_init__(self) -> None:
        check_id(self.world_id, "world id")
        check_id(self.agent_id, "agent id")
        _finite(self)
        _require(self.epoch >= 0, "Welcome.epoch must be >= 0")
        _require(self.blueprint_version >= 0, "Welcome.blueprint_version must be >= 0")
        _require(self.world_width >= 0 and self.world_height >= 0, "Welcome world size must be >= 0")
        _require(len(self.site_xs) == len(self.site_ys), "Welcome site_xs/site_ys differ in length")
        _require(len(self.site_xs) <= MAX_SITES, "Welcome has too many sites")
        _require(1 <= self.sectors <= MAX_SECTORS, "Welcome.sectors out of range")
        _require(self.sensor_range > 0 and self.cell_size > 0, "Welcome ranges must be > 0")
        _require(self.body >= 0 and self.tick >= 0 and self.restarts >= 0, "Welcome counts must be >= 0")
        _require(min(getattr(self, name) for name in WELCOME_CONSTANTS) >= 0, "Welcome constants must be >= 0")


# The error messages of the per-tick messages' checks, made once: every frame and command
# is checked on both ends of the bus, and formatting them on each check cost a tenth of it.
_FRAME_CUES = f"SensorFrame.cues must hold 0 or {len(CUE_KINDS)} x sectors values"
_CUE_UNDER = ("", *CUE_KINDS)
_FRAME_CUE_UNDER = f"SensorFrame.cue_under must be '' or one of {CUE_KINDS}"
_FRAME_RANGES = f"SensorFrame.ranges must hold {len(CHANNELS)} x sectors values"
_COMMAND_ACTION = f"AgentCommand.action must be one of {ACTIONS}"
_COMMAND_MARK_KIND = f"AgentCommand.mark_kind must be one of {CUE_KINDS}"


@dataclass(frozen=True)
class SensorFrame:
    """World -> agent, once per tick: what the agent's sensors report.

    `ranges` holds len(CHANNELS) x sectors distances, channel-major; sector k covers
    compass angles [k, k+1) * 2*pi/sectors counter-clockwise from east. NO_READING (-1)
    means nothing of that colour in range. Odometry is the displacement of the last
    tick in the compass frame, as the wheel encoders and compass report it (noisy).
    The flags report the outcome of the action the agent sent for the previous tick.
    `epoch` is the Welcome's: a frame with another epoch is not from the world the agent
    attached to. In a world with cues (Welcome.cue_reach > 0), `cues` holds len(CUE_KINDS) x
    sectors distances to the nearest cue of each kind, laid out as `ranges`, and `cue_under`
    the kind of the cue in the cell under the body's centre ("" for none); a cue covered by
    a disc is not seen. Without cues, `cues` is empty.
    """

    agent_id: str
    tick: int
    heading: float
    odom_dx: float
    odom_dy: float
    sectors: int
    ranges: tuple[float, ...]
    holding: bool
    grabbed: bool = False
    dropped: bool = False
    ate: bool = False
    drank: bool = False
    epoch: int = 0
    cues: tuple[float, ...] = ()
    cue_under: str = ""

    def __post_init__(self) -> None:
        check_id(self.agent_id, "agent id")
        _finite(self)
        _require(self.tick >= 0, "SensorFrame.tick must be >= 0")
        _require(len(self.cues) in (0, len(CUE_KINDS) * self.sectors), _FRAME_CUES)
        _require(all(c >= 0.0 or c == NO_READING for c in self.cues), "SensorFrame cue range < 0")
        _require(self.cue_under in _CUE_UNDER, _FRAME_CUE_UNDER)
        _require(self.epoch >= 0, "SensorFrame.epoch must be >= 0")
        _require(1 <= self.sectors <= MAX_SECTORS, "SensorFrame.sectors out of range")
        _require(len(self.ranges) == len(CHANNELS) * self.sectors, _FRAME_RANGES)
        # Every negative reading must be NO_READING (counted with C-level loops: hot path).
        negatives = len(self.ranges) - sum(map((0.0).__le__, self.ranges))
        _require(self.ranges.count(NO_READING) == negatives, "SensorFrame range < 0")


@dataclass(frozen=True)
class AgentCommand:
    """Agent -> world: motor command (forward speed, turn angle) and one action, for `tick`.

    `mark` puts a cue of `mark_kind` on the cell holding the point (mark_dx, mark_dy) world
    units from the body's centre (world axes), `unmark` takes the cue off that cell; the
    offset must be within Welcome.cue_reach. Other actions ignore the mark fields.
    """

    agent_id: str
    tick: int
    speed: float
    turn: float
    action: str = "none"
    mark_dx: float = 0.0
    mark_dy: float = 0.0
    mark_kind: str = "site"

    def __post_init__(self) -> None:
        check_id(self.agent_id, "agent id")
        _finite(self)
        _require(self.tick >= 0, "AgentCommand.tick must be >= 0")
        _require(self.action in ACTIONS, _COMMAND_ACTION)
        _require(self.mark_kind in CUE_KINDS, _COMMAND_MARK_KIND)


@dataclass(frozen=True)
class CommandRejected:
    """World -> agent: the world did not take a command on this agent's command key, and why.

    Sent for every command it rejects (undecodable, wrong types, unknown action, another
    agent's id, an agent not attached, or in lockstep a tick other than `tick`), each also
    counted in WorldStatus.bad_messages. `tick` is the world's tick when it rejected the
    command: in lockstep, the tick it is waiting for a command for.
    """

    agent_id: str
    tick: int
    reason: str

    def __post_init__(self) -> None:
        check_id(self.agent_id, "agent id")
        _require(self.tick >= 0, "CommandRejected.tick must be >= 0")
        _require(len(self.reason) <= MAX_STRING, "CommandRejected.reason too long")


@dataclass(frozen=True)
class WorldStatus:
    """World -> anyone, periodically: progress of the build and per-agent counters."""

    world_id: str
    scenario: str
    seed: int
    mode: str
    tick: int
    sites_filled: int
    sites_total: int
    bricks_total: int
    agents_alive: int
    bad_messages: int
    completed: bool
    agent_ids: tuple[str, ...] = ()
    agent_alive: tuple[bool, ...] = ()
    agent_distance: tuple[float, ...] = ()
    agent_grabs: tuple[int, ...] = ()
    agent_drops: tuple[int, ...] = ()
    agent_restarts: tuple[int, ...] = ()
    agent_x: tuple[float, ...] = ()   # where each body is now (world coordinates)
    agent_y: tuple[float, ...] = ()
    seq: int = 0  # +1 per status the world publishes: of two readings the higher seq is the newer
    # Whether each body is in the world: False once a gone agent's body has left it (after
    # body_grace_ticks; it collides with nothing and is not sensed), True again when it attaches.
    agent_present: tuple[bool, ...] = ()


    def __post_init__(self) -> None:
        check_id(self.world_id, "world id")
        _finite(self)
        _require(self.mode in TICK_MODES, f"WorldStatus.mode must be one of {TICK_MODES}")
        _require(0 <= self.sites_filled <= self.sites_total, "WorldStatus sites out of range")
        _require(min(self.tick, self.bricks_total, self.agents_alive, self.bad_messages, self.seq) >= 0,
                 "WorldStatus counts must be >= 0")
        n = len(self.agent_ids)
        _require(n <= MAX_AGENTS_IN_STATUS, "WorldStatus lists too many agents")
        _require(len(self.scenario) <= MAX_STRING, "WorldStatus.scenario too long")
        for name in ("agent_alive", "agent_distance", "agent_grabs", "agent_drops", "agent_restarts",
                     "agent_x", "agent_y", "agent_present"):
            _require(len(getattr(self, name)) == n, f"WorldStatus.{name} must match agent_ids")
        for a in self.agent_ids:
            check_id(a, "agent id")


@dataclass(frozen=True)
class Perturbation:
    """Anyone -> world (as a query): change a disc or the blueprint while the world runs.

    `remove` and `move` act on the disc nearest (x, y) within 0.75 cell; `add` puts a
    disc of `kind` at (x, y), refused in a drop site's cell (a brick there would fill it)
    or where the disc would overlap an agent's body, unless `force`; `move` puts the
    removed disc at (to_x, to_y). `add_site` makes the cell holding (x, y) a drop site;
    `remove_site` takes the drop site of that cell out of the blueprint (a brick on it
    becomes a free brick). `kind` and `force` are ignored by the site operations.
    """

    op: str
    x: float
    y: float
    kind: str = "brick"
    to_x: float = 0.0
    to_y: float = 0.0
    force: bool = False

    def __post_init__(self) -> None:
        _finite(self)
        _require(self.op in PERTURB_OPS, f"Perturbation.op must be one of {PERTURB_OPS}")
        _require(self.kind in DISC_KINDS, f"Perturbation.kind must be one of {DISC_KINDS}")


@dataclass(frozen=True)
class PerturbResult:
    """World -> perturber: whether the perturbation was applied, and at which tick."""

    ok: bool
    message: str
    tick: int

    def __post_init__(self) -> None:
        _require(self.tick >= 0, "PerturbResult.tick must be >= 0")
        _require(len(self.message) <= MAX_STRING, "PerturbResult.message too long")


@dataclass(frozen=True)
class Perturbed:
    """World -> anyone (published, reliable): a perturbation it was asked for at `tick`, the
    Perturbation's fields and the PerturbResult's `ok` and `message`.

    The perturb query reaches the world alone; this publication is how a recorder (and a
    replay that reproduces the run) learns what changed and when: it was applied between
    the frames of `tick` and the step that follows them.
    """

    tick: int
    op: str
    x: float
    y: float
    kind: str
    to_x: float
    to_y: float
    ok: bool
    message: str

    def __post_init__(self) -> None:
        _finite(self)
        _require(self.tick >= 0, "Perturbed.tick must be >= 0")
        _require(self.op in PERTURB_OPS, f"Perturbed.op must be one of {PERTURB_OPS}")
        _require(self.kind in DISC_KINDS, f"Perturbed.kind must be one of {DISC_KINDS}")
        _require(len(self.message) <= MAX_STRING, "Perturbed.message too long")

    @classmethod
    def of(cls, p: Perturbation, result: PerturbResult) -> Perturbed:
        """The publication of Perturbation `p` answered by `result`."""
        return cls(result.tick, p.op, p.x, p.y, p.kind, p.to_x, p.to_y, result.ok, result.message)

    def perturbation(self) -> Perturbation:
        """The Perturbation that was asked for, forced: it was applied (a replay must apply it
        too, even where the world would refuse it unforced)."""
        return Perturbation(self.op, self.x, self.y, self.kind, self.to_x, self.to_y, force=True)


@dataclass(frozen=True)
class LockstepTimeout:
    """World -> anyone (published, reliable, only when it happens): in lockstep, the world
    stepped from `tick` without the commands of `agent_ids` (its lockstep timeout passed).

    Their commands for `tick`, when they come, are refused (a lockstep command counts for
    the tick it names only): the bodies kept their speed set points, with no turn and no
    action, for that step, and a replay must step them the same way (`conag.recording.replay`).
    """

    world_id: str
    tick: int
    agent_ids: tuple[str, ...]

    def __post_init__(self) -> None:
        check_id(self.world_id, "world id")
        _require(self.tick >= 0, "LockstepTimeout.tick must be >= 0")
        _require(len(self.agent_ids) <= MAX_AGENTS_IN_STATUS, "LockstepTimeout lists too many agents")
        for a in self.agent_ids:
            check_id(a, "agent id")


@dataclass(frozen=True)
class Decision:
    """Student -> teacher, once per step: its internal state nodes and what it chose.

    `state` holds the six state nodes (Holding-Brick, At-Drop-Site, At-Brick,
    Near-Brick, Brick-Available, Drop-Site-Available); `outputs` the activations of
    the seven construction outputs; `arm` and `motor` the output chosen for each.
    """

    agent_id: str
    tick: int
    state: tuple[float, ...]
    outputs: tuple[float, ...]
    arm: str
    motor: str

    def __post_init__(self) -> None:
        check_id(self.agent_id, "agent id")
        _finite(self)
        _require(len(self.state) == 6, "Decision.state must hold 6 state nodes")
        _require(len(self.outputs) == 7, "Decision.outputs must hold 7 outputs")
        _require(len(self.arm) <= 32 and len(self.motor) <= 32, "Decision output names too long")


@dataclass(frozen=True)
class Reinforcement:
    """Teacher -> student: +1 or -1 for the arm and the motor choice of one decision.

    `seq` increases by one per reinforcement to a student, so a student can tell a gap
    (none is expected: these are sent reliably) from a teacher restart (seq back to 0).
    """

    agent_id: str
    tick: int
    seq: int
    arm: int
    motor: int

    def __post_init__(self) -> None:
        check_id(self.agent_id, "agent id")
        _require(self.arm in (-1, 1) and self.motor in (-1, 1), "Reinforcement signals must be +1 or -1")
        _require(self.tick >= 0 and self.seq >= 0, "Reinforcement counts must be >= 0")


@dataclass(frozen=True)
class Blueprint:
    """World -> agents, whenever the blueprint changes (reliable): every drop site now.

    `version` starts at 0 (the scenario's sites, as in Welcome) and grows by one per
    change; an agent keeps the highest version it has seen. Coordinates are world
    coordinates of the site cells' centres, as in Welcome.
    """

    world_id: str
    tick: int
    version: int
    site_xs: tuple[float, ...]
    site_ys: tuple[float, ...]

    def __post_init__(self) -> None:
        check_id(self.world_id, "world id")
        _finite(self)
        _require(self.tick >= 0 and self.version >= 0, "Blueprint counts must be >= 0")
        _require(len(self.site_xs) == len(self.site_ys), "Blueprint site_xs/site_ys differ in length")
        _require(len(self.site_xs) <= MAX_SITES, "Blueprint has too many sites")


BEHAVIOURS = ("none", "eat", "drink", "avoid", "approach_water", "approach_food", "grab", "drop",
              "config_nav", "brick_nav", "explore", "avoid_red", "approach_red", "unstick")


@dataclass(frozen=True)
class AgentState:
    """Agent -> anyone, every few hundred ticks and when it changes behaviour for long:
    what it is doing and, when it is not building, why (for stall reports).

    `behaviour_ticks` counts the ticks spent in each behaviour of BEHAVIOURS, in that
    order, since the process started. `sites_open` is how many sites it believes still
    missing a brick; `blocker` says in words what keeps it from building ("" if nothing).
    """

    agent_id: str
    tick: int
    behaviour: str
    holding: bool
    sites_open: int
    blocker: str
    behaviour_ticks: tuple[int, ...]

    def __post_init__(self) -> None:
        check_id(self.agent_id, "agent id")
        _require(self.tick >= 0 and self.sites_open >= 0, "AgentState counts must be >= 0")
        _require(self.behaviour in BEHAVIOURS, f"AgentState.behaviour must be one of {BEHAVIOURS}")
        _require(len(self.blocker) <= MAX_STRING, "AgentState.blocker too long")
        _require(len(self.behaviour_ticks) == len(BEHAVIOURS), "AgentState.behaviour_ticks must match BEHAVIOURS")
        _require(min(self.behaviour_ticks) >= 0, "AgentState.behaviour_ticks must be >= 0")


MAX_NEWS_CELLS = 1024  # cells one BrickNews list holds at most (a sender's sight holds far fewer)


@dataclass(frozen=True)
class BrickNews:
    """Agent -> agents, every few ticks, with `AgentConfig.share_bricks` on (best effort):
    what the sender knows of the bricks (agent_runtime.brick_news).

    Cells are the world's grid cells, (x east, y north) as world coordinates over the cell
    size, floored: the free bricks in the sender's sight (`seen_*`), the bricks it took
    since its last news (`taken_*`) and the brick it heads for (`claimed_*`: none or one).
    """

    agent_id: str
    tick: int
    seen_xs: tuple[int, ...]
    seen_ys: tuple[int, ...]
    taken_xs: tuple[int, ...]
    taken_ys: tuple[int, ...]
    claimed_xs: tuple[int, ...]
    claimed_ys: tuple[int, ...]

    def __post_init__(self) -> None:
        check_id(self.agent_id, "agent id")
        _require(self.tick >= 0, "BrickNews.tick must be >= 0")
        for name in ("seen", "taken", "claimed"):
            xs, ys = getattr(self, f"{name}_xs"), getattr(self, f"{name}_ys")
            _require(len(xs) == len(ys), f"BrickNews {name}_xs/{name}_ys differ in length")
            _require(len(xs) <= MAX_NEWS_CELLS, f"BrickNews has too many {name} cells")


RUN_OPS = ("kill", "restart")


@dataclass(frozen=True)
class RunControl:
    """Anyone -> a running `conag run` (as a query): kill or restart one agent process."""

    op: str
    agent_id: str

    def __post_init__(self) -> None:
        _require(self.op in RUN_OPS, f"RunControl.op must be one of {RUN_OPS}")
        check_id(self.agent_id, "agent id")


@dataclass(frozen=True)
class RunControlResult:
    """`conag run` -> the asker: whether it did it."""

    ok: bool
    message: str

    def __post_init__(self) -> None:
        _require(len(self.message) <= MAX_STRING, "RunControlResult.message too long")


MAX_VIEW_ITEMS = 4096  # discs, wall cells, and cues, a WorldView holds at most (a message stays under 256 KiB)


@dataclass(frozen=True)
class WorldView:
    """World -> anyone (a viewer, a recorder): what there is to draw at one tick.

    Published every few ticks while someone subscribes to it, and the answer to a query on
    the same key. Discs lying in the world (a carried brick is not among them: its agent's
    `agent_holding` says so), every drop site and whether it holds a brick, every body with
    its heading, the fixed `#` wall cells, and in a world with cues every cue lying on the
    floor (its cell's centre and kind, covered by a disc or not; none without cues). One
    entry per item in each group of arrays.
    """

    world_id: str
    tick: int
    width: float
    height: float
    disc_xs: tuple[float, ...]
    disc_ys: tuple[float, ...]
    disc_kinds: tuple[str, ...]
    site_xs: tuple[float, ...]
    site_ys: tuple[float, ...]
    site_filled: tuple[bool, ...]
    agent_ids: tuple[str, ...]
    agent_alive: tuple[bool, ...]
    agent_x: tuple[float, ...]
    agent_y: tuple[float, ...]
    agent_heading: tuple[float, ...]
    agent_holding: tuple[bool, ...]
    wall_xs: tuple[float, ...]
    wall_ys: tuple[float, ...]
    cue_xs: tuple[float, ...] = ()
    cue_ys: tuple[float, ...] = ()
    cue_kinds: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        check_id(self.world_id, "world id")
        _finite(self)
        _require(self.tick >= 0 and self.width > 0 and self.height > 0, "WorldView tick/extent out of range")
        groups = (("disc_xs", "disc_ys", "disc_kinds"), ("site_xs", "site_ys", "site_filled"),
                  ("agent_ids", "agent_alive", "agent_x", "agent_y", "agent_heading", "agent_holding"),
                  ("wall_xs", "wall_ys"), ("cue_xs", "cue_ys", "cue_kinds"))
        for group in groups:
            n = len(getattr(self, group[0]))
            for name in group[1:]:
                _require(len(getattr(self, name)) == n, f"WorldView.{name} must match {group[0]}")
        _require(max(len(self.disc_xs), len(self.wall_xs), len(self.cue_xs)) <= MAX_VIEW_ITEMS,
                 "WorldView holds too many discs, walls or cues")
        _require(len(self.site_xs) <= MAX_SITES, "WorldView has too many sites")
        _require(len(self.agent_ids) <= MAX_AGENTS_IN_STATUS, "WorldView lists too many agents")
        _require(all(k in DISC_KINDS for k in self.disc_kinds), f"WorldView.disc_kinds must be among {DISC_KINDS}")
        _require(all(k in CUE_KINDS for k in self.cue_kinds), f"WorldView.cue_kinds must be among {CUE_KINDS}")
        for a in self.agent_ids:
            check_id(a, "agent id")


# The layers of an agent's map snapshot (AgentMap.layer): its six ESMs, both navigation maps
# and the Matching grid.
MAP_LAYERS = ("food", "water", "brick", "obstacle", "config", "agent", "config_nm", "brick_nm", "matching")
MAP_LEVEL = 127  # cell values are 0..MAP_LEVEL (one msgpack byte each)
NM_UNREACHABLE = MAP_LEVEL  # a navigation map cell from which no goal can be reached


@dataclass(frozen=True)
class AgentMap:
    """Agent -> anyone (a viewer, a recorder), on request: one layer of its maps at `tick`.

    `cells` is the size x size grid row by row, row 0 north, columns growing east, the
    agent in the centre cell. ESM layers (food ... agent) and `matching` hold their value in
    [0, 1] times MAP_LEVEL, rounded; the navigation maps (`config_nm`, `brick_nm`) hold the
    path distance to the nearest goal in cells, rounded and capped at MAP_LEVEL - 1, and
    NM_UNREACHABLE where no goal can be reached.
    """

    agent_id: str
    tick: int
    layer: str
    size: int
    cells: tuple[int, ...]

    def __post_init__(self) -> None:
        check_id(self.agent_id, "agent id")
        _require(self.tick >= 0, "AgentMap.tick must be >= 0")
        _require(self.layer in MAP_LAYERS, f"AgentMap.layer must be one of {MAP_LAYERS}")
        _require(1 <= self.size <= 89 and self.size % 2 == 1, "AgentMap.size must be odd, 1 to 89")
        _require(len(self.cells) == self.size * self.size, "AgentMap.cells must hold size x size values")
        # min and max run in C: a snapshot of nine 41 x 41 layers is 15,129 cells
        _require(min(self.cells) >= 0 and max(self.cells) <= MAP_LEVEL, f"AgentMap.cells must be 0 to {MAP_LEVEL}")


MESSAGE_TYPES: tuple[type, ...] = (
    Hello, Welcome, SensorFrame, AgentCommand, CommandRejected, WorldStatus,
    Perturbation, PerturbResult, Decision, Reinforcement, RunControl, RunControlResult,
    Blueprint, AgentState, Perturbed, LockstepTimeout, WorldView, AgentMap, BrickNews,
)
