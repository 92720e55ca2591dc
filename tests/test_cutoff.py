"""faults/cutoff.py: the partition run's story in process, from a seed: two agents cut off,
detached, and attached again with new brains while the third builds on."""

from __future__ import annotations

import argparse

import pytest

from faults.cutoff import cutoff_run, schedule, seeds_arg


def test_the_cut_comes_in_the_ranges_partition_runs_show_and_the_same_for_a_seed():
    for seed in range(200):
        cut, dead, back = schedule(seed)
        assert 150 <= cut < 260 and cut + 150 <= dead < cut + 350 and cut + 600 <= back < cut + 800
        assert schedule(seed) == (cut, dead, back)


def test_seeds_are_given_as_ranges_and_lists():
    assert seeds_arg("3,7,10-12") == [3, 7, 10, 11, 12]
    assert seeds_arg("364") == [364]
    for bad in ("", "a-b", "5-", "9-3", "1,,2"):
        with pytest.raises(argparse.ArgumentTypeError):
            seeds_arg(bad)


@pytest.mark.slow
def test_agents_cut_off_and_back_with_new_brains_complete_the_build_with_every_brick():
    run = cutoff_run(0)
    assert run.completed and run.sites_filled == run.sites_total == 32, run.line()
    assert run.bricks_total == 34                        # a detached agent's brick is put down, not lost
    assert run.restarts == {"a1": 1, "a2": 1, "a3": 0}   # each cut agent attached again once
    assert run.back < run.ticks


@pytest.mark.slow
def test_two_agents_closing_a_rings_last_gaps_at_once_leave_no_site_sealed_in():
    # Seed 364: a1 and a2 filled the outer ring's last two gaps 19 ticks apart, each
    # trusting the other's as the way in (seen empty lately), and sealed the inner ring's
    # last open site in (31/32). A gap another agent stands beside is no way in (SealGuard).
    run = cutoff_run(364)
    assert run.completed and run.sites_filled == run.sites_total == 32, run.line()
