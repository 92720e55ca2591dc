"""Navigation maps (paper §4.2.2 Eq. 1-2, A3): the distance field is the true
8-connected shortest path, equals the paper's spreading rule, and its gradient leads to a goal."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from agent_runtime.spreading import activation, distance_field, gradient_step, spread_iterative

SQRT2 = math.sqrt(2.0)


def free_cell(obstacles: np.ndarray, r: int, c: int) -> bool:
    n, m = obstacles.shape
    return 0 <= r < n and 0 <= c < m and not obstacles[r, c]


def legal_step(obstacles: np.ndarray, r: int, c: int, dr: int, dc: int) -> bool:
    """The movement rule, written out independently of the module: free target, and a
    diagonal only between two free flanking cells."""
    if (dr, dc) == (0, 0) or not free_cell(obstacles, r + dr, c + dc):
        return False
    return dr == 0 or dc == 0 or (free_cell(obstacles, r + dr, c) and free_cell(obstacles, r, c + dc))


def scipy_reference(goals: np.ndarray, obstacles: np.ndarray) -> np.ndarray:
    """Multi-source scipy Dijkstra on the grid graph built cell by cell."""
    n, m = goals.shape
    rows, cols, weights = [], [], []
    for r in range(n):
        for c in range(m):
            if obstacles[r, c]:
                continue
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    if legal_step(obstacles, r, c, dr, dc):
                        rows.append(r * m + c)
                        cols.append((r + dr) * m + c + dc)
                        weights.append(math.hypot(dr, dc))
    sources = [r * m + c for r, c in zip(*np.nonzero(goals)) if not obstacles[r, c]]
    if not sources:
        return np.full((n, m), np.inf)
    graph = csr_matrix((weights, (rows, cols)), shape=(n * m, n * m))
    return dijkstra(graph, directed=True, indices=sources, min_only=True).reshape(n, m)


def assert_fields_equal(a: np.ndarray, b: np.ndarray) -> None:
    np.testing.assert_array_equal(np.isinf(a), np.isinf(b))
    np.testing.assert_allclose(a[np.isfinite(a)], b[np.isfinite(b)], rtol=0, atol=1e-9)


@st.composite
def grids(draw, min_size: int = 5, max_size: int = 41):
    """Random maps: 0-40% obstacle cells and 1-5 goals (a goal may land on an obstacle)."""
    n = draw(st.integers(min_size, max_size))
    m = draw(st.integers(min_size, max_size))
    density = draw(st.floats(0.0, 0.4))
    n_goals = draw(st.integers(1, 5))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    obstacles = rng.random((n, m)) < density
    goals = np.zeros((n, m), bool)
    goals.flat[rng.choice(n * m, n_goals, replace=False)] = True
    return goals, obstacles


def serpentine(n: int) -> tuple[np.ndarray, np.ndarray]:
    """An n x n maze of full-width walls on odd rows, each open at alternating ends; the
    goal is top left, so the bottom row is about n * n / 2 steps away."""
    obstacles = np.zeros((n, n), bool)
    for i, r in enumerate(range(1, n - 1, 2)):
        obstacles[r, :] = True
        obstacles[r, n - 1 if i % 2 == 0 else 0] = False
    goals = np.zeros((n, n), bool)
    goals[0, 0] = True
    return goals, obstacles


# --- distance_field ----------------------------------------------------------------


@settings(max_examples=200, deadline=None)
@given(grids())
def test_distance_field_equals_scipy_dijkstra_on_the_same_graph(grid):
    goals, obstacles = grid
    assert_fields_equal(distance_field(goals, obstacles), scipy_reference(goals, obstacles))


def test_distance_field_values_on_an_open_map():
    goals = np.zeros((5, 7), bool)
    goals[2, 2] = goals[2, 6] = True
    dist = distance_field(goals, np.zeros((5, 7), bool))
    assert dist[2, 2] == 0 and dist[2, 6] == 0
    assert dist[2, 3] == 1 and dist[1, 1] == pytest.approx(SQRT2)
    assert dist[0, 0] == pytest.approx(2 * SQRT2)
    assert dist[0, 4] == pytest.approx(2 * SQRT2)  # equidistant from both goals
    assert dist[4, 5] == pytest.approx(1 + SQRT2)  # the nearer goal wins
    assert dist.dtype == np.float64 and dist.shape == (5, 7)


def test_distance_field_accepts_any_truthy_arrays_and_views():
    goals, obstacles = serpentine(9)
    expected = distance_field(goals, obstacles)
    assert_fields_equal(distance_field(goals.astype(int), obstacles.astype(np.uint8)), expected)
    assert_fields_equal(distance_field(goals.T, obstacles.T), expected.T)  # non-contiguous views


def test_distance_field_rejects_mismatched_shapes():
    with pytest.raises(ValueError):
        distance_field(np.zeros((4, 5), bool), np.zeros((5, 4), bool))


def test_no_goal_means_every_cell_is_unreachable():
    dist = distance_field(np.zeros((6, 6), bool), np.zeros((6, 6), bool))
    assert np.isinf(dist).all()
    assert gradient_step(dist) is None


# --- the paper's rule: Eq. 1-2 iterated ----------------------------------------------


@settings(max_examples=60, deadline=None)
@given(grids(), st.sampled_from(["default", 0.02, 0.15]))
def test_paper_rule_iterated_equals_activation_of_distance_field(grid, decay):
    goals, obstacles = grid
    decay = 1 / (2 * max(goals.shape)) if decay == "default" else decay
    expected = activation(distance_field(goals, obstacles), decay, obstacles=obstacles)
    np.testing.assert_allclose(spread_iterative(goals, obstacles, decay), expected, rtol=0, atol=1e-9)


def test_activation_levels_of_eq_1_2():
    goals, obstacles = np.zeros((7, 7), bool), np.zeros((7, 7), bool)
    goals[0, 0] = True
    obstacles[3, :3] = obstacles[:3, 3] = True  # closes the top-left 3 x 3 corner
    obstacles[5, 5] = True
    dist = distance_field(goals, obstacles)
    act = activation(dist, obstacles=obstacles)
    assert act[0, 0] == 1
    assert (act[obstacles] == -1).all()
    outside = ~obstacles
    outside[:3, :3] = False
    assert (act[outside] == 0).all()  # free but cut off from the goal
    corner = act[:3, :3]
    assert ((corner > 0) & (corner <= 1)).all()
    np.testing.assert_allclose(act[:3, :3], 1 - dist[:3, :3] / 14)  # default decay 1 / (2 * 7)
    # Without the obstacle map an inf cell cannot be told apart: it reads 0.
    assert activation(dist)[5, 5] == 0


def test_default_decay_keeps_every_reachable_cell_positive_even_in_a_maze():
    goals, obstacles = serpentine(41)
    dist = distance_field(goals, obstacles)
    assert dist[np.isfinite(dist)].max() > 2 * 41  # longer than 1 / (2 * max(N, M)) allows
    act = activation(dist, obstacles=obstacles)
    reachable = np.isfinite(dist)
    assert (act[reachable] > 0).all()
    # and still strictly ordered by distance, so the gradient survives
    order = np.argsort(dist[reachable], kind="stable")
    assert (np.diff(act[reachable][order]) <= 0).all()


def test_too_large_a_decay_floors_far_cells_at_zero_like_eq_2():
    goals, obstacles = np.zeros((1, 12), bool), np.zeros((1, 12), bool)
    goals[0, 0] = True
    act = activation(distance_field(goals, obstacles), 0.25)
    np.testing.assert_allclose(act[0, :6], [1, 0.75, 0.5, 0.25, 0, 0])
    np.testing.assert_allclose(spread_iterative(goals, obstacles, 0.25), act)


# --- gradient_step -------------------------------------------------------------------


def follow(dist: np.ndarray, obstacles: np.ndarray, start: tuple[int, int]) -> int:
    """Walk the gradient from `start` to a goal, checking every step; return the steps."""
    r, c = start
    for steps in range(dist.size + 1):
        move = gradient_step(dist, (r, c))
        if move == (0, 0):
            assert dist[r, c] == 0
            return steps
        assert move is not None
        dr, dc = move
        assert legal_step(obstacles, r, c, dr, dc), f"illegal step {move} from {(r, c)}"
        # strictly downhill, and by exactly the step length: the move is on a shortest path
        assert dist[r + dr, c + dc] < dist[r, c]
        assert dist[r, c] - dist[r + dr, c + dc] == pytest.approx(math.hypot(dr, dc), abs=1e-9)
        r, c = r + dr, c + dc
    raise AssertionError(f"no goal after {dist.size} steps from {start}")


@settings(max_examples=60, deadline=None)
@given(grids(), st.integers(0, 2**32 - 1))
def test_following_the_gradient_reaches_a_goal_from_any_reachable_cell(grid, seed):
    goals, obstacles = grid
    dist = distance_field(goals, obstacles)
    cells = np.argwhere(np.isfinite(dist))
    rng = np.random.default_rng(seed)
    for r, c in cells[rng.permutation(len(cells))[:25]]:
        assert follow(dist, obstacles, (int(r), int(c))) <= goals.size
    for r, c in np.argwhere(np.isinf(dist)):
        assert gradient_step(dist, (int(r), int(c))) is None


def test_gradient_step_defaults_to_the_map_centre():
    goals, obstacles = np.zeros((9, 9), bool), np.zeros((9, 9), bool)
    goals[4, 8] = True
    dist = distance_field(goals, obstacles)
    assert gradient_step(dist) == (0, 1)  # from (4, 4), east
    goals[4, 4] = True
    assert gradient_step(distance_field(goals, obstacles)) == (0, 0)  # on a goal
    with pytest.raises(ValueError):
        gradient_step(dist, (9, 0))


@pytest.mark.parametrize(("goal_cells", "move"), [
    ([(3, 4)], (0, 1)),  # E then SE ties with SE then E: orthogonal first
    ([(4, 3)], (1, 0)),  # S then SE ties with SE then S
    ([(2, 0), (2, 4)], (0, 1)),  # W and E tie: E comes before W
    ([(0, 2), (4, 2)], (-1, 0)),  # N and S tie: N comes first
    ([(0, 0), (4, 4)], (1, 1)),  # NW and SE tie: SE comes before NW
])
def test_gradient_ties_are_broken_orthogonal_first_then_in_a_fixed_order(goal_cells, move):
    goals = np.zeros((5, 5), bool)
    for cell in goal_cells:
        goals[cell] = True
    dist = distance_field(goals, np.zeros((5, 5), bool))
    for _ in range(3):  # deterministic
        assert gradient_step(dist, (2, 2)) == move


# --- obstacles never radiate ---------------------------------------------------------


def ring_map() -> tuple[np.ndarray, np.ndarray]:
    """11 x 11, goals in two corners, a closed ring of obstacles around rows/cols 4-6."""
    goals, obstacles = np.zeros((11, 11), bool), np.zeros((11, 11), bool)
    goals[0, 0] = goals[10, 10] = True
    obstacles[3:8, 3] = obstacles[3:8, 7] = obstacles[3, 3:8] = obstacles[7, 3:8] = True
    return goals, obstacles


def test_activation_does_not_leak_through_a_ring_of_obstacles():
    goals, obstacles = ring_map()
    dist = distance_field(goals, obstacles)
    assert np.isinf(dist[4:7, 4:7]).all()
    assert np.isfinite(dist[~obstacles][:10]).all() and np.isfinite(dist[0, 5])
    for act in (activation(dist, obstacles=obstacles), spread_iterative(goals, obstacles, 0.05)):
        assert (act[4:7, 4:7] == 0).all()
        assert (act[obstacles] == -1).all()
    assert gradient_step(dist, (5, 5)) is None


def test_a_wall_beside_a_goal_does_not_relay_its_activation():
    goals, obstacles = np.zeros((7, 7), bool), np.zeros((7, 7), bool)
    goals[0, 2] = True
    obstacles[:6, 3] = True  # a wall beside the goal, open only at the bottom row
    dist = distance_field(goals, obstacles)
    assert dist[0, 4] > 10  # the long way round, not 2 through the wall
    assert_fields_equal(dist, scipy_reference(goals, obstacles))


def block_map() -> tuple[np.ndarray, np.ndarray]:
    """9 x 9, a goal in a corner and a 3 x 3 block of obstacles in the middle."""
    goals = np.zeros((9, 9), bool)
    goals[0, 0] = True
    return goals, np.pad(np.ones((3, 3), bool), 3)


@pytest.mark.parametrize("grid", [ring_map(), block_map()], ids=["ring", "block"])
def test_a_cell_beside_an_obstacle_is_never_a_false_maximum(grid):
    goals, obstacles = grid
    dist = distance_field(goals, obstacles)
    padded = np.pad(obstacles, 1)
    beside = np.zeros_like(obstacles)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            beside |= padded[1 + dr:1 + dr + obstacles.shape[0], 1 + dc:1 + dc + obstacles.shape[1]]
    cells = np.argwhere(beside & ~obstacles & np.isfinite(dist) & ~goals)
    assert len(cells) > 10
    for act in (activation(dist, obstacles=obstacles), spread_iterative(goals, obstacles, 1 / 22)):
        for r, c in cells:
            uphill = [act[r + dr, c + dc] for dr in (-1, 0, 1) for dc in (-1, 0, 1)
                      if legal_step(obstacles, r, c, dr, dc)]
            assert max(uphill) > act[r, c], f"{(r, c)} beside an obstacle is a local maximum"


# --- no corner cutting, obstacle on a goal ---------------------------------------------


def test_two_obstacles_touching_diagonally_block_the_diagonal_passage():
    goals, obstacles = np.zeros((3, 3), bool), np.zeros((3, 3), bool)
    goals[0, 0] = True
    obstacles[0, 1] = obstacles[1, 0] = True  # the goal's only way out is between them
    dist = distance_field(goals, obstacles)
    assert dist[0, 0] == 0 and np.isinf(dist[1:, 1:]).all()
    assert gradient_step(dist, (1, 1)) is None
    assert (spread_iterative(goals, obstacles, 0.1)[1:, 1:] == 0).all()


def test_a_diagonal_line_of_obstacles_is_a_wall():
    n = 8
    goals, obstacles = np.zeros((n, n), bool), np.zeros((n, n), bool)
    goals[0, 0] = True
    rows, cols = np.indices((n, n))
    obstacles[rows + cols == n - 1] = True
    dist = distance_field(goals, obstacles)
    assert np.isfinite(dist[rows + cols < n - 1]).all()
    assert np.isinf(dist[rows + cols > n - 1]).all()


def test_one_diagonal_pair_forces_a_detour():
    goals, obstacles = np.zeros((6, 6), bool), np.zeros((6, 6), bool)
    goals[2, 2] = True
    obstacles[2, 3] = obstacles[3, 2] = True
    dist = distance_field(goals, obstacles)
    assert dist[3, 3] > SQRT2 + 1  # not the direct diagonal
    assert_fields_equal(dist, scipy_reference(goals, obstacles))
    assert gradient_step(dist, (3, 3)) != (-1, -1)


def test_an_obstacle_on_a_goal_cell_is_not_a_goal():
    goals, obstacles = np.zeros((5, 5), bool), np.zeros((5, 5), bool)
    goals[2, 2] = True
    obstacles[2, 2] = True
    dist = distance_field(goals, obstacles)
    assert np.isinf(dist).all()
    assert gradient_step(dist, (2, 2)) is None
    goals[0, 0] = True
    dist = distance_field(goals, obstacles)
    assert np.isinf(dist[2, 2]) and np.isfinite(dist[2, 3])
    assert_fields_equal(dist, scipy_reference(goals, obstacles))
    act = activation(dist, obstacles=obstacles)
    assert act[2, 2] == -1 and act[0, 0] == 1
    np.testing.assert_allclose(spread_iterative(goals, obstacles, 0.1), activation(dist, 0.1, obstacles=obstacles))
