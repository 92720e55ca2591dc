"""Bad input gets a one-line error naming the file or key, and a non-zero exit; never a
traceback, never silence (issue 35): a directory or a binary file given as a scenario;
an empty, random or foreign file given as a recording (to replay, verify or view); a
recording cut short before its first command; a maps request token whose period is no
count of ticks."""

from __future__ import annotations

import logging

import pytest

from conag.cli import main
from conag.exit_codes import EXIT_USAGE
from conag.recording.mcap_log import McapRecorder, RecordingError, read_recording
from conag.recording.replay import LockstepScript
from protocol import keys
from protocol.codec import encode
from protocol.messages import AgentCommand, SensorFrame, Welcome, WorldStatus
from tests.conftest import SCENARIOS, wait_until
from world_server.scenario import ScenarioError, load_scenario

W = "w0"


def _one_line_error(capsys, *names: str) -> str:
    """The command's stderr: one line, `error: ...`, naming each of `names`; no traceback."""
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for name in names:
        assert name in lines[0], err
    return lines[0]


# --- scenarios ------------------------------------------------------------------------------------

@pytest.mark.parametrize("command", [["run", "--headless"], ["world"], ["render"]])
def test_a_directory_given_as_a_scenario_is_refused_by_name(tmp_path, capsys, command):
    assert main([command[0], str(tmp_path), *command[1:]]) == EXIT_USAGE
    line = _one_line_error(capsys, str(tmp_path))
    assert "expected a scenario file (found a directory)" in line


@pytest.mark.parametrize("command", [["run", "--headless"], ["world"], ["render"]])
def test_a_binary_scenario_file_is_refused_with_its_name_and_place(tmp_path, capsys, command):
    path = tmp_path / "binary.toml"
    path.write_bytes(b'name = "x"\n# caf\xe4\n')
    assert main([command[0], str(path), *command[1:]]) == EXIT_USAGE
    line = _one_line_error(capsys, f"{path}:2:6")
    assert "expected UTF-8 text (found byte 0xe4)" in line


def test_load_scenario_raises_scenario_errors_that_name_the_file(tmp_path):
    with pytest.raises(ScenarioError, match="found a directory"):
        load_scenario(tmp_path)
    (tmp_path / "b.toml").write_bytes(b"\xe4")
    with pytest.raises(ScenarioError, match=r"b\.toml:1:1: expected UTF-8 text"):
        load_scenario(tmp_path / "b.toml")
    with pytest.raises(FileNotFoundError):
        load_scenario(tmp_path / "missing.toml")


# --- recordings -----------------------------------------------------------------------------------

def _bad_recordings(tmp_path):
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    noise = tmp_path / "noise.mcap"
    noise.write_bytes(bytes(range(256)) * 20)
    return {"the file is empty": empty, "not an MCAP file": noise, "Is a directory": tmp_path}


@pytest.mark.parametrize("verb", [["replay", "--wait", "0"], ["replay", "--verify"], ["view", "--port", "0"]])
def test_a_file_that_is_no_recording_is_refused_by_name(tmp_path, capsys, verb):
    for why, path in _bad_recordings(tmp_path).items():
        assert main([verb[0], str(path), *verb[1:]]) == EXIT_USAGE, why
        assert why in _one_line_error(capsys, str(path))


def test_an_mcap_file_without_conag_metadata_is_refused(tmp_path):
    from mcap.writer import Writer

    path = tmp_path / "foreign.mcap"
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start(profile="ros2", library="someone else")
        writer.finish()
    with pytest.raises(RecordingError, match="not a ConAg recording"):
        read_recording(path)


def _welcome(agent: str, body: int) -> bytes:
    return encode(Welcome(W, agent, 0, body, 1.0, 1.0, 0.0, False, 0, 1, 6.0, 1.0, (), ()))


def _frame(tick: int, agent: str) -> bytes:
    return encode(SensorFrame(agent, tick, 0.0, 0.0, 0.0, 1, (-1.0,) * 5, False))


def test_replay_verify_refuses_a_recording_that_holds_no_frame(tmp_path, capsys):
    path = tmp_path / "r.mcap"
    scenario = (SCENARIOS / "fig6.toml").read_text()
    with McapRecorder(path, {"scenario": scenario, "seed": "6", "world_id": W}) as rec:
        rec.add(keys.status(W), encode(WorldStatus(W, "fig6", 6, "lockstep", 0, 0, 4, 3, 0, 0, False)), 1)
    assert main(["replay", str(path), "--verify"]) == EXIT_USAGE
    assert "holds no agent's frame to compare" in _one_line_error(capsys, str(path))


def test_a_recording_cut_before_every_agents_first_command_takes_no_step(tmp_path):
    # Cut right after the attaches: a1's frame of tick 0 is there, and a2's command of tick
    # 0, but not a1's. A world fed a2's command would wait for a1's for ever (the replay
    # waited 60 s, then ended in a traceback): the script compares the attaches' frames only.
    with McapRecorder(tmp_path / "r.mcap") as rec:
        for body, a in enumerate(("a1", "a2")):
            rec.add(keys.welcome(W, a), _welcome(a, body), 1)
            rec.add(keys.sensors(W, a), _frame(0, a), 2)
        rec.add(keys.command(W, "a2"), encode(AgentCommand("a2", 0, 1.0, 0.0)), 3)
    script = LockstepScript.from_entries(read_recording(tmp_path / "r.mcap").entries)
    assert "no command of a1 after tick -1" in script.cut_short
    assert script.last_tick == 0 and script.end_tick == 0 and not script.commands.get(0)
    assert sorted(a for _, a in script.frames) == ["a1", "a2"]


# --- the bus --------------------------------------------------------------------------------------

@pytest.mark.parametrize("segment, every", [("5", 5), ("1", 1), ("1000000000", 10**9), ("0", None), ("²", None),
                                            ("٣", None), ("", None), ("+5", None), (" 5", None), ("5 ", None),
                                            ("1000000001", None), ("9" * 5000, None), ("five", None)])
def test_a_maps_request_period_is_ascii_digits_in_range(segment, every):
    assert keys.maps_request_every(f"{keys.ROOT}/world/{W}/alive/maps/viewer/a1/{segment}") == every


def test_an_agent_ignores_a_maps_request_token_whose_period_is_no_number_with_a_warning(bus, caplog):
    from agent_runtime.feeds import AgentFeeds

    feeds_session, asker = bus.server_session(), bus.client_session()
    feeds = AgentFeeds(feeds_session, W, "a1")
    bad_key = f"{keys.world_root(W)}/alive/maps/intruder/a1/²"
    try:
        with caplog.at_level(logging.WARNING, logger="conag.agent"):
            bad = asker.liveliness().declare_token(bad_key)
            good = asker.liveliness().declare_token(keys.maps_request_token(W, "viewer", 4, agent="a1"))
            wait_until(lambda: feeds.maps_every == 4, what="the agent to hear the good request")
            wait_until(lambda: bad_key in caplog.text, what="the warning about the bad one")
            bad.undeclare()
            good.undeclare()
            wait_until(lambda: feeds.maps_every == 0, what="the request to go")
        warning = next(r for r in caplog.records if bad_key in r.getMessage())
        assert warning.levelno == logging.WARNING and "no period" in warning.getMessage()
    finally:
        feeds.close()
