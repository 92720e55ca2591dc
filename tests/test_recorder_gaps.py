"""A recorder on a busy machine (issue 35): it is kept from starving, and a recording that
lacks some of the world's ticks says which, never lacks them silently.

* `conag.recording.gaps.TickGaps` finds the ticks a recorder missed as it writes;
* an idle recorder that starves runs at the normal priority from then on (`PriorityGuard`);
* a real recorder whose link the world closed (SIGSTOP for its starving) links again and
  names, in its log and its recording, exactly the ticks it lacks;
* `bench.bench_record_load` measures it, finding what a recording lacks from the file itself.
"""

from __future__ import annotations

import signal
import time

import pytest

from conag.recording.mcap_log import McapRecorder, read_recording
from protocol import keys
from protocol.codec import encode
from protocol.messages import AgentCommand, LockstepTimeout, SensorFrame, WorldStatus
from tests.conftest import Process, wait_until

W = "w0"


def test_the_world_ticks_a_recorder_missed_are_found_as_it_goes():
    from conag.recording.gaps import TickGaps, describe_lost, format_gaps, lost_ticks

    # Lockstep: every tick brings frames, so a jump of the newest tick is a gap.
    g = TickGaps(lockstep=True)
    assert [g.heard(t) for t in (0, 1, 1, 2)] == [None] * 4
    assert g.heard(6) == (3, 5) and g.heard(7) is None
    # A world resumed from an older checkpoint goes back in ticks: no gap, then on from there.
    assert [g.heard(t) for t in (4, 5, 6, 7, 8)] == [None] * 5
    assert g.heard(10) == (9, 9) and g.lost == 4
    assert g.end_metadata() == {"ticks_lost": "4", "lost_ticks": "3-5,9"}
    assert lost_ticks(g.end_metadata()) == [(3, 5), (9, 9)] and lost_ticks({}) == []
    assert "lacks the world's ticks 3-5,9 (4 ticks)" in describe_lost(g.gaps) and describe_lost([]) == ""
    # Realtime (frames are latest-wins): only the ticks between the world's token going and
    # coming back count, as the first message after says.
    g = TickGaps()
    assert [g.heard(t) for t in (0, 5, 9)] == [None] * 3
    g.token(False)
    assert g.heard(10) is None        # still on its way when the link went
    g.token(True)
    assert g.heard(30) == (11, 29) and g.heard(40) is None
    g.token(False)
    g.token(True)
    assert g.heard(12) is None        # a world that died and came back from a checkpoint: nothing lost
    assert format_gaps(g.gaps) == "11-29"


def test_an_idle_recorder_that_starves_runs_at_the_normal_priority_from_then_on():
    from conag.recording.recorder import STARVED, PriorityGuard, RecordReport

    now, raised = [0.0], []
    report = RecordReport()
    guard = PriorityGuard(True, report, clock=lambda: now[0], raise_priority=lambda: raised.append(now[0]) or True)
    for dt in (0.002, 0.5, STARVED * 0.9):   # a busy loop, late turns: not starved
        now[0] += dt
        guard.turn()
    assert raised == [] and not report.raised
    now[0] += STARVED
    guard.turn()
    now[0] += 5 * STARVED
    guard.turn()                              # once raised, it stays
    assert raised == [now[0] - 5 * STARVED] and report.raised
    idle_at_start = PriorityGuard(True, RecordReport(), clock=lambda: now[0], raise_priority=lambda: False)
    now[0] += 2 * STARVED
    idle_at_start.turn()                      # started idle (chrt -i 0): nothing to raise it to
    assert not idle_at_start.report.raised
    normal = PriorityGuard(False, RecordReport(), clock=lambda: now[0], raise_priority=lambda: raised.append(-1))
    now[0] += 2 * STARVED
    normal.turn()
    assert raised[-1] != -1



class _Sample:
    def __init__(self, key: str, data: bytes, work: float, now: list[float]):
        self.key_expr, self._data, self._work, self._now = key, data, work, now

    @property
    def payload(self):
        return self

    def to_bytes(self) -> bytes:
        self._now[0] += self._work   # writing this message takes `work` seconds of the clock
        return self._data


class _Inbox:
    def __init__(self, samples):
        self.samples = list(samples)

    def try_recv(self):
        return self.samples.pop(0) if self.samples else None


def test_a_long_drain_is_work_not_starving_but_a_gap_between_two_messages_is(tmp_path):
    from conag.recording.recorder import STARVED, PriorityGuard, RecordReport, _drain

    def drain(gaps: list[float]) -> tuple[int, list[float]]:
        """Drain one message per entry of `gaps`, each taking that long on the clock; what the guard raised."""
        now, raised = [0.0], []
        report = RecordReport()
        guard = PriorityGuard(True, report, clock=lambda: now[0], raise_priority=lambda: raised.append(now[0]) or True)
        key = keys.command("w0", "a1")
        inbox = _Inbox(_Sample(key, encode(AgentCommand("a1", t, 0.0, 0.0, "none")), gap, now)
                       for t, gap in enumerate(gaps))
        with McapRecorder(tmp_path / f"r{len(gaps)}.mcap") as rec:
            n = _drain(inbox, rec, keys.status("w0"), report, lambda: 0, guard.turn, most=len(gaps) - 1)
        return n, raised

    # 20 messages of 0.2 STARVED each: four times STARVED in one drain, never that long between two
    n, raised = drain([STARVED * 0.2] * 20)
    assert n == 19 and raised == []   # at most `most` at a time; not raised
    # the same drain with one message held up for longer than STARVED (the recorder had no CPU)
    n, raised = drain([STARVED * 0.2] * 10 + [STARVED * 1.5] + [STARVED * 0.2] * 10)
    assert n == 20 and raised == [pytest.approx(STARVED * 3.5)]

