"""Noise and occlusion as world settings (issue 37; docs/noise.md): what each option does to
the readings and the odometry, that they are off by default and change nothing then, that a
noisy run is reproduced by its seed, and that bad values are refused with a clear message."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from conag import sim
from conag.cli import build_parser
from conag.noise_flags import from_note, noise_settings, to_note
from experiments.noise import MapError, misplaced_bricks
from protocol.messages import CHANNELS, NO_READING
from tests.conftest import ROOT, make, scenario
from world_server.config import WorldConfig
from world_server.noise import NoiseSettings
from world_server.scenario import ScenarioError, load_scenario
from world_server.sensors import sense

FOOD, BRICK = CHANNELS.index("food"), CHANNELS.index("brick")
EAST, NORTH = 0, 4   # sectors of 16: east is sector 0, north sector 4

# An agent at (10, 10); east of it a food disc at 2, bricks at 4 and 6; north a brick at 3.
AGENT = np.array([[10.0, 10.0]])
DISCS = np.array([[12.0, 10.1], [14.0, 10.2], [16.0, 10.1], [10.0, 13.0]])
KINDS = np.array([FOOD, BRICK, BRICK, BRICK])


def read(**options) -> np.ndarray:
    return sense(AGENT, np.ones(1, bool), DISCS, KINDS, 16, 8.0, (20.0, 20.0), **options)[0]


# ---------------------------------------------------------------- the sensors


def test_without_occlusion_each_colour_sees_its_nearest_disc():
    r = read()
    assert r[FOOD, EAST] == pytest.approx(2.0, abs=0.01)
    assert r[BRICK, EAST] == pytest.approx(4.0, abs=0.01)   # behind the food disc, seen


def test_occlusion_stops_a_sector_at_its_first_object_of_any_colour():
    r = read(occlusion=True)
    assert r[FOOD, EAST] == pytest.approx(2.0, abs=0.01)
    assert r[BRICK, EAST] == NO_READING                      # hidden behind the food disc
    assert r[BRICK, NORTH] == pytest.approx(3.0)             # nothing in front of it


def test_aliasing_reports_the_second_disc_with_its_probability():
    assert read(aliasing=1.0, alias_seed=5)[BRICK, EAST] == pytest.approx(6.0, abs=0.01)
    assert read(aliasing=1.0, alias_seed=5)[BRICK, NORTH] == pytest.approx(3.0)  # one disc: no other to take
    swapped = np.mean([read(aliasing=0.3, alias_seed=k)[BRICK, EAST] > 5 for k in range(1000)])
    assert 0.25 < swapped < 0.35
    # With occlusion the second brick hides behind the food disc as the first does.
    assert read(aliasing=1.0, alias_seed=5, occlusion=True)[BRICK, EAST] == NO_READING


def test_the_options_off_read_exactly_as_before():
    assert np.array_equal(read(noise=0.05, seed=9), read(noise=0.05, seed=9, occlusion=False, aliasing=0.0,
                                                         alias_seed=123))


def test_world_occlusion_hides_a_brick_behind_food():
    layout = ".........\n.A.F.b...\n........."
    plain, occluded = make(layout, sensor_noise=0.0), make(layout, sensor_noise=0.0, occlusion=True)
    for w in (plain, occluded):
        w.attach("a")
    brick = lambda w: np.array(w.frame("a").ranges).reshape(len(CHANNELS), -1)[BRICK, EAST]  # noqa: E731
    assert brick(plain) == pytest.approx(4.0)
    assert brick(occluded) == NO_READING


# ---------------------------------------------------------------- the odometry


def _steps(w, n: int = 40) -> list[tuple[np.ndarray, np.ndarray]]:
    """(true step, reported step) of agent a driving east for n ticks."""
    out = []
    for _ in range(n):
        before = w.agent_poses()[0, :2].copy()
        w.set_command("a", 3.0, 0.0, "none")
        w.step()
        f = w.frame("a")
        out.append((w.agent_poses()[0, :2] - before, np.array([f.odom_dx, f.odom_dy])))
    return out


def test_distance_slip_changes_the_length_of_a_step_not_its_direction():
    w = make("A" + "." * 29, seed=3, odometry_distance_slip=0.1)
    w.attach("a")
    steps = [(t, r) for t, r in _steps(w) if np.hypot(*t) > 0.05]
    assert steps
    for true, rep in steps:
        assert abs(true[0] * rep[1] - true[1] * rep[0]) < 1e-9   # parallel
    assert max(abs(np.hypot(*r) / np.hypot(*t) - 1) for t, r in steps) > 0.02


def test_heading_slip_turns_a_step_not_its_length():
    w = make("A" + "." * 29, seed=3, odometry_heading_slip=0.1)
    w.attach("a")
    steps = [(t, r) for t, r in _steps(w) if np.hypot(*t) > 0.05]
    for true, rep in steps:
        assert np.hypot(*rep) == pytest.approx(np.hypot(*true), rel=1e-9)
    assert max(abs(math.atan2(r[1], r[0]) - math.atan2(t[1], t[0])) for t, r in steps) > 0.02


def test_slip_only_while_moving():
    w = make("A" + "." * 29, seed=3, odometry_distance_slip=0.2, odometry_heading_slip=0.2)
    w.attach("a")
    for _ in range(3):
        w.step()
    f = w.frame("a")
    assert (f.odom_dx, f.odom_dy) == (0.0, 0.0)


# ---------------------------------------------------------------- settings


def test_defaults_are_off():
    cfg = WorldConfig()
    assert (cfg.odometry_noise, cfg.odometry_distance_slip, cfg.odometry_heading_slip) == (0.0, 0.0, 0.0)
    assert (cfg.occlusion, cfg.aliasing, cfg.sensor_noise) == (False, 0.0, 0.02)
    sc = load_scenario(ROOT / "scenarios" / "fig6.toml")
    assert NoiseSettings().apply(sc) is sc


@pytest.mark.parametrize(("setting", "message"), [
    ("odometry_distance_slip = -0.1", "odometry_distance_slip must be a finite number >= 0"),
    ("odometry_heading_slip = -1", "odometry_heading_slip must be a finite number >= 0"),
    ("odometry_noise = -0.1", "odometry_noise must be >= 0"),
    ("sensor_noise = -0.02", "sensor_noise must be >= 0"),
    ("aliasing = 1.5", "aliasing must be a probability from 0 to 1"),
    ("aliasing = -0.1", "aliasing must be a probability from 0 to 1"),
    ("occlusion = 1", "occlusion must be true or false"),
])
def test_a_scenario_file_with_a_bad_noise_setting_is_refused_where_it_is(setting, message):
    text = f'name = "t"\nseed = 1\nagents = 1\nlayout = """\nA..\n"""\n[world]\n{setting}\n'
    from world_server.scenario import parse_scenario

    with pytest.raises(ScenarioError, match=message) as err:
        parse_scenario(text, "bad.toml")
    assert err.value.line == 8


def test_a_scenario_file_sets_every_option():
    sc = scenario("A..", odometry_distance_slip=0.05, odometry_heading_slip=0.02, occlusion=True, aliasing=0.1)
    assert (sc.world.odometry_distance_slip, sc.world.odometry_heading_slip) == (0.05, 0.02)
    assert (sc.world.occlusion, sc.world.aliasing) == (True, 0.1)


def test_settings_override_the_scenario_and_scale_its_sensor_noise():
    sc = scenario("A..", sensor_noise=0.03, occlusion=True)
    got = NoiseSettings(sensor_noise_scale=2.0, occlusion=False, aliasing=0.2, odometry_noise=0.01).apply(sc)
    assert got.world.sensor_noise == pytest.approx(0.06)
    assert (got.world.occlusion, got.world.aliasing, got.world.odometry_noise) == (False, 0.2, 0.01)
    with pytest.raises(ValueError, match="aliasing"):
        NoiseSettings(aliasing=2.0).apply(sc)
    with pytest.raises(ValueError, match="scale"):
        NoiseSettings(sensor_noise_scale=-1.0)


def test_command_line_flags_round_trip():
    settings = NoiseSettings(odometry_distance_slip=0.05, odometry_heading_slip=0.1, sensor_noise_scale=4.0,
                             occlusion=True, aliasing=0.25, odometry_noise=0.01)
    for command in ("world", "run"):
        args = build_parser().parse_args([command, "scenarios/fig6.toml", *settings.to_args()])
        assert noise_settings(args) == settings
    args = build_parser().parse_args(["world", "scenarios/fig6.toml", "--no-occlusion"])
    assert noise_settings(args) == NoiseSettings(occlusion=False)
    assert noise_settings(build_parser().parse_args(["world", "x.toml"])).changes_nothing
    assert from_note(to_note(settings)) == settings


@pytest.mark.parametrize("flags", [["--aliasing", "1.5"], ["--odometry-distance-slip", "-0.1"],
                                   ["--sensor-noise-scale", "nan"]])
def test_bad_flags_are_usage_errors(flags, capsys):
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(["world", "scenarios/fig6.toml", *flags])
    assert exit_.value.code == 2
    assert flags[0] in capsys.readouterr().err


# ---------------------------------------------------------------- runs


NOISY = NoiseSettings(odometry_distance_slip=0.1, odometry_heading_slip=0.1, sensor_noise_scale=2.0,
                      occlusion=True, aliasing=0.2)


def _trace(seed: int, noise: NoiseSettings, ticks: int = 300) -> tuple[list, bytes]:
    run = sim.start(load_scenario(ROOT / "scenarios" / "quick_wall.toml"), seed=seed, noise=noise)
    decisions: list = []
    run.on_step = lambda agent, s: decisions.append((agent, s.speed, s.turn, s.action))
    run.run(ticks, until_complete=False)
    return decisions, run.world.agent_poses().tobytes()


def test_a_noisy_run_is_reproduced_by_its_seed():
    assert _trace(4, NOISY) == _trace(4, NOISY)
    assert _trace(4, NOISY) != _trace(5, NOISY)
    assert _trace(4, NOISY) != _trace(4, NoiseSettings())


def test_options_written_out_at_their_defaults_change_nothing():
    sc = load_scenario(ROOT / "scenarios" / "quick_wall.toml")
    off = NoiseSettings(odometry_noise=0.0, odometry_distance_slip=0.0, odometry_heading_slip=0.0,
                        occlusion=False, aliasing=0.0)
    assert off.apply(sc) is not sc
    runs = [sim.start(s) for s in (sc, off.apply(sc))]
    for run in runs:
        run.run(300, until_complete=False)
    assert runs[0].world.agent_poses().tobytes() == runs[1].world.agent_poses().tobytes()
    assert np.array_equal(runs[0].world.frames()[0].ranges, runs[1].world.frames()[0].ranges)


def test_map_error_is_zero_without_odometry_noise_and_grows_with_it():
    sc = load_scenario(ROOT / "scenarios" / "quick_wall.toml")
    errors = {}
    for slip in (0.0, 0.2):
        run = sim.start(sc, noise=NoiseSettings(odometry_distance_slip=slip, odometry_heading_slip=slip))
        err = MapError(run, every=1)
        run.run(120, until_complete=False, observers=[err])
        errors[slip] = max(err.samples)
    assert errors[0.0] < 1e-6
    assert errors[0.2] > 0.05


def test_a_brick_dropped_beside_a_site_is_misplaced():
    run = sim.start(scenario(".....\n.+b..\n..A..\n....."))
    start = run.world.scenario.to_cell(run.world.discs.xy)
    assert misplaced_bricks(run, start) == 0                   # it lies beside the site, but always did
    from protocol.messages import Perturbation

    run.perturb(Perturbation(op="move", x=2.5, y=2.5, to_x=1.5, to_y=1.5))   # one cell south of the site
    assert misplaced_bricks(run, start) == 1
    run.perturb(Perturbation(op="move", x=1.5, y=1.5, to_x=1.5, to_y=2.5))   # onto the site
    assert misplaced_bricks(run, start) == 0


@pytest.mark.slow
def test_conag_world_takes_the_noise_flags():
    out = subprocess.run([sys.executable, "-m", "conag", "world", "scenarios/fig6.toml", "--aliasing", "2"],
                         cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert "--aliasing" in out.stderr
