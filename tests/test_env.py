"""ConAg as a PettingZoo ParallelEnv and a Gymnasium env over the real bus (conag/env.py): the
PettingZoo conformance tests, determinism, the reward, and a short training run."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pettingzoo")  # the optional extra: pip install -e '.[env]'

from pettingzoo.test import parallel_api_test, parallel_seed_test

from conag.env import ConAgGymEnv, ConAgParallelEnv
from protocol.messages import ACTIONS, Perturbation
from tests.conftest import ROOT, SCENARIOS


def test_passes_pettingzoos_parallel_api_test():
    env = ConAgParallelEnv(SCENARIOS / "quick_wall.toml")
    try:
        parallel_api_test(env, num_cycles=60)
    finally:
        env.close()


@pytest.mark.slow  # two worlds at once, reset twice each
def test_passes_pettingzoos_parallel_seed_test_with_three_agents():
    parallel_seed_test(lambda: ConAgParallelEnv(SCENARIOS / "fig6.toml", max_cycles=60), num_cycles=60)


def test_a_step_moves_the_body_and_filling_a_site_is_rewarded():
    env = ConAgParallelEnv(SCENARIOS / "quick_wall.toml")
    try:
        obs, infos = env.reset(seed=5)
        assert env.agents == ["a1"] and infos["a1"]["tick"] == 0
        go = {"a1": {"speed": np.array([1.0], np.float32), "turn": np.array([0.0], np.float32), "action": 0}}
        for _ in range(10):
            obs, rewards, term, trunc, infos = env.step(go)
        # speed 1.0 is 0.1 units per tick, once inertia has caught up (docs/protocol.md)
        assert infos["a1"]["tick"] == 10 and obs["a1"]["odometry"][0] == pytest.approx(0.1, rel=0.01)
        assert rewards == {"a1": 0.0} and term == {"a1": False} and trunc == {"a1": False}
        # A brick put on a site between two steps is a site filled during the next one.
        x, y = env.world.sites_xy[0]
        assert env.world.perturb(Perturbation("add", float(x), float(y), force=True)).ok
        _, rewards, *_ = env.step({"a1": {"speed": [0.0], "turn": [0.0], "action": ACTIONS.index("none")}})
        assert rewards == {"a1": 1.0}
    finally:
        env.close()


def test_in_a_world_with_cues_each_observation_holds_the_cue_readings():
    import dataclasses

    from protocol.messages import CHANNELS, CUE_KINDS, NO_READING
    from world_server.scenario import load_scenario

    plain = ConAgParallelEnv(SCENARIOS / "quick_wall.toml")
    sc = load_scenario(SCENARIOS / "quick_wall.toml")
    cued = ConAgParallelEnv(dataclasses.replace(sc, world=dataclasses.replace(sc.world, cue_reach=5.0)))
    try:
        obs, _ = plain.reset(seed=5)
        assert set(obs["a1"]) == set(plain.observation_space("a1").spaces) == {"ranges", "heading", "odometry",
                                                                              "holding"}
        obs, _ = cued.reset(seed=5)
        sectors = sc.world.sensor_sectors
        space = cued.observation_space("a1")
        assert space["cues"].shape == (len(CUE_KINDS) * sectors,) and space["cue_under"].n == 1 + len(CUE_KINDS)
        assert space.contains(obs["a1"]) and (obs["a1"]["cues"] == NO_READING).all() and obs["a1"]["cue_under"] == 0
        # Cues put on the floor between two steps (the world waits for the commands): a supply
        # cue under the body, a site cue two cells east of it.
        col, row = (int(v) for v in cued.world.scenario.to_cell(cued.world.agent_poses()[:1, :2])[0])
        cued.world.cues.place((col, row), "supply")
        cued.world.cues.place((col + 2, row), "site")
        obs, *_ = cued.step({"a1": {"speed": [0.0], "turn": [0.0], "action": 0}})
        o = obs["a1"]
        assert space.contains(o) and o["cue_under"] == 1 + CUE_KINDS.index("supply")
        site = o["cues"][:sectors]
        assert (site >= 0).sum() == 1 and 1.0 < site.max() < 3.0  # one site cue, about two cells away
        assert len(o["ranges"]) == len(CHANNELS) * sectors
    finally:
        plain.close()
        cued.close()


def test_an_env_closed_while_another_is_open_does_not_wait_for_the_others_threads(monkeypatch):
    # Closing waits (up to 2 s) for zenoh's callback threads, for the interpreter's exit; an
    # open env's threads live on, so only the last env to close waits.
    import weakref

    import conag.env
    import protocol.bus

    joins = []
    monkeypatch.setattr(protocol.bus, "join_callback_threads", lambda: joins.append(1) or True)
    monkeypatch.setattr(conag.env, "_OPEN_ENVS", weakref.WeakSet())  # other tests' envs do not count
    first, second = ConAgParallelEnv(SCENARIOS / "quick_wall.toml"), ConAgParallelEnv(SCENARIOS / "quick_wall.toml")
    try:
        first.reset(seed=1)
        second.reset(seed=1)
    finally:
        first.close()
        assert joins == []
        second.close()
        assert joins == [1]


def test_the_gymnasium_env_drives_one_agent_among_conag_agents():
    env = ConAgGymEnv(SCENARIOS / "fig6.toml", max_cycles=50)
    try:
        obs, info = env.reset(seed=1)
        assert env.observation_space.contains(obs) and set(env.brains) == {"a2", "a3"}
        env.action_space.seed(0)
        for _ in range(50):
            obs, _reward, terminated, truncated, info = env.step(env.action_space.sample())
            if terminated or truncated:
                break
        assert truncated and info["tick"] == 50
        moved = env.env.world.status().agent_distance
        assert moved[1] > 1.0 and moved[2] > 1.0  # the ConAg agents went about their work
    finally:
        env.close()


def test_the_tabular_example_trains_for_a_few_hundred_steps():
    import runpy

    train = runpy.run_path(str(ROOT / "examples" / "train_tabular.py"))["train"]
    result = train(steps=300, seed=0)
    assert result["steps"] == 300 and np.count_nonzero(result["q"]) > 0  # every step cost a little


def test_with_the_teacher_the_arm_action_is_reinforced_as_the_engineered_network_would_choose():
    none, grab = ACTIONS.index("none"), ACTIONS.index("grab")
    still = {"speed": [0.0], "turn": [0.0]}
    env = ConAgParallelEnv(SCENARIOS / "quick_wall.toml", teacher=True)
    try:
        env.reset(seed=3)
        # Nothing in reach: the teacher's arm output is none; grabbing at the air is an error.
        _, rewards, _, _, infos = env.step({"a1": still | {"action": grab}})
        assert infos["a1"]["teacher_arm"] == -1 and rewards == {"a1": -1.0}
        _, rewards, _, _, infos = env.step({"a1": still | {"action": none}})
        assert infos["a1"]["teacher_arm"] == 1 and rewards == {"a1": 1.0}
        # A free brick put just in front of the body: now the teacher would grab it.
        w = env.welcomes["a1"]
        x, y, heading = *env.world.agent_poses()[0, :2], env.frames["a1"].heading
        gap = w.agent_radius + w.disc_radius + 0.05
        assert env.world.perturb(Perturbation("add", float(x + gap * np.cos(heading)),
                                              float(y + gap * np.sin(heading)), "brick")).ok
        env.step({"a1": still | {"action": none}})          # the frame that sees it
        _, rewards, _, _, infos = env.step({"a1": still | {"action": none}})
        assert infos["a1"]["teacher_arm"] == -1
        _, rewards, _, _, infos = env.step({"a1": still | {"action": grab}})
        assert infos["a1"]["teacher_arm"] == 1 and infos["a1"]["grabbed"] and env.frames["a1"].holding
    finally:
        env.close()


def test_without_the_teacher_the_reward_is_sites_filled_only():
    env = ConAgParallelEnv(SCENARIOS / "quick_wall.toml")
    try:
        env.reset(seed=3)
        _, rewards, _, _, infos = env.step({"a1": {"speed": [0.0], "turn": [0.0], "action": ACTIONS.index("grab")}})
        assert rewards == {"a1": 0.0} and "teacher_arm" not in infos["a1"]
    finally:
        env.close()
