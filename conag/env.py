"""ConAg as a PettingZoo ParallelEnv over the real bus, and a Gymnasium single-agent wrapper.

`ConAgParallelEnv(scenario)` serves a lockstep world in a thread of this process, on a
zenoh peer listening on a free loopback port, and drives one body per agent through the
same `WorldLink` the agent processes use (liveliness token, frames, attach, commands):
every step crosses the bus both ways. `reset(seed=...)` starts the world afresh (the
seed seeds its noise); `step(actions)` sends every agent's command for the current tick
and returns the frames of the next one as observations.

* Action, per agent: `{"speed": [0, max_speed], "turn": [-max_turn, max_turn], "action":
  index into protocol.BODY_ACTIONS}` (world units per second, radians per tick; see
  docs/protocol.md).
* Observation, per agent: `{"ranges": 5 x sectors readings (-1: nothing), "heading":
  radians, "odometry": the last tick's (dx, dy) on world axes, "holding": 0 or 1}`. In a
  world with cues (`[world] cue_reach` > 0: docs/society.md) it holds the cue readings too:
  `"cues"`, len(CUE_KINDS) x sectors distances to the nearest uncovered cue of each kind
  (site, then supply; -1: nothing), and `"cue_under"`, the cue under the body (0: none,
  1 + its index in CUE_KINDS); without cues the observation is as above. The action space
  stays the body's (protocol.BODY_ACTIONS): marking cues is a foreman's, not the env's.
* Reward: `reward(env, agent, filled_now)`, by default the number of drop sites filled
  during the step (shared by every agent; negative when a brick leaves a site), plus,
  with `teacher=True`, the teacher's reinforcement of the agent's arm action (below).
* Teacher (`teacher=True`): the teacher's rule of §5.1 (`teacher.core`) judges each agent's
  arm action (grab, drop or neither) against what the engineered network would choose on
  the same six state nodes, +1 or -1, in `env.teacher_arm[agent]` and `infos[agent]
  ["teacher_arm"]`. The state nodes come from a ConAg brain that perceives the agent's own
  frames alongside it (the agent does not report them, as a ConAg student does in its
  Decision). Only the arm is judged: the motor output of §5.1 is a navigation behaviour,
  which an action of speed and turn has no counterpart for.
* Episodes end (terminated) when the structure is complete, or are truncated after
  `max_cycles` steps.
* Agent (`cfg`): the ConAg agent the env runs where it runs one (the teacher's judge, the
  Gymnasium env's other agents), an AgentConfig or a preset's name as `conag run --agent`
  takes it (`cfg="paper"`: the agent as the paper describes it). The reset's infos record
  which agent it is, as the run summary does: `infos[agent]["agent"]` (`AgentConfig.describe`).

`ConAgGymEnv(scenario)` is one agent's view as a `gymnasium.Env`, the other agents of the
scenario being ConAg's own agents (`agent_runtime.Brain`), driven in this process over the
same bus. Both need the optional extra: `pip install -e '.[env]'`.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import ClassVar

import gymnasium
import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from agent_runtime.brain import Brain
from agent_runtime.config import AgentConfig
from agent_runtime.world_link import WorldLink
from protocol.bus import BusOptions, open_session
from protocol.messages import BODY_ACTIONS, CHANNELS, CUE_KINDS, Decision, SensorFrame, Welcome
from teacher.core import Teacher
from world_server.scenario import Scenario, load_scenario
from world_server.server import WorldServer
from world_server.world import World

RewardFn = Callable[["ConAgParallelEnv", str, int], float]


def sites_filled_reward(env: ConAgParallelEnv, agent: str, filled_now: int) -> float:
    """The default reward: drop sites filled during the step (the same for every agent), plus
    the teacher's +1 / -1 for the agent's arm action when the env runs the teacher."""
    return float(filled_now) + float(env.teacher_arm.get(agent, 0))


# The envs of this process not yet closed: only the last to close waits for zenoh's callback
# threads (`close`), as another open env's threads live until it closes.
_OPEN_ENVS: weakref.WeakSet = weakref.WeakSet()
_OPEN_ENVS_LOCK = threading.Lock()
_NO_OUTPUTS = (0.0,) * 7  # a Decision's output activations: the teacher's rule does not read them


def _agent_config(cfg: AgentConfig | str | None) -> tuple[AgentConfig, dict]:
    """The AgentConfig `cfg` names (a preset's name, a config, None: the default) and its record."""
    preset = cfg if isinstance(cfg, str) else None
    config = AgentConfig.preset(cfg) if isinstance(cfg, str) else cfg or AgentConfig()
    if config.share_bricks:
        # The env's agents meet only in its world: nothing carries news between them.
        raise ValueError("the env: share_bricks is not carried between the env's agents")
    return config, config.describe(preset)


def _brain(welcome: Welcome, cfg: AgentConfig, rng: np.random.Generator | None = None) -> Brain:
    return Brain(welcome, cfg, rng)


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ConAgParallelEnv(ParallelEnv):
    """A lockstep ConAg world as a PettingZoo ParallelEnv, every step over zenoh (see the module)."""

    metadata: ClassVar[dict] = {"name": "conag_v0", "render_modes": []}

    def __init__(self, scenario: Scenario | str | Path = "scenarios/quick_wall.toml", *, agents: int | None = None,
                 max_cycles: int = 1000, reward: RewardFn = sites_filled_reward, frame_timeout: float = 30.0,
                 teacher: bool = False, cfg: AgentConfig | str | None = None):
        self.agent_config, self.agent_record = _agent_config(cfg)
        sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        # Lockstep, and the world never steps on its own: the env's commands drive every tick.
        self.scenario = dataclasses.replace(sc, tick_mode="lockstep",
                                            world=dataclasses.replace(sc.world, lockstep_timeout=3600.0))
        n = self.scenario.agents if agents is None else agents
        self.possible_agents = [f"a{i + 1}" for i in range(n)]
        self.agents: list[str] = []
        self.max_cycles = max_cycles
        self.reward_fn = reward
        self.frame_timeout = frame_timeout
        self.render_mode = None
        self.teacher = Teacher() if teacher else None
        self.teacher_arm: dict[str, int] = {}       # the last step's arm reinforcement per agent
        self._observers: dict[str, Brain] = {}     # with the teacher: state nodes from each agent's frames
        self.frames: dict[str, SensorFrame] = {}
        self.welcomes: dict[str, Welcome] = {}
        self.world: World | None = None
        endpoint = f"tcp/127.0.0.1:{_free_port()}"
        self._env_id = f"env{endpoint.rsplit(':', 1)[1]}"
        self._resets = 0
        self.world_id = self._env_id  # a new one per reset (`reset`)
        self._server_session = open_session(BusOptions(listen=(endpoint,)), serve=True)
        self._session = open_session(BusOptions(connect=(endpoint,)))
        with _OPEN_ENVS_LOCK:
            _OPEN_ENVS.add(self)
        self._links: dict[str, WorldLink] = {}
        self._stop: threading.Event | None = None
        self._thread: threading.Thread | None = None
        self._cycles = 0
        self._sent: set[str] = set()  # agents commanded for the current tick (`command`)
        cfg = self.scenario.world
        ranges = len(CHANNELS) * cfg.sensor_sectors
        self.cues = cfg.cue_reach > 0  # the world has cues: observations hold their readings
        obs = {
            "ranges": spaces.Box(-1.0, cfg.sensor_range, (ranges,), np.float32),
            "heading": spaces.Box(-math.pi, math.pi, (1,), np.float32),
            "odometry": spaces.Box(-np.inf, np.inf, (2,), np.float32),
            "holding": spaces.Discrete(2),
        }
        if self.cues:
            obs["cues"] = spaces.Box(-1.0, cfg.sensor_range, (len(CUE_KINDS) * cfg.sensor_sectors,), np.float32)
            obs["cue_under"] = spaces.Discrete(1 + len(CUE_KINDS))
        self._obs_space = spaces.Dict(obs)
        self._act_space = {a: spaces.Dict({
            "speed": spaces.Box(0.0, cfg.max_speed, (1,), np.float32),
            "turn": spaces.Box(-cfg.max_turn, cfg.max_turn, (1,), np.float32),
            "action": spaces.Discrete(len(BODY_ACTIONS)),
        }) for a in self.possible_agents}

    def observation_space(self, agent: str) -> spaces.Space:  # noqa: ARG002 -- PettingZoo's signature
        """The same Dict space for every agent (PettingZoo wants the same object each call)."""
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Space:
        """This agent's action space (one object per agent, so each can be seeded)."""
        return self._act_space[agent]

    # the world -----------------------------------------------------------------------------
    def _stop_world(self) -> None:
        for link in self._links.values():
            link.close()
        self._links = {}
        if self._thread is not None:
            self._stop.set()
            self._thread.join(30)
            self._thread = None

    def reset(self, seed: int | None = None, options: dict | None = None):  # noqa: ARG002 -- PettingZoo's
        """Start the world afresh (`seed` seeds its noise; default the scenario's) and attach every agent."""
        self._stop_world()
        # Each reset's world has an id of its own. The worlds share this env's sessions, and
        # the old world's liveliness token going could reach a new link after it attached,
        # which then took the new world for lost and waited for no frame (`WorldLink.world_lost`).
        self._resets += 1
        self.world_id = f"{self._env_id}r{self._resets}"
        self.world = World(self.scenario, np.random.default_rng(self.scenario.seed if seed is None else seed),
                           world_id=self.world_id)
        # BLOCK both ways: on a busy machine zenoh drops a DROP message that waits too long, and a
        # lost frame or command would hold a lockstep world that never steps on its own.
        server = WorldServer(self.world, self._server_session, mode="lockstep",
                             wait_agents=len(self.possible_agents), block_frames=True)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=server.run, args=(self._stop,), daemon=True)
        self._thread.start()
        self.agents = list(self.possible_agents)
        self._cycles = 0
        self._sent.clear()
        for a in self.agents:
            link = self._links[a] = WorldLink(self._session, self.world_id, a, block=True)
            self.welcomes[a] = link.attach(timeout=self.frame_timeout)
        for a in self.agents:
            self.frames[a] = self._next(a, self.welcomes[a].tick - 1)
        self.teacher_arm = {}
        if self.teacher is not None:
            self.teacher = Teacher()
            self._observers = {a: _brain(self.welcomes[a], self.agent_config) for a in self.agents}
        self._filled = int(self.world.sites_filled().sum())
        infos = {a: self._info(a) for a in self.agents}
        if self.teacher is not None:  # the teacher's judge is a ConAg agent: which one
            for info in infos.values():
                info["agent"] = self.agent_record
        return {a: self._observe(a) for a in self.agents}, infos

    def _next(self, agent: str, after: int) -> SensorFrame:
        frame = self._links[agent].next_frame(after, timeout=self.frame_timeout)
        if frame is None:
            raise RuntimeError(f"no frame for {agent} after tick {after} within {self.frame_timeout:g} s")
        return frame

    def _observe(self, agent: str) -> dict:
        f = self.frames[agent]
        obs = {"ranges": np.asarray(f.ranges, np.float32), "heading": np.array([f.heading], np.float32),
               "odometry": np.array([f.odom_dx, f.odom_dy], np.float32), "holding": int(f.holding)}
        if self.cues:
            obs["cues"] = np.asarray(f.cues, np.float32)
            obs["cue_under"] = 1 + CUE_KINDS.index(f.cue_under) if f.cue_under else 0
        return obs

    def _info(self, agent: str) -> dict:
        f = self.frames[agent]
        info = {"tick": f.tick, "grabbed": f.grabbed, "dropped": f.dropped}
        if self.teacher is not None:
            info["teacher_arm"] = self.teacher_arm.get(agent, 0)
        return info

    def _judge(self, agent: str, action: str) -> None:
        """The teacher's arm signal for `action` on the frame it answers (see the module)."""
        assert self.teacher is not None
        frame, brain = self.frames[agent], self._observers[agent]
        brain.perceive(frame)
        state = brain.state_nodes(frame, brain.plan())
        arm = action if action in ("grab", "drop") else "none"
        decision = Decision(agent, frame.tick, tuple(float(v) for v in state), _NO_OUTPUTS, arm, "none")
        self.teacher_arm[agent] = self.teacher.reinforce(decision).arm

    def command(self, agent: str, speed: float, turn: float, action: str = "none") -> None:
        """Send one agent's command for the current tick (what `step` does with each action)."""
        if self.teacher is not None:
            self._judge(agent, action)
        self._links[agent].send(self.frames[agent].tick, float(speed), float(turn), action)
        self._sent.add(agent)

    def step(self, actions: dict):
        """Send every agent's command, wait for the next frames; (obs, rewards, terminated, truncated, infos)."""
        for a in self.agents:
            act = actions.get(a)
            if act is None:
                if a not in self._sent:  # neither an action nor a command: stand still
                    self.command(a, 0.0, 0.0)
            else:
                self.command(a, float(np.asarray(act["speed"]).reshape(-1)[0]),
                             float(np.asarray(act["turn"]).reshape(-1)[0]), BODY_ACTIONS[int(act["action"])])
        for a in self.agents:
            self.frames[a] = self._next(a, self.frames[a].tick)
        self._sent.clear()
        self._cycles += 1
        # Every frame of the new tick is in: the world waits for the next commands, so it is still.
        filled = int(self.world.sites_filled().sum())
        filled_now, self._filled = filled - self._filled, filled
        done = self.world.completed()
        truncated = self._cycles >= self.max_cycles
        agents = self.agents
        obs = {a: self._observe(a) for a in agents}
        rewards = {a: self.reward_fn(self, a, filled_now) for a in agents}
        infos = {a: self._info(a) for a in agents}
        if done or truncated:
            self.agents = []
        return obs, rewards, dict.fromkeys(agents, done), dict.fromkeys(agents, truncated and not done), infos

    def render(self) -> None:
        """No rendering (`conag render` draws scenarios)."""
        return None

    def close(self) -> None:
        """Stop the world and close both sessions."""
        from protocol.bus import join_callback_threads

        self._stop_world()
        for s in (self._session, self._server_session):
            try:
                s.close()
            except Exception:  # noqa: BLE001 -- closing twice, or after zenoh shut down: nothing left to do
                pass
        with _OPEN_ENVS_LOCK:
            _OPEN_ENVS.discard(self)
            last = not _OPEN_ENVS
        if last:
            # The world's callback threads, declared in a daemon thread (bus.session says why).
            # Not while another env is open: its threads would hold this one for the timeout.
            join_callback_threads()


