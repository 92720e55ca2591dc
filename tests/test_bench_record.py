"""bench_record's paired slowdown: each recorded build is judged against its own repetition's
plain build, so a machine that speeds up during the run does not pass for a recorder that
costs nothing (the figure in docs/results/benchmarks.md, recording)."""

import pytest

from bench.bench_record import paired_slowdown


def test_a_drifting_machine_does_not_hide_a_steady_cost():
    # the machine speeds up from 100 to 200 ticks/s; recording costs 5% in every repetition
    plain = [100, 125, 150, 175, 200]
    recorded = [95, 118.75, 142.5, 166.25, 190]
    assert paired_slowdown(plain, recorded) == pytest.approx(0.05)


def test_the_paired_figure_of_a_real_run_is_not_the_unpaired_one():
    # twelve repetitions measured on 2026-11-24 (a cold first build, then a machine speeding
    # up): the unpaired medians, 185 and 203 ticks/s, say recording made the run 9.7% faster
    plain = [97, 169, 172, 180, 190, 208, 228, 214, 211, 175, 178, 209]
    recorded = [190, 161, 164, 176, 198, 212, 222, 214, 209, 167, 217, 208]
    ratios = sorted(b / a for a, b in zip(plain, recorded, strict=True))
    assert paired_slowdown(plain, recorded) == pytest.approx(1 - (ratios[5] + ratios[6]) / 2)
    assert 0 < paired_slowdown(plain, recorded) < 0.02


def test_one_outlying_repetition_does_not_move_the_median():
    plain = [97, 169, 172, 180, 190]      # a cold first build
    recorded = [190, 161, 164, 176, 198]
    assert paired_slowdown(plain, recorded) == pytest.approx(1 - 176 / 180)


def test_unmatched_repetitions_are_refused():
    with pytest.raises(ValueError, match="one plain build per recorded one"):
        paired_slowdown([100, 100], [95])
    with pytest.raises(ValueError):
        paired_slowdown([], [])


def test_the_build_clock_can_start_past_the_first_ticks():
    from bench.bench_record import BuildClock

    lines = ["tick       1  sites 0/4  agents alive 10/10      0.5 ticks/s     3.9 s",
             "tick     120  sites 0/4  agents alive 10/10     50.0 ticks/s     5.0 s",
             "tick     320  sites 2/4  agents alive 10/10     70.0 ticks/s     8.0 s",
             "tick     700  sites 4/4  agents alive 10/10     70.0 ticks/s    13.0 s"]
    clock = BuildClock(start_tick=300)
    assert [clock.observe(line) for line in lines] == [False, False, True, True]
    assert clock.first[0] == 320 and clock.last[0] == 700
    assert BuildClock().observe(lines[0])  # by default, from tick 1
