"""The `conag` argument parser, without starting anything: what a user types is what it reads."""

from __future__ import annotations

import logging
import threading
import time

import pytest

from conag.cli import build_parser, log_level
from conag.commands.run import report_a_slow_stop


@pytest.mark.parametrize("argv, level", [
    (["status"], logging.WARNING),
    (["-v", "status"], logging.INFO),
    (["status", "-v"], logging.INFO),        # after the subcommand as well as before
    (["status", "-vv"], logging.DEBUG),
    (["-v", "world", "x.toml", "--verbose"], logging.DEBUG),  # before and after add up
    (["perturb", "add", "--at", "1,2", "-v"], logging.INFO),
])
def test_verbosity_is_accepted_before_and_after_the_subcommand(argv, level):
    assert log_level(build_parser().parse_args(argv)) == level


def test_perturb_force_reaches_the_request():
    args = build_parser().parse_args(["perturb", "add", "--at", "2.5,5.5", "--force"])
    assert args.force and not build_parser().parse_args(["perturb", "add", "--at", "2.5,5.5"]).force


def _checkpoint(tmp_path):
    from tests.conftest import SCENARIOS
    from world_server.checkpoint import checkpoint_world, write_checkpoint
    from world_server.scenario import load_scenario
    from world_server.world import World

    path = tmp_path / "w.ckpt"
    write_checkpoint(path, checkpoint_world(World(load_scenario(SCENARIOS / "quick_wall.toml"))))
    return path


@pytest.mark.parametrize("extra, words", [
    ([], "is corrupt"),
    (["--seed", "3"], "--seed cannot be used with --resume"),
    (["FIG6"], "leave SCENARIO out"),
    (["--world-id", "w9"], "holds world 'w0'"),
])
def test_conag_world_refuses_a_bad_resume_with_a_usage_error(tmp_path, capsys, extra, words):
    from conag.cli import main
    from conag.exit_codes import EXIT_USAGE
    from tests.conftest import SCENARIOS

    path = _checkpoint(tmp_path)
    extra = [str(SCENARIOS / "fig6.toml") if a == "FIG6" else a for a in extra]
    if not extra:
        data = bytearray(path.read_bytes())
        data[-3] ^= 0xFF  # one flipped byte
        path.write_bytes(bytes(data))
    assert main(["world", "--resume", str(path), *extra]) == EXIT_USAGE  # before any session is opened
    assert words in capsys.readouterr().err


def test_conag_world_needs_a_scenario_or_a_checkpoint(capsys):
    from conag.cli import main
    from conag.exit_codes import EXIT_USAGE

    assert main(["world"]) == EXIT_USAGE
    assert "needs a SCENARIO file (or --resume CHECKPOINT)" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        build_parser().parse_args(["world", "x.toml", "--checkpoint-every", "0"])


def test_a_run_that_is_slow_to_stop_shows_where_each_thread_waits(capfd):
    # CI once found `conag run` alive 120 s after two Ctrl-Cs and nothing said where it waited.
    stop = threading.Event()
    report_a_slow_stop(stop, after=0.1)
    time.sleep(0.3)
    assert "still stopping" not in capfd.readouterr().err   # nothing before the signal
    stop.set()
    err = _stderr_until(capfd, "most recent call first")
    assert "conag run: still stopping 0.1 s after the signal" in err
    assert "test_a_run_that_is_slow_to_stop_shows_where_each_thread_waits" in err   # this thread's stack


def _stderr_until(capfd, text: str, timeout: float = 5.0) -> str:
    """What the process wrote to stderr until `text` appeared in it (or `timeout` passed)."""
    deadline, err = time.monotonic() + timeout, ""
    while text not in err and time.monotonic() < deadline:
        time.sleep(0.05)
        err += capfd.readouterr().err
    return err


def test_conag_run_starts_its_recorder_at_the_priority_asked_for(monkeypatch):
    from conag import run as run_module
    from conag.common import RECORDER_PRIORITY
    from tests.conftest import SCENARIOS
    from world_server.scenario import load_scenario

    args = build_parser().parse_args(["run", "fig6.toml", "--record", "r.mcap", "--record-priority", "low"])
    assert args.record_priority == "low"
    assert build_parser().parse_args(["run", "fig6.toml"]).record_priority == RECORDER_PRIORITY == "idle"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["run", "fig6.toml", "--record-priority", "high"])
    started = []
    monkeypatch.setattr(run_module.subprocess, "Popen", lambda cmd, **kw: started.append(cmd))
    path = SCENARIOS / "fig6.toml"
    run_module._start_recorder(run_module.RunOptions(str(path), load_scenario(path), "tcp/127.0.0.1:1",
                                                     record="r.mcap", record_priority=args.record_priority))
    cmd = started[0]
    assert cmd[cmd.index("record") - 1:][:2] == ["conag", "record"] and cmd[cmd.index("--priority") + 1] == "low"


def test_the_viewers_display_rate_defaults_to_five_and_refuses_what_it_cannot_send(capsys):
    assert build_parser().parse_args(["view"]).display_hz == 5.0
    assert build_parser().parse_args(["view", "--display-hz", "12.5"]).display_hz == 12.5
    for bad, why in (("0", "out of range"), ("100", "out of range"), ("fast", "expected a number")):
        with pytest.raises(SystemExit) as exc:
            build_parser().parse_args(["view", "--display-hz", bad])
        assert exc.value.code == 2 and why in capsys.readouterr().err


