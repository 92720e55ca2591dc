"""Record, replay, echo (issue 13): what a user relies on.

* a recording holds every message of the world's keys, one MCAP channel per key, with its
  tick, a per-key sequence number and the run's metadata; it is complete once closed and
  readable up to its last chunk when the recorder was killed;
* a world in lockstep fed a recording's commands sends the recorded frames, byte for byte
  (three agents, a perturbation mid-run);
* a recorded agent attaches once it hears the recorder, and a recorder stopped writes on
  until the bus is quiet: the recording holds every agent's commands from first to last;
  one that lost an agent's last commands is replayed up to its last full tick;
* `conag replay` publishes a recording again, paced by --rate, from --from;
* `conag echo` prints decoded messages (text, JSON) and rates.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from agent_runtime.config import AgentConfig
from agent_runtime.node import AgentOptions, run_agent
from conag.recording.echo import RateMeter, describe
from conag.recording.echo_node import run_echo
from conag.recording.mcap_log import McapRecorder, read_recording
from conag.recording.recorder import RecordReport, drain_until_quiet, run_recorder
from conag.recording.replay import Comparison, LockstepScript, paced
from conag.recording.replayer import drive_world, publish_recording
from faults.chaos import world_pid
from protocol import keys
from protocol.codec import decode, encode
from protocol.messages import (
    AgentCommand,
    Decision,
    Hello,
    LockstepTimeout,
    Perturbation,
    PerturbResult,
    SensorFrame,
    Welcome,
    WorldStatus,
)
from tests.conftest import ROOT, SCENARIOS, Bus, Process, RunningWorld, conag, free_port, wait_until
from world_server.scenario import load_scenario
from world_server.world import World

W = "w0"


def _cmd(tick, agent="a1", speed=1.0):
    return encode(AgentCommand(agent, tick, speed, 0.0))


def _frame(tick, agent="a1"):
    return encode(SensorFrame(agent, tick, 0.0, 0.0, 0.0, 1, (-1.0,) * 5, False))


# --- the file -------------------------------------------------------------------------------------

def test_a_recording_has_a_channel_per_key_with_ticks_sequences_and_metadata(tmp_path):
    out = tmp_path / "r.mcap"
    with McapRecorder(out, {"scenario": "name = 'x'", "seed": "6"}) as rec:
        for t in range(5):
            rec.add(keys.sensors(W, "a1"), _frame(t), 1000 + 10 * t)
            rec.add(keys.command(W, "a1"), _cmd(t), 1001 + 10 * t)
        rec.add(keys.command(W, "a2"), _cmd(7, "a2"), 2000)
        assert not out.exists() and rec.part.exists()   # only a finished file takes the name
    assert out.exists() and not rec.part.exists()
    with open(out, "rb") as f:   # a plain MCAP file, as any MCAP tool reads it
        reader = make_reader(f)
        summary = reader.get_summary()
        assert sorted(c.topic for c in summary.channels.values()) == sorted(
            [keys.sensors(W, "a1"), keys.command(W, "a1"), keys.command(W, "a2")])
        assert {c.message_encoding for c in summary.channels.values()} == {"msgpack"}
        assert summary.statistics.message_count == 11
    recording = read_recording(out)
    assert recording.complete
    assert recording.info["scenario"] == "name = 'x'" and recording.info["seed"] == "6"
    assert recording.metadata["conag.end"]["messages"] == "11"
    commands = [e for e in recording.entries if e.key == keys.command(W, "a1")]
    assert [(e.tick, e.seq) for e in commands] == [(t, t + 1) for t in range(5)]
    assert [decode(e.data) for e in commands] == [decode(_cmd(t)) for t in range(5)]   # the bytes that travelled
    assert recording.entries[-1].tick == 7 and recording.entries[-1].seq == 1


def test_a_recording_that_lost_the_world_before_the_run_ended_says_so(tmp_path):
    from conag.recording.mcap_log import read_end, world_cut_short

    rec = McapRecorder(tmp_path / "r.mcap")
    rec.add(keys.sensors(W, "a1"), _frame(0), 1)
    rec.close({"ticks": "115"})     # the newest status it heard
    end = read_end(tmp_path / "r.mcap")
    assert end["ticks"] == "115"
    assert "only up to about tick 115 of 300" in world_cut_short(end, 300)
    assert world_cut_short(end, 115) == ""
    assert world_cut_short({}, 300) == "holds no status of the world"
    assert read_end(tmp_path / "missing.mcap") == {}


def test_a_recording_cut_by_sigkill_reads_up_to_its_last_flushed_chunk(tmp_path):
    rec = McapRecorder(tmp_path / "r.mcap")
    for t in range(50):
        rec.add(keys.command(W, "a1"), _cmd(t), t)
    rec.flush()                                   # the recorder process does this every second
    for t in range(50, 60):
        rec.add(keys.command(W, "a1"), _cmd(t), t)
    cut = tmp_path / "cut.mcap.part"
    shutil.copy(rec.part, cut)                    # what a SIGKILL now would leave
    rec.close()
    recording = read_recording(cut)
    assert not recording.complete and "did not finish" in recording.problem
    assert [e.tick for e in recording.entries] == list(range(50))
    assert read_recording(tmp_path / "r.mcap").complete


# --- pure replay and echo parts -----------------------------------------------------------------

def test_paced_scales_the_recorded_gaps_and_starts_from_a_tick(tmp_path):
    with McapRecorder(tmp_path / "r.mcap") as rec:
        for t in range(6):
            rec.add(keys.command(W, "a1"), _cmd(t), 1_000_000_000 + t * 100_000_000)   # 10 Hz
    entries = read_recording(tmp_path / "r.mcap").entries
    assert [round(d, 3) for d, _ in paced(entries, rate=2.0)] == [0.0, 0.05, 0.1, 0.15, 0.2, 0.25]
    assert [(round(d, 3), e.tick) for d, e in paced(entries, rate=1.0, from_tick=4)] == [(0.0, 4), (0.1, 5)]
    assert [d for d, _ in paced(entries, rate=0)] == [0.0] * 6
    with pytest.raises(ValueError):
        list(paced(entries, rate=-1))


def test_welcomes_heard_out_of_order_are_replayed_in_the_order_the_world_attached_them(tmp_path):
    # An agent attached later sees the bodies attached before it: the order matters, and the
    # recorder can hear one tick's Welcomes (on different keys) in another order.
    with McapRecorder(tmp_path / "r.mcap") as rec:
        for t, (agent, body) in enumerate((("a3", 2), ("a1", 0), ("a2", 1))):
            rec.add(keys.welcome(W, agent), encode(Welcome(W, agent, body, 0, 1.0, 1.0, 0.0, False, 0, 1, 6.0, 1.0,
                                                           (), ())), 1 + t)
    script = LockstepScript.from_entries(read_recording(tmp_path / "r.mcap").entries)
    assert [w.agent_id for w in script.attaches[0]] == ["a1", "a2", "a3"]


def test_a_hello_answered_twice_keeps_its_recorded_place_among_the_attaches(tmp_path):
    # On a busy machine an agent sends its Hello again before the world answered the first:
    # the world attaches it twice (same body, no restart), and the second attach sees the
    # bodies attached in between. Body order says nothing of when the repeat came.
    with McapRecorder(tmp_path / "r.mcap") as rec:
        for t, (agent, body) in enumerate((("a3", 1), ("a1", 0), ("a1", 0), ("a2", 2))):
            rec.add(keys.welcome(W, agent), encode(Welcome(W, agent, body, 0, 1.0, 1.0, 0.0, False, 0, 1, 6.0, 1.0,
                                                           (), ())), 1 + t)
    script = LockstepScript.from_entries(read_recording(tmp_path / "r.mcap").entries)
    assert [w.agent_id for w in script.attaches[0]] == ["a1", "a3", "a1", "a2"]


def test_a_frame_the_recorder_missed_is_no_difference_but_a_changed_one_is():
    def frame(holding=False, heading=0.0):
        return encode(SensorFrame("a1", 0, heading, 0.0, 0.0, 1, (-1.0,) * 5, holding))

    attach, step, other = frame(), frame(holding=True), frame(holding=True, heading=1.0)
    # The attach frame of tick 0 was lost on the way to the recorder; the step's was kept.
    c = Comparison()
    c.check(0, "a1", attach, [step])
    c.check(0, "a1", step, [step])
    assert c.settle() and c.identical and (c.matched, c.missing) == (1, 1)
    # The world sent something else where the recording holds the step's frame.
    c = Comparison()
    c.check(0, "a1", attach, [step])
    c.check(0, "a1", other, [step])
    assert not c.settle() and "tick 0, agent a1" in c.first_difference


def test_a_late_command_is_sent_at_the_tick_the_world_got_it(tmp_path):
    with McapRecorder(tmp_path / "r.mcap") as rec:
        rec.add(keys.welcome(W, "a1"), encode(Welcome(W, "a1", 0, 0, 1.0, 1.0, 0.0, False, 0, 1, 6.0, 1.0, (), ())),
                1)
        for t in range(4):        # the world stepped on without the agent (a lockstep timeout) ...
            rec.add(keys.sensors(W, "a1"), _frame(t), 10 + t)
            if t < 3:
                rec.add(keys.lockstep_timeouts(W), encode(LockstepTimeout(W, t, ("a1",))), 10 + t)
        rec.add(keys.command(W, "a1"), _cmd(0), 20)          # ... whose answer to frame 0 came at tick 3
        rec.add(keys.command(W, "a1"), _cmd(3), 21)
        rec.add(keys.command(W, "a2"), _cmd(3, "a2"), 22)
        rec.add(keys.sensors(W, "a1"), _frame(4), 23)
        rec.add(keys.command(W, "a2"), _cmd(3, "a2"), 24)    # on time, though recorded after the next frame
        rec.add(keys.command(W, "a1"), _cmd(4), 25)
    script = LockstepScript.from_entries(read_recording(tmp_path / "r.mcap").entries)
    # Stand-ins for the steps taken without a1: what the world then had (speed 0 after the
    # attach, no turn, no action), tick 2 without anything from it.
    stand_in = [AgentCommand("a1", t, 0.0, 0.0, "none") for t in range(3)]
    assert script.commands[0] == [stand_in[0]] and script.commands[1] == [stand_in[1]]
    assert script.commands[2] == [stand_in[2]]
    assert [(c.agent_id, c.tick) for c in script.commands[3]] == [("a1", 0), ("a1", 3), ("a2", 3), ("a2", 3)]
    assert [(c.agent_id, c.tick) for c in script.commands[4]] == [("a1", 4)]
    assert script.agents() == ["a1"] and script.last_tick == 4


def test_a_recording_that_lost_an_agents_last_commands_is_replayed_up_to_its_last_full_tick(tmp_path):
    # A recorder stopped on a busy machine held the world's frames to tick 5 (a2's last one
    # dropped on the way) but a2's commands only to tick 2: past that, a replayed world would
    # wait for ever for a2.
    with McapRecorder(tmp_path / "r.mcap") as rec:
        for body, a in enumerate(("a1", "a2")):
            rec.add(keys.welcome(W, a), encode(Welcome(W, a, 0, body, 1.0, 1.0, 0.0, False, 0, 1, 6.0, 1.0, (), ())), 1)
        for t in range(6):
            for a in ("a1", "a2") if t < 5 else ("a1",):
                rec.add(keys.sensors(W, a), _frame(t, a), 10 + t)
            rec.add(keys.command(W, "a1"), _cmd(t), 10 + t)
            if t <= 2:
                rec.add(keys.command(W, "a2"), _cmd(t, "a2"), 10 + t)
    script = LockstepScript.from_entries(read_recording(tmp_path / "r.mcap").entries)
    assert script.last_tick == 2
    assert "no command of a2 after tick 2" in script.cut_short


def test_a_recording_whose_last_tick_lacks_an_agents_command_is_replayed_up_to_the_tick_before(tmp_path):
    # The world stopped at tick 5 (its last frames went out); a2's answer to frame 5 came too
    # late for the recorder, a1's did not: a world fed a1's command of tick 5 waits for a2's.
    with McapRecorder(tmp_path / "r.mcap") as rec:
        for body, a in enumerate(("a1", "a2")):
            rec.add(keys.welcome(W, a), encode(Welcome(W, a, 0, body, 1.0, 1.0, 0.0, False, 0, 1, 6.0, 1.0, (), ())), 1)
        for t in range(6):
            for a in ("a1", "a2"):
                rec.add(keys.sensors(W, a), _frame(t, a), 10 + t)
                if a == "a1" or t < 5:
                    rec.add(keys.command(W, a), _cmd(t, a), 10 + t)
    script = LockstepScript.from_entries(read_recording(tmp_path / "r.mcap").entries)
    assert script.last_tick == 4 and "no command of a2 after tick 4" in script.cut_short


def test_an_agent_that_went_away_does_not_cut_the_replay_short(tmp_path):
    with McapRecorder(tmp_path / "r.mcap") as rec:
        for body, a in enumerate(("a1", "a2")):
            rec.add(keys.welcome(W, a), encode(Welcome(W, a, 0, body, 1.0, 1.0, 0.0, False, 0, 1, 6.0, 1.0, (), ())), 1)
        for t in range(6):
            rec.add(keys.sensors(W, "a1"), _frame(t), 10 + t)
            rec.add(keys.command(W, "a1"), _cmd(t), 10 + t)
            if t <= 2:   # a2's frames and commands end together: it went away
                rec.add(keys.sensors(W, "a2"), _frame(t, "a2"), 10 + t)
                rec.add(keys.command(W, "a2"), _cmd(t, "a2"), 10 + t)
    script = LockstepScript.from_entries(read_recording(tmp_path / "r.mcap").entries)
    assert script.last_tick == 5 and script.cut_short == ""


def _welcome(agent="a1", tick=0, epoch=0, body=0):
    return encode(Welcome(W, agent, body, tick, 1.0, 1.0, 0.0, False, 0, 1, 6.0, 1.0, (), (), epoch=epoch))


def _epoch_frame(tick, epoch, agent="a1"):
    return encode(SensorFrame(agent, tick, 0.0, 0.0, 0.0, 1, (-1.0,) * 5, False, epoch=epoch))


def test_a_recording_across_world_restarts_is_split_into_the_runs_that_count(tmp_path):
    from conag.recording.replay import world_runs

    with McapRecorder(tmp_path / "r.mcap") as rec:
        rec.add(keys.welcome(W, "a1"), _welcome(epoch=7), 1)
        for t in range(7):         # the first run reaches tick 6; its checkpoint of tick 4 survives it
            rec.add(keys.sensors(W, "a1"), _epoch_frame(t, 7), 10 + t)
            if t < 6:
                rec.add(keys.command(W, "a1"), _cmd(t, speed=1.0), 10 + t)
        rec.add(keys.welcome(W, "a1"), _welcome(tick=4, epoch=9), 20)   # resumed at tick 4: another epoch
        for t in range(4, 9):
            rec.add(keys.sensors(W, "a1"), _epoch_frame(t, 9), 20 + t)
            rec.add(keys.command(W, "a1"), _cmd(t, speed=2.0), 20 + t)
    first, second = world_runs(read_recording(tmp_path / "r.mcap").entries)
    # The first run counts up to the checkpoint the second was resumed from: its ticks 5-6 were undone.
    assert (first.first_tick, first.end, first.last_tick, first.end_tick, first.resumed) == (0, 4, 3, 4, False)
    assert sorted(first.frames) == [(t, "a1") for t in range(5)] and first.epoch == 7
    assert {t: [c.speed for c in cs] for t, cs in first.commands.items() if cs} == {t: [1.0] for t in range(4)}
    # The second from there, with its own commands: for ticks 4 and 5, which both runs
    # reached, the agent's last command recorded (the first run's came before it).
    assert (second.first_tick, second.end, second.last_tick, second.resumed, second.epoch) == (4, None, 8, True, 9)
    assert [w.agent_id for w in second.attaches[4]] == ["a1"] and second.cut_short == ""
    assert {t: [c.speed for c in cs] for t, cs in second.commands.items() if cs} == {t: [2.0] for t in range(4, 9)}
    assert sorted(second.frames) == [(t, "a1") for t in range(4, 9)]


def test_a_world_started_again_from_the_start_replaces_the_run_it_follows(tmp_path):
    from conag.recording.replay import world_runs

    with McapRecorder(tmp_path / "r.mcap") as rec:
        for run, speed in ((0, 1.0), (1, 2.0)):   # no checkpoint yet: the same epoch, ticks from 0 again
            rec.add(keys.welcome(W, "a1"), _welcome(epoch=7), 10 * run)
            for t in range(3 + run):
                rec.add(keys.sensors(W, "a1"), _epoch_frame(t, 7), 10 * run + t)
                rec.add(keys.command(W, "a1"), _cmd(t, speed=speed), 10 * run + t)
    (only,) = world_runs(read_recording(tmp_path / "r.mcap").entries)
    assert (only.first_tick, only.end, only.resumed, only.last_tick) == (0, None, False, 3)
    assert [w.agent_id for w in only.attaches[0]] == ["a1"]
    assert {t: [c.speed for c in cs] for t, cs in only.commands.items() if cs} == {t: [2.0] for t in range(4)}


def test_a_recording_that_lacks_ticks_mid_run_is_replayed_up_to_them(tmp_path):
    # Its recorder lost the world's link (and the agent's) for ticks 4-6: a replay past tick
    # 3 would wait for ever for the command of tick 4.
    with McapRecorder(tmp_path / "r.mcap") as rec:
        rec.add(keys.welcome(W, "a1"), _welcome(), 1)
        for t in (*range(4), *range(7, 10)):
            rec.add(keys.sensors(W, "a1"), _frame(t), 10 + t)
            rec.add(keys.command(W, "a1"), _cmd(t), 10 + t)
    script = LockstepScript.from_entries(read_recording(tmp_path / "r.mcap").entries)
    assert script.last_tick == 3 and script.end_tick == 4
    assert "no command of a1 after tick 3, though it holds its frames to tick 9" in script.cut_short
    assert "lost them" in script.cut_short


def test_a_stopped_recorder_writes_on_until_the_bus_is_quiet():
    now = [0.0]
    arrivals = {0.3: 5, 0.7: 2, 1.1: 1, 3.0: 9}   # when messages still on their way come in, and how many

    def drain():
        due = [t for t in arrivals if t <= now[0]]
        return sum(arrivals.pop(t) for t in due)

    def sleep(dt):
        now[0] += dt

    drain_until_quiet(drain, quiet=0.5, limit=10.0, clock=lambda: now[0], sleep=sleep)
    assert list(arrivals) == [3.0]          # took the three bursts, each within 0.5 s of the one before
    assert 1.6 <= now[0] < 1.7              # and stopped 0.5 s after the last
    arrivals.update({t / 10: 1 for t in range(30, 200)})   # a bus that never goes quiet
    drain_until_quiet(drain, quiet=0.5, limit=2.0, clock=lambda: now[0], sleep=sleep)
    assert now[0] < 1.7 + 2.1


def test_describe_prints_a_message_as_text_or_json_and_never_raises():
    line = describe(keys.command(W, "a1"), _cmd(3, speed=1.5))
    assert line == (f"{keys.command(W, 'a1')}: AgentCommand(agent_id='a1', tick=3, speed=1.5, turn=0, action='none', "
                    "mark_dx=0, mark_dy=0, mark_kind='site')")
    assert "... 80 values" in describe("k", encode(SensorFrame("a1", 1, 0.0, 0.0, 0.0, 16, (1.0,) * 80, False)))
    doc = json.loads(describe("k", _cmd(3), as_json=True))
    assert doc == {"key": "k", "type": "AgentCommand",
                   "message": {"agent_id": "a1", "tick": 3, "speed": 1.0, "turn": 0.0, "action": "none",
                               "mark_dx": 0.0, "mark_dy": 0.0, "mark_kind": "site"}}
    assert "not a ConAg message" in describe("k", b"\x00garbage")
    assert "error" in json.loads(describe("k", b"\x00garbage", as_json=True))


def test_rate_meter_reports_rate_and_spread_of_the_gaps():
    meter = RateMeter(window=10)
    assert meter.rate() is None
    for t in (0.0, 0.1, 0.2, 0.3, 0.5):
        meter.add(t)
    rate = meter.rate()
    assert rate.hz == pytest.approx(8.0) and rate.min_gap == pytest.approx(0.1)
    assert rate.max_gap == pytest.approx(0.2) and rate.window == 4
    assert rate.line().startswith("average rate: 8.000 Hz")


# --- over the bus ---------------------------------------------------------------------------------

@pytest.mark.slow   # a build of three agents over the bus, recorded and replayed: about 2 s
def test_a_recorded_run_of_three_agents_is_reproduced_frame_for_frame_by_a_fresh_world(bus, start_world, tmp_path):
    scenario = load_scenario(SCENARIOS / "fig6.toml")
    # The agents compile their kernels on their first step: no lockstep timeout meanwhile, so
    # that the test is quick (a replay waits through every timeout the recording had).
    scenario = replace(scenario, world=replace(scenario.world, lockstep_timeout=60.0))
    # No tick limit until the perturbation is answered: a world that reached a fixed limit
    # first (80 ticks took less than a CI worker's query) stopped with the query unanswered.
    rw = start_world(scenario, wait_agents=3, max_ticks=1_000_000)
    stop_rec, report = threading.Event(), RecordReport()
    recorder = threading.Thread(target=run_recorder, args=(bus.client_session(), W, tmp_path / "run.mcap", stop_rec),
                                kwargs=dict(metadata={"seed": str(scenario.seed)}, report=report), daemon=True)
    recorder.start()
    wait_until(report.heard_world.is_set, what="the recorder to hear the world")
    stop_agents = threading.Event()
    agents = [threading.Thread(target=run_agent, daemon=True, kwargs=dict(
        session=bus.client_session(), opts=AgentOptions(W, f"a{i}", AgentConfig(), seed=i), stop=stop_agents))
        for i in (1, 2, 3)]
    for a in agents:
        a.start()
    perturber = bus.client_session()
    wait_until(lambda: rw.world.tick >= 40, 60, what="tick 40")
    # A perturbation mid-run: the query reaches the world alone; its Perturbed publication is recorded.
    reply = next(iter(perturber.get(keys.perturb(W), payload=encode(Perturbation("remove", 9.5, 8.5, "food")),
                                    timeout=5)))
    assert decode(reply.ok.payload.to_bytes(), PerturbResult).ok
    ticks = rw.world.tick + 80          # read by the world's loop after every tick
    rw.server.max_ticks = ticks
    rw.thread.join(60)
    assert rw.world.tick == ticks
    stop_agents.set()
    for a in agents:
        a.join(10)
    wait_until(lambda: report.status is not None and report.status.tick == ticks, what="the last status recorded")
    stop_rec.set()
    recorder.join(10)

    recording = read_recording(tmp_path / "run.mcap")
    assert recording.complete
    leaves = Counter(e.key.removeprefix(keys.world_root(W) + "/").split("/")[-1] for e in recording.entries)
    assert leaves["welcome"] == 3 and leaves["perturbed"] == 1
    assert leaves["command"] >= 3 * ticks and leaves["decision"] >= 3 * ticks
    # Frames are latest-wins (congestion control DROP): on a loaded machine a few never reach
    # the recorder. Those are not compared below; nearly all must be there.
    assert leaves["sensors"] >= 0.9 * 3 * ticks
    assert leaves["status"] >= 1 and leaves["state"] >= 3

    # A fresh world from the same scenario and seed, fed the recorded attaches, perturbation and commands.
    script = LockstepScript.from_entries(recording.entries)
    assert script.agents() == ["a1", "a2", "a3"] or sorted(script.agents()) == ["a1", "a2", "a3"]
    assert sum(len(p) for p in script.perturbations.values()) == 1 and not script.limits
    other = Bus(f"tcp/127.0.0.1:{free_port()}")   # a bus of its own: the recorded world still holds its endpoint
    try:
        replayed = RunningWorld(World(scenario, np.random.default_rng(int(recording.info["seed"]))),
                                other.server_session(), wait_agents=3, max_ticks=ticks)
        result = drive_world(other.client_session(), script, W, to_tick=ticks - 1)
        replayed.close()
    finally:
        other.close()
    assert result.first_difference == ""
    # Every frame that reached both the recorder and the replay is the same, byte for byte;
    # a few may be lost on the way (latest-wins), never more than a tenth.
    recorded = sum(len(f) for f in script.frames.values())
    assert result.identical and result.matched + result.dropped >= recorded and result.matched >= 0.9 * recorded
    assert replayed.world.tick == ticks
    assert replayed.world.status().sites_filled == rw.world.status().sites_filled
    assert np.array_equal(replayed.world.agent_poses(), rw.world.agent_poses())


def test_a_recorded_agent_attaches_only_once_it_hears_the_recorder(bus, start_world):
    # On the one-host bus peers do not forward for each other: an agent's commands reach the
    # recorder only over their own link, which may come up after the world's (seconds, for an
    # idle-priority recorder on a busy machine). A recorded agent waits for it.
    rw = start_world(SCENARIOS / "quick_wall.toml", wait_agents=1)
    stop = threading.Event()
    agent = threading.Thread(target=run_agent, daemon=True, kwargs=dict(
        session=bus.client_session(), opts=AgentOptions(W, "a1", AgentConfig(), recorded=True, attach_timeout=30),
        stop=stop))
    agent.start()
    try:
        # The agent is up (its liveliness token is on the bus) and waits: it must not attach
        # meanwhile (a bare sleep would pass before the agent had even started).
        watcher = bus.client_session()
        wait_until(lambda: list(watcher.liveliness().get(keys.agent_token(W, "a1"), timeout=1)), 20,
                   what="a1's liveliness token")
        time.sleep(0.5)
        assert rw.world.live_agents() == [] and rw.world.tick == 0
        token = bus.client_session().liveliness().declare_token(keys.recorder_token(W, "recorder"))
        wait_until(lambda: rw.world.live_agents() == ["a1"], 20, what="a1 to attach once the recorder is up")
        wait_until(lambda: rw.world.tick > 0, 20, what="the world to step")
        token.undeclare()
    finally:
        stop.set()
        agent.join(10)


def test_a_recorded_world_lets_agents_attach_only_once_a_recorder_is_linked(bus, start_world, monkeypatch):
    # A world `conag run` starts again links to the recorder seconds after to the agents (an
    # idle recorder reconnects late): the agents' attaches to it would be missing from the
    # recording, and a replay could not tell which agents came back. It waits for the recorder.
    from world_server import server as server_node

    monkeypatch.setattr(server_node, "RECORDER_WAIT", 120.0)   # longer than any busy machine takes here
    rw = start_world(SCENARIOS / "quick_wall.toml", wait_agents=1, recorded=True)
    agent = bus.client_session()
    token = agent.liveliness().declare_token(keys.agent_token(W, "a1"))  # kept: a token dropped is undeclared

    def attach():
        replies = list(agent.get(keys.attach(W, "a1"), payload=encode(Hello("a1", 1)), timeout=5))
        return replies[0] if replies else None

    refused = wait_until(attach, 60, what="the world's answer")
    assert refused.ok is None and "waits for its recorder" in refused.err.payload.to_bytes().decode()
    assert rw.world.live_agents() == []
    recorder = bus.client_session().liveliness().declare_token(keys.recorder_token(W, "recorder"))
    wait_until(lambda: (r := attach()) is not None and r.ok is not None, 60, what="an attach once the recorder is up")
    assert rw.world.live_agents() == ["a1"]
    recorder.undeclare()
    token.undeclare()


def test_a_recorded_world_without_a_recorder_lets_agents_attach_after_a_while(bus, start_world, monkeypatch,
                                                                               caplog):
    from world_server import server as server_node

    monkeypatch.setattr(server_node, "RECORDER_WAIT", 0.2)
    rw = start_world(SCENARIOS / "quick_wall.toml", wait_agents=1, recorded=True)
    agent = bus.client_session()
    token = agent.liveliness().declare_token(keys.agent_token(W, "a1"))  # kept: a token dropped is undeclared
    hello = encode(Hello("a1", 1))
    wait_until(lambda: any(r.ok is not None for r in agent.get(keys.attach(W, "a1"), payload=hello, timeout=5)),
               60, what="an attach without a recorder")
    assert rw.world.live_agents() == ["a1"]
    token.undeclare()
    assert "no recorder linked within 0.2 s" in caplog.text


def test_replay_publishes_a_recording_from_a_tick_and_echo_prints_it(bus, tmp_path):
    with McapRecorder(tmp_path / "r.mcap") as rec:
        for t in range(10):
            rec.add(keys.command(W, "a1"), _cmd(t), 1_000_000 * t)
            rec.add(keys.status(W), encode(WorldStatus(W, "s", 1, "lockstep", t, 0, 1, 1, 1, 0, False)),
                    1_000_000 * t + 1)
    entries = read_recording(tmp_path / "r.mcap").entries
    lines: list[str] = []
    stop = threading.Event()
    echo = threading.Thread(target=run_echo, args=(bus.server_session(), keys.all_agents(W, "command"), stop),
                            kwargs=dict(out=lines.append), daemon=True)
    echo.start()
    sent = publish_recording(bus.client_session(), entries, threading.Event(), rate=0, from_tick=4, wait=10)
    assert sent == 12
    wait_until(lambda: len(lines) == 6, what="six commands echoed")
    stop.set()
    echo.join(5)
    assert [line.split("tick=")[1].split(",")[0] for line in lines] == ["4", "5", "6", "7", "8", "9"]


def test_a_replay_answers_a_decision_query_with_the_newest_decision_it_sent(bus, tmp_path):
    # A live viewer asks the shown agent for its newest Decision; in a replay the replayer answers.
    with McapRecorder(tmp_path / "r.mcap") as rec:
        for t in range(10):
            d = Decision("a1", t, (float(t),) + (0.0,) * 5, (0.0,) * 7, "none", "explore")
            rec.add(keys.decision(W, "a1"), encode(d), 1_000_000 * t)
    asker = bus.server_session()
    answered: list[int] = []

    def ask(entry) -> None:
        if entry.tick not in (3, 8):
            return
        for _ in range(100):  # until the replayer's queryable is known on this side
            for reply in asker.get(keys.decision(W, "a1"), timeout=5):
                if reply.ok is not None:
                    answered.append(decode(reply.ok.payload.to_bytes(), Decision).tick)
                    return
            time.sleep(0.05)

    sent = publish_recording(bus.client_session(), read_recording(tmp_path / "r.mcap").entries, threading.Event(),
                             rate=0, wait=0.5, on_message=ask)
    assert sent == 10
    assert answered == [3, 8]


def test_echo_once_prints_one_message_as_json(bus):
    lines: list[str] = []
    echo = threading.Thread(target=run_echo, args=(bus.server_session(), keys.command(W, "a1"), threading.Event()),
                            kwargs=dict(once=True, as_json=True, out=lines.append), daemon=True)
    echo.start()
    pub = bus.client_session().declare_publisher(keys.command(W, "a1"))
    wait_until(lambda: pub.put(_cmd(5)) or not echo.is_alive(), what="echo --once to print and stop")
    assert json.loads(lines[0])["message"]["tick"] == 5 and len(lines) == 1


# --- the commands -----------------------------------------------------------------------------------

@pytest.mark.slow
def test_conag_run_record_then_replay_verify_reproduces_fig6(tmp_path, endpoint):
    out = tmp_path / "fig6.mcap"
    run = conag("run", SCENARIOS / "fig6.toml", "--headless", "--quiet", "--max-ticks", "300", "--record", out,
                "--listen", endpoint, timeout=120)
    assert run.returncode in (0, 3), run.stderr
    recording = read_recording(out)
    assert recording.complete and recording.info["scenario_name"] == "fig6" and recording.info["seed"] == "6"
    verify = conag("replay", out, "--verify", "--quiet", timeout=120)
    assert verify.returncode == 0, verify.stdout + verify.stderr
    assert "identical" in verify.stdout
    # Cut short after the attaches, with some of tick 0's commands (a1's missing): the replay
    # compares the attaches' frames and stops, where it waited 60 s for a step that could not come.
    cut = tmp_path / "cut.mcap"
    with McapRecorder(cut, recording.info) as rec:
        for e in recording.entries:
            # (and without a LockstepTimeout: on a busy machine the world stepped from tick 0 without
            # the agents, compiling their kernels, and the replay would take that step too)
            if e.tick == 0 and not e.key.endswith(("/a1/command", "/status", "/lockstep_timeout")):
                rec.add(e.key, e.data, e.log_time)
    started = time.monotonic()
    verify = conag("replay", cut, "--verify", "--quiet", timeout=120)
    assert verify.returncode == 0, verify.stdout + verify.stderr
    assert "identical: 3 frames of 3 agents over ticks 0-0" in verify.stdout
    assert "no command of a1 after tick -1" in verify.stderr
    assert time.monotonic() - started < 50


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_replay_verify_reproduces_a_recorded_run_across_a_world_restart(tmp_path, endpoint):
    # The world is SIGKILLed past its first checkpoint; `conag run` resumes it from its newest
    # checkpoint and the agent attaches again. The recording then holds two runs of the world
    # (the dead one's last ticks twice); --verify replays the second from the state the
    # replay of the first reached at the checkpoint's tick, to the run's end.
    out = tmp_path / "r.mcap"
    run = subprocess.Popen([sys.executable, "-m", "conag", "run", str(SCENARIOS / "nested_squares.toml"),
                            "--agents", "1", "--headless", "--record", str(out), "--checkpoint-every", "50",
                            "--max-ticks", "900", "--stall-ticks", "0", "--listen", endpoint],
                           cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert run.stdout is not None
        for line in run.stdout:  # past the first checkpoint (tick 50)
            if line.startswith("tick ") and int(line.split()[1]) >= 60:
                break
        os.kill(wait_until(lambda: world_pid(run.pid), what="the world process"), signal.SIGKILL)
        rest, _ = run.communicate(timeout=300)
    finally:
        if run.poll() is None:
            run.kill()
            run.wait(10)
    assert run.returncode == 3, rest   # not complete in 900 ticks: what matters is that it got there
    said = next(line for line in rest.splitlines() if "the world died" in line)
    resumed_at = int(said.split("checkpoint of tick ")[1].split()[0])
    assert resumed_at > 0 and resumed_at % 50 == 0, said
    verify = conag("replay", out, "--verify", "--quiet", timeout=300)
    assert verify.returncode == 0, verify.stdout + verify.stderr
    assert "over ticks 0-90" in verify.stdout, verify.stdout   # to the run's end (900, or 901: one step more)
    assert f"across 1 world restart (started again at tick {resumed_at};" in verify.stdout, verify.stdout
    frames = int(verify.stdout.split("identical: ")[1].split()[0])
    assert frames >= 900, verify.stdout   # every tick compared once, the resumed one's from its checkpoint on


@pytest.mark.slow
def test_conag_record_finishes_its_file_on_sigterm(tmp_path, endpoint):
    out = tmp_path / "r.mcap"
    rec = Process("record", str(out), "--connect", endpoint, "--scenario", str(SCENARIOS / "quick_wall.toml"))
    try:
        rec.wait_for("recording world")
        assert rec.stop() == 0
        recording = read_recording(out)
        assert recording.complete and recording.info["scenario_name"] == "quick_wall"
        assert not out.with_name(out.name + ".part").exists()
    finally:
        rec.kill()


def _scheduling(pid: int) -> set[tuple[int, int]]:
    """(nice value, scheduling policy) of every thread of process `pid` (Linux keeps them per thread)."""
    found = set()
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            fields = task.joinpath("stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # the thread ended meanwhile
        found.add((int(fields[16]), int(fields[38])))
    return found


def test_a_stopping_recorder_finishes_at_the_normal_priority():
    # Idle on a machine whose cores are all busy, a stopped recorder took longer than 5 s to
    # finish its file. The signal handler restores the normal policy on every thread first:
    # the one the process started with (normal, as a rule; idle under `chrt -i 0`).
    code = ("import os, signal, threading; from conag.common import lower_priority, restore_priority, "
            "stop_on_signals\n"
            "lower_priority('idle'); t = threading.Thread(target=threading.Event().wait, args=(5,), daemon=True)\n"
            "t.start()\n"
            "with stop_on_signals(on_stop=lambda: restore_priority('idle')) as stop:\n"
            "    before = {os.sched_getscheduler(int(x)) for x in os.listdir('/proc/self/task')}\n"
            "    os.kill(os.getpid(), signal.SIGTERM); stop.wait(5)\n"
            "    after = {os.sched_getscheduler(int(x)) for x in os.listdir('/proc/self/task')}\n"
            "print(sorted(before), sorted(after), stop.is_set())")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == [f"[{os.SCHED_IDLE}]", f"[{os.sched_getscheduler(0)}]", "True"]


@pytest.mark.parametrize("priority", ["idle", "low"])
def test_conag_record_runs_all_its_threads_at_a_lower_priority_so_the_run_gets_the_cpu_first(tmp_path, endpoint,
                                                                                            priority):
    base = os.getpriority(os.PRIO_PROCESS, 0)
    rec = Process("record", str(tmp_path / "r.mcap"), "--connect", endpoint, "--priority", priority)
    try:
        rec.wait_for("recording world")
        threads = _scheduling(rec.proc.pid)
        # zenoh's threads too: they start after the priority is lowered, and inherit it.
        if priority == "idle":
            assert {policy for _, policy in threads} == {os.SCHED_IDLE}
        else:   # nice raised by 10; the policy as this process's (idle under `chrt -i 0`)
            assert threads == {(min(base + 10, 19), os.sched_getscheduler(0))}
        assert len(list(Path(f"/proc/{rec.proc.pid}/task").iterdir())) > 1
    finally:
        rec.kill()


def test_conag_record_refuses_an_unknown_priority(tmp_path):
    done = conag("record", tmp_path / "r.mcap", "--priority", "high", timeout=60)
    assert done.returncode == 2 and "invalid choice: 'high'" in done.stderr
    assert not (tmp_path / "r.mcap").exists()
