"""Scale (issue 15): what `conag run --agents N` shows, and many agents building at once."""

from __future__ import annotations

from conag.run import TickRate


def test_tick_rate_follows_the_last_seconds_and_restarts_with_a_new_world():
    now = [0.0]
    rate = TickRate(window=2.0, clock=lambda: now[0])
    assert rate.observe(0) is None  # one status: no rate yet
    for i in range(1, 5):  # 100 ticks/s for two seconds
        now[0] = 0.5 * i
        assert rate.observe(50 * i) == 100.0
    for i in range(5, 13):  # then 20 ticks/s: after the window only the new rate is left
        now[0] = 0.5 * i
        r = rate.observe(200 + 10 * (i - 4))
    assert r == 20.0
    now[0] += 0.5
    assert rate.observe(3) is None  # a lower tick: a world started again, counting anew