def test_the_slow_stop_report_fires_even_while_the_stop_events_lock_is_held(capfd):
    # The state CI's hang left: the first signal's handler inside `stop.set()` (flag set, the
    # Event's lock held, waiters not yet woken). A report waiting on the Event never woke.
    stop = threading.Event()
    report_a_slow_stop(stop, after=0.1)
    time.sleep(0.2)
    with stop._cond:
        stop._flag = True
        err = _stderr_until(capfd, "still stopping")
    assert "conag run: still stopping 0.1 s after the signal" in err


def test_conag_help_loads_no_subcommand_module():
    # The table's help lines are enough for `conag --help`: no command module (and none of
    # numpy, zenoh or the world) is imported until its subcommand is parsed.
    import subprocess
    import sys

    from tests.conftest import ROOT

    code = ("import sys\nfrom conag.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in sys.modules if m.startswith(('conag.commands.', 'numpy', 'zenoh', "
            "'world_server', 'agent_runtime'))))")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "world" in r.stdout and r.stdout.splitlines()[-1] == "[]"


def test_every_subcommand_has_a_module_with_its_flags_and_its_run():
    from conag.cli import COMMANDS

    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    assert list(sub.choices) == list(COMMANDS)
    for name, command in sub.choices.items():
        assert f"usage: conag {name}" in command.format_help()
        assert callable(command.get_default("func")), name


@pytest.mark.parametrize("argv", [
    [],
    ["--map-size", "31", "--nearest-first"],
    ["--agent", "paper", "--without", "unstick, seal_guard"],
    ["--with", "anchor_maps"],
    ["--with", "yield_goals,anchor_maps"],
    ["--learn", "--eta", "0.25"],
])
def test_the_agent_flags_conag_run_forwards_ask_an_agent_for_the_same_settings(argv):
    from conag.agent_settings import AgentSettings

    settings = AgentSettings.from_args(build_parser().parse_args(["run", "fig6.toml", *argv]))
    forwarded = build_parser().parse_args(["agent", "--id", "a1", *settings.argv()])
    assert AgentSettings.from_args(forwarded) == settings
    if not settings.learn:  # `conag agents` hosts no learners (conag run refuses --per-process for them)
        hosted = build_parser().parse_args(["agents", "--ids", "a1..a3", *settings.argv()])
        assert AgentSettings.from_args(hosted) == settings


def test_with_switches_on_corrections_and_the_additions_the_default_agent_leaves_off():
    from agent_runtime.config import OFF_BY_DEFAULT
    from conag.agent_settings import AgentSettings

    args = build_parser().parse_args(["run", "fig6.toml", "--with", "anchor_maps,yield_goals"])
    cfg = AgentSettings.from_args(args).config()
    assert cfg.anchor_maps and cfg.yield_goals
    assert not any(getattr(cfg, name) for name in OFF_BY_DEFAULT if name != "yield_goals")
    with pytest.raises(ValueError, match=r"unknown name.*unstick"):   # on by default: --without is its switch
        AgentSettings.from_args(build_parser().parse_args(["run", "fig6.toml", "--with", "unstick"])).config()


def test_without_switches_off_a_correction_on_by_default():
    from conag.agent_settings import AgentSettings

    args = build_parser().parse_args(["run", "fig6.toml", "--without", "occlusion_clearing,unstick"])
    cfg = AgentSettings.from_args(args).config()
    assert not cfg.occlusion_clearing and not cfg.unstick and AgentSettings().config().occlusion_clearing
    with pytest.raises(ValueError, match=r"unknown name.*nonsense"):
        AgentSettings.from_args(build_parser().parse_args(["run", "fig6.toml", "--without", "nonsense"])).config()


def test_conag_run_passes_its_attach_timeout_to_every_agent_process():
    from conag import run as run_module
    from conag.commands.run import run_options
    from tests.conftest import SCENARIOS

    path = str(SCENARIOS / "fig6.toml")

    def timeout(*extra):
        opts = run_options(build_parser().parse_args(["run", path, "--listen", "tcp/127.0.0.1:1", *extra]))
        args = run_module.Fleet(opts)._bus_args("a1")
        return args[args.index("--attach-timeout") + 1]

    assert timeout() == "30" and timeout("--agents", "100") == "200"  # the default grows with the processes
    assert timeout("--agents", "1000", "--per-process", "100", "--attach-timeout", "900") == "900.0"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["run", path, "--attach-timeout", "0"])


def test_conag_run_passes_its_max_tick_rate_to_the_world(monkeypatch, tmp_path):
    from conag import run as run_module
    from conag.commands.run import run_options
    from tests.conftest import SCENARIOS

    started = []
    monkeypatch.setattr(run_module.subprocess, "Popen", lambda cmd, **kw: started.append(cmd))

    def world_cmd(*extra):
        opts = run_options(build_parser().parse_args(["run", str(SCENARIOS / "fig6.toml"), "--listen",
                                                      "tcp/127.0.0.1:1", *extra]))
        run_module._start_world(opts, 3, tmp_path / "final.json", tmp_path / "world.ckpt")
        return started.pop()

    assert "--max-tick-rate" not in world_cmd()
    cmd = world_cmd("--max-tick-rate", "50")
    assert cmd[cmd.index("--max-tick-rate") + 1] == "50.0"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["run", "fig6.toml", "--max-tick-rate", "0"])