@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_recorder_whose_world_link_was_closed_names_the_ticks_it_lacks(tmp_path, endpoint):
    # A recorder that gets no CPU (SIGSTOP here; starved, on a busy machine) has the world's
    # link to it closed once a blocked frame has waited the world's `wait_before_close` (5 s
    # by default; 0.2 s here). zenoh links it again once it runs; the frames in between are
    # not in the file, and the recording must say which, never lack them silently.
    import zenoh

    from conag.recording.gaps import format_gaps, lost_ticks
    from conag.recording.mcap_log import read_end
    from protocol.bus import BusOptions, make_config

    config = make_config(BusOptions(listen=(endpoint,)), serve=True)
    config.insert_json5("transport/link/tx/queue/congestion_control/block/wait_before_close", "200000")
    world = zenoh.open(config)
    out = tmp_path / "r.mcap"
    rec = Process("record", str(out), "--connect", endpoint, "--priority", "normal", "--msgpack-only")
    try:
        token = world.liveliness().declare_token(keys.world_token(W))  # kept: dropped, it is undeclared
        block = dict(congestion_control=zenoh.CongestionControl.BLOCK, reliability=zenoh.Reliability.RELIABLE)
        frames = world.declare_publisher(keys.sensors(W, "a1"), **block)
        rec.wait_for("recording world", timeout=120)   # a busy machine starts Python slowly
        wait_until(lambda: frames.matching_status.matching, timeout=60, what="the recorder's subscriber")
        world.put(keys.status(W), encode(WorldStatus(W, "t", 1, "lockstep", 0, 0, 1, 1, 1, 0, False)))
        tick = 0

        def publish(n: int, pause: float = 0.005) -> None:
            nonlocal tick
            for _ in range(n):
                frames.put(_big_frame(tick))
                tick += 1
                time.sleep(pause)

        publish(20)
        rec.proc.send_signal(signal.SIGSTOP)
        deadline = time.monotonic() + 60
        while frames.matching_status.matching and time.monotonic() < deadline:
            publish(1, pause=0)                       # until the world closes the link to it
        assert not frames.matching_status.matching, "the world never closed its link to the stopped recorder"
        publish(10)                                   # published while nobody records
        rec.proc.send_signal(signal.SIGCONT)
        wait_until(lambda: frames.matching_status.matching, timeout=60, what="the recorder to link again")
        publish(20)
        assert rec.stop(timeout=120) == 0, rec.err
        token.undeclare()
    finally:
        rec.proc.send_signal(signal.SIGCONT)
        rec.kill()
        world.close()
    recorded = {e.tick for e in read_recording(out).entries if e.key.endswith("/sensors")}
    missing = sorted(set(range(tick)) - recorded)
    assert missing and max(recorded) == tick - 1, (missing, sorted(recorded)[-5:])
    reported = lost_ticks(read_end(out))
    assert sorted(t for a, b in reported for t in range(a, b + 1)) == missing   # every one named, no other
    assert "the recording lacks the world's ticks" in rec.err, rec.err
    assert f"lacks the world's ticks {format_gaps(reported[:1])} " in rec.err


def _big_frame(tick: int) -> bytes:
    """A frame of the most sectors: fills the world's queue to a stopped recorder quickly."""
    return encode(SensorFrame("a1", tick, 0.0, 0.0, 0.0, 64, (1.0,) * 320, False))


def test_the_load_measurement_finds_what_a_recording_lacks_from_the_file_itself(tmp_path):
    from bench.bench_record_load import lost_data

    with McapRecorder(tmp_path / "r.mcap") as rec:
        for t in (*range(5), *range(8, 11)):      # the world's ticks 5-7 and 11 are not in it
            rec.add(keys.sensors(W, "a1"), _big_frame(t), t)
            if t == 2:                             # stepped without the agent: a timeout says so
                rec.add(keys.lockstep_timeouts(W), encode(LockstepTimeout(W, 2, ("a1",))), t)
            elif t != 9:                           # the command of tick 9 is lost
                rec.add(keys.command(W, "a1"), encode(AgentCommand("a1", t, 1.0, 0.0)), t)
    loss = lost_data(tmp_path / "r.mcap", final_tick=11)
    assert loss.ticks == ((5, 7), (11, 11)) and loss.commands == 1 and loss.any
    assert not lost_data(tmp_path / "r.mcap", final_tick=4).any
