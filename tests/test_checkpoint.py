"""World checkpoints (issue 12, point 2): a resumed world steps on exactly as one that never
stopped; a bad checkpoint file is refused with a clear error and never replaces a good one.
No bus here: `world_server.checkpoint` and the world core only."""

from __future__ import annotations

import os

import numpy as np
import pytest

from conag.sim.loop import start
from protocol.codec import encode
from tests.conftest import SCENARIOS, make
from world_server.checkpoint import (
    CheckpointError,
    checkpoint_world,
    decode_checkpoint,
    encode_checkpoint,
    load_world,
    newest_good,
    previous_path,
    read_checkpoint,
    restore_world,
    world_state,
    write_checkpoint,
)
from world_server.scenario import load_scenario
from world_server.world import World


def _commands_run(scenario_name: str, ticks: int, checkpoint_at: int, agents: int = 3, kill: str | None = None):
    """Run real brains on a scenario for `ticks` ticks, checkpointing at `checkpoint_at`; return
    the checkpoint bytes, the commands of every tick from then on, and the encoded frames and
    positions after each of those ticks. With `kill`, that agent is detached at tick 5 (a dead
    body in its grace period, its brick put down)."""
    run = start(load_scenario(SCENARIOS / f"{scenario_name}.toml"), agents=agents)
    world = run.world
    data, commands, frames = None, [], []
    for _ in range(ticks):
        if world.tick == 5 and kill:
            world.detach(kill)
            del run.brains[kill]
        if world.tick == checkpoint_at:
            data = checkpoint_world(world)
        tick_commands = []
        for frame in world.frames():
            s = run.brains[frame.agent_id].step(frame)
            tick_commands.append((frame.agent_id, s.speed, s.turn, s.action))
            world.set_command(frame.agent_id, s.speed, s.turn, s.action)
        world.step()
        if data is not None:
            commands.append(tick_commands)
            frames.append(_observed(world))
    return data, commands, frames


def _observed(world: World):
    """What must match tick for tick: every frame byte for byte, every body and disc."""
    return ([encode(f) for f in world.frames()], world.agent_poses().tobytes(), world.discs.xy.tobytes(),
            world.discs.state.tobytes(), world.status().bricks_total, [r.holding for r in world._order])


# quick_wall's checkpoint is taken at tick 8, after the kill (tick 5) and before the first grab
# (tick 11): its two extra agents start next to its one A cell, and its three sites are full long
# before tick 120.
@pytest.mark.parametrize("scenario_name,agents,kill,at", [("fig6", 3, None, 120), ("quick_wall", 3, "a2", 8)])
def test_resumed_world_gives_the_same_frames_as_one_that_never_stopped(scenario_name, agents, kill, at):
    ticks = 260
    data, commands, frames = _commands_run(scenario_name, ticks, at, agents, kill)
    resumed = restore_world(decode_checkpoint(data))
    assert resumed.tick == at
    for t, tick_commands in enumerate(commands):
        for agent, speed, turn, action in tick_commands:
            assert resumed.set_command(agent, speed, turn, action)
        resumed.step()
        assert _observed(resumed) == frames[t], f"tick {resumed.tick} differs"
    # The build did something in between: bricks were carried (and put down), bodies moved.
    assert any(any(h >= 0 for h in f[5]) for f in frames)


PEN = """
bbbbbbbbbb
b.A.A.A..b
b..bb....b
b.A..A.A.b
bbbbbbbbbb
"""


def _crowd(rebuild: bool) -> int | None:
    """Six bodies driving full speed into each other and the discs around them, turning at
    random, checkpointed at tick 150 (`rebuild`: as a checkpointing world does; else the state
    is only saved) and resumed; the first tick whose poses differ from the run that went on, or None."""
    world = make(PEN, seed=1, agents=6)
    for i in range(6):
        world.attach(f"a{i + 1}")
    rng = np.random.default_rng(5)
    data, script, poses = None, [], []
    for _ in range(300):
        if world.tick == 150:
            data = checkpoint_world(world) if rebuild else encode_checkpoint(world_state(world))
        turns = rng.uniform(-0.3, 0.3, 6)
        for i in range(6):
            world.set_command(f"a{i + 1}", 3.0, float(turns[i]), "none")
        world.step()
        if data is not None:
            script.append(turns)
            poses.append(world.agent_poses().tobytes())
    resumed = restore_world(decode_checkpoint(data))
    for turns, expected in zip(script, poses):
        for i in range(6):
            resumed.set_command(f"a{i + 1}", 3.0, float(turns[i]), "none")
        resumed.step()
        if resumed.agent_poses().tobytes() != expected:
            return resumed.tick
    return None


def test_bodies_in_contact_resume_exactly_only_because_both_runs_rebuild_the_space():
    # pymunk's contact caches (warm starting) make a merely restored space drift at once...
    assert _crowd(rebuild=False) == 151
    # ...so a checkpointing world rebuilds its own space from the state it wrote.
    assert _crowd(rebuild=True) is None


