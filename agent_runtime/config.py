"""Agent configuration: a frozen dataclass, loadable from a TOML table.

Map geometry follows the world: one map cell is one world cell (one disc diameter).
Maps are indexed [row, col] with row 0 the northmost row and the agent in the centre
cell (size // 2, size // 2).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class AgentConfig:
    """The agent's settings (motivations, speeds, distances, map size, goal sequencing); frozen."""

    map_size: int = 41              # cells per side of every ESM and NM (odd; cut to a smaller world: esm.map_extent)
    hunger_rate: float = 0.002      # hunger and thirst grow by this much per tick ...
    thirst_rate: float = 0.0025
    need_threshold: float = 0.8     # ... and a need above this interrupts construction until one
                                    # eat / drink succeeds, which resets it to 0 (`Motivations`)
    cruise_speed: float = 2.0       # world units per second when following a plan
    near_brick: float = 2.5         # Near-Brick: an available brick within this many cells
    reach: float = 1.3              # a brick closer than this (cells) is within the gripper's reach
    touch: float = 1.0              # food/water closer than this (centre to centre) is touching
    drop_centering: float = 0.3     # drop only this close (cells) to the site cell's centre
    avoid_distance: float = 0.9     # Avoid: another agent closer than this
    explore_turn: float = 0.6       # largest random turn per tick while exploring
    goal_sequencing: bool = True    # ConAg-TS (§6): calculateMatching and drop-site selection;
                                    # False gives the plain nearest-first agent of §4
    site_memory: float = 300.0      # an open site not seen for this many ticks may have been
                                    # filled by another agent: no planned path may cross it
    stuck_ticks: int = 120          # no headway for this many ticks (net < stuck_distance cells)
    stuck_distance: float = 1.5     # ... makes the agent back off for stuck_ticks/4 to /2 ticks
    idle_near: float = 3.0          # `idle_wait`: wait within this many cells (by a way) of a known free brick ...
    idle_patience: int = 600        # ... and after this many ticks of waiting take one leg of wandering
    # Additions beyond paper §4 and §6, each switchable by name (docs/design.md, "The paper's
    # agent and what we added"); `preset("paper")` switches every one of them off.
    far_memory: bool = True         # sites, bricks, walls and discs that leave the map are remembered
                                    # (agent_runtime.far_memory); off, what leaves the map is forgotten
    obstacle_layer: bool = True     # `#` walls and the world's edge are mapped as fixed obstacles (the
                                    # OBSTACLE ESM); off, neither is mapped (the paper's worlds have neither)
    agents_as_obstacles: bool = True  # other agents in sight are obstacles on both NMs
    explore_sweep: bool = True      # Explore heads for unseen squares, else straight legs (paper: random)
    unstick: bool = True            # back off at random after stuck_ticks without headway
    give_way: bool = True           # an agent without a brick avoids others from half as far
    agents_in_the_way: bool = True  # back away from agents that alone keep a site out of reach
    closed_sites: bool = True       # goal sequencing: no path across a site not seen for site_memory ticks
    supply_beyond: bool = True      # goal sequencing: the held brick's source and far bricks are supply
    mouth_side: bool = True         # goal sequencing: no site beside a site held open, no deeper than it
    seal_guard: bool = True         # no goal site whose brick would cut another open site off
    enclosed_sites: bool = True     # open sites no way reaches are believed filled
    off_own_brick: bool = True      # leave a brick just dropped on the side away from a pocket
    sequencing_fallback: bool = True  # plain goals when sequencing leaves none reachable
    # Additions for big teams (issue 36), off by default (docs/design.md says why):
    idle_wait: bool = False         # knowing bricks but nothing to fetch, wait near the supply, off the sites
    yield_goals: bool = False       # leave a brick or site to another agent in sight that is nearer to it
    spread_search: bool = False     # searching for bricks, leave unseen ground nearer another agent in sight to it
    share_bricks: bool = False      # tell the other agents the free bricks in sight, the one headed for and
                                    # those taken; remember what they tell (agent_runtime.brick_news; the bus)
    # Refinements of the ESMs' sensing rule (agent_runtime.esm; off: the plain rule).
    ghost_association: bool = True  # a reading explains a cell already marked; other brick marks in its band are ghosts
    clear_margins: bool = True      # a sector clears only cells well in front of its reading, well inside its range
    site_core: bool = True          # a site cell is cleared of bricks only by the sectors covering its centre
    obstacle_trust: bool = True     # walls only from readings near enough to land in their cell; far food
                                    # and water never on a blueprint site
    # Corrections for noisy worlds (docs/noise.md): CORRECTIONS.
    anchor_maps: bool = False       # the belief of where the agent is follows structure bricks and the
                                    # world's edge it sees (agent_runtime.anchoring), so the maps stay true
    occlusion_clearing: bool = True  # where the world's sensors occlude, a colour not reported is cleared
                                     # only in front of the nearest thing reported (agent_runtime.esm)

    def __post_init__(self) -> None:
        if not (isinstance(self.map_size, int) and self.map_size >= 5 and self.map_size % 2 == 1):
            raise ValueError("agent.map_size must be an odd integer >= 5")
        for name in ADDITIONS + CORRECTIONS:
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"agent.{name} must be true or false")
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, float) and not (math.isfinite(v) and v >= 0):
                raise ValueError(f"agent.{f.name} must be a finite number >= 0")
        if not (isinstance(self.stuck_ticks, int) and self.stuck_ticks >= 8):
            raise ValueError("agent.stuck_ticks must be an integer >= 8")
        if not (isinstance(self.idle_patience, int) and self.idle_patience >= 1):
            raise ValueError("agent.idle_patience must be an integer >= 1")
        if not isinstance(self.goal_sequencing, bool):
            raise ValueError("agent.goal_sequencing must be true or false")

    @classmethod
    def preset(cls, name: str, **overrides: Any) -> AgentConfig:
        """The named set of additions (PRESETS), with `overrides` on top."""
        if name not in PRESETS:
            raise ValueError(f"unknown agent preset {name!r}; known: {', '.join(PRESETS)}")
        return cls(**{**PRESETS[name], **overrides})

    def additions(self) -> dict[str, bool]:
        """Each addition beyond the paper by name, and whether it is on."""
        return {name: getattr(self, name) for name in ADDITIONS}

    def describe(self, preset: str | None = None) -> dict[str, Any]:
        """Which agent this is, as a run's summary records it: {"preset": NAME, "without":
        [additions on in that preset, off here], "changed": {every other setting that
        differs from the preset: name: value}}, so that
        `AgentConfig.preset(NAME, **dict.fromkeys(without, False), **changed)` is this config.

        `preset` is the one it was made from (`--agent`); by default the first preset
        (PRESETS order) with the fewest additions off beyond it, among those it only
        switches additions off from (if none, the one it differs from in fewest additions).
        """
        if preset is None:
            mine = self.additions()
            # An addition off in every preset (on here) is a change of the nearest one.
            candidates = [name for name in PRESETS
                          if all(on or not mine[a] for a, on in AgentConfig.preset(name).additions().items())]
            preset = min(candidates or list(PRESETS), key=lambda name: sum(
                on != mine[a] for a, on in AgentConfig.preset(name).additions().items()))
        base = AgentConfig.preset(preset)
        without = [a for a in ADDITIONS if getattr(base, a) and not getattr(self, a)]
        changed = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                   if f.name not in without and getattr(self, f.name) != getattr(base, f.name)}
        return {"preset": preset, "without": without, "changed": changed}

    @classmethod
    def from_mapping(cls, table: dict) -> AgentConfig:
        """An AgentConfig from a TOML table; unknown keys are a ValueError naming the known ones."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(table) - known)
        if unknown:
            raise ValueError(f"unknown agent setting(s): {', '.join(unknown)}; known: {', '.join(sorted(known))}")
        values: dict[str, Any] = {k: (float(v) if isinstance(getattr(cls, k), float) and isinstance(v, int) else v)
                                  for k, v in table.items()}
        return cls(**values)


# The additions beyond the paper, in the order AgentConfig declares them.
ADDITIONS = ("far_memory", "obstacle_layer", "agents_as_obstacles", "explore_sweep", "unstick", "give_way",
             "agents_in_the_way", "closed_sites", "supply_beyond", "mouth_side", "seal_guard", "enclosed_sites",
             "off_own_brick", "sequencing_fallback", "idle_wait", "yield_goals", "spread_search", "share_bricks",
             "ghost_association", "clear_margins", "site_core", "obstacle_trust")
# Additions that the default agent leaves off (docs/design.md says why for each).
OFF_BY_DEFAULT = ("idle_wait", "yield_goals", "spread_search", "share_bricks")
# Corrections for a world the paper's agent assumed away (odometry noise, occluding sensors,
# docs/noise.md), in AgentConfig order. anchor_maps is off in the default agent: in a world
# without noise it would only ever move a true belief by the sensors' noise. occlusion_clearing
# is on: it acts only where the world says its sensors occlude, and changes nothing elsewhere.
CORRECTIONS = ("anchor_maps", "occlusion_clearing")
# Named agents: "default" is the best agent, "paper" the agent as the paper describes it:
# every addition off but ghost association. One object seen from two places is one object,
# and the paper's agent built its own figures, so its maps kept no ghosts, whatever its
# rule was. By the plain rule a structure brick seen from two places leaves a ghost free
# brick beside it that no sector clears (it lies at the real brick's distance) and the
# agents drive to it: Fig. 6 completed in 13 of 20 seeds (20 of 20 with it; `python3 -m
# experiments.fig6 --agent paper --without ghost_association`).
PRESETS: dict[str, dict[str, Any]] = {
    "default": {},
    "paper": {**dict.fromkeys(ADDITIONS, False), "ghost_association": True},
}
