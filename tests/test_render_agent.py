"""One agent's ESMs and NMs beside the world: the picture is drawn, from the API and the CLI."""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from agent_runtime.esm import CONFIG
from conag import sim
from conag.cli import main
from conag.sim.render_agent import nm_obstacles, render_agent_maps
from tests.conftest import ROOT, SCENARIOS
from world_server.scenario import load_scenario

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == PNG_SIGNATURE
    return struct.unpack(">II", head[16:24])


@pytest.fixture(scope="module")
def fig6():
    return load_scenario(SCENARIOS / "fig6.toml")


@pytest.mark.parametrize("ticks", [0, pytest.param(200, marks=pytest.mark.slow)])
def test_agent_maps_render_to_a_sensible_png(tmp_path, fig6, ticks):
    out = render_agent_maps(fig6, tmp_path / f"maps{ticks}.png", agent="a2", ticks=ticks)
    assert out == tmp_path / f"maps{ticks}.png" and out.stat().st_size > 30_000
    width, height = _png_size(out)
    assert 1000 <= width <= 3000 and 500 <= height <= 1500
    assert imread(out)[..., :3].std() > 0.05   # not a blank canvas


def test_nm_obstacles_are_the_discs_the_agent_knows_but_never_its_own_cell(fig6):
    run = sim.start(fig6)
    for _ in range(50):
        run.step()
    brain = run.brains["a1"]
    config_obs, brick_obs = nm_obstacles(brain)
    c = brain.maps.centre
    assert not config_obs[c, c] and not brick_obs[c, c]
    assert brick_obs.sum() <= config_obs.sum()   # free bricks block only the configuration NM
    plans = brain.plan()
    assert np.all(np.isinf(plans.config[config_obs])) and np.all(np.isinf(plans.brick[brick_obs]))
    assert brain.maps.maps[CONFIG].sum() == 4    # the blueprint diamond the panel shows


@pytest.mark.slow
def test_cli_agent_maps_writes_the_file(tmp_path):
    out = tmp_path / "maps.png"
    r = subprocess.run([sys.executable, "-m", "conag", "render", str(SCENARIOS / "fig6.toml"), "--agent-maps",
                        "--agent", "a3", "--ticks", "20", "--out", str(out)],
                       cwd=ROOT, text=True, capture_output=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert out.read_bytes()[:8] == PNG_SIGNATURE and str(out) in r.stdout


def test_bad_agent_id_is_a_clear_error(tmp_path, fig6, capsys):
    with pytest.raises(ValueError, match=r"unknown agent 'a9'.*a1, a2, a3"):
        render_agent_maps(fig6, tmp_path / "x.png", agent="a9")
    code = main(["render", str(SCENARIOS / "fig6.toml"), "--agent-maps", "--agent", "a9",
                 "--out", str(tmp_path / "x.png")])
    assert code == 2 and "unknown agent 'a9'" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()


def test_agent_and_ticks_without_agent_maps_are_refused(tmp_path, capsys):
    code = main(["render", str(SCENARIOS / "fig6.toml"), "--ticks", "5", "--out", str(tmp_path / "x.png")])
    assert code == 2 and "--agent-maps" in capsys.readouterr().err


def test_negative_ticks_are_refused(tmp_path, fig6):
    with pytest.raises(ValueError, match="ticks"):
        render_agent_maps(fig6, tmp_path / "x.png", ticks=-1)


def test_with_goal_sequencing_the_matching_grid_is_drawn(fig6):
    from conag.sim.render_agent import _figure

    run = sim.start(load_scenario(SCENARIOS / "fig18.toml"))
    brain = run.brains["a1"]
    from agent_runtime.esm import BRICK, CONFIG

    def d1_waits() -> bool:   # it has seen a brick and the pocket: D2's path runs through D1
        m = brain.maps.maps > 0.5
        return brain.plans is not None and bool((brain.plans.matching.match & m[CONFIG] & ~m[BRICK]).any())

    while not d1_waits():
        run.step()
        assert run.world.tick < 3000
    fig = _figure(run.world.scenario, run, "a1", brain, brain.plan())
    titles = [ax.get_title() for ax in fig.axes]
    assert "Matching grid (goal sequencing)" in titles
    grid = next(ax for ax in fig.axes if ax.get_title().startswith("Matching grid"))
    drawn = grid.images[0].get_array()
    assert (drawn == 3).sum() == 1 and (drawn == 2).sum() == 1   # D1 waits, D2 is the goal
