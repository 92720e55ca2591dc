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


# --- bench_record_windows: the recorder listening in turns within one build ---------------------

def _windows(listening: list[bool], rates: list[float | None]):
    from bench.bench_record_windows import Window

    return [Window(float(i), float(i + 1), on, r) for i, (on, r) in enumerate(zip(listening, rates, strict=True))]


def test_a_window_s_rate_is_taken_between_its_views_after_it_settled():
    from bench.bench_record_windows import window_rates

    windows = [{"start": 0.0, "end": 1.0, "listening": False}, {"start": 1.0, "end": 2.0, "listening": True},
               {"start": 2.0, "end": 3.0, "listening": False}]
    views = [(0.05, 10), (0.2, 20), (0.7, 120),            # the first view is in the settling time: left out
             (1.3, 200), (1.8, 290),                         # 90 ticks in 0.5 s
             (2.9, 400)]                                     # one view: no rate
    got = window_rates(windows, views, settle=0.15)
    assert [w.listening for w in got] == [False, True, False]
    assert got[0].rate == pytest.approx(100 / 0.5) and got[1].rate == pytest.approx(90 / 0.5)
    assert got[2].rate is None


def test_a_machine_that_speeds_up_does_not_hide_a_steady_cost_from_the_windows():
    from bench.bench_record_windows import paired_slowdowns

    # the machine goes from 300 to 700 ticks/s over the build; listening costs 5% in every window
    listening = [i % 2 == 1 for i in range(11)]
    rates = [(300 + 40 * i) * (0.95 if on else 1.0) for i, on in enumerate(listening)]
    got = paired_slowdowns(_windows(listening, rates))
    assert len(got) == 5 and got == pytest.approx([0.05] * 5)


def test_only_listening_windows_between_two_measured_windows_without_the_recorder_are_paired():
    from bench.bench_record_windows import paired_slowdowns

    listening = [True, False, True, False, True, False, True]  # the first and last have a neighbour on one side only
    rates = [1.0, 100.0, 90.0, 100.0, 80.0, None, 50.0]        # the window without a rate breaks the pair beside it
    assert paired_slowdowns(_windows(listening, rates)) == pytest.approx([1 - 90 / 100])


def test_the_median_s_interval_is_reproducible_and_holds_the_median():
    from bench.bench_record_windows import median_interval

    pairs = [0.01 * (i % 13) - 0.04 for i in range(101)]
    median, low, high = median_interval(pairs)
    assert median_interval(pairs) == (median, low, high)   # seeded: the same figures every time
    assert low <= median <= high
    with pytest.raises(ValueError, match="no pairs"):
        median_interval([])
