"""experiments.site_beliefs: a site an agent believes filled while the world has it empty is
counted, and only such a site."""

from __future__ import annotations

from conag import sim
from experiments.site_beliefs import GhostCount
from tests.conftest import SCENARIOS
from world_server.scenario import load_scenario


def test_a_site_believed_filled_that_the_world_has_empty_is_counted_once_per_sample():
    run = sim.start(load_scenario(SCENARIOS / "fig6.toml"))
    count = GhostCount(every=10)
    count(run)                                        # tick 0: every belief is "open", none wrong
    assert (count.samples, count.ghost_sites, count.ghost_samples) == (len(run.brains), 0, 0)
    brain = next(iter(run.brains.values()))
    brain.far.site_open[0] = False                    # a ghost brick seen on site 0, which is empty
    assert not run.world.sites_filled()[0]
    count(run)
    assert (count.ghost_sites, count.ghost_samples) == (1, 1)
    run.world.tick += 1                               # not a sample tick: nothing counted
    count(run)
    assert count.samples == 2 * len(run.brains)
