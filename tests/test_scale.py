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


def test_border_seed_is_the_octile_distance_to_the_nearest_target_beyond_the_map():
    import math

    import numpy as np

    from agent_runtime.far_memory import border_seed

    n = 9
    obstacles = np.zeros((n, n), bool)
    obstacles[0, 4] = True  # a wall on the border: no seed there
    targets = np.array([[-3, 4], [4, 12]])  # 3 rows north of the map; 4 columns east
    seed = border_seed(targets, n, obstacles)
    assert np.isinf(seed[0, 4]) and np.isinf(seed[4, 4])  # walls and inner cells get none
    assert seed[0, 3] == 3 + (math.sqrt(2) - 1) * 1  # 3 rows, 1 column away
    assert seed[4, 8] == 4.0  # straight east to the second target
    assert seed[8, 0] == min(11 + (math.sqrt(2) - 1) * 4, 12 + (math.sqrt(2) - 1) * 4)
    assert border_seed(np.zeros((0, 2), np.int64), n, obstacles) is None
