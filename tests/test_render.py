"""The bird's-eye renderer draws every scenario, with live poses and discs when given."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_rgb
from matplotlib.image import imread

from world_server.render import DISC_STYLE, render_scenario
from world_server.scenario import load_scenario

SCENARIO_DIR = Path(__file__).resolve().parent.parent / "scenarios"
SCENARIOS = sorted(SCENARIO_DIR.glob("*.toml"))
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == PNG_SIGNATURE
    return struct.unpack(">II", head[16:24])


def _has_colour(path: Path, colour: str, tol: float = 0.02) -> bool:
    rgb = imread(path)[..., :3]
    return bool(np.any(np.all(np.abs(rgb - np.array(to_rgb(colour))) < tol, axis=-1)))


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_every_scenario_renders_with_each_of_its_disc_kinds_in_its_colour(tmp_path, path):
    s = load_scenario(path)
    out = render_scenario(s, tmp_path / f"{s.name}.png")
    assert out == tmp_path / f"{s.name}.png"
    width, height = _png_size(out)
    assert 300 <= width <= 3000 and 200 <= height <= 3000
    for kind, cells in (("food", "F"), ("water", "W"), ("brick", "bB")):
        assert _has_colour(out, DISC_STYLE[kind]["facecolor"]) == (len(s.cells_col_row(cells)) > 0), kind


def test_overrides_replace_agents_and_discs(tmp_path):
    s = load_scenario(SCENARIO_DIR / "quick_wall.toml")
    default = render_scenario(s, tmp_path / "default.png")
    agents = [(1.5, 1.5, math.pi / 2), (10.2, 6.7, -2.0)]
    discs = [(4.5, 5.5, "brick"), (2.5, 2.5, "food"), (9.5, 1.5, "water")]
    out = render_scenario(s, tmp_path / "live.png", agents=agents, discs=discs, title="tick 120")
    assert out.stat().st_size > 5_000
    assert out.read_bytes() != default.read_bytes()
    assert not _has_colour(default, DISC_STYLE["water"]["facecolor"])
    assert _has_colour(out, DISC_STYLE["water"]["facecolor"])


def test_empty_overrides_draw_an_empty_world(tmp_path):
    s = load_scenario(SCENARIO_DIR / "quick_wall.toml")
    out = render_scenario(s, tmp_path / "sub" / "empty.png", agents=[], discs=[])
    assert out.exists()
    assert not _has_colour(out, DISC_STYLE["brick"]["facecolor"])


def test_unknown_disc_kind_is_rejected(tmp_path):
    s = load_scenario(SCENARIO_DIR / "quick_wall.toml")
    with pytest.raises(ValueError, match="disc kind"):
        render_scenario(s, tmp_path / "bad.png", discs=[(1.0, 1.0, "gold")])