def test_checkpoint_keeps_agents_bricks_and_grace_state():
    run = start(load_scenario(SCENARIOS / "fig6.toml"), agents=3)
    world = run.world
    for _ in range(400):
        run.step()
        if any(r.holding >= 0 for r in world._order):
            break
    holder = next(r for r in world._order if r.holding >= 0)
    world.detach("a3" if holder.agent_id != "a3" else "a2")
    before = world.status()
    resumed = restore_world(decode_checkpoint(checkpoint_world(world)))
    after = resumed.status()
    assert after == before
    assert resumed.agents[holder.agent_id].holding == holder.holding
    assert [(r.agent_id, r.alive, r.gone_at, r.pid, r.restarts) for r in resumed._order] == \
           [(r.agent_id, r.alive, r.gone_at, r.pid, r.restarts) for r in world._order]
    assert resumed.epoch == world.epoch and resumed.rng.bit_generator.state == world.rng.bit_generator.state


def test_written_checkpoint_reads_back_and_the_previous_one_is_kept(tmp_path):
    world = World(load_scenario(SCENARIOS / "quick_wall.toml"))
    world.attach("a1")
    path = tmp_path / "w.ckpt"
    write_checkpoint(path, checkpoint_world(world))
    world.step()
    write_checkpoint(path, checkpoint_world(world))
    assert read_checkpoint(path)["tick"] == 1
    assert read_checkpoint(previous_path(path))["tick"] == 0
    assert load_world(path).tick == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.ckpt", "w.ckpt.prev"]  # no temporary left


@pytest.mark.parametrize("damage,words", [
    (lambda b: b[: len(b) // 2], "truncated"),
    (lambda b: b[:10], "truncated"),
    (lambda b: b[:-1] + bytes([b[-1] ^ 0xFF]), "corrupt"),
    (lambda b: b"NOTACKPT" + b[8:], "not a ConAg world checkpoint"),
    (lambda b: b[:8] + (99).to_bytes(4, "little") + b[12:], "format version 99"),
])
def test_bad_checkpoint_is_refused_with_a_clear_error(tmp_path, damage, words):
    world = World(load_scenario(SCENARIOS / "quick_wall.toml"))
    path = tmp_path / "w.ckpt"
    write_checkpoint(path, checkpoint_world(world))
    world.attach("a1")
    world.step()
    write_checkpoint(path, checkpoint_world(world))
    path.write_bytes(damage(path.read_bytes()))
    with pytest.raises(CheckpointError, match=words) as err:
        load_world(path)
    assert "w.ckpt.prev (tick 0), is intact" in str(err.value)
    assert newest_good(path) == previous_path(path)


def test_a_missing_checkpoint_names_the_previous_one_if_it_is_intact(tmp_path):
    world = World(load_scenario(SCENARIOS / "quick_wall.toml"))
    path = tmp_path / "w.ckpt"
    with pytest.raises(FileNotFoundError):
        load_world(path)  # nothing at all: the plain error
    write_checkpoint(path, checkpoint_world(world))
    world.attach("a1")
    world.step()
    write_checkpoint(path, checkpoint_world(world))
    path.unlink()
    with pytest.raises(CheckpointError, match=r"no checkpoint at .*w\.ckpt; .*w\.ckpt\.prev \(tick 0\), is intact"):
        load_world(path)


def test_a_failed_write_leaves_the_good_checkpoint_in_place(tmp_path, monkeypatch):
    world = World(load_scenario(SCENARIOS / "quick_wall.toml"))
    path = tmp_path / "w.ckpt"
    write_checkpoint(path, checkpoint_world(world))
    good = path.read_bytes()

    def full_disk(_fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    world.step()
    with pytest.raises(OSError):
        write_checkpoint(path, checkpoint_world(world))
    monkeypatch.undo()
    assert path.read_bytes() == good
    assert [p.name for p in tmp_path.iterdir()] == ["w.ckpt"]
    # Bytes that do not read back (a bad write) never replace it either.
    with pytest.raises(CheckpointError):
        write_checkpoint(path, good[:-5])
    assert path.read_bytes() == good


@pytest.mark.parametrize("hard_links", [True, False])
def test_the_checkpoint_file_is_never_absent_while_a_new_one_is_written(tmp_path, monkeypatch, hard_links):
    """A process killed at any step of a write leaves FILE readable: `conag world --resume
    FILE`, started by hand, looks nowhere else. (Renaming FILE to FILE.prev first left no
    FILE for a moment, and a world killed then could not be resumed.)"""
    world = World(load_scenario(SCENARIOS / "quick_wall.toml"))
    path = tmp_path / "w.ckpt"
    write_checkpoint(path, checkpoint_world(world))
    seen = []
    real_replace, real_link = os.replace, os.link

    def replace(src, dst):
        seen.append(read_checkpoint(path)["tick"])  # as a process killed just before this step leaves it
        real_replace(src, dst)
        seen.append(read_checkpoint(path)["tick"])

    def no_link(src, dst):
        raise OSError(1, "Operation not permitted")  # a file system without hard links: a copy instead

    monkeypatch.setattr(os, "replace", replace)
    monkeypatch.setattr(os, "link", real_link if hard_links else no_link)
    world.attach("a1")
    world.step()
    write_checkpoint(path, checkpoint_world(world))
    monkeypatch.undo()
    assert seen[0] == 0 and seen[-1] == 1 and len(seen) == 4  # two steps, FILE there before and after each
    assert read_checkpoint(previous_path(path))["tick"] == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.ckpt", "w.ckpt.prev"]  # no temporary left