class ConAgGymEnv(gymnasium.Env):
    """One agent (`agent`, default a1) as a Gymnasium env; the scenario's other agents are ConAg's
    own (`agent_runtime.Brain`), all driven over the bus in lockstep (see the module)."""

    metadata: ClassVar[dict] = {"render_modes": []}

    def __init__(self, scenario: Scenario | str | Path = "scenarios/quick_wall.toml", *, agents: int | None = None,
                 agent: str = "a1", max_cycles: int = 1000, reward: RewardFn = sites_filled_reward,
                 teacher: bool = False, cfg: AgentConfig | str | None = None):
        self.env = ConAgParallelEnv(scenario, agents=agents, max_cycles=max_cycles, reward=reward, teacher=teacher,
                                    cfg=cfg)
        if agent not in self.env.possible_agents:
            raise ValueError(f"{agent!r} is not one of {self.env.possible_agents}")
        self.agent = agent
        self.observation_space = self.env.observation_space(agent)
        self.action_space = self.env.action_space(agent)
        self.brains: dict[str, Brain] = {}

    def reset(self, *, seed: int | None = None, options: dict | None = None):  # noqa: ARG002 -- Gymnasium's
        """Reset the world; the other agents get fresh brains (seeded from `seed`) of the env's
        agent (`cfg`), which the info records (`info["agent"]`)."""
        super().reset(seed=seed)
        obs, infos = self.env.reset(seed=seed)
        others = [a for a in self.env.possible_agents if a != self.agent]
        self.brains = {a: _brain(self.env.welcomes[a], self.env.agent_config, np.random.default_rng([seed or 0, i]))
                       for i, a in enumerate(others)}
        return obs[self.agent], {**infos[self.agent], "agent": self.env.agent_record}

    def step(self, action):
        """Our agent's action; the others act on their brains. (obs, reward, terminated, truncated, info)."""
        for a, brain in self.brains.items():
            s = brain.step(self.env.frames[a])
            self.env.command(a, s.speed, s.turn, s.action)
        obs, rewards, term, trunc, infos = self.env.step({self.agent: action})
        a = self.agent
        return obs[a], rewards[a], term[a], trunc[a], infos[a]

    def close(self) -> None:
        """Stop the world and close the sessions."""
        self.env.close()
