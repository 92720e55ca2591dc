"""A society of foremen and workers (issue 37 item 4; docs/society.md): in process, and as
processes under `conag run --foremen F --workers W`, its members killed and restarted, and
recorded: its cues in the recording's views and Foxglove scene, its run replayed tick for tick."""

from __future__ import annotations

import json

import pytest

from conag.sim.society import society_ids, start_society
from tests.conftest import conag, free_port, run_acting_mid_build
from world_server.scenario import load_scenario


def _built_by(run) -> dict[str, int]:
    """Bricks each member laid: its drops, less a worker's bricks taken back to a supply."""
    st = run.world.status()
    return {a: n - getattr(run.brains[a], "returns", 0) for a, n in zip(st.agent_ids, st.agent_drops)}


def test_a_society_in_process_builds_with_its_workers_filling_marked_sites():
    run = start_society(load_scenario("scenarios/quick_wall.toml"), foremen=1, workers=3, seed=1)
    result = run.run(3000, stall_ticks=2000)
    assert result.completed
    drops = _built_by(run)
    assert list(drops) == society_ids(1, 3) == ["f1", "w1", "w2", "w3"]
    assert sum(drops[w] for w in ("w1", "w2", "w3")) >= 1     # workers filled sites the foreman marked
    assert sum(drops.values()) == 3                            # no brick dropped anywhere but on a site


def test_society_flags_do_not_go_with_agents_or_learning():
    from conag.cli import build_parser
    from conag.commands.run import run_options
    for extra in (["--agents", "3"], ["--learn"], ["--per-process", "2"]):
        args = build_parser().parse_args(["run", "scenarios/quick_wall.toml", "--foremen", "1", "--workers", "2",
                                          *extra])
        with pytest.raises(ValueError, match="--foremen and --workers"):
            run_options(args)
    # and the command line says so, with the usage exit code (one process: the rest is the same check)
    r = conag("run", "scenarios/quick_wall.toml", "--foremen", "1", "--workers", "2", "--agents", "3",
              "--listen", f"tcp/127.0.0.1:{free_port()}")
    assert r.returncode == 2 and "--foremen and --workers" in r.stderr


@pytest.mark.parametrize("foremen", [1, pytest.param(2, marks=pytest.mark.slow)])  # the fast tier's 60 s
def test_a_society_completes_a_wall_of_sites_along_the_worlds_edge(foremen):
    # gen-wall 20: a wall two sites thick against the world's east edge. The foreman's
    # safety check took the whole open region for the outside (every marking passed) and
    # knew nothing of the sites its own building filled; workers sealed the edge column's
    # last sites in (14-16 of 18). Two foremen also mark side by side.
    from experiments.generalisation import LAYOUTS
    from world_server.scenario import parse_scenario
    name = "020-gen-wall-20260020.toml"
    run = start_society(parse_scenario((LAYOUTS / name).read_text(encoding="utf-8"), name), foremen, 4)
    assert run.run(20000, stall_ticks=3000).completed
    laid = _built_by(run)
    assert sum(laid.values()) == run.world.status().sites_total   # every brick laid went on a site
    assert sum(n for a, n in laid.items() if a.startswith("w")) >= 2


@pytest.mark.slow
def test_fig19_in_process_one_foreman_and_six_workers_complete_every_site_on_its_site():
    run = start_society(load_scenario("scenarios/fig19.toml"), foremen=1, workers=6)
    assert run.run(20000, stall_ticks=5000).completed
    drops = _built_by(run)
    assert sum(drops.values()) == 19                           # 21 sites, 2 built from the start
    assert sum(n for a, n in drops.items() if a.startswith("w")) >= 3


@pytest.mark.slow
def test_conag_run_fig19_with_a_foreman_and_six_workers_completes_through_kills_and_restarts(tmp_path):
    out = tmp_path / "summary.json"

    def kill_and_restart(ep: str, _run) -> list:
        return [conag("restart", "f1", "--connect", ep), conag("kill", "w2", "--connect", ep),
                conag("restart", "w2", "--connect", ep)]

    answers = run_acting_mid_build("scenarios/fig19.toml", out, kill_and_restart, "--foremen", 1, "--workers", 6,
                                   timeout=600)
    assert all(a.returncode == 0 for a in answers), [a.stderr for a in answers]
    s = json.loads(out.read_text())
    assert s["completed"] and s["sites_filled"] == s["sites_total"] == 21
    restarts = {a["id"]: a["restarts"] for a in s["agents"]}
    assert sorted(restarts) == sorted(society_ids(1, 6))
    assert restarts["f1"] == 1 and restarts["w2"] >= 1 and restarts["w1"] == 0


@pytest.mark.slow
def test_a_recorded_society_shows_its_cues_and_replays_tick_for_tick(tmp_path):
    from conag.recording.mcap_log import read_recording
    from protocol.codec import decode
    from tests.test_foxglove import assert_scene_matches, read_foxglove

    out = tmp_path / "society.mcap"
    run = conag("run", "scenarios/quick_wall.toml", "--foremen", "1", "--workers", "3", "--headless", "--quiet",
                "--record", out, "--listen", f"tcp/127.0.0.1:{free_port()}", timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    views = {e.tick: decode(e.data) for e in read_recording(out).entries if e.key.endswith("/view")}
    assert any(v.cue_kinds for v in views.values())             # the foreman's marks reached the recorder
    scenes = read_foxglove(out)["/world/scene"]
    assert {t for t, _ in scenes} == set(views)
    for tick, update in scenes:
        assert_scene_matches(update, views[tick])               # cues/site and cues/supply where the world had them
    # The world's cue reach is `conag run`'s, not the scenario's: the replay takes it from the Welcomes.
    verify = conag("replay", out, "--verify", "--quiet", timeout=300)
    assert verify.returncode == 0, verify.stdout + verify.stderr
    assert "identical" in verify.stdout
