"""Named agents (issue 33): `--agent PRESET` gives the same agent in `conag run`, the
in-process simulator and the env, and what ran is recorded as the run summary records it
(`AgentConfig.describe`)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agent_runtime.config import ADDITIONS, OFF_BY_DEFAULT, PRESETS, AgentConfig
from agent_runtime.esm import Sensing
from conag import sim
from conag.agent_settings import AgentSettings
from tests.conftest import SCENARIOS, scenario

ONE = scenario("""
A.b.
..+.
""")


def rebuilt(record: dict) -> AgentConfig:
    """The config a summary's `agent` record names."""
    return AgentConfig.preset(record["preset"], **dict.fromkeys(record["without"], False), **record["changed"])


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(list(PRESETS)), st.sets(st.sampled_from(ADDITIONS)), st.sets(st.sampled_from(ADDITIONS)),
       st.sampled_from([21, 41]), st.booleans(), st.sampled_from([None, *PRESETS]))
def test_the_record_of_an_agent_gives_that_agent_back(base, off, on, map_size, sequencing, named):
    cfg = AgentConfig.preset(base, **dict.fromkeys(off, False), **dict.fromkeys(on - off, True),
                             map_size=map_size, goal_sequencing=sequencing)
    record = cfg.describe(named)
    assert rebuilt(record) == cfg
    assert record["preset"] == (named or record["preset"]) and set(record) == {"preset", "without", "changed"}
    assert all(name in ADDITIONS for name in record["without"])


@pytest.mark.parametrize("cfg, record", [
    (AgentConfig(), {"preset": "default", "without": [], "changed": {}}),
    (AgentConfig(yield_goals=True), {"preset": "default", "without": [], "changed": {"yield_goals": True}}),
    (AgentConfig.preset("paper"), {"preset": "paper", "without": [], "changed": {}}),
    (AgentConfig(unstick=False, map_size=31),
     {"preset": "default", "without": ["unstick"], "changed": {"map_size": 31}}),
    (AgentConfig.preset("paper", ghost_association=False),
     {"preset": "paper", "without": ["ghost_association"], "changed": {}}),
])
def test_a_config_made_without_a_preset_is_recorded_by_the_nearest_preset(cfg, record):
    assert cfg.describe() == record


def test_the_paper_preset_switches_every_addition_off_but_ghost_association():
    paper = AgentConfig.preset("paper").additions()
    assert [name for name, on in paper.items() if on] == ["ghost_association"]
    assert [name for name, on in AgentConfig().additions().items() if not on] == list(OFF_BY_DEFAULT)


def test_the_agent_flags_are_recorded_as_the_run_asked_for_them():
    settings_ = AgentSettings(preset="paper", without=("ghost_association",), nearest_first=True)
    assert settings_.describe() == {"preset": "paper", "without": ["ghost_association"],
                                    "changed": {"goal_sequencing": False}}
    # A default agent with every addition off is still recorded as asked: the default, without them.
    asked = AgentSettings(without=ADDITIONS).describe()
    assert asked["preset"] == "default" and asked["without"] == [a for a in ADDITIONS if a not in OFF_BY_DEFAULT]
    assert AgentSettings(learn=True, eta=0.2).describe() == {"preset": "default", "without": [], "changed": {},
                                                             "learn": True, "eta": 0.2}


def test_the_simulator_runs_a_preset_by_name_and_its_result_says_which():
    run = sim.start(ONE, cfg="paper")
    paper = AgentSettings(preset="paper").config()       # what `conag run --agent paper` starts
    brain = run.brains["a1"]
    assert brain.cfg == paper and brain.maps.sensing == Sensing.of(paper)
    result = run.run(3)
    assert result.agent == run.agent == {"preset": "paper", "without": [], "changed": {}}
    assert sim.start(ONE, cfg=AgentConfig(unstick=False)).run(1).agent == \
        {"preset": "default", "without": ["unstick"], "changed": {}}
    assert sim.start(ONE).run(1).agent == {"preset": "default", "without": [], "changed": {}}
    with pytest.raises(ValueError, match="known: default, paper"):
        sim.start(ONE, cfg="papr")


def test_an_agent_process_maps_with_the_sensing_of_its_config(bus, start_world):
    from agent_runtime.node import AgentOptions, AgentProcess, AgentReport

    start_world(ONE)
    cfg = AgentConfig.preset("paper", ghost_association=False)
    agent = AgentProcess(bus.client_session(), AgentOptions("w0", "a1", cfg), AgentReport())
    try:
        agent.attach()
        assert agent.brain.cfg == cfg and agent.brain.maps.sensing == Sensing(False, False, False, False)
    finally:
        agent.close()


@pytest.mark.slow  # a few seconds: an env over the bus
def test_the_env_runs_the_preset_it_is_given_and_its_reset_info_says_which():
    pytest.importorskip("gymnasium")
    from conag.env import ConAgGymEnv, ConAgParallelEnv

    env = ConAgGymEnv(SCENARIOS / "fig6.toml", max_cycles=5, cfg="paper")
    try:
        _obs, info = env.reset(seed=1)
        paper = AgentConfig.preset("paper")
        assert info["agent"] == {"preset": "paper", "without": [], "changed": {}}
        assert all(b.cfg == paper and b.maps.sensing == Sensing.of(paper) for b in env.brains.values())
        env.step(env.action_space.sample())
    finally:
        env.close()
    parallel = ConAgParallelEnv(SCENARIOS / "fig6.toml", max_cycles=5, teacher=True,
                                cfg=AgentConfig(explore_sweep=False))
    try:
        _obs, infos = parallel.reset(seed=1)
        assert infos["a1"]["agent"] == {"preset": "default", "without": ["explore_sweep"], "changed": {}}
        assert parallel._observers["a1"].cfg == AgentConfig(explore_sweep=False)
    finally:
        parallel.close()

